"""Workpieces: depth-of-cut profiles along the cut.

A profile is a chain of straight segments over ``[0, length_mm]``; each segment goes from
one depth to another (equal for a plateau, different for a taper), and neighbouring segments
may differ (a step pre-machined into the bar, as in Noh, Kim & Kim 1992 Fig. 7). Past the
end of the workpiece and before its start the depth is zero: the tool cuts air.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numba
import numpy as np

from machining_envs.core.checks import PY_NUMBER_TYPES, is_real
from machining_envs.core.compiled.kernels import copy_into
from machining_envs.core.splits import (
    _split_key,
    lane_split_state,
    split_state,
    stream_bounded,
    stream_fill,
)

__all__ = [
    "DepthProfile",
    "DEPTH_RANGE_MM",
    "drawn_profile",
    "drawn_lane_cuts",
    "drawn_lane_profile",
    "cut_ranges",
    "SplitCuts",
    "lane_segments",
    "load_segments",
    "SegmentTables",
    "SingleCut",
    "traverse_time",
]

#: Depths of cut any profile may hold, mm. Above 6 mm the 1822 N/mm^(1+p) force law of the
#: paper's tool would pass the breakage force at every usable feed; zero is air.
DEPTH_RANGE_MM = (0.0, 6.0)


@dataclass(frozen=True)
class DepthProfile:
    """Piecewise-linear depth of cut ``a(x)`` (mm) against position ``x`` (mm).

    Parameters
    ----------
    edges_mm : tuple of float
        Segment boundaries, strictly increasing, starting at 0; the last is the length.
    start_depths_mm, end_depths_mm : tuple of float
        Depth at the start and end of each segment (one fewer than ``edges_mm``).
    name : str
        Label for plots and tables.
    """

    edges_mm: tuple[float, ...]
    start_depths_mm: tuple[float, ...]
    end_depths_mm: tuple[float, ...]
    name: str = "custom"

    def __post_init__(self) -> None:
        try:
            e = [float(v) for v in self.edges_mm]
        except (TypeError, ValueError):
            raise ValueError(
                f"edges_mm must be a sequence of numbers, got {self.edges_mm!r}"
            ) from None
        if len(e) < 2 or not all(math.isfinite(v) for v in e):
            raise ValueError(
                f"edges_mm must hold at least two finite values, got {self.edges_mm!r}"
            )
        if e[0] != 0.0 or any(b <= a for a, b in zip(e[:-1], e[1:], strict=True)):
            raise ValueError(
                f"edges_mm must start at 0 and increase strictly, got {self.edges_mm!r}"
            )
        lo, hi = DEPTH_RANGE_MM
        rows = []
        for label, d in (
            ("start_depths_mm", self.start_depths_mm),
            ("end_depths_mm", self.end_depths_mm),
        ):
            try:
                vals = [float(v) for v in d]
            except (TypeError, ValueError):
                raise ValueError(f"{label} must be a sequence of numbers, got {d!r}") from None
            if len(vals) != len(e) - 1:
                raise ValueError(f"{label} must hold {len(e) - 1} values, got {d!r}")
            if not all(lo <= v <= hi for v in vals):  # NaN fails too; inf is out of range
                raise ValueError(f"{label} must lie in [{lo}, {hi}] mm, got {d!r}")
            rows.append(vals)
        starts, ends = rows
        self._set_tables(e, starts, ends)

    def _set_tables(self, edges: list, starts: list, ends: list) -> None:
        """Keep the segments, with their slopes, as lists of floats (for
        :meth:`segment_table` and the loops over segments); :attr:`_segments` makes an
        array of them when first asked."""
        slopes = [
            (b - a) / (x1 - x0)
            for a, b, x0, x1 in zip(starts, ends, edges[:-1], edges[1:], strict=True)
        ]
        object.__setattr__(self, "_table", (edges, starts, slopes))
        object.__setattr__(self, "_ends", ends)

    @functools.cached_property
    def _segments(self) -> np.ndarray:
        """The segments as one array of rows of ``n + 1`` values: the edges, then the start
        depths, end depths and slopes, each with an unused last value (the table of
        :meth:`__call__` and the compiled loops; :func:`_random_segments` makes it for a
        random profile)."""
        edges, starts, slopes = self._table
        out = np.zeros((4, len(edges)))
        out[0] = edges
        out[1, :-1] = starts
        out[2, :-1] = self._ends
        out[3, :-1] = slopes
        out.flags.writeable = False
        return out

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        if "_ends" not in state:  # pickled by an earlier version: make the tables
            self.__post_init__()
        segments = state.get("_segments")
        if segments is not None:  # a pickled array comes back writeable
            segments.flags.writeable = False

    @classmethod
    def _built(cls, segments: np.ndarray, name: str) -> DepthProfile:
        """A profile from a read-only segments array this module computed itself (the
        layout of :attr:`_segments`, of values ``__post_init__`` would accept): the same
        object, without checking it again. A vector env draws a workpiece at every lane's
        reset, and the checks were a fifth of that reset's cost."""
        n = segments.shape[1] - 1
        edges, starts, ends, slopes = segments.tolist()
        del starts[n], ends[n], slopes[n]
        new = object.__new__(cls)
        d = new.__dict__  # a frozen dataclass's fields, set as its own __init__ would
        d["edges_mm"] = tuple(edges)
        d["start_depths_mm"] = tuple(starts)
        d["end_depths_mm"] = tuple(ends)
        d["name"] = name
        d["_table"] = (edges, starts, slopes)
        d["_ends"] = ends
        d["_segments"] = segments
        return new

    # ---- constructors ---------------------------------------------------------------------
    @classmethod
    def steps(cls, depths_mm=(1.0, 2.0, 3.0), segment_mm: float = 10.0, name: str = "step"):
        """Plateaus of equal length, e.g. the paper's 1 -> 2 -> 3 mm bar (Fig. 7).

        The paper does not give the length of each step; 10 mm keeps every plateau several
        closed-loop time constants long at all three spindle speeds (at 700 rpm and 3 mm the
        reference feed 0.10 mm/rev crosses 10 mm in about 8 s).
        """
        d = tuple(float(v) for v in depths_mm)
        if not (
            is_real(segment_mm, PY_NUMBER_TYPES) and math.isfinite(segment_mm) and segment_mm > 0
        ):
            raise ValueError(f"segment_mm must be > 0, got {segment_mm!r}")
        edges = tuple(segment_mm * i for i in range(len(d) + 1))
        return cls(edges, d, d, name)

    @classmethod
    def taper(
        cls,
        start_mm: float = 1.0,
        end_mm: float = 3.0,
        length_mm: float = 30.0,
        name: str = "taper",
    ):
        """Depth rising (or falling) linearly from ``start_mm`` to ``end_mm``."""
        return cls((0.0, float(length_mm)), (float(start_mm),), (float(end_mm),), name)

    @classmethod
    def random(
        cls,
        rng: np.random.Generator,
        depth_range_mm: tuple[float, float] = (0.5, 3.0),
        n_segments: tuple[int, int] = (2, 5),
        segment_mm: tuple[float, float] = (4.0, 12.0),
        taper_probability: float = 0.3,
        max_jump_ratio: float = 2.5,
        name: str = "random",
    ) -> DepthProfile:
        """Random chain of plateaus and tapers; every number drawn from ``rng``.

        ``n_segments`` is an inclusive integer range; lengths are uniform in ``segment_mm``.
        Each depth is uniform in ``depth_range_mm`` narrowed so that no step multiplies or
        divides the depth by more than ``max_jump_ratio``: the force jumps by the same
        ratio before any controller can react, and 2.5 keeps a cut held at the 1 kN reference
        below the 3 kN breakage force (the paper's own steps are 2x and 1.5x).
        """
        lo, hi, s_lo, s_hi = cls._check_ranges(depth_range_mm, segment_mm, max_jump_ratio)
        n = int(rng.integers(n_segments[0], n_segments[1] + 1))
        if n < 1:
            raise ValueError(f"n_segments must be a range of integers >= 1, got {n_segments!r}")
        # lengths, start depths, taper?, end depths: one row of n draws each
        table = _random_segments(
            rng.random((4, n)),
            float(lo),
            float(hi),
            s_lo,
            s_hi,
            float(taper_probability),
            float(max_jump_ratio),
        )
        table.flags.writeable = False
        # Built from checked ranges: every edge grows by at least s_lo > 0, every depth
        # lies in [lo, hi] within DEPTH_RANGE_MM.
        if cls is not DepthProfile:  # a subclass may check more: let it
            edges, starts, ends = (tuple(row) for row in table[:3].tolist())
            return cls(edges, starts[:n], ends[:n], name)
        return cls._built(table, str(name))

    @staticmethod
    def _check_ranges(depth_range_mm, segment_mm, max_jump_ratio) -> tuple:
        """:meth:`random`'s checks of its ranges before it draws; ``(lo, hi, s_lo, s_hi)``."""
        lo, hi = depth_range_mm
        if not (0 < lo <= hi <= DEPTH_RANGE_MM[1]):
            raise ValueError(
                f"depth_range_mm must satisfy 0 < lo <= hi <= {DEPTH_RANGE_MM[1]}, got {depth_range_mm!r}"
            )
        if not max_jump_ratio > 1.0:
            raise ValueError(f"max_jump_ratio must be > 1, got {max_jump_ratio!r}")
        s_lo, s_hi = (float(v) for v in segment_mm)
        if not (0.0 < s_lo <= s_hi < math.inf):
            raise ValueError(f"segment_mm must satisfy 0 < lo <= hi < inf, got {segment_mm!r}")
        return lo, hi, s_lo, s_hi

    @classmethod
    def check_random_ranges(
        cls, depth_range_mm, n_segments, segment_mm, max_jump_ratio: float = 2.5
    ) -> None:
        """``ValueError`` unless :meth:`random` accepts these ranges for every draw: what a
        scenario factory checks once before it draws through :func:`drawn_profile`."""
        cls._check_ranges(depth_range_mm, segment_mm, max_jump_ratio)
        if not 1 <= n_segments[0] <= n_segments[1]:
            raise ValueError(f"n_segments must be a range of integers >= 1, got {n_segments!r}")

    # ---- evaluation -----------------------------------------------------------------------
    @property
    def length_mm(self) -> float:
        return float(self.edges_mm[-1])

    @property
    def max_depth_mm(self) -> float:
        return float(max(max(self.start_depths_mm), max(self.end_depths_mm)))

    def segment_table(self) -> tuple[list[float], list[float], list[float]]:
        """The segments as lists of floats, for loops that look one segment up at a time.

        Returns
        -------
        edges : list of float
            Segment boundaries, mm (``edges_mm``).
        start_depths : list of float
            Depth at the start of each segment, mm.
        slopes : list of float
            Depth change per mm along each segment (0 for a plateau): the depth at ``x``
            in segment ``i`` is ``start_depths[i] + slopes[i] * (x - edges[i])``, as
            :meth:`__call__` evaluates it.
        """
        edges, starts, slopes = self._table
        return list(edges), list(starts), list(slopes)

    def segment_array(self) -> np.ndarray:
        """The segments as one read-only array for compiled loops and per-lane tables: rows
        of ``n + 1`` values, the edges (``edges_mm``), then the start depths, end depths and
        slopes of :meth:`segment_table`, each with an unused last value."""
        return self._segments

    def segment_copy(self) -> np.ndarray:
        """:meth:`segment_array` as a new writable array: what a compiled lane start takes,
        the type :func:`lane_segments` gives a batch's lanes (a read-only array is another
        type, and the start would be compiled again for it)."""
        return self._segments.copy()

    def __call__(self, x_mm) -> np.ndarray:
        """Depth (mm) at positions ``x_mm`` (array); zero outside ``[0, length_mm)``."""
        x = np.asarray(x_mm, dtype=np.float64)
        segments = self._segments
        e, d0, slope = segments[0], segments[1, :-1], segments[3, :-1]
        i = np.clip(np.searchsorted(e, x, side="right") - 1, 0, e.size - 2)
        d = d0[i] + slope[i] * (x - e[i])
        return np.where((x >= 0.0) & (x < e[-1]), d, 0.0)

    def change_positions_mm(self) -> tuple[float, ...]:
        """Interior edges where the depth jumps (the steps a controller must absorb)."""
        out = []
        for k in range(1, len(self.edges_mm) - 1):
            if self.end_depths_mm[k - 1] != self.start_depths_mm[k]:
                out.append(float(self.edges_mm[k]))
        return tuple(out)

    def traverse_time_s(self, c: float, q: float, v_max: float) -> float:
        r"""``\int_0^{\ell} \max(1 / v_{max}, c\, a(x)^q)\, dx``, in closed form.

        The time to travel the workpiece at the speed ``v(x) = min(v_max, 1 / (c a(x)^q))``:
        with ``c a^q`` the inverse of the speed a process law allows at depth ``a`` (the
        physical floors of the machining time, e.g. ``machining_envs.turning.scenarios.
        machining_time_bound``). Segment by segment: a plateau exactly, a linear taper by
        the antiderivative of ``a^q``, split where ``c a^q`` crosses ``1 / v_max``; in air
        (``a = 0``) the top speed.
        """
        if not (c > 0 and q > 0 and v_max > 0):
            raise ValueError(f"c, q and v_max must be > 0, got {c!r}, {q!r}, {v_max!r}")
        return traverse_time(self._segments, float(c), float(q), float(v_max))

    def worn_traverse_time_s(
        self, c: float, q: float, v_max: float, wear_per_mm: float, wear_exponent: float
    ) -> float:
        r""":meth:`traverse_time_s` with a tool that dulls along the cut:
        ``\int_0^{\ell} \max(1 / v_{max}, c\, a(x)^q (1 + w x)^r)\, dx`` (``w`` =
        ``wear_per_mm``, ``r`` = ``wear_exponent``), by the trapezoid rule on 20001 points
        with every change of depth resolved to 1e-4 of the length (the same as the closed
        form to about 1e-6 for ``w = 0``)."""
        from scipy.integrate import trapezoid

        if wear_per_mm == 0.0:
            return self.traverse_time_s(c, q, v_max)
        length = self.length_mm
        x = np.unique(
            np.concatenate(
                [
                    np.linspace(0.0, length, 20001),
                    *[[e - 1e-4 * length, e] for e in self.change_positions_mm()],
                ]
            )
        )
        x = x[(x >= 0.0) & (x <= length)]
        a = self(x)
        with np.errstate(divide="ignore"):
            slowness = np.where(a > 0, c * a**q * (1.0 + wear_per_mm * x) ** wear_exponent, 0.0)
        return float(trapezoid(np.maximum(slowness, 1.0 / v_max), x))


