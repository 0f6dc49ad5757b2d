"""Golden closed-loop data: every classical agent on its env's paper scenarios and on two
seeds of the out-of-distribution ``ood`` scenario, recorded step by step.

The data in this folder is the safety net for changes that must not change the physics or
the controllers (a new layout, a faster implementation): ``test_golden.py`` replays every
case and compares it with the recording. When the physics or a controller changes on
purpose, regenerate the data and commit it with the change that explains it::

    python -m tests.golden.record            # rewrites tests/golden/*.npz

Each file holds, for one episode, the observations, actions, rewards, terminations and
every numeric ``info`` signal (row 0 is the reset): the values at up to ``KEEP_ROWS``
evenly spaced steps (always the last one) and a SHA-256 digest of every signal over all
steps, so that a replay is checked bit for bit on every step while the files stay small
(the full trajectories take about 30 MB).

Each file also stores the fingerprint of the machine it was recorded on
(:func:`machine_fingerprint`: the processor's features numpy dispatches on, the versions
of numpy, OpenBLAS and its kernel, numba, llvmlite, the C library and Python). On a machine with the
same fingerprint the replay must give the same numbers to the last bit, digests included;
elsewhere ``test_golden.py`` compares the stored rows to a tolerance.

Only the public API is used here (env ids, ``from agents import ...``), so the cases stay
valid whatever the modules behind them are called, with one exception: the H-infinity
designs. Their synthesis at the optimal gamma leaves a near-degenerate controller whose
numbers depend on the BLAS kernels of the CPU (OpenBLAS's Haswell and Sandybridge kernels
give discrete controllers whose frequency responses differ by about 1e-3), far beyond the
1e-9 a replay allows. So a case also stores every design it synthesised
(``machining_envs.contouring.servo._hinf``, by its arguments), and the replay runs on the
stored designs: the data then checks the physics and the controllers' implementation on
any CPU, and ``test_golden.py`` checks a fresh synthesis against the stored designs with a
tolerance that fits its conditioning.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import json
import math
import platform
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np

import machining_envs  # noqa: F401  (registers the env ids)

HERE = Path(__file__).resolve().parent
#: Seeds of the ``ood`` scenario recorded for every agent (the widest ranges; ``test`` is
#: left to the benchmark's final table).
OOD_SEEDS = (1000, 1001)
#: Seed of the paper scenarios (their sensor noise is seeded too).
PAPER_SEED = 0
#: Rows kept in full per signal (evenly spaced, the last always among them).
KEEP_ROWS = 64


def _groups():
    """``(env id, env kwargs, paper scenarios, agent factories)`` of every recorded group."""
    import agents as a

    override_1 = functools.partial(a.ConstantOverride.from_env, override=1.0)
    override_1.__name__ = "ConstantOverride_1.0"
    drilling_papers = ("paper_0.5", "paper_0.6", "paper_0.7", "paper_0.8")
    contour_papers = ("paper_corner", "paper_circle", "paper_involute")
    return (
        (
            "machining_envs/Turning-v0",
            {},
            ("paper_245", "paper_405", "paper_700", "taper_405"),
            (a.ConstantFeed.from_env, a.FixedGainPI.from_env, a.VariableGainPI.from_env),
        ),
        (
            "machining_envs/EndMilling-v0",
            {},
            ("paper_step", "paper_taper"),
            (a.MillingConstantFeed.from_env, a.FixedGainIntegral.from_env, a.IntegralACC.from_env),
        ),
        (
            "machining_envs/MicroDrilling-v0",
            {},
            drilling_papers,
            (a.NoControl.from_env, a.PD.from_env, a.SlidingMode.from_env),
        ),
        # Peck drilling commands the feed of the stage, not the valve voltage.
        (
            "machining_envs/MicroDrilling-v0",
            {"control": "feed"},
            drilling_papers,
            (a.PeckDrilling.from_env,),
        ),
        (
            "machining_envs/Contouring-v0",
            {},
            ("paper_step", "paper_step_load", *contour_papers, "paper_circle_load"),
            (a.PIPosition.from_env, a.HInf2DOF.from_env),
        ),
        (
            "machining_envs/ContouringFeed-v0",
            {},
            contour_papers,
            (a.ConstantOverride.from_env, override_1),
        ),
    )


def _factory_name(factory) -> str:
    if isinstance(factory, functools.partial):
        return factory.__name__
    owner = getattr(factory, "__self__", None)  # a class's from_env: the class, not its base
    if isinstance(owner, type):
        return owner.__name__
    return factory.__qualname__.replace(".from_env", "")


def cases():
    """Every recorded case: ``(file stem, env id, env kwargs, agent factory, scenario, seed)``."""
    out = []
    for env_id, kwargs, papers, factories in _groups():
        env_name = env_id.split("/")[1]
        for factory in factories:
            runs = [(sc, PAPER_SEED) for sc in papers] + [("ood", s) for s in OOD_SEEDS]
            for sc, seed in runs:
                stem = f"{env_name}__{_factory_name(factory)}__{sc}__{seed}"
                out.append((stem, env_id, kwargs, factory, sc, seed))
    return out


#: The float arguments of ``servo._hinf`` (its third, ``axis``, is a string).
_HINF_FLOATS = (0, 1, 3, 4, 5, 6)
_DESIGN_ARRAYS = ("a", "b", "c", "d")


@contextlib.contextmanager
def hinf_designs(designs: list | None = None):
    """Within the block, ``servo._hinf`` is replaced: with ``designs`` None it synthesises,
    recording each new ``(args, design)`` in the yielded list; with a list of them it returns
    the stored design whose arguments match (floats to 1e-12 relative: a scenario's numbers
    may differ in the last bit between CPUs) and fails if there is none."""
    from machining_envs.contouring import servo

    synthesise = servo._hinf
    seen: list = [] if designs is None else designs

    def lookup(*args):
        for stored, design in seen:
            if stored[2] == args[2] and all(
                math.isclose(stored[i], args[i], rel_tol=1e-12, abs_tol=0.0) for i in _HINF_FLOATS
            ):
                return design
        if designs is not None:
            raise AssertionError(
                f"the case asked for an H-infinity design that was not recorded: {args}; "
                "regenerate the data if the physics changed on purpose"
            )
        design = synthesise(*args)
        seen.append((args, design))
        return design

    # The package's stored designs (machining_envs/contouring/hinf_designs.json) step
    # aside: a case runs on the designs it recorded, through ``servo._hinf``.
    shipped = servo._stored_designs
    servo._hinf = lookup
    servo._stored_designs = dict
    try:
        yield seen
    finally:
        servo._hinf = synthesise
        servo._stored_designs = shipped


def pack_designs(designs: list) -> dict:
    """The stored form of recorded ``(args, design)`` pairs (npz entries, no pickles)."""
    out = {"designs/n": np.array(len(designs))}
    for i, (args, d) in enumerate(designs):
        pre = f"designs/{i}/"
        out[pre + "args"] = np.array([args[j] for j in _HINF_FLOATS], dtype=np.float64)
        out[pre + "axis"] = np.array(args[2])
        for name in _DESIGN_ARRAYS:
            out[pre + name] = getattr(d, name)
        for j, m in enumerate(d.continuous):
            out[pre + f"continuous{j}"] = m
        out[pre + "gamma"] = np.array(d.gamma, dtype=np.float64)
        out[pre + "details"] = np.array(json.dumps(d.details))
    return out


def unpack_designs(golden: dict) -> list:
    """The ``(args, design)`` pairs a golden file stores (``[]`` for a file without)."""
    from machining_envs.contouring.servo import ServoDesign

    out = []
    for i in range(int(golden.get("designs/n", 0))):
        pre = f"designs/{i}/"
        f = golden[pre + "args"].tolist()
        args = (f[0], f[1], str(golden[pre + "axis"]), *f[2:])
        arrays = []
        for m in [golden[pre + n] for n in _DESIGN_ARRAYS] + [
            golden[pre + f"continuous{j}"] for j in range(4)
        ]:
            m = np.array(m, dtype=np.float64)
            m.setflags(write=False)
            arrays.append(m)
        design = ServoDesign(
            "hinf",
            args[2],
            args[1],
            *arrays[:4],
            continuous=tuple(arrays[4:]),
            gamma=float(golden[pre + "gamma"]),
            details=json.loads(str(golden[pre + "details"])),
        )
        out.append((args, design))
    return out


#: Info keys computed from other recorded signals, not recorded: each step's ``excess`` (the
#: force, torque or contour error over its limit, from the recorded signal, limit and cost)
#: and the scenario's ``overload_ratio`` (tests/core/test_severity.py checks both).
DERIVED_INFO = frozenset({"excess", "overload_ratio"})


def run_case(
    env_id: str, kwargs: dict, factory, scenario: str, seed: int, designs: list | None = None
) -> dict:
    """One closed-loop episode: observations, actions, rewards, terminations and every
    numeric ``info`` signal, as arrays (row 0 is the reset). The H-infinity designs are
    synthesised and recorded (``designs`` None; they are then in ``out["designs"]``) or
    taken from ``designs`` (:func:`hinf_designs`)."""
    with hinf_designs(designs) as used:
        out = _run_episode(env_id, kwargs, factory, scenario, seed)
    if designs is None and used:
        out["designs"] = used
    return out


def _run_episode(env_id: str, kwargs: dict, factory, scenario: str, seed: int) -> dict:
    env = gym.make(env_id, **kwargs)
    try:
        agent = factory(env)
        obs, info = env.reset(seed=seed, options={"scenario": scenario})
        n_act = env.action_space.shape
        obs_l, act_l, rew_l, term_l, trunc_l, info_l = [obs], [], [0.0], [0], [0], [info]
        act_l.append(np.full(n_act, np.nan, dtype=np.float32))
        state, start, done = None, np.ones(1, dtype=bool), False
        while not done:
            action, state = agent.predict(obs, state=state, episode_start=start)
            start = np.zeros(1, dtype=bool)
            obs, reward, terminated, truncated, info = env.step(action)
            obs_l.append(obs)
            act_l.append(np.asarray(action, dtype=np.float32).reshape(n_act))
            rew_l.append(float(reward))
            term_l.append(int(terminated))
            trunc_l.append(int(truncated))
            info_l.append(info)
            done = terminated or truncated
    finally:
        env.close()
    out = {
        "obs": np.array(obs_l),
        "action": np.array(act_l),
        "reward": np.array(rew_l, dtype=np.float64),
        "terminated": np.array(term_l, dtype=np.int8),
        "truncated": np.array(trunc_l, dtype=np.int8),
    }
    keys = sorted(
        k
        for k, v in info_l[-1].items()
        if isinstance(v, (bool, int, float, np.number)) and k not in DERIVED_INFO
    )
    for k in keys:
        out["info/" + k] = np.array([r.get(k, math.nan) for r in info_l], dtype=np.float64)
    return out


def machine_fingerprint() -> str:
    """What decides the last bits of a replay besides the code, as one JSON string: the
    processor's architecture and the features numpy picks its SIMD kernels by (its
    transcendental functions differ in the last bit between AVX2 and AVX-512), numpy's
    version, numpy's BLAS (its version and kernel: the plants' discretisation), numba's and
    llvmlite's versions (the kernels' code), the C library (libm: the kernels' ``pow``,
    ``sin``, ``hypot``...) and Python's version. Two machines with the same fingerprint
    replay a case alike: the compiled kernels keep IEEE arithmetic (no fast-math), so the
    processor's model beyond these features does not change their numbers."""
    import llvmlite
    import numba
    from threadpoolctl import threadpool_info

    try:
        from numpy._core._multiarray_umath import __cpu_features__ as features
    except ImportError:  # numpy's layout changed: the versions below still tell apart
        features = {}
    blas = [
        {k: str(i.get(k, "")) for k in ("internal_api", "version", "architecture")}
        for i in threadpool_info()
        if i.get("user_api") == "blas" and "numpy" in str(i.get("filepath", ""))
    ]
    return json.dumps(
        {
            "machine": platform.machine(),
            "cpu": sorted(k for k, on in features.items() if on),
            "numpy": np.__version__,
            "blas": blas,
            "numba": numba.__version__,
            "llvmlite": llvmlite.__version__,
            "libc": list(platform.libc_ver()),
            "python": platform.python_version(),  # math.hypot, float formatting
        },
        sort_keys=True,
    )


