"""Replay every golden case (``tests/golden/record.py``) and compare it with its recording.

The comparison is bit for bit on the kind of CPU the data was recorded on: same signals,
same number of steps, the stored rows equal to the last bit and the SHA-256 digest of every
signal over all steps equal. A change that only moves code or reorganises it must keep that.
numpy picks its SIMD kernels for the transcendental functions (exp, sin, power, ...) by the
CPU it runs on, and its AVX-512 kernels differ from the AVX2 ones in the last bit or two;
where the stored rows are not bit-equal for that reason, they must still agree to 1e-9
relative (1e-12 absolute), and the digests, which cannot see a last-bit change from a real
one, are then not compared. When the physics or a controller changes on
purpose, regenerate the data (``python -m tests.golden.record``) in the same commit and say
why in its message.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.golden.record import HERE, cases, digest, kept_rows, run_case

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


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_replay_matches_recording(case):
    stem, env_id, kwargs, factory, scenario, seed = case
    with np.load(HERE / f"{stem}.npz") as f:
        golden = {k: f[k] for k in f.files}
    data = run_case(env_id, kwargs, factory, scenario, seed)

    recorded = sorted(k.removeprefix("sha256/") for k in golden if k.startswith("sha256/"))
    assert sorted(data) == recorded, "the recorded signals changed"
    assert len(data["reward"]) == int(golden["n_rows"]), "the episode length changed"
    rows = kept_rows(len(data["reward"]))
    np.testing.assert_array_equal(rows, golden["rows"])
    exact = all(np.array_equal(v[rows], golden["rows/" + k]) for k, v in data.items())
    for key, values in data.items():
        # Where a stored row differs, this names the signal, the rows and the size of the change.
        if values.dtype.kind == "f":
            np.testing.assert_allclose(
                values[rows], golden["rows/" + key], rtol=1e-9, atol=1e-12, err_msg=key
            )
        else:
            np.testing.assert_array_equal(values[rows], golden["rows/" + key], err_msg=key)
    if not exact:  # another CPU's SIMD kernels: last-bit differences, checked above
        return
    for key, values in data.items():
        assert digest(values) == str(golden["sha256/" + key]), (
            f"{key}: equal on the stored rows but not bit for bit on every step"
        )