def drawn_profile(state, before: int, ranges: tuple, after: int, name: str):
    """A random workpiece drawn from a split's compiled stream (``state``:
    :func:`~machining_envs.core.splits.split_state`) between ``before`` and ``after``
    uniform numbers, in one compiled call: ``(the uniforms before, the profile, the
    uniforms after)``, the numbers that ``rng.random(before)``,
    :meth:`DepthProfile.random` ``(rng, ...)`` and ``rng.random(after)`` give from the
    split's generator, ``ranges`` being :func:`cut_ranges` of the same arguments. For
    scenario factories, which check their ranges once: these are not checked again."""
    b, table, a = _draw_cut(state, before, *ranges, after)
    return b, _drawn(table, name), a


def drawn_lane_profile(segments: np.ndarray, i: int, count: int, name: str) -> DepthProfile:
    """Lane ``i``'s workpiece from :func:`drawn_lane_cuts`' ``segments`` (``count`` of its
    own), named ``name``: the profile :func:`drawn_profile` makes of the same numbers."""
    return _drawn(segments[i, :, : count + 1].copy(), name)


class SplitCuts:
    """The base of a cutting process's split factories (Turning-v0, EndMilling-v0): a
    scenario is ``before`` uniforms, a random workpiece (:meth:`DepthProfile.random` with
    ``depth``, ``segments`` and ``segment_mm``, tapers at 0.3, jumps at most 2.5x) and one
    uniform per range ``[lows[k], lows[k] + spans[k])``, the wear rate's last (where the
    split has ``wear``), all from the split's stream of the env's generator in one compiled
    call. A vector env draws the numbers of many lanes at once (:meth:`lanes_drawn`), and
    builds a lane's workpiece from them only when asked for (:meth:`lane_profile`).

    ``lows`` and ``highs`` are the process's ranges before the wear rate's.
    """

    #: Uniforms the process draws before the workpiece.
    before = 0

    def __init__(
        self,
        name: str,
        depth: tuple[float, float],
        segments: tuple[int, int],
        segment_mm: tuple[float, float],
        lows: list[float],
        highs: list[float],
        wear: tuple[float, float] | None,
    ) -> None:
        self.name = name
        self.profile_name = f"{name} profile"
        self.wear = wear
        lows, highs = list(lows), list(highs)
        if wear is not None:  # drawn last: the same cuts as without wear
            lows.append(float(wear[0]))
            highs.append(float(wear[1]))
        self.lows = lows
        self.spans = [hi - lo for lo, hi in zip(lows, highs, strict=True)]
        self.depth, self.segments = depth, segments
        # Checked here, once: the factory builds its workpieces without checking again.
        DepthProfile.check_random_ranges(depth, segments, segment_mm, 2.5)
        self._cut_ranges = cut_ranges(depth, segments, segment_mm, 0.3, 2.5)

    def drawn(self, env_rng: np.random.Generator) -> tuple[np.ndarray, DepthProfile, list[float]]:
        """One scenario's numbers from the env's generator: the uniforms before, the
        workpiece, and the ranges' uniforms (:func:`drawn_profile`)."""
        state = split_state(env_rng, self.name)
        b, profile, v = drawn_profile(
            state, self.before, self._cut_ranges, len(self.lows), self.profile_name
        )
        return b, profile, v.tolist()

    def lanes_drawn(self, table, lanes: np.ndarray) -> tuple:
        """The numbers of :meth:`drawn` for every lane in ``lanes``, each from its
        generator in ``table`` (``LaneGenerators.table``): ``(uniforms before, segments,
        segment counts, uniforms)`` of shapes ``(L, before)``, ``(L, 4, S + 1)``, ``(L,)``
        and ``(L, len(lows))`` (:func:`drawn_lane_cuts`)."""
        return drawn_lane_cuts(
            table, lanes, self.name, self.before, self._cut_ranges, len(self.lows)
        )

    def lane_profile(self, segments: np.ndarray, counts: np.ndarray, i: int) -> DepthProfile:
        """Lane ``i``'s workpiece from :meth:`lanes_drawn`' segments and counts."""
        return drawn_lane_profile(segments, i, int(counts[i]), self.profile_name)

    def in_ranges(self, v: list[float]) -> list[float]:
        """The ranges' values for their uniforms ``v``: ``low + span u`` each (what
        ``rng.uniform(low, high)`` gives)."""
        return [lo + span * x for lo, span, x in zip(self.lows, self.spans, v, strict=True)]


