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
Field = tuple[str, type, float | None]


class Record:
    """A record type, declared once from its fields: ``dtype`` (a numpy record, fields by attribute, C
    alignment), ``names`` in order, ``new`` to make one."""

    def __init__(self, *fields: Field) -> None:
        self.fields = fields
        self.names = tuple(name for name, _, _ in fields)
        self.dtype = np.dtype((np.record, np.dtype([(name, kind) for name, kind, _ in fields], align=True)))
        self._starts = {name: start for name, _, start in fields}
        self._required = [name for name, _, start in fields if start is None]
        self._at_start = b"" if self._required else np.array(
            [tuple(start for _, _, start in fields)], dtype=self.dtype).tobytes()

    def new(self, **values: Any) -> np.ndarray:
        """A one-element array of this record: each field at its value in ``values``, else at its
        declared start (``KeyError`` naming a field that does not exist or one without a start left
        out). A few microseconds: a simulation makes three."""
        if values.keys() != self._starts.keys():
            unknown = sorted(values.keys() - self._starts.keys())
            missing = [name for name in self._required if name not in values]
            if unknown or missing:
                raise KeyError(f"record fields unknown: {unknown}; without a value: {missing}")
            if not values:
                return np.frombuffer(bytearray(self._at_start), dtype=self.dtype)
        return np.array([tuple(values.get(name, start) for name, start in self._starts.items())], dtype=self.dtype)


def read(record: np.ndarray) -> dict[str, Any]:
    """A record's fields by name, as Python numbers (from its one-element array, all at once: numpy's
    record scalars read a field in about a microsecond)."""
    return dict(zip(record.dtype.names or (), record.item(0), strict=True))
