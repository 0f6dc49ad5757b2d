"""What every native vector env shares: N lanes of one process stepped as arrays.

A process's vector env subclasses :class:`LaneVectorEnv`. It holds its batched physics as
``self._core``, the process's core that its single env shares, and its default scenario
as ``self.default_scenario`` (from :meth:`LaneVectorEnv._lane_scenarios`). Through the
core's public hooks (:class:`machining_envs.core.lanes.LaneCore`) the base implements the
three methods of a step:

- ``_reset_lanes(lanes, options)``: start new episodes in the lanes ``lanes`` (an index
  array), drawing each lane's scenario from its own generator ``self.lane_rngs[i]``
  (``core.start(lane, spec, rng)``), and return their observations
  ``(len(lanes), *obs_shape)`` (from ``core.obs``, every lane's observation as it
  stands). A lane holds its reset info from the moment it starts: until its first step,
  ``_info_now()`` reports it for the lane (the single env's reset info is the same lane's
  info);
- ``_info_now()``: every lane's info as it stands (``core.info_arrays()``), as new arrays
  of length ``num_envs`` (a key that only some lanes have comes with a boolean mask under
  ``"_" + key``; the base adds the masks of the others to it);
- ``_step_lanes(actions)``: advance every lane by one control period with the checked
  actions ``(num_envs, *action_shape)`` (``core.set_actions``, ``core.step``); return
  observations, rewards, terminations, truncations and the step info in the same form.
  The arrays are new, not views of the lanes' state: they become the ``final_info`` of
  the lanes that end, which are reset after them.

A scenario (the constructor's ``scenario`` or ``reset(options={"scenario": ...})``) is one
for every lane, or a list of one per lane: lane ``i`` then runs the ``i``-th (a name is
drawn from the lane's own generator), as a sweep over operating points needs. The
constructor's is what a lane restarts with when its episode ends.

This base checks the actions (a non-finite action in any lane raises ``ValueError``
naming the lane, and nothing is stepped) and seeds lane ``i`` with ``seed + i`` exactly as
``env.reset(seed=seed + i)`` seeds the single env. What happens to a lane whose episode
ends is the ``autoreset_mode`` every vector env takes (Gymnasium's
:class:`~gymnasium.vector.AutoresetMode`, or its name as a string), declared in
``metadata["autoreset_mode"]``; in each mode a lane runs the episodes of the single env
with the same seed, as Gymnasium's ``SyncVectorEnv`` in that mode runs them:

- ``NEXT_STEP`` (the default, as Gymnasium's own; its vector wrappers such as
  ``NormalizeObservation`` require it): the step where a lane ends returns its last
  observation; the next step resets it instead of stepping it (its action is ignored,
  its reward is 0, it is neither terminated nor truncated, and its info is its reset
  info).
- ``SAME_STEP`` (what :class:`agents.rl.vec.SB3VecEnv` and the harness's batched rollouts
  need, and pass): the lane is reset in the step where it ends. The returned observation
  is its new episode's first; its last observation and info are in ``info["final_obs"]``
  and ``info["final_info"]``.
- ``DISABLED``: nothing is reset by itself. ``reset(options={"reset_mask": mask})`` resets
  the lanes where the boolean array ``mask`` is true (``seed``, if given, seeds those
  lanes only; the other lanes keep their observations, and the info's masks select the
  reset lanes); stepping a lane that ended without resetting it raises
  ``RuntimeError``, as the single env does.

Every vector env takes ``num_threads`` (default 1): its kernel then steps blocks of lanes on
that many threads at once (:mod:`machining_envs.core.compiled.blocks`; blocks of at least
``min_block`` lanes, so a small N runs on fewer), with the same numbers in every lane. The
rest of a step (the checks, resets, info) stays on the calling thread. No process's resets
call BLAS (its discretisations are compiled): OpenBLAS's threads spin on the cores for
about 0.1 ms after a call they take part in, which would slow the kernel's threads.
"""

from __future__ import annotations

import abc
import inspect
import math
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

from machining_envs.core.actions import real_actions
from machining_envs.core.checks import is_integer
from machining_envs.core.compiled.blocks import MIN_BLOCK, LaneBlocks, check_num_threads
from machining_envs.core.env import (
    check_scenario_spec,
    scenario_option,
)
from machining_envs.core.lanes import start_each
from machining_envs.core.metrics import note_severity

__all__ = [
    "LaneVectorEnv",
    "check_num_envs",
    "check_autoreset_mode",
    "check_vector_args",
    "first_scenario",
    "vector_signature",
]