def _drawn(table: np.ndarray, name: str) -> DepthProfile:
    """The profile of a drawn segment table (read-only from now on; not checked again)."""
    table.flags.writeable = False
    return DepthProfile._built(table, name)


def drawn_lane_cuts(table, lanes: np.ndarray, split: str, before: int, ranges: tuple, after: int):
    """:func:`drawn_profile`'s numbers for many lanes in one compiled call, each from the
    ``split``'s stream of its own generator (row ``lanes[i]`` of ``table``, a
    :class:`~machining_envs.core.compiled.normals.LaneGenerators` table): what ``drawn_profile(
    split_state(rng_i, split), ...)`` gives lane by lane, every generator left where that
    leaves it. Returns ``(before, segments, counts, after)``: the uniforms before, of
    shape ``(L, before)``; every lane's segments (:meth:`DepthProfile.segment_array`'s
    rows), lane ``i``'s in ``segments[i, :, : counts[i] + 1]``; the uniforms after,
    ``(L, after)``."""
    return _draw_lane_cuts(table, lanes, _split_key(split), before, *ranges, after)


def cut_ranges(depth_range_mm, n_segments, segment_mm, taper_probability, max_jump_ratio):
    """The ranges of a random workpiece (the arguments of :meth:`DepthProfile.random`
    after its generator, checked by :meth:`DepthProfile.check_random_ranges`) as
    :func:`drawn_profile` and :func:`drawn_lane_cuts` take them: floats and ints, in
    order."""
    lo, hi = depth_range_mm
    s_lo, s_hi = segment_mm
    return (
        float(lo),
        float(hi),
        int(n_segments[0]),
        int(n_segments[1]),
        float(s_lo),
        float(s_hi),
        float(taper_probability),
        float(max_jump_ratio),
    )


