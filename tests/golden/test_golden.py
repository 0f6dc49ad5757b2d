"""Replay every golden case (``tests/golden/record.py``) and compare it with its recording.

The comparison is bit for bit on a machine like the one the data was recorded on (the same
``record.machine_fingerprint``, which each file stores): same signals, same number of steps,
the stored rows equal to the last bit and the SHA-256 digest of every signal over all steps
equal. A change that only moves code or reorganises it must keep that.
numpy picks its SIMD kernels for the transcendental functions (exp, sin, power, ...) by the
CPU it runs on, and its AVX-512 kernels differ from the AVX2 ones in the last bit or two,
as OpenBLAS's kernels do in the small products that discretise the plants. On another
machine, every float signal must still agree to 1e-9 of its
own scale (the largest magnitude of its stored rows, per column; a last-bit change in a
coefficient moves a signal in proportion to its size, not to each value, which may pass
through zero; for a component of a larger quantity, that quantity's size: ``SCALE_OF``),
float32 signals (observations, actions) to one float32 step at that scale
(a last-bit change may move a float32 rounding by one step), and the digests, which cannot
see a last-bit change from a real one, are then not compared. Where the agent's
observations themselves differ by more than that step, a last-bit change has flipped an
observation's float32 rounding and the agent acted on it: from there the closed loop
carries the change, and every signal need only agree to ``LOOP_RTOL`` of its scale (see
there). The H-infinity designs a case
uses are replayed from the file (``record.py`` says why); a fresh synthesis is checked
against them separately, to the tolerance its conditioning allows. When the physics or a
controller changes on purpose, regenerate the data (``python -m tests.golden.record``) in
the same commit and say why in its message.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.golden.record import (
    HERE,
    cases,
    digest,
    kept_rows,
    machine_fingerprint,
    run_case,
    unpack_designs,
)
from tests.helpers import servo_step_response

CASES = cases()


def test_every_case_has_its_file_and_no_file_is_stale():
    stems = {c[0] for c in CASES}
    files = {p.stem for p in HERE.glob("*.npz")}
    assert stems == files, (
        f"missing: {sorted(stems - files)}; stale: {sorted(files - stems)} "
        "(regenerate with `python -m tests.golden.record`)"
    )


def test_golden_data_stays_small():
    total = sum(p.stat().st_size for p in HERE.glob("*.npz"))
    assert total < 5 * 2**20, f"golden data takes {total / 2**20:.2f} MiB (budget 5 MiB)"


#: Signals that are a component of a larger quantity the case also records: the scale of
#: their rounding is that quantity's, not their own. A contouring motor torque sits at
#: +-1e-10 N m while its axis cruises (the difference of the controller's terms, each of
#: the size of the torques that accelerate it), so a last-bit change in a position moves
#: it by some 1e-10 N m, well past 1e-9 of the cruising rows; the torques the motors give
#: in the run (the root of ``torque_sq_Nm2``, both axes over a decision) are their scale.
SCALE_OF = {
    "info/torque_x_Nm": "info/torque_sq_Nm2",
    "info/torque_y_Nm": "info/torque_sq_Nm2",
}


#: The agreement, relative to each signal's scale, of a case whose observations differ
#: on another machine by more than one float32 step (module docstring). Measured: on a
#: second machine (16-core Xeon, Python 3.12, glibc 2.39, scipy 1.18.1) the contouring
#: table's positions differ in the last bit from the first periods on, under the same
#: commands, and in Contouring-v0 HInf2DOF on ``paper_corner`` (100 021 servo periods) an
#: observation's rounding first flipped at period 60 597; the H-infinity loop carried it
#: to 3.8e-7 of the scale by the end (contour error, commands, torques), every other case
#: staying below 1e-9. A flip at the first period could carry some 2.5 times as far in that case; 1e-5
#: leaves a tenfold margin over that and still fails any change of the physics or of a
#: controller, which moves these signals by far more.
LOOP_RTOL = 1e-5


def case_scale(key: str, golden: dict) -> float:
    """The least scale of ``key``'s rounding in a recorded case: 0, or from ``SCALE_OF``."""
    whole = SCALE_OF.get(key)
    if whole is None or "rows/" + whole not in golden:
        return 0.0
    return float(np.sqrt(np.nanmax(np.abs(golden["rows/" + whole]))))


