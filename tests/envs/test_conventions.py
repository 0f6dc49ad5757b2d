"""The conventions every env keeps, written once and run on every id in
``machining_envs.ENV_IDS`` (MicroDrilling-v0 in both control modes).

What differs between the envs (the signal they regulate, the info keys they promise, their
command range, how many steps a check takes) is one row of ``CASES``; what each env does
beyond these conventions is tested in its process's folder (``tests/<process>/test_env.py``).
A new env id must get a row here: ``test_every_registered_id_has_a_case`` fails until it has.
"""

from __future__ import annotations

import pickle
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import machining_envs
from machining_envs import (
    ContouringEnv,
    ContouringFeedEnv,
    EndMillingEnv,
    MicroDrillingEnv,
    TurningEnv,
)
from tests.helpers import (
    CONTOURING,
    CONTOURING_FEED,
    DRILLING,
    MILLING,
    TURNING,
    random_rollout,
    random_steps,
    run_python,
)

#: Info keys every env reports, at reset and after every step.
SHARED_INFO_KEYS = frozenset(
    {"t_s", "command", "action_clipped", "n_action_clipped", "breakage", "diverged"}
)
#: Keys of the envs that regulate a cut (turning, milling, drilling): the measurement and the cut.
_CUT_KEYS = frozenset(
    {
        "measured",
        "feed_mm_per_rev",
        "depth_mm",
        "spindle_rpm",
        "position_mm",
        "finished",
        "segment",
        "cost",
        "score_bound",
    }
)


@dataclass(frozen=True)
class RandomRun:
    """Random actions (some out of the box) over random scenarios: nothing may go non-finite
    or leave the observation space, and at least ``min_resets`` episodes must end."""

    n_steps: int
    seed: int
    scenarios: tuple[str, ...]
    kwargs: dict = field(default_factory=dict)
    min_resets: int = 1


@dataclass(frozen=True)
class EnvCase:
    """One env (an id and its constructor keywords) and how the conventions drive it."""

    env_id: str
    env_class: type
    obs_dim: int
    #: The info signal the env is about (recorded by the seeded rollouts, in vector infos).
    signal: str
    #: Info keys the env promises beyond ``SHARED_INFO_KEYS``.
    info_keys: frozenset
    #: Named scenarios: every one passes the checkers and reports the info keys; the first
    #: is rendered and built directly (unless ``direct_kwargs`` names another).
    scenarios: tuple[str, ...]
    #: The commands an action of +5 (first component) and of -3 (last component) are
    #: clipped to, for the unwrapped env, and the info keys that show them.
    clip_commands: Callable[[gym.Env], tuple[float, float]]
    #: Keywords of the "time is up" case: constant ``action`` for ``n`` steps, the last
    #: one truncated and none terminated.
    truncation: tuple[dict, float, int]
    random_runs: tuple[RandomRun, ...]
    #: A misspelt constructor keyword and the one the error must suggest.
    misspelt: tuple[str, str]
    #: A term of the env's reward.
    reward_term: str
    kwargs: dict = field(default_factory=dict)
    act_dim: int = 1
    clip_keys: tuple[str, str] = ("command", "command")
    #: More constructor keywords the checkers must pass on.
    checker_variants: tuple[dict, ...] = ()
    #: Keywords for building the class directly (without ``gym.make``).
    direct_kwargs: dict = field(default_factory=dict)
    seed_steps: int = 1000
    #: Steps and constant action before pickling, then after it.
    pickle_run: tuple[int, float, int, float] = (20, 0.1, 30, 0.2)
    vector_run: tuple[int, float] = (20, 0.0)
    render_run: tuple[int, float] = (30, 0.0)

    @property
    def name(self) -> str:
        """The case's test id: the env id's name, then its constructor keywords' values."""
        return "-".join((self.env_id.split("/")[1], *map(str, self.kwargs.values())))

    def make(self, **kwargs) -> gym.Env:
        return gym.make(self.env_id, **{**self.kwargs, **kwargs})

    def action(self, value: float) -> np.ndarray:
        return np.full(self.act_dim, value, dtype=np.float32)