@numba.njit(cache=True)
def _draw_lane_cuts(
    table,
    lanes,
    key,
    before,
    lo,
    hi,
    n_lo,
    n_hi,
    s_lo,
    s_hi,
    taper_probability,
    max_jump_ratio,
    after,
):
    """:func:`drawn_lane_cuts`' numbers."""
    n_lanes = lanes.size
    b = np.empty((n_lanes, before))
    a = np.empty((n_lanes, after))
    segments = np.zeros((n_lanes, 4, n_hi + 1))
    counts = np.empty(n_lanes, dtype=np.int64)
    state = np.empty(6, dtype=np.uint64)
    for i in range(n_lanes):
        lane_split_state(table, lanes[i], key, state)
        bi, cut, ai = _draw_cut(
            state, before, lo, hi, n_lo, n_hi, s_lo, s_hi, taper_probability, max_jump_ratio, after
        )
        copy_into(b[i], bi)
        copy_into(a[i], ai)
        n = cut.shape[1] - 1
        for r in range(cut.shape[0]):
            copy_into(segments[i, r], cut[r])
        counts[i] = n
    return b, segments, counts, a


@numba.njit(cache=True)
def _draw_cut(
    state, before, lo, hi, n_lo, n_hi, s_lo, s_hi, taper_probability, max_jump_ratio, after
):
    """:func:`drawn_profile`'s numbers: ``before`` uniforms, the number of segments
    (``integers(n_lo, n_hi + 1)``), a ``(4, n)`` block of uniforms (:meth:`DepthProfile.
    random`'s), its segments (:func:`_random_segments`), ``after`` uniforms."""
    b = np.empty(before)
    stream_fill(state, b)
    n = n_lo + stream_bounded(state, n_hi - n_lo)
    draws = np.empty((4, n))
    stream_fill(state, draws.reshape(-1))
    table = _random_segments(draws, lo, hi, s_lo, s_hi, taper_probability, max_jump_ratio)
    a = np.empty(after)
    stream_fill(state, a)
    return b, table, a