def assert_close_to_scale(
    key: str,
    actual: np.ndarray,
    desired: np.ndarray,
    least_scale: float = 0.0,
    rtol: float | None = None,
) -> None:
    """``actual`` equals ``desired`` where it is not finite, and elsewhere within 1e-9 of
    each column's scale (float32: one float32 step at that scale), plus 1e-12; a column's
    scale is the largest magnitude of its recorded values, or ``least_scale`` if larger.
    With ``rtol``: within ``rtol`` of each column's scale instead (float32: at least one
    step)."""
    a, b = np.asarray(actual), np.asarray(desired)
    assert a.shape == b.shape, f"{key}: shape {a.shape}, recorded {b.shape}"
    finite = np.isfinite(b)
    np.testing.assert_array_equal(a[~finite], b[~finite], err_msg=key)
    scale = np.maximum(np.max(np.where(finite, np.abs(b), 0.0), axis=0), least_scale)
    if b.dtype == np.float32:
        tol = np.spacing(scale.astype(np.float32)).astype(np.float64)
    else:
        tol = 1e-9 * scale
    if rtol is not None:
        tol = np.maximum(tol, rtol * scale)
    tol = tol + 1e-12
    diff = np.where(finite, np.abs(a.astype(np.float64) - b.astype(np.float64)), 0.0)
    bad = diff > tol
    if bad.any():
        i = np.unravel_index(np.argmax(np.where(bad, diff / tol, 0.0)), diff.shape)
        raise AssertionError(
            f"{key}: {int(bad.sum())} of {b.size} stored values differ beyond tolerance; worst "
            f"at {tuple(int(v) for v in i)}: {a[i]!r} (recorded {b[i]!r}), difference "
            f"{diff[i]:.3e} > {np.broadcast_to(tol, diff.shape)[i]:.3e}"
        )


def test_assert_close_to_scale_fails_beyond_its_tolerance():
    """The comparison accepts a last-bit change and refuses anything larger."""
    b = np.array([[1e-11, 2.0], [0.5, -3.0], [np.nan, 1.0]])
    assert_close_to_scale("x", b * (1 + 1e-15), b)
    assert_close_to_scale("x", b + np.array([1e-12, 2e-9]), b)  # 1e-12 is 0.1 of column 0's tol
    with pytest.raises(AssertionError, match="differ beyond"):
        assert_close_to_scale("x", b + np.array([0.0, 4e-9]), b)
    # a component of a larger quantity: 1e-9 of that quantity's scale (here 5), not its own
    assert_close_to_scale("x", b + np.array([4e-9, 4e-9]), b, least_scale=5.0)
    with pytest.raises(AssertionError, match="differ beyond"):
        assert_close_to_scale("x", b + np.array([6e-9, 0.0]), b, least_scale=5.0)
    with pytest.raises(AssertionError):
        assert_close_to_scale("x", np.where(np.isnan(b), 0.0, b), b)
    f = b.astype(np.float32)
    assert_close_to_scale("x", np.nextafter(f, np.float32(np.inf)), f)
    with pytest.raises(AssertionError, match="differ beyond"):
        assert_close_to_scale("x", f * np.float32(1.001), f)