def digest(a: np.ndarray) -> str:
    """SHA-256 of an array's dtype, shape and bytes."""
    a = np.ascontiguousarray(a)
    h = hashlib.sha256(f"{a.dtype.str}{a.shape}".encode())
    h.update(a.tobytes())
    return h.hexdigest()


def kept_rows(n: int) -> np.ndarray:
    """The rows stored in full for an episode of ``n`` rows."""
    return np.unique(np.linspace(0, n - 1, min(n, KEEP_ROWS)).round().astype(np.int64))


def pack(data: dict) -> dict:
    """What a golden file stores for one episode (see the module docstring)."""
    data = dict(data)
    designs = data.pop("designs", [])
    n = len(data["reward"])
    rows = kept_rows(n)
    out = {"n_rows": np.array(n), "rows": rows, "machine": np.array(machine_fingerprint())}
    for k, v in data.items():
        out["rows/" + k] = v[rows]
        out["sha256/" + k] = np.array(digest(v))
    if designs:
        out.update(pack_designs(designs))
    return out


def main(argv=None) -> int:
    """Record every case, or with arguments only the cases whose name starts with one of
    them (``python -m tests.golden.record Turning-v0``), keeping the other files.

    With ``--keep-designs`` a case that has a file is recorded on the H-infinity designs
    that file stores, not on a fresh synthesis: the data of this machine for the same
    controllers (a fresh synthesis differs between BLAS kernels far beyond the replay's
    tolerance; ``record.py``'s docstring)."""
    args = list(sys.argv[1:] if argv is None else argv)
    keep = "--keep-designs" in args
    prefixes = tuple(a for a in args if a != "--keep-designs")
    kept: dict = {}
    for old in HERE.glob("*.npz"):
        if not prefixes or old.stem.startswith(prefixes):
            if keep:
                with np.load(old) as f:
                    kept[old.stem] = unpack_designs({k: f[k] for k in f.files})
            old.unlink()
    total = 0
    for stem, env_id, kwargs, factory, sc, seed in cases():
        if prefixes and not stem.startswith(prefixes):
            continue
        designs = kept.get(stem) or None
        data = run_case(env_id, kwargs, factory, sc, seed, designs=designs)
        if designs:
            data["designs"] = designs
        path = HERE / f"{stem}.npz"
        np.savez_compressed(path, **pack(data))
        total += path.stat().st_size
        print(f"{stem}: {len(data['reward'])} rows, {path.stat().st_size / 1024:.0f} KiB")
    print(f"{len(cases())} cases, {total / 2**20:.2f} MiB in {HERE}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
