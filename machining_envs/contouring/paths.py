r"""Toolpaths for two-axis contouring and the exact contour error.

A :class:`Path` is a chain of segments (straight lines, circular arcs, involutes of a
circle) parametrised by arc length ``s`` (mm). The reference of a contouring run moves
along it at the feed ``F``: ``s = F t``. The **contour error** is the distance from the
tool's actual position to the path (the shortest distance to any of its segments), not the
tracking error to the current set point; each segment computes it in closed form:

- line: the distance to the segment (projection clamped to its ends);
- arc: ``| |P - C| - R |`` when ``P`` lies in the arc's angular range, otherwise the
  distance to the nearer end;
- involute of a circle of radius ``R`` centred at ``C``: every normal of an involute is
  tangent to its base circle, so the feet of the normals from ``P`` are where the tangents
  from ``P`` touch the base circle, ``phi = alpha +- arccos(R / rho)`` with
  ``P - C = rho (cos alpha, sin alpha)``; the distance is the least over those feet (every
  turn that lies in the segment's range) and the two ends.

The paper's paths (Choi et al., seed 004, §3 and §5): :meth:`Path.paper_corner`,
:meth:`Path.paper_circle` and :meth:`Path.paper_involute`; random tangent-continuous chains
of lines and arcs for training: :meth:`Path.random_smooth`.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numba
import numpy as np

from machining_envs.contouring._exact import np_mean, py_hypot
from machining_envs.core.checks import is_real
from machining_envs.core.compiled.kernels import bits_float, float_bits, sincos_row, vector_hypot

__all__ = ["Line", "Arc", "Involute", "Path", "PAPER_CORNER_FEED_MM_S", "PAPER_FEED_MM_S"]
__all__ += ["SEGMENT_COLUMNS", "path_point", "path_points", "path_heading", "path_distance"]
__all__ += ["path_distances", "path_segment_index", "smooth_table"]

#: Feed of the paper's corner test, mm/s (§5, Fig. 6).
PAPER_CORNER_FEED_MM_S = 5.0
#: Feed of the paper's circle and involute tests, mm/s (§5, Fig. 7-8).
PAPER_FEED_MM_S = 50.0

_TWO_PI = 2.0 * math.pi


def _finite(name: str, value) -> float:
    if not (is_real(value) and math.isfinite(value)):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    return float(value)


def _point(name: str, p) -> tuple[float, float]:
    try:
        x, y = p
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a pair (x, y) in mm, got {p!r}") from None
    return _finite(f"{name}[0]", x), _finite(f"{name}[1]", y)


def _circle(center, radius) -> tuple[tuple[float, float], float]:
    """The checked ``center`` (a point) and ``radius`` (> 0 mm) of an arc or an involute's
    base circle."""
    center_mm, radius_mm = _point("center", center), _finite("radius", radius)
    if not radius_mm > 0:
        raise ValueError(f"radius must be > 0 mm, got {radius!r}")
    return center_mm, radius_mm


class Line:
    """Straight segment from ``start`` to ``end`` (mm)."""

    kind = "line"

    def __init__(self, start, end) -> None:
        self._set(_point("start", start), _point("end", end))

    @classmethod
    def _trusted(cls, start: tuple[float, float], end: tuple[float, float]) -> Line:
        """A line between two pairs of finite Python floats the library computed itself
        (:meth:`Path.random_smooth`), without checking their types again (a reset builds
        several); the distinct ends are still checked."""
        self = cls.__new__(cls)
        self._set(start, end)
        return self

    def _set(self, start: tuple[float, float], end: tuple[float, float]) -> None:
        self.start = start
        self.end = end
        dx, dy = end[0] - start[0], end[1] - start[1]
        self.length = math.hypot(dx, dy)
        if not self.length > 1e-9:
            raise ValueError(f"a Line needs distinct ends, got {start!r} and {end!r}")
        self._u = (dx / self.length, dy / self.length)
        self.heading0 = math.atan2(dy, dx)

    def _row(self) -> list[float]:
        """The segment's row of :meth:`Path.table` (its place in the path left at zero)."""
        return _segment_row(_LINE, *self.start, *self._u, self.length)

    def points(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.start[0] + self._u[0] * s, self.start[1] + self._u[1] * s

    def point(self, s: float) -> tuple[float, float]:
        return self.start[0] + self._u[0] * s, self.start[1] + self._u[1] * s

    def turning(self, s: np.ndarray) -> np.ndarray:
        """Heading change since the segment's start, rad."""
        return np.zeros_like(s)

    def curvatures(self, s: np.ndarray) -> np.ndarray:
        return np.zeros_like(s)

    @property
    def heading1(self) -> float:
        return self.heading0

    def closest(self, px: float, py: float) -> tuple[float, float, float]:
        """``(distance, qx, qy)``: the nearest point ``q`` of the segment to ``p``."""
        x0, y0 = self.start
        ux, uy = self._u
        t = (px - x0) * ux + (py - y0) * uy
        t = 0.0 if t < 0.0 else (self.length if t > self.length else t)
        qx, qy = x0 + ux * t, y0 + uy * t
        return math.hypot(px - qx, py - qy), qx, qy

    def closest_many(self, px: np.ndarray, py: np.ndarray):
        x0, y0 = self.start
        ux, uy = self._u
        t = np.minimum(np.maximum((px - x0) * ux + (py - y0) * uy, 0.0), self.length)
        qx, qy = x0 + ux * t, y0 + uy * t
        return np.hypot(px - qx, py - qy), qx, qy

    def __repr__(self) -> str:
        return f"Line({self.start}, {self.end})"


class Arc:
    """Circular arc: centre ``center`` (mm), ``radius`` (mm), from ``start_angle`` (rad)
    through ``sweep`` (rad; positive counter-clockwise, ``|sweep| <= 2 pi``)."""

    kind = "arc"

    def __init__(self, center, radius: float, start_angle: float, sweep: float) -> None:
        self.center, self.radius = _circle(center, radius)
        self.start_angle = _finite("start_angle", start_angle)
        self.sweep = _finite("sweep", sweep)
        if not 0 < abs(self.sweep) <= _TWO_PI + 1e-12:
            raise ValueError(f"sweep must satisfy 0 < |sweep| <= 2 pi rad, got {sweep!r}")
        self._derive()

    @classmethod
    def _trusted(
        cls, center: tuple[float, float], radius: float, start_angle: float, sweep: float
    ) -> Arc:
        """An arc from Python floats the library computed itself within the ranges the
        constructor checks (:meth:`Path.random_smooth`: radius > 0, ``0 < |sweep| <= 2
        pi``), without checking them again (a reset builds several)."""
        self = cls.__new__(cls)
        self.center = center
        self.radius = radius
        self.start_angle = start_angle
        self.sweep = sweep
        self._derive()
        return self

    def _derive(self) -> None:
        """The arc's derived numbers, from its checked ones."""
        self.sign = 1.0 if self.sweep > 0 else -1.0
        self.length = self.radius * abs(self.sweep)
        self.start = self._at(self.start_angle)
        self.end = self._at(self.start_angle + self.sweep)
        self.heading0 = self.start_angle + self.sign * 0.5 * math.pi

    def _at(self, ang: float) -> tuple[float, float]:
        return (
            self.center[0] + self.radius * math.cos(ang),
            self.center[1] + self.radius * math.sin(ang),
        )

    def points(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ang = self.start_angle + self.sign * s / self.radius
        return (
            self.center[0] + self.radius * np.cos(ang),
            self.center[1] + self.radius * np.sin(ang),
        )

    def turning(self, s: np.ndarray) -> np.ndarray:
        return self.sign * s / self.radius

    def point(self, s: float) -> tuple[float, float]:
        return self._at(self.start_angle + self.sign * s / self.radius)

    def curvatures(self, s: np.ndarray) -> np.ndarray:
        return np.full_like(s, self.sign / self.radius)

    @property
    def heading1(self) -> float:
        return self.heading0 + self.sweep

    def _row(self) -> list[float]:
        """The segment's row of :meth:`Path.table` (its place in the path left at zero)."""
        turn = (self.start_angle, self.sign, abs(self.sweep))
        return _segment_row(_ARC, *self.center, self.radius, *turn, *self.start, *self.end)

    def closest(self, px: float, py: float) -> tuple[float, float, float]:
        cx, cy = self.center
        dx, dy = px - cx, py - cy
        rho = math.hypot(dx, dy)
        rel = (math.atan2(dy, dx) - self.start_angle) * self.sign % _TWO_PI
        if rel <= abs(self.sweep) and rho > 0.0:
            k = self.radius / rho
            return abs(rho - self.radius), cx + dx * k, cy + dy * k
        if rho == 0.0:  # every point of the arc is R away; the start is one of them
            return self.radius, self.start[0], self.start[1]
        d0 = math.hypot(px - self.start[0], py - self.start[1])
        d1 = math.hypot(px - self.end[0], py - self.end[1])
        return (d0, *self.start) if d0 <= d1 else (d1, *self.end)

    def closest_many(self, px: np.ndarray, py: np.ndarray):
        cx, cy = self.center
        dx, dy = px - cx, py - cy
        rho = np.hypot(dx, dy)
        rel = np.mod((np.arctan2(dy, dx) - self.start_angle) * self.sign, _TWO_PI)
        inside = (rel <= abs(self.sweep)) & (rho > 0.0)
        if inside.all():
            k = self.radius / rho
            return np.abs(rho - self.radius), cx + dx * k, cy + dy * k
        k = self.radius / np.where(rho > 0.0, rho, 1.0)
        d = np.abs(rho - self.radius)
        qx, qy = cx + dx * k, cy + dy * k
        d0 = np.hypot(px - self.start[0], py - self.start[1])
        d1 = np.hypot(px - self.end[0], py - self.end[1])
        use0 = d0 <= d1
        ex = np.where(use0, self.start[0], self.end[0])
        ey = np.where(use0, self.start[1], self.end[1])
        ed = np.where(use0, d0, d1)
        return np.where(inside, d, ed), np.where(inside, qx, ex), np.where(inside, qy, ey)

    def __repr__(self) -> str:
        return f"Arc(center={self.center}, radius={self.radius}, start_angle={self.start_angle}, sweep={self.sweep})"


class Involute:
    r"""Involute of the circle of ``radius`` R centred at ``center`` (paper §3.3):

    .. math::

        X &= R(\cos(\theta + \theta_1) + \theta \sin(\theta + \theta_1)) + X_0 \\
        Y &= R(\sin(\theta + \theta_1) - \theta \cos(\theta + \theta_1)) + Y_0

    for ``theta_start <= theta <= theta_end`` (rad, ``>= 0``). The arc length from
    ``theta = 0`` is ``R theta^2 / 2``, so the constant feed ``F`` runs it with
    ``theta = sqrt(2 F t / R)`` from ``theta = 0`` (the OCR'd ``sqrt(2 pi / R) t`` corrected).
    """

    kind = "involute"

    def __init__(
        self,
        center,
        radius: float,
        theta1: float = 0.0,
        theta_start: float = 0.0,
        theta_end: float = 0.5 * math.pi,
    ) -> None:
        self.center, self.radius = _circle(center, radius)
        self.theta1 = _finite("theta1", theta1)
        self.theta_start = _finite("theta_start", theta_start)
        self.theta_end = _finite("theta_end", theta_end)
        if not 0.0 <= self.theta_start < self.theta_end <= 100.0:
            raise ValueError(
                "theta_start and theta_end must satisfy 0 <= theta_start < theta_end <= 100 rad, "
                f"got {theta_start!r}, {theta_end!r}"
            )
        self.length = 0.5 * self.radius * (self.theta_end**2 - self.theta_start**2)
        self.start = self.point_at(self.theta_start)
        self.end = self.point_at(self.theta_end)
        self.heading0 = self.theta_start + self.theta1
        self._k_span = int(math.ceil((self.theta_end - self.theta_start) / _TWO_PI)) + 2

    def point_at(self, theta: float) -> tuple[float, float]:
        """The involute's point at parameter ``theta`` (rad)."""
        phi = theta + self.theta1
        c, s = math.cos(phi), math.sin(phi)
        return (
            self.center[0] + self.radius * (c + theta * s),
            self.center[1] + self.radius * (s - theta * c),
        )

    def point(self, s: float) -> tuple[float, float]:
        return self.point_at(math.sqrt(self.theta_start**2 + 2.0 * s / self.radius))

    def theta_of(self, s: np.ndarray) -> np.ndarray:
        """Parameter ``theta`` at arc length ``s`` from the segment's start."""
        return np.sqrt(self.theta_start**2 + 2.0 * s / self.radius)

    def points(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        th = self.theta_of(s)
        phi = th + self.theta1
        c, sn = np.cos(phi), np.sin(phi)
        return (
            self.center[0] + self.radius * (c + th * sn),
            self.center[1] + self.radius * (sn - th * c),
        )

    def turning(self, s: np.ndarray) -> np.ndarray:
        return self.theta_of(s) - self.theta_start

    def curvatures(self, s: np.ndarray) -> np.ndarray:
        th = self.theta_of(s)
        with np.errstate(divide="ignore"):
            return np.where(th > 0, 1.0 / (self.radius * np.maximum(th, 1e-300)), np.inf)

    @property
    def heading1(self) -> float:
        return self.theta_end + self.theta1

    def _row(self) -> list[float]:
        """The segment's row of :meth:`Path.table` (its place in the path left at zero)."""
        angles = (self.theta1, self.theta_start, self.theta_end, self.theta_start**2)
        return _segment_row(_INVOLUTE, *self.center, self.radius, *angles, float(self._k_span))

    def _feet(self, px: float, py: float) -> list[float]:
        """Parameters of the feet of the normals from ``p`` that lie on the segment."""
        dx, dy = px - self.center[0], py - self.center[1]
        rho = math.hypot(dx, dy)
        out = [self.theta_start, self.theta_end]
        if rho <= self.radius:
            return out
        alpha = math.atan2(dy, dx)
        off = math.acos(self.radius / rho)
        for phi in (alpha + off, alpha - off):
            base = phi - self.theta1
            k0 = math.ceil((self.theta_start - base) / _TWO_PI)
            for k in range(k0, k0 + self._k_span):
                th = base + k * _TWO_PI
                if th > self.theta_end:
                    break
                out.append(th)
        return out

    def closest(self, px: float, py: float) -> tuple[float, float, float]:
        best = (math.inf, 0.0, 0.0)
        for th in self._feet(px, py):
            qx, qy = self.point_at(th)
            d = math.hypot(px - qx, py - qy)
            if d < best[0]:
                best = (d, qx, qy)
        return best

    def closest_many(self, px: np.ndarray, py: np.ndarray):
        px = np.asarray(px, dtype=np.float64)
        py = np.asarray(py, dtype=np.float64)
        cands = [np.full(px.shape, self.theta_start), np.full(px.shape, self.theta_end)]
        dx, dy = px - self.center[0], py - self.center[1]
        rho = np.hypot(dx, dy)
        outside = rho > self.radius
        alpha = np.arctan2(dy, dx)
        off = np.arccos(np.where(outside, self.radius / np.where(outside, rho, 1.0), 1.0))
        for phi in (alpha + off, alpha - off):
            base = phi - self.theta1
            k0 = np.ceil((self.theta_start - base) / _TWO_PI)
            for k in range(self._k_span):
                th = base + (k0 + k) * _TWO_PI
                ok = outside & (th <= self.theta_end)
                cands.append(np.where(ok, th, self.theta_start))
        th = np.stack(cands)
        phi = th + self.theta1
        c, sn = np.cos(phi), np.sin(phi)
        qx = self.center[0] + self.radius * (c + th * sn)
        qy = self.center[1] + self.radius * (sn - th * c)
        d = np.hypot(px - qx, py - qy)
        i = np.argmin(d, axis=0)
        cols = np.arange(d.shape[1]) if d.ndim == 2 else None
        if cols is None:
            return d[i], qx[i], qy[i]
        return d[i, cols], qx[i, cols], qy[i, cols]

    def __repr__(self) -> str:
        return (
            f"Involute(center={self.center}, radius={self.radius}, theta1={self.theta1}, "
            f"theta_start={self.theta_start}, theta_end={self.theta_end})"
        )


Segment = Line | Arc | Involute


def _bounding_circle(seg) -> tuple[float, float, float]:
    """A circle ``(cx, cy, radius)`` that contains the whole segment.

    A line's: its midpoint and half its length. An arc's of at most half a turn: the
    circle on its chord (the arc sees the chord at a right angle or more, so it lies
    inside); of more: its own circle. Each radius is widened by ``1e-9`` of the
    segment's magnitudes (the coordinates of its centre or start, its length or radius),
    far above the rounding of its points. An involute's, from 257 points along it: their
    centroid, and the largest distance to them plus the largest gap between neighbours
    (the curve between two neighbours stays within that), the numbers of
    ``np.linspace``, the segment's ``points``, ``np.mean`` and ``np.hypot`` to the last
    bit. Compiled (:func:`_bounding_circle_of_row`).
    """
    cx, cy, r = _bounding_circle_of_row(np.array(seg._row()), float(seg.length))
    return float(cx), float(cy), float(r)


@numba.njit(cache=True)
def _bounding_circle_of_row(row, length):
    """:func:`_bounding_circle` of the segment ``row`` (of arc length ``length``)."""
    kind = row[0]
    if kind == _LINE:
        half = 0.5 * length
        size = abs(row[6]) + abs(row[7]) + length
        mx, my = _line_xy(row, half)
        return mx, my, half + 1e-9 * size
    if kind == _ARC:
        size = abs(row[6]) + abs(row[7]) + row[8]
        if row[11] > math.pi:
            return row[6], row[7], row[8] + 1e-9 * size
        half = 0.5 * math.hypot(row[14] - row[12], row[15] - row[13])
        return 0.5 * (row[12] + row[14]), 0.5 * (row[13] + row[15]), half + 1e-9 * size
    n = 257
    x = np.empty(n)
    y = np.empty(n)
    step = length / (n - 1)  # np.linspace(0, length, n): i * step, the last exactly length
    for i in range(n):
        s = float(i) * step + 0.0 if i < n - 1 else length
        if step == 0.0:
            s = float(i) / (n - 1) * length + 0.0 if i < n - 1 else length
        x[i], y[i] = _segment_point(row, s)
    cx = np_mean(x)
    cy = np_mean(y)
    gap = _largest_hypot(x, y, 0.0, 0.0, True)
    far = _largest_hypot(x, y, cx, cy, False)
    return cx, cy, far + gap


@numba.njit(cache=True, inline="always")
def _offset(x, y, i, cx, cy, neighbours):
    """``(x[i + 1] - x[i], y[i + 1] - y[i])`` or ``(x[i] - cx, y[i] - cy)``."""
    if neighbours:
        return x[i + 1] - x[i], y[i + 1] - y[i]
    return x[i] - cx, y[i] - cy


@numba.njit(cache=True)
def _largest_hypot(x, y, cx, cy, neighbours):
    """The largest ``math.hypot`` of the gaps between neighbouring points
    (``neighbours``) or of the points' offsets from ``(cx, cy)``, to the last bit.

    ``hypot`` is evaluated only where the plain sum of squares comes within 1e-9 of its
    largest value: a sum of squares is within a few units in the last place of the true
    square of the distance and ``hypot`` within one of the distance, so every offset left
    out has a smaller ``hypot`` than the one with the largest sum. Where the sums could
    underflow, overflow or be NaN, every ``hypot`` is taken."""
    n = x.shape[0] - 1 if neighbours else x.shape[0]
    m2 = 0.0
    bad = False
    for i in range(n):
        dx, dy = _offset(x, y, i, cx, cy, neighbours)
        d2 = dx * dx + dy * dy
        if d2 > m2:
            m2 = d2
        elif d2 != d2:
            bad = True
    full = bad or not (1e-280 < m2 < 1e280)
    thr = m2 * (1.0 - 1e-9)
    best = -np.inf
    for i in range(n):
        dx, dy = _offset(x, y, i, cx, cy, neighbours)
        if full or dx * dx + dy * dy >= thr:
            best = max(best, math.hypot(dx, dy))
    return best


@numba.njit(cache=True)
def smooth_table(draws, n, heading, line_mm, radius_mm, sweep_deg, line_probability, tab):
    """The table (:meth:`Path.table`) of :meth:`Path.random_smooth`'s path from the start
    ``(0, 0)`` into ``tab[:n]``, from its drawn numbers (``draws[r, k]``: the five numbers
    of segment ``k``; ``heading``: the first heading) and ranges (pairs); returns the path's
    ``(length, start x, start y, end x, end y)``. Every number is the one the segments'
    and the path's own arithmetic gives in Python, in its order (``math.hypot`` as
    CPython computes it: ``py_hypot``), so the table is ``Path.table()`` to the last bit
    (``tests/contouring/test_batched_start.py``)."""
    px = 0.0
    py = 0.0
    total = 0.0
    head = 0.0
    h1_prev = 0.0
    h0_prev = 0.0
    x0 = 0.0
    y0 = 0.0
    for k in range(n):
        row = tab[k]
        for c in range(row.shape[0]):
            row[c] = 0.0
        if draws[0, k] < line_probability:  # Line._set
            length = line_mm[0] + (line_mm[1] - line_mm[0]) * draws[1, k]
            ex = px + length * math.cos(heading)
            ey = py + length * math.sin(heading)
            dx = ex - px
            dy = ey - py
            seg_len = py_hypot(dx, dy)
            h0 = math.atan2(dy, dx)
            h1 = h0
            sx = px
            sy = py
            row[0] = _LINE
            row[6] = px
            row[7] = py
            row[8] = dx / seg_len
            row[9] = dy / seg_len
            row[10] = seg_len
        else:  # Arc._derive, of random_smooth's centre, radius, start angle and sweep
            r = radius_mm[0] + (radius_mm[1] - radius_mm[0]) * draws[1, k]
            sweep = math.radians(sweep_deg[0] + (sweep_deg[1] - sweep_deg[0]) * draws[2, k])
            sign = 1.0 if draws[3, k] < 0.5 else -1.0
            cx = px - sign * r * math.sin(heading)
            cy = py + sign * r * math.cos(heading)
            a0 = math.atan2(py - cy, px - cx)
            sw = sign * sweep
            arc_sign = 1.0 if sw > 0 else -1.0
            seg_len = r * abs(sw)
            sx = cx + r * math.cos(a0)
            sy = cy + r * math.sin(a0)
            ex = cx + r * math.cos(a0 + sw)
            ey = cy + r * math.sin(a0 + sw)
            h0 = a0 + arc_sign * 0.5 * math.pi
            h1 = h0 + sw
            heading += sign * sweep
            row[0] = _ARC
            row[6] = cx
            row[7] = cy
            row[8] = r
            row[9] = a0
            row[10] = arc_sign
            row[11] = abs(sw)
            row[12] = sx
            row[13] = sy
            row[14] = ex
            row[15] = ey
        if k == 0:  # Path._build: the running arc length and the unwrapped heading
            head = h0
            x0 = sx
            y0 = sy
        else:
            head = head + (h1_prev - h0_prev)
            a = h0 - head  # _wrap(a)
            head += a - _TWO_PI * math.floor((a + math.pi) / _TWO_PI)
        row[1] = total
        row[2] = head
        row[3] = seg_len
        total = seg_len if k == 0 else total + seg_len
        h0_prev = h0
        h1_prev = h1
        px = ex
        py = ey
    _bounding_circles(tab[:n])
    return total, x0, y0, px, py


@numba.njit(cache=True)
def _bounding_circles(tab):
    """:func:`_bounding_circle_of_row` of every row of ``tab`` into its columns 3-5, in one
    call (a reset builds a path of several segments); column 3 holds the segment's arc
    length until then."""
    for k in range(tab.shape[0]):
        cx, cy, r = _bounding_circle_of_row(tab[k], tab[k, 3])
        tab[k, 3] = cx
        tab[k, 4] = cy
        tab[k, 5] = r


def _wrap(a: float) -> float:
    """Angle wrapped to (-pi, pi]."""
    return a - _TWO_PI * math.floor((a + math.pi) / _TWO_PI)


class Path:
    """A chain of segments, each starting where the previous one ends (within 1 um).

    Parameters
    ----------
    segments : sequence of Line, Arc, Involute
    name : str
        Label for plots and tables.

    Positions along the path are arc lengths ``s`` in ``[0, length]`` mm; values outside are
    clamped to the ends. Scalar queries (:meth:`closest`, :meth:`distance`) run in plain
    Python for per-step use; the ``*_many`` / vector forms take arrays.
    """

    def __init__(self, segments: Sequence[Segment], name: str = "path") -> None:
        segs = list(segments)
        if not segs:
            raise ValueError("segments must hold at least one Line, Arc or Involute")
        for k, seg in enumerate(segs):
            if not isinstance(seg, (Line, Arc, Involute)):
                raise ValueError(
                    f"segments[{k}] must be a Line, Arc or Involute, got {type(seg).__name__}"
                )
            if k:
                gap = math.hypot(
                    seg.start[0] - segs[k - 1].end[0], seg.start[1] - segs[k - 1].end[1]
                )
                if gap > 1e-3:
                    raise ValueError(
                        f"segments[{k}] starts {gap:.3g} mm from where segments[{k - 1}] ends; "
                        "a path must be continuous"
                    )
        self._build(segs, str(name))

    @classmethod
    def _trusted(cls, segs: list[Segment], name: str) -> Path:
        """A path of segments the library chained itself (:meth:`random_smooth`: each
        starts exactly where the previous one ends), without checking them again (a reset
        builds one)."""
        self = cls.__new__(cls)
        self._build(segs, name)
        return self

    def _build(self, segs: list[Segment], name: str) -> None:
        """The path's numbers from its checked segments, its :meth:`table` among them."""
        self.segments = tuple(segs)
        self.name = name
        lengths = [seg.length for seg in segs]
        # np.cumsum's running sum, in Python floats (one numpy call fewer per reset).
        self._start_list = [0.0, *itertools.accumulate(lengths)]
        self._starts = np.array(self._start_list)
        self._inner = self._starts[1:-1].copy()
        self.length = self._start_list[-1]
        # Unwrapped heading at each segment's start: corners add their turn in (-pi, pi].
        head = [segs[0].heading0]
        for k in range(1, len(segs)):
            head.append(head[-1] + (segs[k - 1].heading1 - segs[k - 1].heading0))
            head[-1] += _wrap(segs[k].heading0 - head[-1])
        self._heading_starts = np.array(head)
        rows = [seg._row() for seg in segs]
        for row, start, h, length in zip(rows, self._start_list, head, lengths, strict=False):
            row[1] = start
            row[2] = h
            row[3] = length  # read, then replaced, by _bounding_circles
        tab = np.array(rows, dtype=np.float64)
        _bounding_circles(tab)
        tab.setflags(write=False)
        self._table = tab
        self._bounds = [tuple(b) for b in tab[:, 3:6].tolist()]

    # ---- constructors: the paper's paths -------------------------------------------------
    @classmethod
    def paper_corner(cls) -> Path:
        """(0, 0) -> (35.3553, 35.3553) -> (70.7107, 0) mm: a 90 degree corner (Fig. 6)."""
        a = 50.0 / math.sqrt(2.0)
        return cls([Line((0.0, 0.0), (a, a)), Line((a, a), (2.0 * a, 0.0))], name="corner")

    @classmethod
    def paper_circle(cls, radius_mm: float = 10.0) -> Path:
        """Full counter-clockwise circle of radius 10 mm centred at the origin, from (R, 0):
        ``x = R cos(w t)``, ``y = R sin(w t)`` (§3.2, Fig. 7)."""
        return cls([Arc((0.0, 0.0), radius_mm, 0.0, _TWO_PI)], name="circle")

    @classmethod
    def paper_involute(cls, radius_mm: float = 50.0, theta_end: float = 0.5 * math.pi) -> Path:
        """Involute of a 50 mm base circle (§3.3, Fig. 8) from ``theta = 0`` to ``theta_end``.

        The paper zooms into part of the curve and does not say which; a quarter turn of the
        generating line (61.7 mm of path, 1.23 s at 50 mm/s) is taken, with ``theta1 = 0`` and
        the base circle centred at ``(-R, 0)`` so that the path starts at the origin.
        """
        return cls([Involute((-radius_mm, 0.0), radius_mm, 0.0, 0.0, theta_end)], name="involute")

    @classmethod
    def line(cls, start, end, name: str = "line") -> Path:
        return cls([Line(start, end)], name=name)

    @classmethod
    def random_smooth(
        cls,
        rng: np.random.Generator,
        n_segments: tuple[int, int] = (3, 6),
        line_mm: tuple[float, float] = (5.0, 30.0),
        radius_mm: tuple[float, float] = (3.0, 30.0),
        sweep_deg: tuple[float, float] = (30.0, 180.0),
        line_probability: float = 0.4,
        start=(0.0, 0.0),
        name: str = "random",
    ) -> Path:
        """Random tangent-continuous chain of lines and arcs from ``start``.

        ``n_segments`` is an inclusive integer range; the first heading is uniform; each
        segment is a line (probability ``line_probability``, length uniform in ``line_mm``)
        or an arc turning left or right (radius uniform in ``radius_mm``, sweep uniform in
        ``sweep_deg``). Every number is drawn from ``rng``.
        """
        lo, hi = n_segments
        if not (isinstance(lo, int) and isinstance(hi, int) and 1 <= lo <= hi <= 100):
            raise ValueError(
                f"n_segments must be integers 1 <= lo <= hi <= 100, got {n_segments!r}"
            )
        for label, (a, b) in (("line_mm", line_mm), ("radius_mm", radius_mm)):
            if not (0 < a <= b < 1e4):
                raise ValueError(f"{label} must satisfy 0 < lo <= hi < 10000, got {(a, b)!r}")
        if not (0 < sweep_deg[0] <= sweep_deg[1] <= 360):
            raise ValueError(f"sweep_deg must satisfy 0 < lo <= hi <= 360, got {sweep_deg!r}")
        if not 0.0 <= line_probability <= 1.0:
            raise ValueError(f"line_probability must be in [0, 1], got {line_probability!r}")
        n = int(rng.integers(lo, hi + 1))
        draws = rng.random((5, n)).tolist()  # kind, length/radius, sweep, direction, spare
        heading = float(rng.uniform(-math.pi, math.pi))
        p = _point("start", start)
        return cls._smooth(
            draws, heading, line_mm, radius_mm, sweep_deg, line_probability, p, str(name)
        )

    @classmethod
    def _smooth(
        cls,
        draws,
        heading: float,
        line_mm,
        radius_mm,
        sweep_deg,
        line_probability: float,
        p: tuple[float, float],
        name: str,
    ) -> Path:
        """:meth:`random_smooth`'s path from its drawn numbers (``draws``: five lists of
        one number per segment; ``heading``: the first heading; ``p``: the start), its
        ranges checked; :func:`smooth_table` computes the same path's table."""
        segs: list[Segment] = []
        for k in range(len(draws[0])):
            if draws[0][k] < line_probability:
                length = float(line_mm[0] + (line_mm[1] - line_mm[0]) * draws[1][k])
                end = (p[0] + length * math.cos(heading), p[1] + length * math.sin(heading))
                segs.append(Line._trusted(p, end))
            else:
                r = float(radius_mm[0] + (radius_mm[1] - radius_mm[0]) * draws[1][k])
                sweep = math.radians(sweep_deg[0] + (sweep_deg[1] - sweep_deg[0]) * draws[2][k])
                sign = 1.0 if draws[3][k] < 0.5 else -1.0
                # Centre to the left (sign +1) or right of the heading.
                cx = p[0] - sign * r * math.sin(heading)
                cy = p[1] + sign * r * math.cos(heading)
                a0 = math.atan2(p[1] - cy, p[0] - cx)
                segs.append(Arc._trusted((cx, cy), r, a0, sign * sweep))
                heading += sign * sweep
            p = segs[-1].end
        # Every number above is a finite Python float in the segments' ranges (the ranges
        # checked by random_smooth, the start by _point) and each segment starts where the
        # last ends.
        return cls._trusted(segs, name)

    # ---- geometry ---------------------------------------------------------------------------
    @property
    def start(self) -> tuple[float, float]:
        return self.segments[0].start

    @property
    def end(self) -> tuple[float, float]:
        return self.segments[-1].end

    def duration_s(self, feed_mm_s: float) -> float:
        """Time the reference takes at the constant feed ``feed_mm_s``."""
        return self.length / feed_mm_s

    def _index(self, s: np.ndarray) -> np.ndarray:
        """Segment index of each arc length in ``s`` (already within ``[0, length]``)."""
        return np.searchsorted(self._inner, s, side="right")

    def _per_segment(self, s, fn) -> list:
        """Evaluate ``fn(k, segment, local arc lengths)`` segment by segment over ``s``.

        Returns ``[(mask or None, result), ...]``; ``mask`` is None when one segment holds
        every value (the usual case for the short, ascending runs the envs ask for).
        """
        idx = self._index(s)
        lo, hi = int(idx.min()), int(idx.max())
        if lo == hi:
            return [(None, fn(lo, self.segments[lo], s - self._start_list[lo]))]
        out = []
        for k in range(lo, hi + 1):
            m = idx == k
            if m.any():
                out.append((m, fn(k, self.segments[k], s[m] - self._start_list[k])))
        return out

    def _clamp(self, s) -> np.ndarray:
        return np.minimum(np.maximum(np.asarray(s, dtype=np.float64), 0.0), self.length)

    def points(self, s) -> tuple[np.ndarray, np.ndarray]:
        """Points ``(x, y)`` (mm) at arc lengths ``s`` (array; clamped to the path)."""
        s = self._clamp(s)
        if len(self.segments) == 1 or s.ndim == 0 or s.size == 0:
            if len(self.segments) == 1:
                return self.segments[0].points(s)
            s = np.atleast_1d(s)
        parts = self._per_segment(s, lambda k, seg, loc: seg.points(loc))
        if parts[0][0] is None:
            return parts[0][1]
        x = np.empty_like(s)
        y = np.empty_like(s)
        for m, (px, py) in parts:
            x[m], y[m] = px, py
        return x, y

    def point(self, s: float) -> tuple[float, float]:
        """One point ``(x, y)`` at arc length ``s`` (clamped to the path)."""
        s = min(max(float(s), 0.0), self.length)
        starts = self._start_list
        k = len(self.segments) - 1
        while k > 0 and s < starts[k]:
            k -= 1
        return self.segments[k].point(s - starts[k])

    def _gather(self, s, fn) -> np.ndarray:
        s = np.atleast_1d(self._clamp(s))
        parts = self._per_segment(s, fn)
        if parts[0][0] is None:
            return np.asarray(parts[0][1], dtype=np.float64) + np.zeros_like(s)
        out = np.empty_like(s)
        for m, v in parts:
            out[m] = v
        return out

    def headings(self, s) -> np.ndarray:
        """Unwrapped heading of the path (rad) at ``s``: the total turn since the start plus
        the first heading. Corners count as the turn they make (in ``(-pi, pi]``)."""
        hs = self._heading_starts
        return self._gather(s, lambda k, seg, loc: hs[k] + seg.turning(loc))

    def curvatures(self, s) -> np.ndarray:
        """Signed curvature (1/mm, positive turning left) at ``s``; corners are not counted."""
        return self._gather(s, lambda k, seg, loc: seg.curvatures(loc))

    def segment_index(self, s: float) -> int:
        """Index of the segment that holds arc length ``s``."""
        s = min(max(float(s), 0.0), self.length)
        starts = self._start_list
        k = len(self.segments) - 1
        while k > 0 and s < starts[k]:
            k -= 1
        return k

    def closest(self, px: float, py: float) -> tuple[float, float, float]:
        """``(contour error, qx, qy)``: distance from ``p`` to the path and the nearest point.

        Segments whose bounding circle lies farther than the best distance so far are
        skipped (they cannot hold a nearer point)."""
        best = (math.inf, 0.0, 0.0)
        for seg, (cx, cy, rad) in zip(self.segments, self._bounds, strict=True):
            if math.hypot(px - cx, py - cy) - rad >= best[0]:
                continue
            c = seg.closest(px, py)
            if c[0] < best[0]:
                best = c
        return best

    def distance(self, px: float, py: float) -> float:
        """Contour error of the point ``(px, py)``, mm: its distance to the path."""
        if len(self.segments) == 1:
            return self.segments[0].closest(px, py)[0]
        return self.closest(px, py)[0]

    def closest_many(self, px, py) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Vector form of :meth:`closest` for arrays of points."""
        px = np.asarray(px, dtype=np.float64)
        py = np.asarray(py, dtype=np.float64)
        if len(self.segments) == 1:
            return self.segments[0].closest_many(px, py)
        # Start from the segment nearest the points' centre; skip every segment whose
        # bounding circle lies beyond the largest distance found so far for all points.
        mx, my = float(np.mean(px)), float(np.mean(py))
        spread = float(np.max(np.hypot(px - mx, py - my))) if px.size else 0.0
        lower = [math.hypot(mx - cx, my - cy) - rad for cx, cy, rad in self._bounds]
        order = sorted(range(len(self.segments)), key=lower.__getitem__)
        d, qx, qy = self.segments[order[0]].closest_many(px, py)
        for k in order[1:]:
            if lower[k] - spread >= float(np.max(d)):
                continue
            d2, qx2, qy2 = self.segments[k].closest_many(px, py)
            better = d2 < d
            d = np.where(better, d2, d)
            qx = np.where(better, qx2, qx)
            qy = np.where(better, qy2, qy)
        return d, qx, qy

    def distances(self, px, py) -> np.ndarray:
        """Vector form of :meth:`distance`."""
        return self.closest_many(px, py)[0]

    def circle(self) -> tuple[float, float, float] | None:
        """``(cx, cy, R)`` when the path is one arc (a circle test), else ``None``."""
        if len(self.segments) == 1 and isinstance(self.segments[0], Arc):
            seg = self.segments[0]
            return seg.center[0], seg.center[1], seg.radius
        return None

    def bounds(self) -> tuple[float, float, float, float]:
        """``(xmin, xmax, ymin, ymax)`` of the path, mm (sampled every 0.1 mm or finer)."""
        s = np.linspace(0.0, self.length, max(50, int(self.length / 0.1) + 1))
        x, y = self.points(s)
        return float(x.min()), float(x.max()), float(y.min()), float(y.max())

    def table(self) -> np.ndarray:
        """The path as one float64 array ``(n_segments, SEGMENT_COLUMNS)`` for the compiled
        geometry (:func:`path_point`, :func:`path_distances`, ...), computed once.

        Row ``k`` holds the segment's kind (0 line, 1 arc, 2 involute), the arc length at
        its start, its unwrapped heading there, its bounding circle ``(cx, cy, r)`` and its
        own numbers from column 6 (line: start, unit direction, length; arc: centre,
        radius, start angle, turning sign, ``|sweep|``, start and end points; involute:
        centre, radius, ``theta1``, ``theta_start``, ``theta_end``, ``theta_start**2``, the
        turns searched for feet of normals).
        """
        return self._table

    def __repr__(self) -> str:
        return f"Path({self.name!r}, {len(self.segments)} segments, {self.length:.4g} mm)"


# ---- compiled geometry over Path.table() ------------------------------------------------------
# Each function below reproduces the arithmetic of the Path method it names, to the last bit:
# the scalar methods (point, distance) in Python floats (CPython's math.hypot), the array
# methods (points, headings, distances) in numpy's (libm's hypot).

#: Columns of a row of :meth:`Path.table`.
SEGMENT_COLUMNS = 16
_LINE, _ARC, _INVOLUTE = 0.0, 1.0, 2.0


def _segment_row(kind: float, *numbers: float) -> list[float]:
    """A row of :meth:`Path.table`: the segment's ``kind``, its place in the path left at
    zero (columns 1-5, filled by :class:`Path`), its own ``numbers`` from column 6, zeros
    after them."""
    return [kind, 0.0, 0.0, 0.0, 0.0, 0.0, *numbers] + [0.0] * (SEGMENT_COLUMNS - 6 - len(numbers))


@numba.njit(cache=True)
def _segment_point(row, s):
    """Point of the segment ``row`` at arc length ``s`` from its start (``Segment.point``)."""
    kind = row[0]
    if kind == _LINE:
        return _line_xy(row, s)
    if kind == _ARC:
        ang = _arc_angle(row, s)
        return _arc_xy(row, math.cos(ang), math.sin(ang))
    return _involute_at(row, _involute_param(row, s))


@numba.njit(cache=True)
def _involute_at(row, th):
    phi = th + row[9]
    return _involute_xy(row, th, math.cos(phi), math.sin(phi))


# A segment's point at ``loc`` along it, in its table row's terms: each formula once, for
# the point-by-point functions and the rows of points alike (inlined: the same operations
# in the same order wherever they run).


@numba.njit(cache=True, inline="always")
def _line_frame(row):
    """A line's start point and unit direction: ``x0, y0, ux, uy``."""
    return row[6], row[7], row[8], row[9]


@numba.njit(cache=True, inline="always")
def _line_xy(row, loc):
    """A line's point ``loc`` along it."""
    return row[6] + row[8] * loc, row[7] + row[9] * loc


@numba.njit(cache=True, inline="always")
def _arc_angle(row, loc):
    """The angle, seen from an arc's centre, of its point ``loc`` along it."""
    return row[9] + row[10] * loc / row[8]


@numba.njit(cache=True, inline="always")
def _arc_xy(row, c, sn):
    """An arc's point of the angle whose cosine and sine are ``c`` and ``sn``."""
    return row[6] + row[8] * c, row[7] + row[8] * sn


@numba.njit(cache=True, inline="always")
def _involute_param(row, loc):
    """The involute's parameter (its unrolled angle) at its point ``loc`` along it."""
    return math.sqrt(row[12] + 2.0 * loc / row[8])


@numba.njit(cache=True, inline="always")
def _involute_xy(row, th, c, sn):
    """An involute's point of parameter ``th``, ``c`` and ``sn`` the cosine and sine of
    ``th`` plus its base angle."""
    return row[6] + row[8] * (c + th * sn), row[7] + row[8] * (sn - th * c)


@numba.njit(cache=True)
def path_segment_index(tab, length, s):
    """``Path.segment_index(s)``."""
    s = min(max(s, 0.0), length)
    k = tab.shape[0] - 1
    while k > 0 and s < tab[k, 1]:
        k -= 1
    return k


@numba.njit(cache=True, _nrt=False)
def path_point(tab, length, s):
    """``Path.point(s)``: one point, ``s`` clamped to the path."""
    s = min(max(s, 0.0), length)
    k = path_segment_index(tab, length, s)
    return _segment_point(tab[k], s - tab[k, 1])


@numba.njit(cache=True, _nrt=False, error_model="numpy")
def path_points(tab, length, s, n, out_x, out_y, scratch):
    """``Path.points(s[:n])`` into ``out_x[:n]``, ``out_y[:n]`` (``scratch``: ``3 n``
    floats), faster than :func:`path_point` point by point.

    The segments' formulas are :func:`path_point`'s in the same order, with the sines
    and cosines of the arcs' and involutes' angles from
    :func:`~machining_envs.core.compiled.kernels.sincos_row`, all the angles of the row at once in
    the processor's vectors, instead of libm's one at a time. A point on a line is
    :func:`path_point`'s to the last bit; on a curve a sine or cosine may differ from
    libm's by one unit in the last place (about 1e-16 of the radius); each point is the
    same wherever it falls in the row.

    A row whose points all lie on one segment (most of a block's) takes that segment's
    formulas in one straight loop (:func:`_segment_points`), the others point by point.
    It divides by radii as numpy does (``error_model="numpy"``: no test for a zero
    divisor at each point, which kept the loop out of the processor's vectors; a path's
    radii are positive, checked when it is made). Like the other functions of a path
    table that the feed env's step calls, it allocates nothing and keeps no reference
    counts of its views (``_nrt=False``).
    """
    ang = scratch[:n]
    th = scratch[n : 2 * n]
    seg = scratch[2 * n : 3 * n]
    last = tab.shape[0] - 1
    # The segment of the first point, and whether every point lies within it: the segment
    # each point's own search finds is then this one.
    k = path_segment_index(tab, length, s[0])
    lo = tab[k, 1] if k > 0 else -np.inf
    hi = tab[k + 1, 1] if k < last else np.inf
    one = True
    for j in range(n):
        sj = min(max(s[j], 0.0), length)
        one = one & (sj >= lo) & (sj < hi)  # (NaN: False, point by point)
        seg[j] = k  # (each point's segment, as the loop point by point leaves it)
    if one:
        _segment_points(tab[k], length, s, n, out_x, out_y, ang, th)
        return
    before = min(max(s[0], 0.0), length)  # the first point walks on from its own segment
    curved = False  # whether a point lies on an arc or involute (else no sine is needed)
    for j in range(n):
        sj = min(max(s[j], 0.0), length)
        if k >= 0 and sj >= before:
            # Not before the last point: its segment or one after it. The segments' starts
            # are sorted, so walking on from there ends where path_segment_index's walk
            # back from the last segment ends (a row of a block's points: a step or none,
            # where the walk back passed every segment after it, for each point).
            while k < last and tab[k + 1, 1] <= sj:
                k += 1
        else:
            k = path_segment_index(tab, length, sj)
        before = sj
        row = tab[k]
        loc = sj - row[1]
        seg[j] = k
        kind = row[0]
        if kind == _LINE:
            th[j] = loc
            ang[j] = 1.0  # unused: any angle in the vector path's range
        elif kind == _ARC:
            th[j] = 0.0
            ang[j] = _arc_angle(row, loc)
            curved = True
        else:
            t = _involute_param(row, loc)
            th[j] = t
            ang[j] = t + row[9]
            curved = True
    if curved:  # (a point on a line reads neither)
        sincos_row(ang, n, out_y, out_x)  # the sines into out_y, the cosines into out_x
    for j in range(n):
        row = tab[int(seg[j])]
        kind = row[0]
        if kind == _LINE:
            out_x[j], out_y[j] = _line_xy(row, th[j])
        elif kind == _ARC:
            out_x[j], out_y[j] = _arc_xy(row, out_x[j], out_y[j])
        else:
            out_x[j], out_y[j] = _involute_xy(row, th[j], out_x[j], out_y[j])


@numba.njit(cache=True, inline="always")
def _segment_points(row, length, s, n, out_x, out_y, ang, th):
    """:func:`path_points` of a row of points that all lie on the segment ``row``: its
    formulas, in their order, one loop of the same operations for every point (``ang``,
    ``th``: scratch of ``n`` floats)."""
    kind = row[0]
    if kind == _LINE:
        for j in range(n):
            out_x[j], out_y[j] = _line_xy(row, min(max(s[j], 0.0), length) - row[1])
        return
    if kind == _ARC:
        for j in range(n):
            ang[j] = _arc_angle(row, min(max(s[j], 0.0), length) - row[1])
        sincos_row(ang, n, out_y, out_x)  # the sines into out_y, the cosines into out_x
        for j in range(n):
            out_x[j], out_y[j] = _arc_xy(row, out_x[j], out_y[j])
        return
    for j in range(n):
        t = _involute_param(row, min(max(s[j], 0.0), length) - row[1])
        th[j] = t
        ang[j] = t + row[9]
    sincos_row(ang, n, out_y, out_x)
    for j in range(n):
        out_x[j], out_y[j] = _involute_xy(row, th[j], out_x[j], out_y[j])


@numba.njit(cache=True, _nrt=False)
def path_heading(tab, length, s):
    """``Path.headings([s])[0]``: the unwrapped heading at ``s`` (rad)."""
    s = min(max(s, 0.0), length)
    k = path_segment_index(tab, length, s)
    row = tab[k]
    loc = s - row[1]
    kind = row[0]
    if kind == _LINE:
        return row[2] + 0.0
    if kind == _ARC:
        return row[2] + row[10] * loc / row[8]
    return row[2] + (_involute_param(row, loc) - row[10])


# -- scalar contour error (Path.distance, Python floats) --


@numba.njit(cache=True)
def _segment_distance(row, px, py):
    """``Segment.closest(px, py)[0]``."""
    kind = row[0]
    if kind == _LINE:
        x0, y0, ux, uy = _line_frame(row)
        t = (px - x0) * ux + (py - y0) * uy
        t = 0.0 if t < 0.0 else (row[10] if t > row[10] else t)
        return py_hypot(px - (x0 + ux * t), py - (y0 + uy * t))
    if kind == _ARC:
        dx = px - row[6]
        dy = py - row[7]
        rho = py_hypot(dx, dy)
        rel = (math.atan2(dy, dx) - row[9]) * row[10] % _TWO_PI
        if rel <= row[11] and rho > 0.0:
            return abs(rho - row[8])
        if rho == 0.0:
            return row[8]
        d0 = py_hypot(px - row[12], py - row[13])
        d1 = py_hypot(px - row[14], py - row[15])
        return d0 if d0 <= d1 else d1
    # involute: the feet of the normals from p, and the two ends
    best = math.inf
    ts = row[10]
    te = row[11]
    for th in (ts, te):
        qx, qy = _involute_at(row, th)
        d = py_hypot(px - qx, py - qy)
        if d < best:
            best = d
    dx = px - row[6]
    dy = py - row[7]
    rho = py_hypot(dx, dy)
    if rho <= row[8]:
        return best
    alpha = math.atan2(dy, dx)
    off = math.acos(row[8] / rho)
    span = int(row[13])
    for phi in (alpha + off, alpha - off):
        base = phi - row[9]
        k0 = math.ceil((ts - base) / _TWO_PI)
        for k in range(k0, k0 + span):
            th = base + k * _TWO_PI
            if th > te:
                break
            qx, qy = _involute_at(row, th)
            d = py_hypot(px - qx, py - qy)
            if d < best:
                best = d
    return best


@numba.njit(cache=True)
def path_distance(tab, px, py):
    """``Path.distance(px, py)``: the contour error of one point (segments whose bounding
    circle lies beyond the best distance so far are skipped, as there)."""
    if tab.shape[0] == 1:
        return _segment_distance(tab[0], px, py)
    best = math.inf
    for k in range(tab.shape[0]):
        row = tab[k]
        if best < math.inf:
            # The exact test below decides; a plain square root (within a few units in the
            # last place of it) settles all but the near-ties first.
            dx = px - row[3]
            dy = py - row[4]
            gap = math.sqrt(dx * dx + dy * dy) - row[5]
            margin = 1e-12 * (abs(gap) + row[5] + best)
            if gap - margin >= best:
                continue
            if not gap + margin < best and py_hypot(dx, dy) - row[5] >= best:
                continue
        d = _segment_distance(row, px, py)
        if d < best:
            best = d
    return best


# -- contour errors of many points (Path.distances, numpy arrays) --


@numba.njit(cache=True, inline="always")
def _arc_wedge(row):
    """An arc's wedge, the angles it spans seen from its centre, as two cross products
    with the unit vectors to its ends: ``(sg, wedge, join, u0x, u0y, u1x, u1y)``. A point
    whose offset ``(dx, dy)`` from the centre has ``sg (u0x dy - u0y dx)`` (after the
    start) and ``sg (dx u1y - dy u1x)`` (before the end) above ``1e-8 rho`` lies well
    inside the wedge: both where ``wedge`` (a sweep under pi: the meet of two
    half-planes), either where ``join`` (pi or more: their join). At an angle ``a`` past
    the start the two are ``rho sin(a)`` and ``rho sin(sweep - a)``: both positive is ``0 <
    a < sweep`` for a sweep under pi, either positive is that for a sweep over pi, and at
    pi the two tests are one. The unit vectors lie within 1e-10 of the angles' and the
    margin is 1e-8, so an end whose rounding puts it across pi moves no point across
    the margin. Neither holds for a radius tiny beside the centre's coordinates."""
    cx = row[6]
    cy = row[7]
    r = row[8]
    sized = r >= 1e-5 * (abs(cx) + abs(cy) + 1.0)
    half = row[11] < math.pi
    return (
        row[10],
        half and sized,
        (not half) and sized,
        (row[12] - cx) / r,
        (row[13] - cy) / r,
        (row[14] - cx) / r,
        (row[15] - cy) / r,
    )


@numba.njit(cache=True)
def _segment_distances(row, px, py, n, out):
    """``Segment.closest_many(px[:n], py[:n])[0]`` into ``out[:n]``."""
    kind = row[0]
    if kind == _LINE:
        x0, y0, ux, uy = _line_frame(row)
        for j in range(n):  # in vectors; the lengths vector_hypot leaves (NaN) then by libm
            t = min(max((px[j] - x0) * ux + (py[j] - y0) * uy, 0.0), row[10])
            out[j] = vector_hypot(px[j] - (x0 + ux * t), py[j] - (y0 + uy * t))
        for j in range(n):
            if out[j] != out[j]:
                t = min(max((px[j] - x0) * ux + (py[j] - y0) * uy, 0.0), row[10])
                out[j] = math.hypot(px[j] - (x0 + ux * t), py[j] - (y0 + uy * t))
        return
    if kind == _ARC:
        # A point well inside the arc's wedge (_arc_wedge) has the distance |rho - R|
        # without the angle.
        cx = row[6]
        cy = row[7]
        r = row[8]
        sg, wedge, join, u0x, u0y, u1x, u1y = _arc_wedge(row)
        # First, in vectors, the points inside the wedge whose radius is ordinary (its
        # number libm's, vector_hypot); the others (marked -1) then point by point.
        for j in range(n):
            dx = px[j] - cx
            dy = py[j] - cy
            rho = vector_hypot(dx, dy)
            m = 1e-8 * rho
            after_start = sg * (u0x * dy - u0y * dx) > m
            before_end = sg * (dx * u1y - dy * u1x) > m
            inside = (wedge & after_start & before_end) | (join & (after_start | before_end))
            out[j] = abs(rho - r) if inside else -1.0
        for j in range(n):
            if not out[j] < 0.0:
                continue
            dx = px[j] - row[6]
            dy = py[j] - row[7]
            rho = math.hypot(dx, dy)
            if wedge:
                m = 1e-8 * rho
                if sg * (u0x * dy - u0y * dx) > m and sg * (dx * u1y - dy * u1x) > m:
                    out[j] = abs(rho - r)
                    continue
            rel = (math.atan2(dy, dx) - row[9]) * row[10] % _TWO_PI
            if rel <= row[11] and rho > 0.0:
                out[j] = abs(rho - row[8])
            else:
                d0 = math.hypot(px[j] - row[12], py[j] - row[13])
                d1 = math.hypot(px[j] - row[14], py[j] - row[15])
                out[j] = d0 if d0 <= d1 else d1
        return
    ts = row[10]
    te = row[11]
    span = int(row[13])
    for j in range(n):
        dx = px[j] - row[6]
        dy = py[j] - row[7]
        rho = math.hypot(dx, dy)
        outside = rho > row[8]
        alpha = math.atan2(dy, dx)
        off = math.acos(row[8] / rho if outside else 1.0)
        qx, qy = _involute_at(row, ts)
        best = math.hypot(px[j] - qx, py[j] - qy)
        qx, qy = _involute_at(row, te)
        d = math.hypot(px[j] - qx, py[j] - qy)
        if d < best:
            best = d
        for phi in (alpha + off, alpha - off):
            base = phi - row[9]
            k0 = math.ceil((ts - base) / _TWO_PI)
            for k in range(span):
                th = base + (k0 + k) * _TWO_PI
                if not (outside and th <= te):
                    continue  # numpy evaluates theta_start there, already counted
                qx, qy = _involute_at(row, th)
                d = math.hypot(px[j] - qx, py[j] - qy)
                if d < best:
                    best = d
        out[j] = best


@numba.njit(cache=True, inline="always")
def _near_distance(row, x, y):
    """A lower bound of the distance of ``(x, y)`` to a segment (``Segment.closest``'s),
    for :func:`path_distances`: the distance less an allowance for rounding (``1e-13`` of
    the magnitudes it is computed from, some 500 units in the last place, where square
    roots of sums of squares, not ``hypot``, and a difference of lengths round by a few).
    An arc's is found without its angle (``atan2``): a point clearly inside the arc's
    wedge (:func:`_arc_wedge`) is ``|rho - R|`` from it, one clearly outside is as far as
    the nearer end, and one near an edge of the wedge, or of an arc whose wedge that test
    cannot tell, is no nearer than the lesser of the two.
    Where a length falls outside ``[1e-100, 1e100]`` (squares that under- or overflow)
    and for an involute: :func:`_segment_distance` itself."""
    kind = row[0]
    if kind == _LINE:
        x0, y0, ux, uy = _line_frame(row)
        t = (x - x0) * ux + (y - y0) * uy
        t = 0.0 if t < 0.0 else (row[10] if t > row[10] else t)
        dx = x - (x0 + ux * t)
        dy = y - (y0 + uy * t)
        d = math.sqrt(dx * dx + dy * dy)
        size = abs(x0) + abs(y0) + row[10]
    elif kind == _ARC:
        cx = row[6]
        cy = row[7]
        r = row[8]
        dx = x - cx
        dy = y - cy
        rho = math.sqrt(dx * dx + dy * dy)
        ex = x - row[12]
        ey = y - row[13]
        d0 = math.sqrt(ex * ex + ey * ey)
        ex = x - row[14]
        ey = y - row[15]
        d1 = math.sqrt(ex * ex + ey * ey)
        ends = d0 if d0 <= d1 else d1
        radial = abs(rho - r)
        d = radial if radial < ends else ends  # no nearer than this, wherever the point is
        sg, wedge, join, u0x, u0y, u1x, u1y = _arc_wedge(row)
        if wedge or join:
            m = 1e-8 * rho
            a = sg * (u0x * dy - u0y * dx)  # after the start
            b = sg * (dx * u1y - dy * u1x)  # before the end
            if wedge:
                inside = a > m and b > m
                outside = a < -m or b < -m
            else:
                inside = a > m or b > m
                outside = a < -m and b < -m
            if inside:
                d = radial
            elif outside:
                d = ends
        d = d if rho > 1e-100 else -1.0  # (the centre: its tests are not sure)
        size = abs(cx) + abs(cy) + r
    else:
        return _segment_distance(row, x, y)
    if 1e-100 <= d <= 1e100:
        return d - 1e-13 * (size + abs(x) + abs(y))
    return _segment_distance(row, x, y)


@numba.njit(cache=True, _nrt=False)
def path_distances(tab, px, py, n, out, scratch, lower, order):
    """``Path.distances(px[:n], py[:n])`` into ``out[:n]`` (scratch: ``scratch`` of ``n``
    floats, ``lower`` and ``order`` of one float and one integer per segment).

    The numbers are those of ``Path.distances`` (each point's least distance over the
    segments, each distance computed as there), found with less work: the segments are
    tried from the one nearest a centre of the points, and a segment is skipped when it
    can be no nearer to any point than the largest distance found so far. A distance moves
    by at most what its point moves, so a point lies no nearer to a segment than the
    centre's distance to it less the points' spread about the centre; the test leaves a
    margin far above the rounding of these numbers. Any centre makes the test sound: here
    the midpoint of the first and last points (a block's points run along the path), and
    the centre's distances are :func:`_near_distance`'s, without its arc angles.
    """
    ns = tab.shape[0]
    if ns == 1:
        _segment_distances(tab[0], px, py, n, out)
        return
    mx = 0.5 * (px[0] + px[n - 1])
    my = 0.5 * (py[0] + py[n - 1])
    # The largest squared offset from the centre (row_largest: in vectors); NaN where a
    # point is not finite (or the centre): then nothing is skipped.
    for j in range(n):
        dx = px[j] - mx
        dy = py[j] - my
        scratch[j] = dx * dx + dy * dy
    spread = math.sqrt(row_largest(scratch, n))
    scale = abs(mx) + abs(my) + spread
    for k in range(ns):  # a stable insertion sort of the segments by their lower bound
        v = _near_distance(tab[k], mx, my) - spread
        lower[k] = v
        i = k
        while i > 0 and lower[order[i - 1]] > v:
            order[i] = order[i - 1]
            i -= 1
        order[i] = k
    _segment_distances(tab[order[0]], px, py, n, out)
    dmax = row_largest(out, n)
    for q in range(1, ns):
        k = order[q]
        if lower[k] - 1e-9 * (scale + abs(lower[k]) + dmax) >= dmax:
            continue
        _segment_distances(tab[k], px, py, n, scratch)
        for j in range(n):
            if scratch[j] < out[j]:
                out[j] = scratch[j]
        dmax = row_largest(out, n)


#: The bits of +inf as an int64: from +0 to +inf, a float's bits as an int64 rise with it.
_INF_BITS = 0x7FF0000000000000


@numba.njit(cache=True, inline="always")
def row_largest(out, n):
    """The largest of ``out[:n]``, or its last NaN if it holds one (then no segment is
    skipped; the feed env's peak contour error reads the same).

    A row of distances (every value from +0 to +inf) is found as the largest of their bits
    read as integers, which rise with the values there: one loop in the processor's
    vectors. Any other row (a NaN, a negative value or -0) is taken value by value."""
    hi = float_bits(out[0])
    lo = hi
    for j in range(1, n):
        b = float_bits(out[j])
        hi = b if b > hi else hi
        lo = b if b < lo else lo
    if lo >= 0 and hi <= _INF_BITS:
        return bits_float(hi)
    dmax = out[0]
    for j in range(1, n):
        if out[j] > dmax or out[j] != out[j]:
            dmax = out[j]
    return dmax