def compare_to_recording(data: dict, golden: dict, same_machine: bool) -> None:
    """Check a replay's signals ``data`` against a golden file's contents ``golden``: on the
    same machine every signal bit for bit (its stored rows, NaN included, and its digest
    over every step), elsewhere its stored rows to :func:`assert_close_to_scale`'s
    tolerance (integer signals exactly), ``LOOP_RTOL`` where the observations differ by
    more than a float32 step (the module docstring says why)."""
    recorded = sorted(k.removeprefix("sha256/") for k in golden if k.startswith("sha256/"))
    assert sorted(data) == recorded, "the recorded signals changed"
    assert len(data["reward"]) == int(golden["n_rows"]), "the episode length changed"
    rows = kept_rows(len(data["reward"]))
    np.testing.assert_array_equal(rows, golden["rows"])
    rtol = None
    if not same_machine:
        try:
            assert_close_to_scale("obs", data["obs"][rows], golden["rows/obs"])
        except AssertionError:  # an observation's rounding flipped: the loop carries it
            rtol = LOOP_RTOL
    for key, values in data.items():
        stored = golden["rows/" + key]
        if same_machine:
            assert values[rows].dtype == stored.dtype, key
            assert values[rows].tobytes() == stored.tobytes(), (
                f"{key}: a stored row differs on the machine it was recorded on"
            )
            assert digest(values) == str(golden["sha256/" + key]), (
                f"{key}: equal on the stored rows but not bit for bit on every step"
            )
        elif values.dtype.kind == "f":
            # Where a stored row differs, this names the signal, the rows and the change.
            assert_close_to_scale(key, values[rows], stored, case_scale(key, golden), rtol)
        else:
            np.testing.assert_array_equal(values[rows], stored, err_msg=key)


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_replay_matches_recording(case):
    stem, env_id, kwargs, factory, scenario, seed = case
    with np.load(HERE / f"{stem}.npz") as f:
        golden = {k: f[k] for k in f.files}
    data = run_case(env_id, kwargs, factory, scenario, seed, designs=unpack_designs(golden))
    same_machine = str(golden.get("machine", "")) == machine_fingerprint()
    compare_to_recording(data, golden, same_machine)


def test_the_comparison_is_bit_for_bit_on_the_recording_machine_only():
    """On the recording machine a last-bit change anywhere fails, on a stored row or on a
    step between them (the digest), and NaN equals NaN; elsewhere a last-bit change passes
    and a larger one fails."""
    from tests.golden.record import pack

    rng = np.random.default_rng(3)
    n = 300
    data = {
        "reward": rng.normal(size=n),
        "obs": rng.normal(size=(n, 3)).astype(np.float32),
        "terminated": np.zeros(n, dtype=np.int8),
        "info/machining_time_s": np.where(np.arange(n) == n - 1, 12.5, np.nan),
    }
    golden = pack(data)
    rows = set(kept_rows(n).tolist())
    between = next(i for i in range(1, n) if i not in rows)
    compare_to_recording(data, golden, same_machine=True)
    compare_to_recording(data, golden, same_machine=False)
    for row in (between, max(rows)):
        bumped = {k: v.copy() for k, v in data.items()}
        bumped["reward"][row] = np.nextafter(bumped["reward"][row], np.inf)
        with pytest.raises(AssertionError, match="reward"):
            compare_to_recording(bumped, golden, same_machine=True)
        compare_to_recording(bumped, golden, same_machine=False)
    bumped = {k: v.copy() for k, v in data.items()}
    bumped["reward"][max(rows)] += 1e-6
    with pytest.raises(AssertionError, match="reward"):
        compare_to_recording(bumped, golden, same_machine=False)
    # an observation a few float32 steps off (a flipped rounding the loop carried): every
    # signal to LOOP_RTOL of its scale, no further
    looped = {k: v.copy() for k, v in data.items()}
    scale = float(np.abs(looped["obs"][:, 0]).max())
    looped["obs"][max(rows), 0] += np.float32(4 * np.spacing(np.float32(scale)))
    with pytest.raises(AssertionError, match="obs"):
        assert_close_to_scale("obs", looped["obs"][sorted(rows)], golden["rows/obs"])
    looped["reward"][max(rows)] += 0.5 * LOOP_RTOL * float(np.abs(data["reward"]).max())
    compare_to_recording(looped, golden, same_machine=False)
    looped["reward"][max(rows)] += 2 * LOOP_RTOL * float(np.abs(data["reward"]).max())
    with pytest.raises(AssertionError, match="reward"):
        compare_to_recording(looped, golden, same_machine=False)


