"""Typed records the kernels take: a solver's run settings, its resumable state and what it tracks, each a
numpy structured type declared once (:class:`Record`), read and written by field name in compiled code
(numba's records) and in Python alike.

A record lives in a one-element array (:meth:`Record.new`), which owns its memory: a kernel is given
the array and takes its element (``array[0]``, a view: what the kernel writes is in the array); numba
types a record array from Python in a fraction of a microsecond, a record scalar in over one. Every
field starts at a value its declaration gives or the caller names (a setting, declared without a
start, must be named); none is left unset.
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: One field: name, numpy scalar type, value at the start (None: the caller gives it).
Field = tuple[str, type, float | int | bool | None]


class Record:
    """A record type, declared once from its fields: ``dtype`` (a numpy record, fields by attribute, C
    alignment), ``names`` in order, ``new`` to make one."""

    def __init__(self, *fields: Field) -> None:
        self.fields = fields
        self.dtype = np.dtype((np.record, np.dtype([(name, kind) for name, kind, _ in fields], align=True)))
        self._starts = {name: start for name, _, start in fields}
        self.names = tuple(self._starts)
        self._required = [name for name, _, start in fields if start is None]
        self._exact = [(name, int if kind is np.int64 else bool) for name, kind, _ in fields
                       if kind in (np.int64, np.bool_)]
        self._at_start = b"" if self._required else np.array(
            [tuple(self._starts.values())], dtype=self.dtype).tobytes()

    def new(self, **values: Any) -> np.ndarray:
        """A one-element array of this record: each field at its value in ``values``, else at its
        declared start. ``TypeError`` names a field that does not exist, one without a start left out,
        or an integer or boolean field given another kind of value (numpy would cast it silently). A
        few microseconds: a simulation makes three."""
        if values.keys() != self._starts.keys():
            unknown = sorted(values.keys() - self._starts.keys())
            missing = [name for name in self._required if name not in values]
            if unknown or missing:
                problems = (("unknown", unknown), ("without a value", missing))
                raise TypeError("record fields " + "; ".join(f"{what}: {', '.join(names)}"
                                                             for what, names in problems if names))
            if not values:
                return np.frombuffer(bytearray(self._at_start), dtype=self.dtype)
        wrong = [name for name, kind in self._exact
                 if name in values and not isinstance(values[name], (kind, np.integer if kind is int else np.bool_))]
        if wrong:
            raise TypeError(f"record fields given a value of another kind: {', '.join(wrong)}")
        return np.array([tuple(values.get(name, start) for name, start in self._starts.items())], dtype=self.dtype)


def read(record: np.ndarray) -> dict[str, Any]:
    """A record's fields by name, as Python numbers (from its one-element array, all at once: numpy's
    record scalars read a field in about a microsecond)."""
    return dict(zip(record.dtype.names or (), record.item(0), strict=True))
