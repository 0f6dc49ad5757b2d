"""The identified physics of each process: numpy and scipy only, no gymnasium."""

from machining_envs.plants.milling import MillingParams, MillingPlant
from machining_envs.plants.turning import TurningParams, TurningPlant

__all__ = ["TurningParams", "TurningPlant", "MillingParams", "MillingPlant"]
