"""Contouring scenarios: bad scenarios refused, drawn ones as checked (by name or object,
and the held-out sets: ``tests/envs/test_scenarios.py``)."""

import pytest

from machining_envs import ContouringScenario, Path


def test_bad_scenarios_name_the_field():
    with pytest.raises(ValueError, match="feed_mm_s"):
        ContouringScenario("x", Path.paper_circle(), feed_mm_s=-5.0)
    with pytest.raises(ValueError, match="inertia_scale"):
        ContouringScenario("x", Path.paper_circle(), 50.0, inertia_scale=(3.0, 1.0))
    with pytest.raises(ValueError, match="load_steps"):
        ContouringScenario("x", Path.paper_circle(), 50.0, load_steps=((0.1, 50.0, 0.0),))


def test_drawn_scenarios_are_what_the_checked_constructor_makes():
    """The random splits build their scenarios without re-checking what they drew (every
    lane pays it at each reset): the result equals the checked constructor's, and the true
    parameters equal ``replace``'s."""
    import dataclasses

    import numpy as np

    from machining_envs.contouring.plant import ContouringParams
    from machining_envs.contouring.scenarios import SHOPFLOOR_OVERRIDE, contouring_scenario

    nominal = ContouringParams()
    for split in ("train", "validation", "test", "ood", "shopfloor"):
        for seed in range(10):
            sc = contouring_scenario(split, np.random.default_rng(seed))
            fields = {f.name: getattr(sc, f.name) for f in dataclasses.fields(sc)}
            assert ContouringScenario(**fields) == sc
            assert sc.actuation is (SHOPFLOOR_OVERRIDE if split == "shopfloor" else None)
            sx, sy = sc.inertia_scale
            truth = sc.true_params(nominal)
            assert truth == nominal.replace(
                inertia_x_kgm2=nominal.inertia_x_kgm2 * sx,
                inertia_y_kgm2=nominal.inertia_y_kgm2 * sy,
            )
            assert hash(truth) == hash(dataclasses.replace(truth))
    # The inertias are still checked: a heavy nominal table scaled past the range.
    heavy = nominal.replace(inertia_x_kgm2=8.0)
    sc = ContouringScenario("x", Path.paper_circle(), 50.0, inertia_scale=(2.0, 1.0))
    with pytest.raises(ValueError, match="inertia_x_kgm2"):
        sc.true_params(heavy)