@numba.njit(cache=True)
def _random_segments(draws, lo, hi, s_lo, s_hi, taper_probability, max_jump_ratio):
    """The segments :meth:`DepthProfile.random` draws, from its ``(4, n)`` uniform numbers
    (lengths, start depths, whether a taper, end depths): rows of ``n + 1`` values, the
    edges, then the start depths, end depths and slopes (each with one unused last value).
    Every number is the one the same arithmetic gives in Python, in the same order."""
    n = draws.shape[1]
    out = np.zeros((4, n + 1))
    edges, starts, ends, slopes = out[0], out[1], out[2], out[3]
    for k in range(n):
        edges[k + 1] = edges[k] + s_lo + (s_hi - s_lo) * draws[0, k]
    prev = 0.0
    for k in range(n):
        a, b = lo, hi
        if k > 0:  # no step multiplies or divides the depth by more than max_jump_ratio
            a = max(lo, prev / max_jump_ratio)
            b = min(hi, prev * max_jump_ratio)
        d0 = a + (b - a) * draws[1, k]
        d1 = lo + (hi - lo) * draws[3, k] if draws[2, k] < taper_probability else d0
        starts[k] = d0
        ends[k] = d1
        slopes[k] = (d1 - d0) / (edges[k + 1] - edges[k])
        prev = d1
    return out