def _recorded_designs() -> list:
    """Every distinct H-infinity design the golden files store, ``(args, design)``."""
    seen: dict = {}
    for path in sorted(HERE.glob("*.npz")):
        with np.load(path) as f:
            golden = {k: f[k] for k in f.files}
        for args, design in unpack_designs(golden):
            seen.setdefault(args, design)
    return list(seen.items())


def test_hinf_synthesis_agrees_with_the_recorded_designs():
    """A fresh synthesis of every stored H-infinity design gives the same gamma and a closed
    loop that answers a unit step the same way, to 5e-3 of the step in position and of the
    peak in command. The synthesis sits at the optimal gamma, where the controller is
    nearly degenerate: two OpenBLAS kernels on one machine (Haswell, Sandybridge) give
    discrete controllers whose frequency responses differ by 1.3e-3 and step responses by
    5.7e-4 (position) and 4.9e-4 (command), so the tolerance is ten times what rounding
    alone moves; a change of the design itself (a weight, the model, rho) moves them by
    far more. Gamma comes out of the same bisection on both kernels; 1e-6 leaves it room."""
    from machining_envs.contouring import servo
    from machining_envs.contouring.plant import ContouringParams

    recorded = _recorded_designs()
    assert recorded, "no golden file stores an H-infinity design"
    for args, stored in recorded:
        fresh = servo._hinf(*args)  # synthesised on this machine (cached per process)
        assert fresh.gamma == pytest.approx(stored.gamma, rel=1e-6), args
        a_pole, ts = args[0], args[1]
        nominal = ContouringParams(sample_time_s=ts)
        plant = nominal.replace(inertia_x_kgm2=nominal.loop_gain_Nms / a_pole)
        # 0.1 s at 5 kHz: the step settles within it.
        y0, u0 = servo_step_response(plant, stored, 500, "x")
        y1, u1 = servo_step_response(plant, fresh, 500, "x")
        assert np.max(np.abs(y1 - y0)) <= 5e-3, args
        assert np.max(np.abs(u1 - u0)) <= 5e-3 * np.max(np.abs(u0)), args


#: Cases whose replay moved by up to 4e-6 of a signal's scale under another BLAS kernel
#: before the H-infinity designs were stored and the servo agents summed in a fixed order.
_KERNEL_CASES = (
    "Contouring-v0__HInf2DOF__ood__1001",
    "Contouring-v0__HInf2DOF__paper_circle_load__0",
    "ContouringFeed-v0__ConstantOverride__ood__1001",
)


def test_replay_holds_under_another_blas_kernel():
    """The replay does not depend on the machine's BLAS kernels: OpenBLAS picks them by the
    CPU, and ``OPENBLAS_CORETYPE=Sandybridge`` makes it take other ones here, as another
    machine would. Three sensitive cases replayed so in a fresh process."""
    env = {**os.environ, "OPENBLAS_CORETYPE": "Sandybridge"}
    probe = (
        "import numpy, threadpoolctl; "
        "print(*[i.get('architecture') for i in threadpoolctl.threadpool_info() "
        "if i['internal_api'] == 'openblas'])"
    )
    arch = subprocess.run(
        [sys.executable, "-c", probe], env=env, capture_output=True, text=True, check=True
    ).stdout.split()
    if "Sandybridge" not in arch:
        pytest.skip(f"numpy's BLAS does not take OPENBLAS_CORETYPE here (kernels: {arch})")
    ids = [f"{Path(__file__).name}::test_replay_matches_recording[{c}]" for c in _KERNEL_CASES]
    out = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *ids],
        cwd=Path(__file__).parent,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert out.returncode == 0 and f"{len(ids)} passed" in out.stdout, out.stdout[-3000:]