def first_scenario(spec):
    """The first of a list or tuple of per-lane scenarios, else ``spec`` itself (what a
    vector env's core checks when it is built; the base checks the whole list)."""
    return spec[0] if isinstance(spec, (list, tuple)) and spec else spec


def check_autoreset_mode(mode) -> AutoresetMode:
    """``mode`` as an :class:`~gymnasium.vector.AutoresetMode`: the enum itself, or its
    name or value as a string (``"NEXT_STEP"``, ``"next_step"``, ``"NextStep"``, ...);
    anything else is a ``ValueError`` listing the three."""
    if isinstance(mode, AutoresetMode):
        return mode
    if isinstance(mode, str):
        for m in AutoresetMode:
            if mode in (m.name, m.name.lower(), m.value):
                return m
    raise ValueError(
        "autoreset_mode must be a gymnasium.vector.AutoresetMode or one of "
        f"{[m.name for m in AutoresetMode]}, got {mode!r}"
    )


def check_vector_args(env_name: str, num_threads, overrides: dict) -> int:
    """What a vector env's constructor checks before it builds anything: ``num_threads``
    (:func:`~machining_envs.core.compiled.blocks.check_num_threads`, returned as an int), and no
    ``render_mode`` among its other keyword arguments ``overrides`` (``None`` is taken:
    no rendering; the key is removed from ``overrides``, which go on to the core). A
    vector env keeps no lane's history to draw; the single env with the lane's seed
    replays the lane's episode and renders it."""
    mode = overrides.pop("render_mode", None)
    if mode is not None:
        raise ValueError(
            f"{env_name} (vector): render_mode={mode!r}, but the vector envs do not render "
            "(metadata['render_modes'] is empty); lane i after reset(seed=s) runs the episode "
            "of the single env after reset(seed=s + i): render that one, gym.make(id, "
            "render_mode=...)"
        )
    return check_num_threads(num_threads)


def check_num_envs(num_envs) -> int:
    """``num_envs`` as an int >= 1 (``TypeError`` / ``ValueError`` naming it otherwise)."""
    if not is_integer(num_envs):
        raise TypeError(f"num_envs must be an integer >= 1, got {num_envs!r}")
    if num_envs < 1:
        raise ValueError(f"num_envs must be an integer >= 1, got {num_envs}")
    return int(num_envs)


def _single_options(single_env: type, scenario, options: dict) -> dict:
    """The arguments of ``single_env`` a vector env of it is given: ``scenario`` (None: the
    single env's default) and the keyword ``options``, bound by name as the single env's
    ``__init__`` binds them (``TypeError`` for an argument it does not take; what its
    ``**overrides`` gathers under ``"overrides"``), with its defaults for the others."""
    given = {} if scenario is None else {"scenario": scenario}
    bound = inspect.signature(single_env).bind_partial(**given, **options)
    bound.apply_defaults()
    arguments = dict(bound.arguments)
    overrides = arguments.setdefault("overrides", {})
    if arguments.get("render_mode") is not None:
        overrides["render_mode"] = arguments["render_mode"]  # refused, by its name
    return arguments


def vector_signature(single_env: type) -> inspect.Signature:
    """The signature of a vector env of ``single_env``: ``num_envs``, then the single env's
    ``scenario`` and its options (keyword-only, with their defaults; not ``render_mode``),
    ``num_threads``, ``autoreset_mode`` and the single env's ``**overrides``."""
    P = inspect.Parameter
    single = inspect.signature(single_env).parameters.values()
    options = [p for p in single if p.name not in ("scenario", "render_mode")]
    keywords = [p.replace(kind=P.KEYWORD_ONLY) for p in options if p.kind is not P.VAR_KEYWORD]
    return inspect.Signature(
        [
            P("num_envs", P.POSITIONAL_OR_KEYWORD, default=1, annotation="int"),
            inspect.signature(single_env).parameters["scenario"],
            *keywords,
            P("num_threads", P.KEYWORD_ONLY, default=1, annotation="int"),
            P(
                "autoreset_mode",
                P.KEYWORD_ONLY,
                default=AutoresetMode.NEXT_STEP,
                annotation="AutoresetMode | str",
            ),
            *(p for p in options if p.kind is P.VAR_KEYWORD),
        ]
    )