@numba.njit(cache=True)
def traverse_time(segments, c, q, v_max):
    """:meth:`DepthProfile.traverse_time_s` over the profile's ``segments``
    (:attr:`DepthProfile._segments`), summed segment by segment in order."""
    a_star = (1.0 / (v_max * c)) ** (1.0 / q)  # the depth at which the two limits meet
    total = 0.0
    for i in range(segments.shape[1] - 1):
        x0 = segments[0, i]
        x1 = segments[0, i + 1]
        a0 = segments[1, i]
        a1 = segments[2, i]
        if a0 == a1:
            total += (x1 - x0) * max(1.0 / v_max, c * a0**q)
            continue
        slope = (a1 - a0) / (x1 - x0)
        xs = x0 + (a_star - a0) / slope
        split = x0 < xs < x1  # two pieces, split where c a^q crosses 1 / v_max
        for piece in range(2 if split else 1):
            u = xs if piece == 1 else x0
            w = xs if split and piece == 0 else x1
            if a0 + slope * (0.5 * (u + w) - x0) <= a_star:
                total += (w - u) / v_max
            else:
                au = a0 + slope * (u - x0)
                aw = a0 + slope * (w - x0)
                total += c * (aw ** (q + 1.0) - au ** (q + 1.0)) / ((q + 1.0) * slope)
    return total