#: Turning and end milling: one feed command from 0 to the machine's maximum.
_CUT_REGULATION = dict(
    obs_dim=7,
    clip_commands=lambda env: (env.params.command_max, 0.0),
    truncation=({"max_episode_time_s": 2.0}, -1.0, 20),
    reward_term="tracking",
)
_DRILLING_SCENARIOS = ("train", "ood", "paper_0.5", "paper_0.8")
_DRILLING = dict(
    env_id=DRILLING,
    env_class=MicroDrillingEnv,
    obs_dim=12,
    signal="torque_Nmm",
    info_keys=_CUT_KEYS | {"torque_Nmm", "torque_limit_Nmm", "thrust_N", "spindle_hz"},
    scenarios=("paper_0.6", "paper_0.5", "paper_0.8"),
    misspelt=("torque_noise_nmm", "torque_noise_Nmm"),
    reward_term="tracking",
    pickle_run=(300, 0.1, 300, 0.2),  # past a noise block boundary (256 draws)
    render_run=(100, 0.0),
)
_CONTOURING = dict(
    signal="contour_error_mm",
    info_keys=frozenset(
        {"x_mm", "y_mm", "x_ref_mm", "y_ref_mm", "contour_error_mm", "finished", "segment"}
    ),
    scenarios=("paper_circle",),
    misspelt=("screw_led_mm", "screw_lead_mm"),
    pickle_run=(20, 0.01, 30, 0.01),
    vector_run=(10, 0.0),
)

CASES = (
    EnvCase(
        env_id=TURNING,
        env_class=TurningEnv,
        signal="force_N",
        info_keys=_CUT_KEYS | {"force_N", "force_limit_N"},
        scenarios=("paper_405", "paper_245"),
        random_runs=(
            RandomRun(100_000, 0, ("train", "ood", "paper_245", "paper_700", "step_range")),
        ),
        misspelt=("sensor_gian", "sensor_gain"),
        render_run=(30, -0.2),
        **_CUT_REGULATION,
    ),
    EnvCase(
        env_id=MILLING,
        env_class=EndMillingEnv,
        signal="torque_Nmm",
        info_keys=_CUT_KEYS | {"torque_Nmm", "torque_limit_Nmm"},
        scenarios=("paper_step", "paper_taper"),
        # Half the steps with each force model.
        random_runs=tuple(
            RandomRun(50_000, seed, ("train", "ood", "paper_step", "paper_taper"), kw)
            for seed, kw in enumerate(({}, {"force_model": "average_force"}))
        ),
        misspelt=("servo_gian", "servo_gain"),
        checker_variants=({"force_model": "average_force"},),
        pickle_run=(20, -0.8, 30, -0.7),
        vector_run=(20, -0.8),
        render_run=(30, -0.8),
        **_CUT_REGULATION,
    ),
    EnvCase(
        kwargs={"control": "voltage"},
        clip_commands=lambda env: (10.0, 0.0),
        truncation=({"max_episode_time_s": 0.2}, 0.0, 20),
        # Random voltages starve the spindle and break drills: episodes end often.
        random_runs=(RandomRun(100_000, 0, _DRILLING_SCENARIOS, min_resets=11),),
        **_DRILLING,
    ),
    EnvCase(
        kwargs={"control": "feed"},
        clip_commands=lambda env: (3.0, -3.0),
        truncation=({"max_episode_time_s": 0.2}, -0.1, 20),
        # Random feeds and retracts: episodes end by breakage or time.
        random_runs=(
            RandomRun(20_000, 1, _DRILLING_SCENARIOS, kwargs={"max_episode_time_s": 20.0}),
        ),
        **_DRILLING,
    ),
    EnvCase(
        kwargs={"control": "voltage_feed"},
        clip_keys=("voltage_V", "feed_velocity_mm_s"),
        clip_commands=lambda env: (10.0, -3.0),
        truncation=({"max_episode_time_s": 0.2}, 0.0, 20),
        random_runs=(
            RandomRun(20_000, 2, _DRILLING_SCENARIOS, kwargs={"max_episode_time_s": 20.0}),
        ),
        **{**_DRILLING, "obs_dim": 13},
        act_dim=2,
    ),
    EnvCase(
        env_id=CONTOURING,
        env_class=ContouringEnv,
        obs_dim=14,
        act_dim=2,
        clip_keys=("command_x_mm_s", "command_y_mm_s"),
        clip_commands=lambda env: (env.params.command_max_mm_s, -env.params.command_max_mm_s),
        truncation=({"max_episode_time_s": 0.01, "scenario": "paper_circle"}, 0.0, 50),
        # Short episodes (0.2 s) so that resets over every scenario kind happen often.
        random_runs=(
            RandomRun(
                100_000,
                0,
                ("train", "ood", "paper_step_load", "paper_circle", "paper_involute")
                + ("paper_corner",),
                {"max_episode_time_s": 0.2},
            ),
        ),
        reward_term="contour",
        direct_kwargs={"scenario": "paper_involute"},
        **_CONTOURING,
    ),
    EnvCase(
        env_id=CONTOURING_FEED,
        env_class=ContouringFeedEnv,
        obs_dim=16,
        clip_keys=("feed_override", "feed_override"),
        clip_commands=lambda env: (2.0, 0.0),
        truncation=({"max_episode_time_s": 0.2}, -1.0, 20),
        # 10^4 decisions are 5 x 10^5 servo periods.
        random_runs=(
            RandomRun(
                10_000,
                1,
                ("train", "ood", "paper_circle", "paper_involute", "paper_corner"),
                {"max_episode_time_s": 0.5},
            ),
        ),
        reward_term="progress",
        checker_variants=({"servo": "hinf"},),
        direct_kwargs={"scenario": "paper_involute", "servo": "hinf"},
        seed_steps=300,
        **_CONTOURING,
    ),
)