class LaneVectorEnv(gym.vector.VectorEnv, abc.ABC):
    """Base of the native vector envs (see the module docstring).

    A process's vector env names its ``single_env`` and the ``core_cls`` they share.
    ``gym.make_vec(id, num_envs=N, **kwargs)`` then takes the keyword arguments of the
    single env (but not ``render_mode``; its signature shows them), ``num_threads``: the
    threads that step the lanes, and ``autoreset_mode``. Lane ``i`` after
    ``reset(seed=s)`` runs exactly the episode the single env runs after
    ``reset(seed=s + i)``, with the same observations, rewards and ``info`` (here a dict of
    arrays; a key only some lanes have comes with its ``_key`` mask); every lane draws its
    own scenario from its own generator. Finished lanes are reset at the next step by
    default, as Gymnasium's (``autoreset_mode``; also ``"SAME_STEP"`` or ``"DISABLED"``).
    """

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}
    #: Name used in error messages (the single env's class name).
    env_name: str = "LaneVectorEnv"
    #: Fewest lanes a thread steps (``core.compiled.blocks.block_edges``; a multiple of 64): a
    #: process whose kernel costs little a lane keeps the default, 128; one whose kernel
    #: costs more hands out smaller blocks, so that a few hundred lanes use more threads.
    min_block: int = MIN_BLOCK
    #: The env's task (``machining_envs.core.score.Task``, the single env's): its
    #: ``limit_keys`` give each step's ``excess`` (``core.metrics.note_severity``).
    task = None

    #: The single env this env runs N of (its class; set by every subclass): the vector env
    #: takes its options, by the same names and with the same defaults.
    single_env: type | None = None
    #: The process's core (a ``machining_envs.core.lanes.LaneCore``) the two envs share.
    core_cls: type | None = None

    def __init_subclass__(cls, **kwargs) -> None:
        super().__init_subclass__(**kwargs)
        single = cls.single_env
        if single is not None:  # its name (for messages), task and options are the env's
            cls.env_name, cls.task = single.__name__, single.task
            cls.__signature__ = vector_signature(single)

    def __init__(
        self,
        num_envs: int = 1,
        scenario=None,
        *,
        num_threads: int = 1,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        **options,
    ) -> None:
        """``num_envs`` lanes of ``single_env`` on ``scenario`` (None: the single env's
        default), whose keyword ``options`` are the single env's (but not ``render_mode``),
        with its defaults: a ``core_cls`` of ``num_envs`` lanes built from them
        (``LaneCore.from_options``), its kernel run on this env's blocks of lanes. The env
        has the attributes every vector env has: ``params``, ``command_map``,
        ``max_episode_time_s`` and ``default_scenario`` (``scenario``, checked: one for
        every lane or a list of one per lane), and those the subclass takes from the core
        (:meth:`_took`)."""
        given = _single_options(self.single_env, scenario, options)
        check_vector_args(self.env_name, num_threads, given["overrides"])
        n, scenario = check_num_envs(num_envs), given["scenario"]
        core = self.core_cls.from_options(type(self).__name__, n, first_scenario(scenario), given)
        self.num_envs = n
        #: What happens to a lane whose episode ends (see the module docstring).
        self.autoreset_mode = check_autoreset_mode(autoreset_mode)
        self.metadata = {**type(self).metadata, "autoreset_mode": self.autoreset_mode}
        #: The blocks of lanes the process's kernel steps at once, on ``num_threads``
        #: threads (the process's core runs its kernel through it).
        self.lane_blocks = LaneBlocks(self.num_envs, num_threads, self.min_block)
        self._core = core
        core.blocks = self.lane_blocks
        self.single_observation_space = core.observation_space
        self.single_action_space = core.action_space
        self.observation_space = batch_space(core.observation_space, self.num_envs)
        self.action_space = batch_space(core.action_space, self.num_envs)
        self.params = core.params
        self.command_map = core.command_map
        self.max_episode_time_s = core.max_episode_time_s
        self.render_mode = None
        #: The step info's keys (as ``_step_lanes`` returns them) -> the masks every lane
        #: gets and the (key, mask) pairs, worked out once per set of keys.
        self._mask_keys: dict[tuple, tuple] = {}
        self._every = np.ones(self.num_envs, dtype=bool)
        #: The default scenario last checked by :meth:`_reset_lanes` (not a list of them).
        self._default_ok = None
        self.lane_rngs: list[np.random.Generator] = [
            seeding.np_random()[0] for _ in range(self.num_envs)
        ]
        self._started = False
        #: Lanes whose episode ended at the last step and that have not been reset since
        #: (``NEXT_STEP``: reset at the next step; ``DISABLED``: not steppable).
        self._ended = np.zeros(self.num_envs, dtype=bool)
        #: Each lane's overload ceiling (its scenario's ``overload_ratio``), for the info.
        self._overload = np.full(self.num_envs, math.inf)
        self.default_scenario = self._lane_scenarios(scenario)

        self._took(core)

    def _took(self, core) -> None:
        """Give the env what it takes from its ``core`` besides the attributes every vector
        env has (the single env's public attributes of the process, say); by default
        nothing."""

    # ---- the command map, for classical agents -----------------------------------------
    def action_to_command(self, action):
        """The physical command for an action in [-1, 1] (``command_map``), as the single
        env's."""
        return self.command_map.action_to_command(action)

    def command_to_action(self, command):
        """The action in [-1, 1] for a physical command (``command_map``)."""
        return self.command_map.command_to_action(command)

    # ---- the VectorEnv interface ------------------------------------------------------------
    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ):
        """Start a new episode in every lane; ``seed`` (int: lane ``i`` gets ``seed + i``;
        or one seed per lane) and ``options`` (e.g. ``{"scenario": ...}``) as for the single
        env. With ``autoreset_mode=DISABLED``, ``options["reset_mask"]`` (a boolean array,
        one value per lane) resets only the lanes it marks (module docstring)."""
        if options is not None and not isinstance(options, dict):
            raise TypeError(f"options must be a dict or None, got {type(options).__name__}")
        mask = None
        if options is not None and "reset_mask" in options:
            mask = self._reset_mask(options["reset_mask"])
            options = {k: v for k, v in options.items() if k != "reset_mask"} or None
        lanes = np.arange(self.num_envs) if mask is None else np.flatnonzero(mask)
        # Everything is checked before any lane's generator is replaced: a refused reset
        # changes nothing, and the lanes' next autoresets draw what they would have.
        rngs = self._seeded(seed, lanes)
        if options is not None:
            self._lane_scenarios(scenario_option(options, self.default_scenario), lanes)
        for i, rng in rngs.items():
            self.lane_rngs[i] = rng
        obs = self._reset_lanes(lanes, options)
        self._started = True
        self._ended[lanes] = False
        info = self._info_now()
        self._with_masks(info)
        if mask is not None:  # the other lanes keep their observations; info of these only
            obs = self._core.obs.copy()  # every lane's observation as it stands
            for key in [k for k in info if k[0] == "_"]:
                info[key] = info[key] & mask
        return obs, info

    def _seeded(self, seed, lanes: np.ndarray) -> dict[int, np.random.Generator]:
        """The new generators of ``lanes`` for ``reset(seed=...)``, by lane (none for a
        lane whose seed is None); ``ValueError`` for a seed that is not one (no lane's
        generator has been replaced)."""
        if seed is None:
            return {}
        if is_integer(seed):
            seeds = [int(seed) + i for i in range(self.num_envs)]
        elif isinstance(seed, (list, tuple)) and len(seed) == self.num_envs:
            seeds = list(seed)
        else:
            raise ValueError(
                f"seed must be None, an int or a list of {self.num_envs} seeds, got {seed!r}"
            )
        rngs = {}
        for i in lanes.tolist():
            if seeds[i] is not None:
                try:
                    rngs[i] = seeding.np_random(seeds[i])[0]
                except gym.error.Error as err:
                    raise ValueError(f"{self.env_name} (vector): seed of lane {i}: {err}") from None
        return rngs

    def _reset_mask(self, mask) -> np.ndarray:
        """Check ``options["reset_mask"]``: only in ``DISABLED`` mode, after a first full
        reset, a boolean array of one value per lane with at least one true."""
        if self.autoreset_mode is not AutoresetMode.DISABLED:
            raise ValueError(
                f"{self.env_name} (vector): options['reset_mask'] resets some lanes only with "
                f"autoreset_mode=DISABLED; this env has {self.autoreset_mode.name}, which "
                "resets lanes itself"
            )
        if not self._started:
            raise RuntimeError(
                f"{self.env_name} (vector): reset() every lane before resetting some of them"
            )
        m = np.asarray(mask)
        if m.dtype != np.bool_ or m.shape != (self.num_envs,) or not m.any():
            raise ValueError(
                f"{self.env_name} (vector): options['reset_mask'] must be a boolean array of "
                f"shape ({self.num_envs},) with at least one True, got {mask!r:.80}"
            )
        return m

    def _lane_scenarios(self, spec, lanes: np.ndarray | None = None):
        """``spec`` checked: one scenario (an object or a name of the process's,
        ``core.scenario_types``) for every lane, returned as it is; or a list or tuple of
        one per lane, returned as a list, whose entries for ``lanes`` (all by default) are
        checked (a masked reset's list may hold anything, None say, for the lanes it leaves
        alone). ``ValueError`` names what is wrong, and the lane."""
        if not isinstance(spec, (list, tuple)):
            check_scenario_spec(spec, *self._core.scenario_types)
            return spec
        if len(spec) != self.num_envs:
            raise ValueError(
                f"{self.env_name} (vector): a list of scenarios must hold one per lane "
                f"({self.num_envs}), got {len(spec)}"
            )
        for i in range(self.num_envs) if lanes is None else lanes.tolist():
            try:
                check_scenario_spec(spec[i], *self._core.scenario_types)
            except ValueError as err:
                raise ValueError(f"{self.env_name} (vector): scenario of lane {i}: {err}") from None
        return list(spec)

    def _reset_lanes(self, lanes: np.ndarray, options: dict | None) -> np.ndarray:
        """Start new episodes in ``lanes``; their first observations (see the module
        docstring). Every scenario is checked before any lane starts: options refused
        change nothing. A start that raises (a scenario the lane's parameters refuse, such
        as a drawn limit above the tool's breakage) may leave lanes started part-way, so
        nothing steps until a ``reset()`` goes through."""
        core = self._core
        spec = self.default_scenario
        if options is not None or spec is not self._default_ok:
            spec = self._lane_scenarios(scenario_option(options, spec), lanes)
            if options is None and not isinstance(spec, list):
                self._default_ok = spec  # checked: the autoresets' scenario, as a rule
        try:
            if not isinstance(spec, list):
                core.start_lanes(lanes, spec, self.lane_rngs)
            else:
                start_each(core, lanes, spec, self.lane_rngs)
        except BaseException:
            self._started = False
            raise
        if isinstance(spec, list):
            self._overload[lanes] = [self._overload_of(spec[k]) for k in lanes.tolist()]
        else:
            self._overload[lanes] = self._overload_of(spec)
        return core.obs[lanes]  # their info is their reset info until they step (_info_now)

    def _step_lanes(self, actions: np.ndarray) -> tuple:
        """Advance every lane by one control period (see the module docstring)."""
        core = self._core
        core.set_actions(actions)
        core.step()
        reward, terminated, truncated = core.step_arrays()
        return (
            core.obs.copy(),
            reward.copy(),
            terminated.copy(),
            truncated.copy(),
            core.info_arrays(),
        )

    def _overload_of(self, spec) -> float:
        """The overload ceiling of a scenario spec: an object's ``overload_ratio``; a
        name's, the scenario class's default (the processes' named scenarios keep it)."""
        ratio = getattr(spec, "overload_ratio", None)
        if ratio is None:
            ratio = getattr(self._core.scenario_types[0], "overload_ratio", math.inf)
        return float(ratio)

    def _noted(self, info: dict) -> dict:
        """``info`` with each lane's ``excess`` and ``overload_ratio`` (the task's
        ``limit_keys``, :func:`machining_envs.core.metrics.note_severity`)."""
        keys = self.task.limit_keys if self.task is not None else None
        return note_severity(info, keys, self._overload.copy())

    def _info_now(self) -> dict:
        """Every lane's info as it stands, as new arrays (a key only some lanes hold comes
        with its ``_key`` mask); a lane just reset reports its reset info."""
        return self._noted(self._core.info_arrays())

    def _with_masks(self, info: dict) -> tuple:
        """Add to ``info`` (a new dict) the mask of every lane for each key that has none:
        one array, shared by those keys. Returns ``(masks added, keys but the masks, masks
        the keys came with)``, worked out once per set of keys (what :meth:`_final_info`
        reads)."""
        keys = tuple(info)
        known = self._mask_keys.get(keys)
        if known is None:
            masks = tuple("_" + k for k in keys if k[0] != "_" and "_" + k not in info)
            plain = tuple(k for k in keys if k[0] != "_")
            own = tuple("_" + k for k in plain if "_" + k in info)
            if len(self._mask_keys) >= 64:  # a few sets of keys occur; never let it grow
                self._mask_keys.clear()
            known = self._mask_keys[keys] = (masks, plain, own)
        info.update(dict.fromkeys(known[0], self._every.copy()))  # (np.ones costs more)
        return known

    @staticmethod
    def _final_info(info: dict, known: tuple, done: np.ndarray) -> dict:
        """The step's ``info`` (with its masks, :meth:`_with_masks`) as the final info of
        the lanes ``done``: every key's array, each mask and-ed with ``done`` (the masks
        that mark every lane are ``done`` itself, one array)."""
        masks, plain, own = known
        final = {k: info[k] for k in plain}
        final.update(dict.fromkeys(masks, done))
        for mk in own:
            final[mk] = info[mk] & done
        return final

    def step(self, actions):
        if not self._started:
            raise RuntimeError(f"{self.env_name} (vector): call reset() before step()")
        mode = self.autoreset_mode
        if mode is AutoresetMode.DISABLED and self._ended.any():
            raise RuntimeError(
                f"{self.env_name} (vector): the episodes of lanes "
                f"{np.flatnonzero(self._ended).tolist()} have ended; reset them "
                "(reset(options={'reset_mask': mask})) before step()"
            )
        shape = (self.num_envs, *self.single_action_space.shape)
        a = real_actions(actions, f"{self.env_name} (vector)")
        if a.shape != shape:
            # Only a batch that differs by dimensions of size 1 is reshaped ((N,) for
            # (N, 1)); one whose entries would move, a (2, N) batch for (N, 2) say, is refused.
            if [d for d in a.shape if d != 1] == [d for d in shape if d != 1]:
                a = a.reshape(shape)
            else:
                raise ValueError(
                    f"{self.env_name} (vector): actions must have shape {shape}, got {a.shape}"
                )
        if not np.isfinite(a).all():
            finite = np.isfinite(a).reshape(self.num_envs, -1).all(axis=1)
            lane = int(np.flatnonzero(~finite)[0])
            raise ValueError(
                f"{self.env_name} (vector): the action of lane {lane} is {a[lane].tolist()} "
                "(not finite); no lane was stepped"
            )
        if mode is not AutoresetMode.SAME_STEP:
            return self._step_without_same_step_reset(a)
        obs, reward, terminated, truncated, info = self._step_lanes(a)
        info = self._noted(info)
        known = self._with_masks(info)  # _step_lanes' dict is new at every step
        done = np.logical_or(terminated, truncated)
        if not done.any():
            return obs, reward, terminated, truncated, info
        lanes = np.flatnonzero(done)
        final_obs = np.empty(self.num_envs, dtype=object)  # all None
        for i, row in zip(lanes.tolist(), obs[lanes], strict=True):  # rows of one copy
            final_obs[i] = row
        # The step's info arrays are the final info; _reset_lanes does not write to them,
        # nor to obs, the step's own new array (_step_lanes), which takes the first ones.
        obs[lanes] = self._reset_lanes(lanes, None)
        final_info = self._final_info(info, known, done)
        top = self._info_now()  # every lane's info again: the reset lanes' is their reset info
        self._with_masks(top)
        top["final_obs"], top["_final_obs"] = final_obs, done.copy()
        top["final_info"], top["_final_info"] = final_info, done.copy()
        return obs, reward, terminated, truncated, top

    def _step_without_same_step_reset(self, a: np.ndarray):
        """``step`` in the ``NEXT_STEP`` and ``DISABLED`` modes (module docstring)."""
        pending = np.flatnonzero(self._ended)  # NEXT_STEP: lanes to reset instead of step
        # The kernel steps every lane: a pending lane takes one step past its episode's end,
        # which its reset below undoes. Its generator is put back first, so that the reset
        # draws what the single env's reset after the end draws.
        states = [self.lane_rngs[i].bit_generator.state for i in pending.tolist()]
        obs, reward, terminated, truncated, info = self._step_lanes(a)
        info = self._noted(info)
        if pending.size:
            for i, state in zip(pending.tolist(), states, strict=True):
                self.lane_rngs[i].bit_generator.state = state
            obs[pending] = self._reset_lanes(pending, None)
            reward[pending] = 0.0
            terminated[pending] = False
            truncated[pending] = False
            info = self._info_now()  # the reset lanes report their reset info
        self._with_masks(info)
        self._ended = np.logical_or(terminated, truncated)
        return obs, reward, terminated, truncated, info

    def close_extras(self, **kwargs) -> None:
        blocks = getattr(self, "lane_blocks", None)  # None: the constructor raised before it
        if blocks is not None:
            blocks.close()