@numba.njit(cache=True)
def lane_segments(segments, i, counts):
    """Lane ``i``'s segments of a batch (:func:`drawn_lane_cuts`' ``segments`` and
    ``counts``) as an array of their own, C-ordered and writable: the type of
    :meth:`DepthProfile.segment_copy`, which a single lane's start hands over, so that the
    compiled start of a lane is compiled once for both (a view into the batch is another
    type, and each type costs seconds of compiling)."""
    n = counts[i] + 1
    out = np.empty((segments.shape[1], n))
    for r in range(segments.shape[1]):
        copy_into(out[r], segments[i, r, :n])
    return out


@numba.njit(cache=True)
def load_segments(segments, lane, edges, d0, slope):
    """Copy a profile's ``segments`` (:meth:`DepthProfile.segment_array`, ``n`` segments)
    into row ``lane`` of the per-lane tables of a batch of cuts: ``edges[lane, : n + 1]``
    (the rest of the row repeats the length), the start depths ``d0[lane, :n]`` and the
    slopes ``slope[lane, :n]`` (the rest zero). The tables must hold ``n`` segments."""
    n = segments.shape[1] - 1
    for i in range(edges.shape[1]):
        edges[lane, i] = segments[0, min(i, n)]
    for i in range(d0.shape[1]):
        d0[lane, i] = segments[1, i] if i < n else 0.0
        slope[lane, i] = segments[3, i] if i < n else 0.0


