r"""Identify a plant from measurements on your own machine: a few cuts in, parameters out.

Each function takes measured data, returns a fit object with the identified constants, a
goodness-of-fit figure and a parameter set the envs accept (``fit.params``), and rejects
data it cannot fit (too few cuts, non-positive or non-finite values, designs in which a
variable does not vary) with an :class:`IdentificationError` (a ``ValueError``) that says
what is wrong.

Cutting laws (log-linear least squares, as the papers fitted them):

- :func:`fit_turning_force`: ``F = Kf f^p a`` (Noh, Kim & Kim 1992, eq. 8) ->
  ``TurningParams``;
- :func:`fit_milling_torque`: ``T = Ks d^l f_t^m D`` (Park & Yoon 1986, eq. 8) ->
  ``MillingParams``;
- :func:`fit_power_law`: the general ``y = C prod x_j^{e_j}`` behind both.

Mean cutting forces of flat end mills (Ahn & Choi, seed 002):

- :func:`fit_calibration_matrix`: the 4 x 3 matrix [C] of eq. (6)-(7) by least squares,
  with ``predict`` for new cuts (eq. 8) and ``to_params`` for the average-force model;
- :func:`fit_cutting_coefficients`: Kt, Kr, Ka of eq. (1) from measured mean forces
  (eq. 2-4 generalised to several cuts by least squares) -> ``MillingParams``.

Feed servo (second order, gain ``K``, natural frequency ``wn``, damping ``zeta``):

- :func:`fit_servo`: from any measured command / response record (exact simulation of the
  model on the record's time grid, nonlinear least squares);
- :func:`fit_servo_step`, :func:`fit_servo_sine`: the usual step and sine tests.

>>> import numpy as np
>>> from machining_envs.identification import fit_milling_torque
>>> d, f = np.meshgrid([1.0, 2.0, 3.0], [0.025, 0.05, 0.075, 0.1])
>>> torque = 118 * 9.80665 * d**0.4236 * f**0.3999 * 16  # N·mm, eq. (8)
>>> fit = fit_milling_torque(d.ravel(), f.ravel(), torque.ravel())
>>> round(fit.coefficient, 3), round(fit.exponents["depth"], 4), round(fit.exponents["feed"], 4)
(118.0, 0.4236, 0.3999)
>>> fit.params.torque_coefficient_kgfmm == fit.coefficient
True
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm
from scipy.optimize import least_squares

from machining_envs.core.checks import is_real
from machining_envs.milling.plant import KGF, MillingParams, mean_forces
from machining_envs.turning.plant import TurningParams

__all__ = [
    "IdentificationError",
    "PowerLawFit",
    "fit_power_law",
    "fit_turning_force",
    "fit_milling_torque",
    "CalibrationFit",
    "fit_calibration_matrix",
    "CoefficientFit",
    "fit_cutting_coefficients",
    "ServoFit",
    "fit_servo",
    "fit_servo_step",
    "fit_servo_sine",
    "SEED_002_C",
    "SEED_002_CUTS",
    "TURNING_RECORD_COLUMNS",
    "TurningRecordFit",
    "read_turning_record",
    "fit_turning_record",
]

#: The calibration matrix [C] Ahn & Choi fitted on Al6061 (seed 002, eq. 9): rows are the
#: coefficients of (1, dr/R, da/R, ft), columns the mean forces Fx, Fy, Fz (N).
SEED_002_C = np.array(
    [
        [38.16, -306.42, 85.01],
        [-105.62, 172.68, -49.27],
        [39.99, 231.92, -49.53],
        [971.45, 2694.42, -770.39],
    ]
)

#: Their test conditions (seed 002, Table 1) as (dr, da, ft) with the 12 mm tool (R = 6 mm):
#: tests 1-6 calibrate [C], tests 7-9 confirm it. As printed: dr up to 15 exceeds the tool
#: diameter, so these are the inputs of the linear model of eq. (6), not cut geometries.
SEED_002_CUTS = {
    "calibration": np.array(
        [
            [15.0, 10.0, 0.05],
            [5.0, 10.0, 0.05],
            [10.0, 15.0, 0.05],
            [10.0, 5.0, 0.05],
            [10.0, 10.0, 0.025],
            [10.0, 10.0, 0.1],
        ]
    ),
    "confirmation": np.array([[10.0, 10.0, 0.05], [10.0, 7.5, 0.05], [10.0, 10.0, 0.075]]),
    "tool_radius_mm": 6.0,
}


class IdentificationError(ValueError):
    """The data cannot be fitted as given (the message says why and what to change)."""


# ---- input checks ---------------------------------------------------------------------------
def _vector(name: str, values, n: int | None = None, per: str = "cut") -> np.ndarray:
    try:
        a = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise IdentificationError(f"{name} must be a sequence of numbers, got {values!r}") from None
    if a.ndim == 0:
        a = a.reshape(1)
    if a.ndim != 1:
        raise IdentificationError(f"{name} must be one-dimensional, got shape {a.shape}")
    if n is not None and a.size != n:
        raise IdentificationError(f"{name} must hold {n} values (one per {per}), got {a.size}")
    bad = np.flatnonzero(~np.isfinite(a))
    if bad.size:
        raise IdentificationError(f"{name} must be finite; entry {bad[0]} is {a[bad[0]]!r}")
    return a


def _positive(name: str, a: np.ndarray) -> np.ndarray:
    bad = np.flatnonzero(a <= 0)
    if bad.size:
        raise IdentificationError(
            f"{name} must be > 0 for a power-law fit (it is taken in logarithms); "
            f"entry {bad[0]} is {a[bad[0]]!r}"
        )
    return a


def _params(base, **changes):
    try:
        return base.replace(**changes)
    except ValueError as exc:
        raise IdentificationError(
            f"the fitted values are outside what the plant accepts: {exc}"
        ) from None


# ---- power laws ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class PowerLawFit:
    """Result of a log-linear least-squares power-law fit ``y = C prod x_j^{e_j}``."""

    coefficient: float
    """C, in the units of the response (and of the parameter set's field)."""
    exponents: dict[str, float]
    """Fitted exponents by factor name (fixed ones included)."""
    std_errors: dict[str, float]
    """Standard errors of the fitted exponents and of ``log C`` (key ``"log_coefficient"``)."""
    r_squared: float
    """Coefficient of determination of the fit in log space (1 is perfect)."""
    rms_relative_error: float
    """Root-mean-square of ``y_fit / y - 1`` over the cuts."""
    n_points: int
    params: TurningParams | MillingParams | None = None
    """The parameter set with the fitted constants (``None`` for :func:`fit_power_law`)."""

    def predict(self, **factors) -> np.ndarray:
        """``C prod x_j^{e_j}`` at new values of the factors (all of them, by name)."""
        missing = set(self.exponents) - set(factors)
        if missing:
            raise TypeError(f"predict() needs every factor; missing {sorted(missing)}")
        extra = set(factors) - set(self.exponents)
        if extra:
            raise TypeError(f"predict() got unknown factors {sorted(extra)}")
        y = np.asarray(self.coefficient, dtype=np.float64)
        for k, e in self.exponents.items():
            y = y * np.asarray(factors[k], dtype=np.float64) ** e
        return y


def fit_power_law(
    response, factors: Mapping[str, object], fixed_exponents: Mapping[str, float] | None = None
) -> PowerLawFit:
    r"""Fit ``y = C \prod_j x_j^{e_j}`` by least squares on ``log y = log C + sum e_j log x_j``.

    Parameters
    ----------
    response : array (n,)
        Measured ``y`` (> 0), one per cut.
    factors : mapping name -> array (n,)
        The cut variables (> 0).
    fixed_exponents : mapping name -> float, optional
        Exponents held at known values (e.g. depth exponent 1 in ``F = Kf f^p a``); those
        factors are divided out before the fit.

    Raises
    ------
    IdentificationError
        Non-finite or non-positive values, fewer cuts than unknowns + 1, or a factor that
        does not vary independently of the others (rank-deficient design).
    """
    fixed = dict(fixed_exponents or {})
    if not factors:
        raise IdentificationError("factors must name at least one cut variable")
    unknown = set(fixed) - set(factors)
    if unknown:
        raise IdentificationError(f"fixed_exponents names unknown factors {sorted(unknown)}")
    for k, e in fixed.items():
        if not (is_real(e) and math.isfinite(e)):
            raise IdentificationError(f"fixed_exponents[{k!r}] must be a finite number, got {e!r}")
    y = _positive("response", _vector("response", response))
    n = y.size
    cols = {k: _positive(k, _vector(k, v, n)) for k, v in factors.items()}
    free = [k for k in cols if k not in fixed]
    n_unknown = len(free) + 1
    if n < n_unknown + 1:
        raise IdentificationError(
            f"need at least {n_unknown + 1} cuts to fit {n_unknown} constants with a "
            f"residual to judge the fit by, got {n}"
        )
    logy = np.log(y) - sum(e * np.log(cols[k]) for k, e in fixed.items())
    x = np.column_stack([np.ones(n)] + [np.log(cols[k]) for k in free])
    for j, k in enumerate(free, start=1):
        if np.ptp(x[:, j]) == 0.0:
            raise IdentificationError(
                f"{k} takes the same value in every cut, so its exponent cannot be fitted: "
                f"vary {k} across the cuts (or fix its exponent)"
            )
    if np.linalg.matrix_rank(x) < x.shape[1]:
        raise IdentificationError(
            f"the cuts do not vary {', '.join(free)} independently (rank-deficient design): "
            "change one variable at a time, or use a factorial or central composite design"
        )
    beta, *_ = np.linalg.lstsq(x, logy, rcond=None)
    resid = logy - x @ beta
    sst = float(np.sum((logy - logy.mean()) ** 2))
    sse = float(np.sum(resid**2))
    r2 = 1.0 - sse / sst if sst > 0 else 1.0
    dof = n - x.shape[1]
    cov = (sse / dof) * np.linalg.inv(x.T @ x)
    se = np.sqrt(np.maximum(np.diag(cov), 0.0))
    exps = {k: float(fixed[k]) if k in fixed else 0.0 for k in cols}
    errs = {"log_coefficient": float(se[0])}
    for j, k in enumerate(free, start=1):
        exps[k] = float(beta[j])
        errs[k] = float(se[j])
    rel = np.exp(-resid) - 1.0  # y_fit / y - 1
    return PowerLawFit(
        coefficient=float(np.exp(beta[0])),
        exponents=exps,
        std_errors=errs,
        r_squared=float(r2),
        rms_relative_error=float(np.sqrt(np.mean(rel**2))),
        n_points=n,
    )


def fit_turning_force(
    feed_mm_per_rev, depth_mm, force_N, base: TurningParams | None = None
) -> PowerLawFit:
    """Fit ``F = Kf f^p a`` (seed 001 eq. 8; depth exponent 1) from turning cuts.

    Returns a :class:`PowerLawFit` whose ``params`` is ``base`` (default: the paper's
    lathe) with ``force_coefficient = Kf`` and ``feed_exponent = p``; ``exponents`` holds
    ``"feed"`` and ``"depth"`` (fixed at 1).
    """
    fit = fit_power_law(force_N, {"feed": feed_mm_per_rev, "depth": depth_mm}, {"depth": 1.0})
    base = base if base is not None else TurningParams()
    if not isinstance(base, TurningParams):
        raise IdentificationError(f"base must be a TurningParams, got {type(base).__name__}")
    params = _params(base, force_coefficient=fit.coefficient, feed_exponent=fit.exponents["feed"])
    return dataclasses.replace(fit, params=params)


def fit_milling_torque(
    radial_depth_mm,
    feed_per_tooth_mm,
    torque_Nmm,
    base: MillingParams | None = None,
) -> PowerLawFit:
    """Fit ``T = Ks d^l f_t^m D`` (seed 000 eq. 8) from end-milling cuts with one tool.

    ``torque_Nmm`` in N·mm; the fitted ``coefficient`` is Ks in the paper's kgf·mm units
    (the unit of ``MillingParams.torque_coefficient_kgfmm``), with D from ``base``
    (default: the paper's 16 mm tool). ``exponents`` holds ``"depth"`` (l) and ``"feed"``
    (m); ``params`` is ``base`` with the three constants and ``force_model="power_law"``.
    """
    base = base if base is not None else MillingParams()
    if not isinstance(base, MillingParams):
        raise IdentificationError(f"base must be a MillingParams, got {type(base).__name__}")
    t = _vector("torque_Nmm", torque_Nmm) / (KGF * base.tool_diameter_mm)
    fit = fit_power_law(t, {"depth": radial_depth_mm, "feed": feed_per_tooth_mm})
    params = _params(
        base,
        force_model="power_law",
        torque_coefficient_kgfmm=fit.coefficient,
        depth_exponent=fit.exponents["depth"],
        feed_exponent=fit.exponents["feed"],
    )
    return dataclasses.replace(fit, params=params)


# ---- mean forces of flat end mills (seed 002) ------------------------------------------------
def _cut_table(radial_depth_mm, axial_depth_mm, feed_per_tooth_mm, forces_N):
    dr = _vector("radial_depth_mm", radial_depth_mm)
    n = dr.size
    da = _vector("axial_depth_mm", axial_depth_mm, n)
    ft = _vector("feed_per_tooth_mm", feed_per_tooth_mm, n)
    f = np.asarray(forces_N, dtype=np.float64)
    if f.shape != (n, 3):
        raise IdentificationError(
            f"forces_N must have shape ({n}, 3): mean Fx, Fy, Fz of each cut, got {f.shape}"
        )
    if not np.all(np.isfinite(f)):
        raise IdentificationError("forces_N must be finite")
    return dr, da, ft, f


@dataclass(frozen=True)
class CalibrationFit:
    """The calibration matrix [C] of seed 002, eq. (6)-(7), and how well it fits."""

    matrix: np.ndarray
    """[C], shape (4, 3): rows (1, dr/R, da/R, ft), columns Fx, Fy, Fz (N)."""
    tool_radius_mm: float
    r_squared: np.ndarray
    """Coefficient of determination per force component (nan where the fit is exact)."""
    rms_residual_N: float
    """Root-mean-square residual over all cuts and components, N (0 with 4 cuts)."""
    n_cuts: int

    def predict(self, radial_depth_mm, axial_depth_mm, feed_per_tooth_mm) -> np.ndarray:
        """Mean forces ``[Fx, Fy, Fz]`` (N) of new cuts: ``[C]^T [1, dr/R, da/R, ft]`` (eq. 8)."""
        x = np.stack(
            np.broadcast_arrays(
                np.ones_like(np.asarray(radial_depth_mm, dtype=np.float64)),
                np.asarray(radial_depth_mm, dtype=np.float64) / self.tool_radius_mm,
                np.asarray(axial_depth_mm, dtype=np.float64) / self.tool_radius_mm,
                np.asarray(feed_per_tooth_mm, dtype=np.float64),
            ),
            axis=-1,
        )
        return x @ self.matrix

    def to_params(
        self,
        radial_depth_mm,
        axial_depth_mm,
        feed_per_tooth_mm,
        base: MillingParams | None = None,
        mode: str | None = None,
    ) -> CoefficientFit:
        """Cutting coefficients for the env's average-force model from this [C].

        [C] is linear in the cut variables and Altintas' model is not, so the two agree
        only near the cuts [C] was calibrated on: give cut conditions inside that range
        (with real geometry, ``0 < dr <= 2R``); the forces [C] predicts there are fitted by
        :func:`fit_cutting_coefficients`, whose goodness of fit shows how well one set of
        Kt, Kr, Ka stands for [C] over them.
        """
        base = base if base is not None else MillingParams.ahn_choi_al6061()
        forces = self.predict(radial_depth_mm, axial_depth_mm, feed_per_tooth_mm)
        return fit_cutting_coefficients(
            radial_depth_mm,
            axial_depth_mm,
            feed_per_tooth_mm,
            np.atleast_2d(forces),
            base=base.replace(tool_diameter_mm=2.0 * self.tool_radius_mm),
            mode=mode,
        )


def fit_calibration_matrix(
    radial_depth_mm, axial_depth_mm, feed_per_tooth_mm, forces_N, tool_radius_mm: float
) -> CalibrationFit:
    """Least-squares [C] of ``[Fx Fy Fz] = [1, dr/R, da/R, ft] [C]`` over m >= 4 cuts (eq. 7).

    Raises
    ------
    IdentificationError
        Fewer than 4 cuts (4 unknowns per force component; the paper used 6), non-finite
        values, or cuts that do not vary dr, da and ft independently.
    """
    dr, da, ft, f = _cut_table(radial_depth_mm, axial_depth_mm, feed_per_tooth_mm, forces_N)
    if not (isinstance(tool_radius_mm, (int, float)) and math.isfinite(tool_radius_mm)) or not (
        tool_radius_mm > 0
    ):
        raise IdentificationError(f"tool_radius_mm must be > 0, got {tool_radius_mm!r}")
    n = dr.size
    if n < 4:
        raise IdentificationError(
            f"need at least 4 cuts to fit [C] (4 unknowns per force component), got {n}"
        )
    x = np.column_stack([np.ones(n), dr / tool_radius_mm, da / tool_radius_mm, ft])
    for j, name in ((1, "radial_depth_mm"), (2, "axial_depth_mm"), (3, "feed_per_tooth_mm")):
        if np.ptp(x[:, j]) == 0.0:
            raise IdentificationError(
                f"{name} takes the same value in every cut, so its row of [C] cannot be "
                f"fitted: vary {name} across the cuts"
            )
    if np.linalg.matrix_rank(x) < 4:
        raise IdentificationError(
            "the cuts do not vary dr, da and ft independently (rank-deficient design): "
            "change one variable at a time from a centre cut, as seed 002 Table 1 does"
        )
    c, *_ = np.linalg.lstsq(x, f, rcond=None)
    resid = f - x @ c
    sst = np.sum((f - f.mean(axis=0)) ** 2, axis=0)
    sse = np.sum(resid**2, axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        r2 = np.where((n > 4) & (sst > 0), 1.0 - sse / np.where(sst > 0, sst, 1.0), np.nan)
    return CalibrationFit(c, float(tool_radius_mm), r2, float(np.sqrt(np.mean(resid**2))), n)


@dataclass(frozen=True)
class CoefficientFit:
    """Cutting coefficients of the average-force model fitted to mean forces."""

    kt: float
    """Tangential coefficient Kt, N/mm²."""
    kr: float
    """Radial coefficient Kr, N/mm²."""
    ka: float
    """Axial coefficient Ka, N/mm²."""
    r_squared: float
    """Coefficient of determination over all cuts and components (1 is perfect)."""
    rms_relative_error: float
    """RMS of the force residuals over the RMS force."""
    params: MillingParams
    """``base`` with ``force_model="average_force"`` and the fitted coefficients."""


def fit_cutting_coefficients(
    radial_depth_mm,
    axial_depth_mm,
    feed_per_tooth_mm,
    forces_N,
    base: MillingParams | None = None,
    mode: str | None = None,
) -> CoefficientFit:
    """Kt, Kr, Ka of Altintas' average-force model (seed 002 eq. 1) from measured mean forces.

    Eq. (2)-(4) of seed 002 solve one cut for the coefficients; with several cuts the same
    linear relations are solved by least squares (Kt and Kr from Fx and Fy together, Ka
    from Fz). ``base`` (default :meth:`MillingParams.ahn_choi_al6061`) gives the tool
    (radius, number of flutes) and the immersion (``mode`` overrides its ``milling_mode``).

    Raises
    ------
    IdentificationError
        Fewer than 2 cuts, radial depths outside ``(0, 2R]``, non-finite values, or
        coefficients that come out negative (the forces do not follow the model).
    """
    base = base if base is not None else MillingParams.ahn_choi_al6061()
    if not isinstance(base, MillingParams):
        raise IdentificationError(f"base must be a MillingParams, got {type(base).__name__}")
    mode = base.milling_mode if mode is None else mode
    dr, da, ft, f = _cut_table(radial_depth_mm, axial_depth_mm, feed_per_tooth_mm, forces_N)
    n = dr.size
    if n < 2:
        raise IdentificationError(
            f"need at least 2 cuts to fit Kt, Kr, Ka with a residual, got {n}"
        )
    r = base.tool_radius_mm
    if np.any(dr <= 0) or np.any(dr > 2 * r):
        raise IdentificationError(
            f"radial_depth_mm must lie in (0, {2 * r:g}] (the tool diameter of base); "
            f"got {dr.tolist()}"
        )
    if np.any(da <= 0) or np.any(ft <= 0):
        raise IdentificationError("axial_depth_mm and feed_per_tooth_mm must be > 0")
    kw = {"n_flutes": base.n_teeth, "tool_radius_mm": r, "mode": mode}
    # The model is linear in (Kt, Kr, Ka): its columns are the forces of unit coefficients.
    gt = mean_forces(dr, da, ft, kt=1.0, kr=0.0, ka=0.0, **kw)
    gr = mean_forces(dr, da, ft, kt=0.0, kr=1.0, ka=0.0, **kw)
    ga = mean_forces(dr, da, ft, kt=0.0, kr=0.0, ka=1.0, **kw)
    a_xy = np.column_stack(
        [np.concatenate([gt[:, 0], gt[:, 1]]), np.concatenate([gr[:, 0], gr[:, 1]])]
    )
    (kt, kr), *_ = np.linalg.lstsq(a_xy, np.concatenate([f[:, 0], f[:, 1]]), rcond=None)
    ka = float(np.dot(ga[:, 2], f[:, 2]) / np.dot(ga[:, 2], ga[:, 2]))
    for name, v in (("Kt", kt), ("Kr", kr), ("Ka", ka)):
        if not v >= 0:
            raise IdentificationError(
                f"{name} comes out negative ({v:.4g} N/mm²): the forces do not follow the "
                f"average-force model with {mode}-milling immersion on this tool"
            )
    pred = mean_forces(dr, da, ft, kt=kt, kr=kr, ka=ka, **kw)
    resid = f - pred
    sst = float(np.sum((f - f.mean(axis=0)) ** 2))
    r2 = 1.0 - float(np.sum(resid**2)) / sst if sst > 0 else 1.0
    rms_f = float(np.sqrt(np.mean(f**2)))
    rel = float(np.sqrt(np.mean(resid**2))) / rms_f if rms_f > 0 else 0.0
    params = _params(
        base,
        force_model="average_force",
        milling_mode=mode,
        tangential_coefficient_N_mm2=float(kt),
        radial_coefficient_N_mm2=float(kr),
        axial_coefficient_N_mm2=ka,
    )
    return CoefficientFit(float(kt), float(kr), ka, r2, rel, params)


# ---- second-order servo ------------------------------------------------------------------------
@dataclass(frozen=True)
class ServoFit:
    r"""A second-order servo ``y'' + 2 zeta wn y' + wn^2 y = K wn^2 u`` fitted to a record."""

    gain: float
    """K, steady response per unit command (e.g. mm/s per count)."""
    natural_freq_hz: float
    damping: float
    r_squared: float
    """1 - SSE / SST of the response (1 is perfect)."""
    nrmse: float
    """RMS residual over the response's peak-to-peak."""
    params: TurningParams | MillingParams | None

    @property
    def natural_freq_rad_s(self) -> float:
        return 2.0 * math.pi * self.natural_freq_hz


def _servo_response(dt, u, gain, wn, zeta) -> np.ndarray:
    """Response from rest to ``u`` linear between samples (exact first-order hold)."""
    a = np.array([[0.0, 1.0], [-(wn**2), -2.0 * zeta * wn]])
    m = np.zeros((4, 4))
    m[:2, :2] = a
    m[1, 2] = gain * wn**2
    m[2, 3] = 1.0
    e = expm(m * dt)
    p00, p01, p10, p11 = e[0, 0], e[0, 1], e[1, 0], e[1, 1]
    g0, g1 = e[0, 2], e[1, 2]
    h0, h1 = e[0, 3] / dt, e[1, 3] / dt
    y = np.empty(u.size)
    x0 = x1 = 0.0
    y[0] = 0.0
    uu = u.tolist()
    for k in range(u.size - 1):
        du = uu[k + 1] - uu[k]
        x0, x1 = (
            p00 * x0 + p01 * x1 + g0 * uu[k] + h0 * du,
            p10 * x0 + p11 * x1 + g1 * uu[k] + h1 * du,
        )
        y[k + 1] = x0
    return y


def fit_servo(
    t_s, command, response, base: TurningParams | MillingParams | None = None
) -> ServoFit:
    """Fit gain, natural frequency and damping of a second-order servo to a measured record.

    The servo is at rest at ``t_s[0]``; the command is taken as linear between samples
    (exact for steps that start at a sample and, for a sine, accurate once it is sampled
    10x faster than it turns). The model is simulated exactly on the record's grid and
    fitted by nonlinear least squares from the best point of a coarse grid over ``wn`` and
    ``zeta``. ``response`` is the feed velocity in the unit the parameter set expects
    (mm/s) and ``command`` in counts; ``params`` is ``base`` (default ``MillingParams``)
    with ``servo_gain`` (for ``TurningParams``: the gain divided by its ``gear_ratio``,
    since there the servo drives the gear train), ``servo_natural_freq_hz`` and
    ``servo_damping``.

    Raises
    ------
    IdentificationError
        Fewer than 20 samples, uneven or non-increasing times, non-finite values, a
        command or response that does not vary, or no second-order fit with a natural
        frequency inside the record's resolvable band and a damping below 50.
    """
    t = _vector("t_s", t_s)
    n = t.size
    u = _vector("command", command, n, "sample")
    y = _vector("response", response, n, "sample")
    if n < 20:
        raise IdentificationError(f"need at least 20 samples of the response, got {n}")
    dts = np.diff(t)
    dt = float(np.mean(dts))
    if not dt > 0 or np.any(dts <= 0) or np.max(np.abs(dts - dt)) > 1e-6 * dt:
        raise IdentificationError("t_s must increase in equal steps (a uniformly sampled record)")
    if np.ptp(u) == 0.0 and u[0] == 0.0:
        raise IdentificationError("command is zero throughout: nothing excites the servo")
    span = float(np.ptp(y))
    if span == 0.0:
        raise IdentificationError("response does not vary: nothing to fit")
    base = base if base is not None else MillingParams()
    if not isinstance(base, (TurningParams, MillingParams)):
        raise IdentificationError(
            f"base must be a TurningParams or MillingParams, got {type(base).__name__}"
        )
    duration = t[-1] - t[0]
    wn_lo = 2.0 * math.pi / duration  # one period in the record
    wn_hi = 0.5 * math.pi / dt  # a quarter of the Nyquist rate
    if not wn_hi > 2.0 * wn_lo:
        raise IdentificationError("the record is too short for its sample time")

    def unit(wn, zeta):
        return _servo_response(dt, u, 1.0, wn, zeta)

    best = None
    for wn in np.geomspace(wn_lo, wn_hi, 25):
        for zeta in (0.15, 0.3, 0.5, 0.7, 1.0, 1.5):
            g = unit(wn, zeta)
            gg = float(g @ g)
            if gg == 0.0:
                continue
            k = float(g @ y) / gg
            sse = float(np.sum((y - k * g) ** 2))
            if best is None or sse < best[0]:
                best = (sse, k, wn, zeta)
    _, k0, wn0, z0 = best
    sign = 1.0 if k0 >= 0 else -1.0

    def resid(theta):
        k, wn, zeta = np.exp(theta)
        return sign * k * unit(wn, zeta) - y

    lo = np.log([1e-12, wn_lo / 10.0, 1e-3])
    hi = np.log([1e12, wn_hi * 10.0, 50.0])
    x0 = np.clip(np.log([abs(k0) or 1.0, wn0, z0]), lo + 1e-9, hi - 1e-9)
    sol = least_squares(resid, x0, bounds=(lo, hi), x_scale="jac")
    k, wn, zeta = np.exp(sol.x)
    k *= sign
    if not (wn_lo / 10.0 * 1.001 < wn < wn_hi * 10.0 * 0.999):
        raise IdentificationError(
            f"no second-order fit with a natural frequency the record resolves "
            f"({wn_lo / (2 * math.pi):.3g} to {wn_hi / (2 * math.pi):.3g} Hz): "
            "record longer, or sample faster"
        )
    if zeta > 0.99 * math.exp(hi[2]):
        raise IdentificationError(
            f"the best fit is damped {zeta:.3g} times critically: the response does not look "
            "like a second-order servo driven by this command (is the command clipped, or "
            "the record the wrong signal?)"
        )
    r = sol.fun
    sst = float(np.sum((y - y.mean()) ** 2))
    r2 = 1.0 - float(r @ r) / sst
    nrmse = float(np.sqrt(np.mean(r**2))) / span
    wn_hz = wn / (2.0 * math.pi)
    if isinstance(base, TurningParams):
        params = _params(
            base,
            servo_gain=float(k / base.gear_ratio),
            servo_natural_freq_hz=float(wn_hz),
            servo_damping=float(zeta),
        )
    else:
        params = _params(
            base, servo_gain=float(k), servo_natural_freq_hz=float(wn_hz), servo_damping=float(zeta)
        )
    return ServoFit(float(k), float(wn_hz), float(zeta), float(r2), nrmse, params)


def fit_servo_step(
    t_s, response, step: float = 1.0, base: TurningParams | MillingParams | None = None
) -> ServoFit:
    """Fit the servo to its response to a command step of height ``step`` at ``t_s[0]``."""
    if not (is_real(step) and math.isfinite(step) and step != 0):
        raise IdentificationError(f"step must be a non-zero number, got {step!r}")
    t = _vector("t_s", t_s)
    return fit_servo(t, np.full(t.size, float(step)), response, base)


def fit_servo_sine(
    t_s,
    response,
    amplitude: float,
    freq_hz: float,
    offset: float = 0.0,
    base: TurningParams | MillingParams | None = None,
) -> ServoFit:
    """Fit the servo to its response to ``offset + amplitude sin(2 pi freq_hz (t - t0))``.

    The record must start with the servo at rest when the sine starts: the transient
    carries the natural frequency and damping, which the steady sine at one frequency
    alone cannot separate (two numbers, gain and phase, for three unknowns).
    """
    for name, v in (("amplitude", amplitude), ("freq_hz", freq_hz)):
        if not (is_real(v) and math.isfinite(v) and v > 0):
            raise IdentificationError(f"{name} must be > 0, got {v!r}")
    if not (is_real(offset) and math.isfinite(offset)):
        raise IdentificationError(f"offset must be a finite number, got {offset!r}")
    t = _vector("t_s", t_s)
    u = offset + amplitude * np.sin(2.0 * math.pi * freq_hz * (t - t[0]))
    return fit_servo(t, u, response, base)


# ---- a turning force record -------------------------------------------------------------------

#: Columns of a turning record (CSV with a header row); ``depth_mm`` may be left out when the
#: depth is given as one number.
TURNING_RECORD_COLUMNS = ("time_s", "command", "force_N", "spindle_rpm", "depth_mm")


@dataclass(frozen=True)
class TurningRecordFit:
    """The plant fitted to a turning record, with what the fit rests on.

    ``fit`` is the cutting-law fit (:func:`fit_turning_force`) on the record's quasi-steady
    samples; ``used`` marks them. ``feed_mm_per_rev`` is the feed the servo model gives for
    the record's commands, ``force_fit_N`` the fitted law's force at every sample.
    """

    fit: PowerLawFit
    time_s: np.ndarray
    force_N: np.ndarray
    force_fit_N: np.ndarray
    feed_mm_per_rev: np.ndarray
    depth_mm: np.ndarray
    spindle_rpm: np.ndarray
    position_mm: np.ndarray
    used: np.ndarray

    @property
    def params(self) -> TurningParams:
        return self.fit.params

    def interval(self, name: str, z: float = 1.96) -> tuple[float, float]:
        """Approximate 95 % interval (``z`` standard errors) of ``"force_coefficient"`` (Kf,
        from the log-space error) or ``"feed_exponent"`` (p)."""
        if not (is_real(z) and 0 < z < math.inf):
            raise ValueError(f"z must be a positive number of standard errors, got {z!r}")
        if name == "force_coefficient":
            c, se = self.fit.coefficient, self.fit.std_errors["log_coefficient"]
            return c * math.exp(-z * se), c * math.exp(z * se)
        if name == "feed_exponent":
            p, se = self.fit.exponents["feed"], self.fit.std_errors["feed"]
            return p - z * se, p + z * se
        raise ValueError(f"name must be 'force_coefficient' or 'feed_exponent', got {name!r}")

    def scenario(self, name: str = "record", force_limit_N: float = 1000.0):
        """A ``TurningScenario`` that replays the record's workpiece (its depth against the
        position the servo model integrates) at the record's median spindle speed; the env
        holds one spindle speed per episode. Use it with ``params=fit.params``."""
        from machining_envs.core.workpieces import DepthProfile
        from machining_envs.turning.scenarios import TurningScenario

        x, d = self.position_mm, self.depth_mm
        length = float(x[-1] - x[0])
        if length <= 0:
            raise IdentificationError("the record does not move the tool: no workpiece to replay")
        # constant-depth segments, each starting where the recorded depth changes
        change = np.flatnonzero(np.abs(np.diff(d)) > 1e-9) + 1
        starts = [0, *[int(i) for i in change if 1e-6 < x[i] - x[0] < length - 1e-6]]
        edges = [float(x[i] - x[0]) for i in starts] + [length]
        depths = tuple(float(d[i]) for i in starts)
        profile = DepthProfile(tuple(edges), depths, depths, name)
        rpm = float(np.median(self.spindle_rpm))
        return TurningScenario(name, profile, rpm, force_limit_N)

    def plot(self, path=None):
        """Measured and fitted force against time, and the relative residual of the samples
        the fit used; a ``matplotlib.figure.Figure`` (saved to ``path`` if given)."""
        from matplotlib.figure import Figure

        fig = Figure(figsize=(8, 5))
        top, bottom = fig.subplots(2, 1, sharex=True)
        top.plot(self.time_s, self.force_N, lw=0.8, color="0.5", label="measured")
        top.plot(self.time_s, self.force_fit_N, lw=1.2, color="C0", label="fitted law")
        top.set_ylabel("force (N)")
        top.legend(fontsize=8)
        u = self.used
        resid = self.force_N[u] / self.force_fit_N[u] - 1.0
        bottom.plot(self.time_s[u], 100 * resid, ".", ms=2, color="C1")
        bottom.axhline(0.0, color="0.3", lw=0.8)
        bottom.set_ylabel("residual (%)")
        bottom.set_xlabel("time (s)")
        fig.suptitle(
            f"Kf = {self.fit.coefficient:.0f}, p = {self.fit.exponents['feed']:.3f}, "
            f"R² = {self.fit.r_squared:.3f} ({u.sum()} of {u.size} samples)",
            fontsize=10,
        )
        fig.tight_layout()
        if path is not None:
            fig.savefig(path, dpi=90)
        return fig


def read_turning_record(path) -> dict[str, np.ndarray]:
    """The columns of a turning record CSV (``TURNING_RECORD_COLUMNS``, header row first).

    :class:`IdentificationError` naming the file (and the row and column) for a file that is
    not UTF-8 text or CSV, a missing column, a row short of a column, or a cell that is not
    a number."""
    import csv

    try:
        with open(path, newline="", encoding="utf-8") as fh:
            rows = list(csv.DictReader(fh))
    except UnicodeDecodeError:
        raise IdentificationError(f"{path}: not a CSV record (not UTF-8 text)") from None
    except csv.Error as exc:
        raise IdentificationError(f"{path}: not a CSV record ({exc})") from None
    if not rows:
        raise IdentificationError(f"{path}: no rows")
    missing = [c for c in TURNING_RECORD_COLUMNS[:4] if c not in rows[0]]
    if missing:
        raise IdentificationError(
            f"{path}: missing columns {missing}; a record has {list(TURNING_RECORD_COLUMNS)}"
        )
    cols = [c for c in TURNING_RECORD_COLUMNS if c in rows[0]]
    out = {c: np.empty(len(rows)) for c in cols}
    for i, row in enumerate(rows):
        for c in cols:
            try:
                out[c][i] = float(row[c])
            except (TypeError, ValueError):  # (None: the row is short of the column)
                raise IdentificationError(
                    f"{path}: row {i + 2}, column {c}: not a number: {row[c]!r:.40}"
                ) from None
    return out


def fit_turning_record(
    record, depth_mm=None, base: TurningParams | None = None, steady_tolerance: float = 0.02
) -> TurningRecordFit:
    """Fit ``F = Kf f^p a`` to a measured turning record (a CSV path or a mapping of columns,
    ``TURNING_RECORD_COLUMNS``): time, servo command (counts), measured force, spindle speed
    and depth (a column, or ``depth_mm`` for the whole record).

    The feed per revolution at each sample comes from the commands through the servo and
    cutting lag of eq. (11) (``base``'s servo constants, default the paper's lathe, at each
    sample's spindle speed): ``f = Ks Km (60 / n) U_eff``. Samples where ``U_eff`` is within
    ``steady_tolerance`` of the command (the lags have settled), with a positive command,
    force and depth, enter the fit. Raises :class:`IdentificationError` for a record it cannot
    fit (columns, non-finite values, uneven time steps, too few steady samples).
    """
    base = base if base is not None else TurningParams()
    if not isinstance(base, TurningParams):
        raise IdentificationError(f"base must be a TurningParams, got {type(base).__name__}")
    cols = read_turning_record(record) if not isinstance(record, Mapping) else dict(record)
    t = _vector("time_s", cols.get("time_s"))
    n = t.size
    u = _vector("command", cols.get("command"), n, "sample")
    force = _vector("force_N", cols.get("force_N"), n, "sample")
    rpm = _positive("spindle_rpm", _vector("spindle_rpm", cols.get("spindle_rpm"), n, "sample"))
    if depth_mm is not None and "depth_mm" in cols:
        raise IdentificationError("give depth_mm as a column or as an argument, not both")
    if depth_mm is not None and not (is_real(depth_mm) and 0 < depth_mm < math.inf):
        raise IdentificationError(
            f"depth_mm must be a positive number (the depth of the whole record), got {depth_mm!r}"
        )
    if not (is_real(steady_tolerance) and 0 < steady_tolerance < 1):
        raise IdentificationError(
            "steady_tolerance must lie in (0, 1) (the share of the command by which the "
            f"lagged command may differ from it), got {steady_tolerance!r}"
        )
    depth_src = cols.get("depth_mm") if depth_mm is None else np.full(n, float(depth_mm))
    if depth_src is None:
        raise IdentificationError("the record has no depth_mm column: pass depth_mm=")
    depth = _vector("depth_mm", depth_src, n, "sample")
    dt = np.diff(t)
    if n < 3 or not np.all(dt > 0) or np.ptp(dt) > 1e-6 * dt.mean():
        raise IdentificationError("time_s must increase in equal steps (one sample time)")
    dt_s = float(dt.mean())
    # The unit-gain servo + cutting lag of eq. (11) on the commands, at each sample's speed
    # (a piecewise-constant speed changes the lag: the filter is rebuilt where it changes).
    u_eff = np.empty(n)
    params = dataclasses.replace(base, sample_time_s=dt_s)
    state_u, state_y = np.zeros(4), np.zeros(4)
    cache: dict[float, tuple[np.ndarray, np.ndarray]] = {}
    for k in range(n):
        key = round(float(rpm[k]), 3)
        if key not in cache:
            b, a = params.discrete_open_loop(key)
            cache[key] = (np.pad(b, (0, 4 - b.size)), np.pad(a, (0, 4 - a.size)))
        b, a = cache[key]
        state_u = np.concatenate([[u[k]], state_u[:3]])
        y = float(b @ state_u - a[1:] @ state_y[:3])
        state_y = np.concatenate([[y], state_y[:3]])
        u_eff[k] = y
    feed_velocity = base.servo_gain * base.gear_ratio * u_eff  # mm/s
    feed = feed_velocity * 60.0 / rpm
    position = np.concatenate([[0.0], np.cumsum(feed_velocity[:-1] * dt)])
    used = (
        (u > 0)
        & (force > 0)
        & (depth > 0)
        & (np.abs(u_eff - u) <= steady_tolerance * np.maximum(np.abs(u), 1e-12))
    )
    if used.sum() < 5:
        raise IdentificationError(
            f"only {int(used.sum())} quasi-steady samples with cutting: hold the command "
            "for a few tenths of a second at several feeds (or raise steady_tolerance)"
        )
    fit = fit_turning_force(feed[used], depth[used], force[used], base)
    force_fit = np.where(
        feed > 0, fit.coefficient * np.maximum(feed, 0.0) ** fit.exponents["feed"] * depth, 0.0
    )
    return TurningRecordFit(fit, t, force, force_fit, feed, depth, rpm, position, used)