cases = pytest.mark.parametrize("case", CASES, ids=lambda c: c.name)


def test_every_registered_id_has_a_case():
    assert {c.env_id for c in CASES} == set(machining_envs.ENV_IDS)


@cases
def test_registered_and_listed(case):
    assert case.env_id in machining_envs.ENV_IDS
    assert case.env_id in gym.registry
    assert type(case.make().unwrapped) is case.env_class


@cases
def test_checkers_pass_without_warnings_on_the_declared_spaces(case):
    variants = [{}, *({"scenario": s} for s in case.scenarios), *case.checker_variants]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for kwargs in variants:
            gym_check_env(case.make(**kwargs).unwrapped)
        sb3_check_env(case.make().unwrapped, warn=True)
    env = case.make()
    assert env.observation_space.shape == (case.obs_dim,)
    assert env.action_space.shape == (case.act_dim,)
    assert np.all(env.action_space.low == -1.0) and np.all(env.action_space.high == 1.0)


@pytest.fixture(scope="module")
def fresh_interpreter_shapes():
    """Every case made by its prefixed id in one fresh interpreter, which imports nothing of
    ours itself: ``{case name: observation shape}`` as it prints them."""
    code = "\n".join(
        [
            "import sys",
            "import gymnasium as gym",
            "assert 'machining_envs' not in sys.modules",
            f"for name, env_id, kwargs in {[(c.name, c.env_id, c.kwargs) for c in CASES]!r}:",
            "    obs, info = gym.make('machining_envs:' + env_id, **kwargs).reset(seed=0)",
            "    print(name, obs.shape)",
        ]
    )
    return dict(line.split(" ", 1) for line in run_python(code).splitlines())


@cases
def test_make_without_import_in_fresh_interpreter(case, fresh_interpreter_shapes):
    assert fresh_interpreter_shapes[case.name] == str((case.obs_dim,))


@cases
def test_same_seed_bit_identical(case):
    a = random_rollout(case.make(), case.seed_steps, 7, case.signal)
    b = random_rollout(case.make(), case.seed_steps, 7, case.signal)
    for x, y in zip(a, b, strict=True):
        assert x.tobytes() == y.tobytes()
    c = random_rollout(case.make(), case.seed_steps, 8, case.signal)
    assert a[0].tobytes() != c[0].tobytes()


@cases
def test_pickle_mid_episode_continues_identically(case):
    warm_steps, warm_action, steps, action = case.pickle_run
    env = case.make()  # the "train" scenario
    env.reset(seed=3)
    for _ in range(warm_steps):
        env.step(case.action(warm_action))
    clone = pickle.loads(pickle.dumps(env))
    for _ in range(steps):
        o1, r1, *_ = env.step(case.action(action))
        o2, r2, *_ = clone.step(case.action(action))
        assert o1.tobytes() == o2.tobytes() and r1 == r2


