"""Named arguments for the compiled lane kernels: records of arrays, declared once.

A process's kernel reads and writes dozens of arrays (the plant's state, the env's
per-lane tables, the outputs). Rather than take them one by one, in an order that
parallel tuples elsewhere must follow, a kernel takes a few **records**: named tuples of
arrays and numbers, which numba types field by field (``plant.z`` compiles to the array
itself, no lookup at run time). A record class is declared once with :func:`record`,
each field with its kind (dtype and dimensions, or a number) and where its array holds
the lanes (on axis 0, on axis 1, or shared by all lanes), and from that declaration
come:

- the record's **reader** (``Cls.reader``, a compiled function ``reader(t, o)``): the
  record rebuilt from a packed table (``core.compiled.packed``) whose slots ``o, o + 1,
  ...`` hold its fields in order, so that a trampoline taking one table hands its kernel
  the same records (and the same arrays, to the last bit) as a direct call;
- the **axis codes** of its fields (:func:`axes`), which
  :class:`~machining_envs.core.compiled.blocks.LaneBlocks` needs to cut the lanes into
  blocks, and the **offsets** of several records laid out one after the other in a table
  (:func:`offsets`);
- a record of an object's attributes of its fields' names (:func:`gather`), the flat
  argument tuple of several records (:func:`flatten`) and back (:func:`unflatten`).

The columns of a per-lane table are named by an ``enum.IntEnum`` (numba reads a member
as a constant: ``ef[k, EF.force_limit]`` is ``ef[k, 3]``), and :func:`bind_columns` makes
the views of the columns a core reads by name in Python.

This module imports numpy, numba, the standard library and ``core.compiled.packed`` only.
"""

from __future__ import annotations

import collections
import dataclasses
import enum

import numba
import numpy as np

from machining_envs.core.compiled import packed

__all__ = [
    "PLACES",
    "Field",
    "axes",
    "bind_columns",
    "flatten",
    "gather",
    "offsets",
    "record",
    "unflatten",
    "via_table",
]

#: The readers of ``core.compiled.packed`` by kind.
_READERS = {
    "f8": "as_float",
    "i8": "as_int",
    "f8_1": "f8_1",
    "f8_2": "f8_2",
    "f8_2_rows": "f8_2_rows",
    "f8_3": "f8_3",
    "f4_2": "f4_2",
    "i8_1": "i8_1",
    "i8_2": "i8_2",
    "b1_1": "b1_1",
    "b1_2": "b1_2",
}


#: Where a field holds the lanes, by the word that names it in a record's spec.
PLACES = {"lanes": 0, "lanes_t": 1, "shared": None}


@dataclasses.dataclass(frozen=True)
class Field:
    """A record field's kind (a key of the packed readers: ``"f8_2"`` a 2-d float64 array,
    ``"f8"`` a float, ``"i8"`` an int, ...) and where it holds the lanes (``0``, ``1`` or
    ``None``: shared)."""

    kind: str
    axis: int | None


def _parse(name: str, spec: str) -> dict[str, Field]:
    """The fields of a record's ``spec``: lines ``names...: place kind`` (a line of names
    alone continues on the next)."""
    fields: dict[str, Field] = {}
    pending: list[str] = []
    for line in spec.strip().splitlines():
        names, sep, what = line.partition(":")
        pending += names.split()
        if not sep:
            continue
        words = what.split()
        if len(words) != 2 or words[0] not in PLACES or words[1] not in _READERS:
            raise ValueError(
                f"record {name}: each line of the spec must be 'names...: place kind' with a "
                f"place of {sorted(PLACES)} and a kind of {sorted(_READERS)}, got {line!r}"
            )
        for field in pending:
            if field in fields:
                raise ValueError(f"record {name}: field {field!r} is declared twice")
            fields[field] = Field(words[1], PLACES[words[0]])
        pending = []
    if pending:
        raise ValueError(f"record {name}: fields {pending} have no 'place kind'")
    return fields


def record(name: str, module: str, spec: str) -> type:
    """A named tuple class ``name`` of ``module`` (where it must be bound to ``name``, for
    pickles and numba's cache) whose fields ``spec`` declares, a line for the fields of
    one kind and place: ``"z buf work: lanes f8_2"`` (places: ``lanes``, the lanes on
    axis 0; ``lanes_t``, on axis 1; ``shared``: every lane's; kinds: the packed readers',
    ``f8`` a float, ``i8`` an int, ``f8_2`` a 2-d float64 array, ...). The fields stand
    in the spec's order. The class gets ``Cls.fields`` (the :class:`Field` of each),
    ``Cls.axes`` (their axis codes) and ``Cls.reader``: the compiled ``reader(t, o)``
    that rebuilds a record from slots ``o ..`` of a packed table (bind it to a module
    global to call it from compiled code)."""
    fields = _parse(name, spec)
    cls = collections.namedtuple(name, list(fields), module=module)
    cls.fields = tuple(fields.values())
    cls.axes = tuple(f.axis for f in cls.fields)
    # The reader, written out for this record: one reader call per field, in order.
    body = ", ".join(f"{_READERS[f.kind]}(t, o + {i})" for i, f in enumerate(cls.fields))
    source = f"def reader(t, o):\n    return cls({body})\n"
    scope = {"cls": cls, **{r: getattr(packed, r) for r in set(_READERS.values())}}
    exec(compile(source, f"<reader of {module}.{name}>", "exec"), scope)  # noqa: S102
    cls.reader = numba.njit(inline="always")(scope["reader"])
    return cls


def gather(cls, obj, **given):
    """A record of ``cls`` whose fields are ``given`` or else ``obj``'s attributes of the
    same names."""
    return cls(*(given[f] if f in given else getattr(obj, f) for f in cls._fields))


def flatten(*records) -> tuple:
    """The fields of ``records``, one after the other: the argument tuple of a table."""
    return tuple(x for r in records for x in r)


def unflatten(args, classes) -> tuple:
    """The records of ``classes`` from the flat ``args`` (:func:`flatten`'s inverse;
    arguments after the last record's are left out)."""
    out = []
    o = 0
    for cls in classes:
        n = len(cls._fields)
        out.append(cls(*args[o : o + n]))
        o += n
    return tuple(out)


def axes(*classes) -> tuple:
    """The axis codes of the flat arguments of records of ``classes`` in order."""
    return tuple(a for cls in classes for a in cls.axes)


def offsets(*classes) -> tuple[int, ...]:
    """Where each record of ``classes`` begins in a table holding them in order, then
    where the table ends."""
    out = [0]
    for cls in classes:
        out.append(out[-1] + len(cls._fields))
    return tuple(out)


def via_table(trampoline, n_args: int):
    """A Python callable taking a kernel's ``n_args`` flat arguments then its trailing
    ones that packs the former and calls ``trampoline`` on the table: a kernel of records
    as :meth:`~machining_envs.core.compiled.blocks.LaneBlocks.run` calls one of flat
    arguments (on its pool, where it does not call the trampoline itself)."""

    def call(*args):
        return trampoline(packed.pack(args[:n_args]), *args[n_args:])

    return call


def bind_columns(obj, table: np.ndarray, columns: type[enum.IntEnum]) -> None:
    """Set ``obj.<name>`` to the view of column ``member`` of ``table`` (``table[:,
    member]``) for each member of ``columns``."""
    for member in columns:
        setattr(obj, member.name, table[:, member])