class SegmentTables:
    """The per-lane workpiece tables of a batch of cuts, which :func:`load_segments` fills:
    ``edges`` (``(n, S + 1)``), ``d0`` and ``slope`` (``(n, S)``), grown to the most
    segments ``S`` a lane's profile has had (:meth:`fit_segments`). A batch's plant
    (``TurningLanes``, ``MillingLanes``) makes them with :meth:`_new_segment_tables`, and
    sets ``STEP_KERNEL`` (its compiled step, a static method) and ``T_COLUMN`` (the column
    of ``lane_f`` that holds each lane's clock) for :meth:`step` and :attr:`t_s`."""

    STEP_KERNEL: staticmethod
    T_COLUMN: int

    def _new_segment_tables(self, n: int) -> None:
        """Tables of ``n`` lanes for one segment each."""
        self._s_max = 1
        #: Counts replacements of the lane arrays (by a profile with more segments).
        self.version = 0
        self.edges = np.zeros((n, 2))
        self.d0 = np.zeros((n, 1))
        self.slope = np.zeros((n, 1))

    def fit_segments(self, n_segments: int) -> None:
        """Widen the per-lane workpiece tables to hold ``n_segments`` segments (a new
        ``version``: references to the old tables are stale)."""
        if n_segments > self._s_max:
            grow = n_segments - self._s_max
            self.edges = np.pad(self.edges, ((0, 0), (0, grow)), mode="edge")
            self.d0 = np.pad(self.d0, ((0, 0), (0, grow)))
            self.slope = np.pad(self.slope, ((0, 0), (0, grow)))
            self._s_max = n_segments
            self.version += 1

    def step(self, commands: np.ndarray, noise_counts: np.ndarray) -> None:
        """Hold ``commands[k]`` (counts; clipped to [0, U_max]) in every lane for one sample,
        with ``noise_counts[k]`` added to lane ``k``'s measurement; results in ``out``,
        ``out_segment`` and ``out_finish``. The plant's compiled kernel is its class's
        ``STEP_KERNEL`` (called with ``arrays()``, the commands and the noise)."""
        commands = np.asarray(commands, dtype=np.float64)
        self.STEP_KERNEL(self.arrays(), commands, np.asarray(noise_counts, dtype=np.float64))

    @property
    def t_s(self) -> np.ndarray:
        """Time of each lane since its cut started, s (column ``T_COLUMN`` of ``lane_f``)."""
        return self.lane_f[:, self.T_COLUMN]


class SingleCut:
    """One cut at a constant spindle speed: a batch of lanes (the class's ``LANES``, a
    :class:`SegmentTables` plant) of one lane, whose :meth:`step` returns the class's
    ``STEP`` record of the lane's signals (``out``), segment and finish time.

    Parameters
    ----------
    params
        The plant's true parameters for this cut.
    spindle_rpm : float
        Spindle speed, rpm, held for the whole cut.
    profile : DepthProfile
        Depth of cut along the workpiece. Reaching its length finishes the cut.
    """

    LANES: type
    STEP: type

    def __init__(self, params, spindle_rpm: float, profile) -> None:
        self._lanes = self.LANES(params, 1)
        self._lanes.start(0, params, spindle_rpm, profile)  # checks the cut
        self.params = params
        self.spindle_rpm = float(spindle_rpm)
        self.profile = profile
        self.length_mm = profile.length_mm
        self.finished = False

    def reset(self) -> None:
        """The tool at rest at the workpiece's start: no feed, no load."""
        self._lanes.start(0, self.params, self.spindle_rpm, self.profile)
        self.finished = False

    @property
    def t_s(self) -> float:
        """Time since the cut started, s."""
        return float(self._lanes.t_s[0])

    def step(self, command: float, noise_counts: float = 0.0):
        """Hold ``command`` (counts; clipped to [0, command_max]) for one sample and advance."""
        lanes = self._lanes
        lanes.step(np.array([command], dtype=np.float64), np.array([noise_counts]))
        fin = float(lanes.out_finish[0])
        self.finished = bool(lanes.finished[0])
        finish = None if math.isnan(fin) else fin
        return self.STEP(*lanes.out[0].tolist(), int(lanes.out_segment[0]), finish)