@cases
def test_async_vector_env_runs(case):
    steps, action = case.vector_run
    envs = gym.vector.AsyncVectorEnv([case.make for _ in range(2)])
    try:
        obs, _ = envs.reset(seed=[1, 2])
        assert obs.shape == (2, case.obs_dim)
        for _ in range(steps):
            obs, rew, term, trunc, info = envs.step(np.stack([case.action(action)] * 2))
        assert np.all(np.isfinite(obs)) and np.all(np.isfinite(rew))
        assert case.signal in info
    finally:
        envs.close()


@cases
def test_info_keys_at_reset_and_after_a_step(case):
    keys = SHARED_INFO_KEYS | case.info_keys
    for scenario in case.scenarios:
        env = case.make(scenario=scenario)
        _, info = env.reset(seed=0)
        assert keys <= set(info), (scenario, keys - set(info))
        _, _, _, _, info = env.step(case.action(0.0))
        assert keys <= set(info), (scenario, keys - set(info))


@cases
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_action_raises_naming_the_env(case, bad):
    env = case.make().unwrapped
    env.reset(seed=0)
    act = case.action(0.0)
    act[0] = bad
    with pytest.raises(ValueError, match=case.env_class.__name__):
        env.step(act)


@cases
def test_out_of_box_action_is_clipped_and_counted(case):
    env = case.make().unwrapped
    # the first named scenario: a drawn one may be deep enough for full feed to end it
    env.reset(seed=0, options={"scenario": case.scenarios[0]})
    high_key, low_key = case.clip_keys
    high, low = case.clip_commands(env)
    act = np.zeros(env.action_space.shape)
    act[0] = 5.0
    _, _, _, _, info = env.step(act)
    assert info["action_clipped"] and info["n_action_clipped"] == 1
    assert info[high_key] == pytest.approx(high)
    act = np.zeros(env.action_space.shape)
    act[-1] = -3.0
    _, _, _, _, info = env.step(act)
    assert info["action_clipped"] and info["n_action_clipped"] == 2
    assert info[low_key] == pytest.approx(low)
    _, _, _, _, info = env.step(np.full(env.action_space.shape, 0.3))
    assert not info["action_clipped"] and info["n_action_clipped"] == 2


@cases
def test_bad_keywords_are_refused_naming_them(case):
    wrong, right = case.misspelt
    term = case.reward_term
    for kwargs, error, match in (
        ({"sample_time_s": 0.0}, ValueError, "sample_time_s"),
        ({"max_episode_time_s": 0}, ValueError, "max_episode_time_s"),
        ({"scenario": "nonexistent"}, ValueError, "scenario"),
        ({wrong: 1.0}, TypeError, f"{wrong}.*did you mean '{right}'"),
        ({"reward": {term[:-1]: 1.0}}, TypeError, term[:-1]),
        ({"reward": {term: -1.0}}, ValueError, term),
    ):
        with pytest.raises(error, match=match):
            case.make(**kwargs)


@cases
@pytest.mark.parametrize(
    "options, match",
    [({"scenario": "nonexistent"}, "scenario"), ({"scenery": "train"}, "reset options")],
)
def test_bad_reset_options_are_refused(case, options, match):
    env = case.make()
    with pytest.raises(ValueError, match=match):
        env.reset(options=options)


@cases
def test_truncation_by_time(case):
    kwargs, action, n = case.truncation
    env = case.make(**kwargs)
    env.reset(seed=0)
    for k in range(n):
        _, _, term, trunc, _ = env.step(case.action(action))
        assert not term
        assert trunc == (k == n - 1)


@cases
def test_render_rgb_array(case):
    steps, action = case.render_run
    env = case.make(render_mode="rgb_array", scenario=case.scenarios[0])
    env.reset(seed=0)
    for _ in range(steps):
        env.step(case.action(action))
    img = env.render()
    assert img.dtype == np.uint8 and img.ndim == 3 and img.shape[2] == 3
    assert img.std() > 0


@cases
def test_random_steps_never_nan_nor_leave_the_observation_space(case):
    for run in case.random_runs:
        bad, resets = random_steps(case.make(**run.kwargs), run.n_steps, run.seed, run.scenarios)
        assert bad == 0 and resets >= run.min_resets, (run, bad, resets)


@cases
def test_env_class_usable_directly(case):
    env = case.env_class(**{"scenario": case.scenarios[0], **case.kwargs, **case.direct_kwargs})
    obs, _ = env.reset(seed=1)
    assert env.observation_space.contains(obs)
