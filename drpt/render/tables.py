"""Small constant tables read as literals: compares and selects in place of a gather.

A kernel reads per-material, per-emitter and per-sphere values (a BSDF's parameters, an
emitter's radiance and selection probability, a sphere's center) by gathering from arrays of
a few rows, indexed per lane. On the CPU a gather of 16 lanes is 16 loads into one register;
where a table's rows form a few *runs* (consecutive equal rows), a chain of one compare of the
index and one select per run gives the same value from the kernel's own literals, in fewer
cycles (docs/performance.md, "Small tables as literals"). A :class:`Table` holds a table's rows
on the host and uploaded (:attr:`Table.array`); :func:`gather` reads it as such a chain where
its rows form at most :data:`RUNS` runs (a table of one run is a literal), on the LLVM backend,
and by ``dr.gather`` elsewhere; given a plain Dr.Jit array it gathers. The chain's values are
the table's float32 values and a masked lane reads zero, as ``dr.gather``'s does, so images are
bit for bit the gather's.

The literals are part of the kernel: two scenes whose tables differ trace two kernels (as the
inline accelerator's constants, :mod:`drpt.accel.inline`), so a table whose values change from
one render to the next must stay a plain array. An index outside the table (a gather's
undefined read) gives the last run's value.
"""

from __future__ import annotations

import drjit as dr
import numpy as np
from drjit.auto import Array3f, Bool, Float, UInt32

from ..backend import name as backend_name

#: the most runs of equal rows that :func:`gather` reads as a chain of selects (more: a gather)
RUNS = 8


class Table:
    """A constant table of ``cls`` rows (``Float``, ``UInt32``, ``Bool``: ``values`` of shape
    ``(n,)``; ``Array3f``: ``(n, 3)``), uploaded (:attr:`array`) and kept on the host as its
    runs of equal rows (:attr:`runs`)."""

    def __init__(self, cls: type, values):
        v = np.asarray(values)
        if cls is Array3f:
            v = v.astype(np.float32).reshape(-1, 3)
            self.array = Array3f(*(Float(np.ascontiguousarray(v[:, c])) for c in range(3)))
        else:
            v = v.astype({Float: np.float32, UInt32: np.uint32, Bool: bool}[cls]).reshape(-1)
            self.array = cls(v)
        self.cls = cls
        self.size = len(v)
        #: ``(end, row)`` per run of equal rows (equal bits: 0.0 and -0.0 differ), in order: rows
        #: ``end`` of the previous run to ``end - 1`` hold ``row`` (Python values: the literals)
        self.runs: list[tuple[int, tuple]] = []
        if len(v):
            bits = v.view(np.uint32) if v.dtype == np.float32 else v
            change = bits[1:] != bits[:-1]
            if change.ndim > 1:
                change = change.any(axis=1)
            ends = np.append(np.flatnonzero(change) + 1, len(v))
            rows = v[ends - 1].tolist()
            self.runs = [(e, tuple(r) if cls is Array3f else (r,)) for e, r in zip(ends.tolist(), rows)]

    def __len__(self) -> int:
        return self.size

    @property
    def literal(self) -> bool:
        """Whether :func:`gather` reads this table as a chain of selects."""
        return 0 < len(self.runs) <= RUNS and backend_name() == "llvm"

    def _value(self, row: tuple, n: int):
        """``row`` as a literal ``n`` lanes wide."""
        if self.cls is Array3f:
            return Array3f(*(dr.full(Float, x, n) for x in row))
        return dr.full(self.cls, row[0], n)


def gather(cls: type, source, index, active=True):
    """``dr.gather(cls, source, index, active)``, where ``source`` is a Dr.Jit array or a
    :class:`Table` (its :attr:`~Table.array`, or where :attr:`Table.literal` a chain of
    selects of its rows' literals on ``index``: the same values)."""
    if not isinstance(source, Table):
        return dr.gather(cls, source, index, active)
    if not source.literal or cls is not source.cls:
        return dr.gather(cls, source.array, index, active)
    runs = source.runs
    n = max(dr.width(index), dr.width(active))
    v = source._value(runs[-1][1], n)
    if len(runs) > 1:
        i = UInt32(index)
        for end, row in reversed(runs[:-1]):
            v = dr.select(i < end, source._value(row, 1), v)
    if active is True:
        return v
    return dr.select(Bool(active), v, dr.zeros(cls, 1))


def search(cdf, u: Float) -> UInt32:
    """The first index whose value exceeds ``u`` in the non-decreasing table ``cdf`` (a
    :class:`Table` or a Dr.Jit array of ``n`` values), at most ``n - 1``: a discrete
    distribution's sample. Where ``cdf`` is a :attr:`~Table.literal` table, the count of its
    first ``n - 1`` values at most ``u`` (a compare with a literal per run), else
    ``dr.binary_search``: the same index."""
    n = len(cdf) if isinstance(cdf, Table) else dr.width(cdf)
    if isinstance(cdf, Table) and cdf.literal and cdf.cls is Float:
        k, start = dr.zeros(UInt32, dr.width(u)), 0
        for end, (x,) in cdf.runs:
            count = min(end, n - 1) - start
            if count > 0:
                k += dr.select(Float(x) <= u, UInt32(count), UInt32(0))
            start = end
        return k
    if n == 1:
        return dr.zeros(UInt32, dr.width(u))
    source = cdf.array if isinstance(cdf, Table) else cdf
    k = dr.binary_search(0, n - 1, lambda i: dr.gather(Float, source, i) <= u)
    return dr.minimum(k, n - 1)


def choose(index: UInt32, keys: list[int], values, active=True) -> Float:
    """``values[j]`` on the lanes whose ``index`` is ``keys[j]`` (a few distinct keys; float32
    ``values``), as compares and selects of literals, zero on the lanes not ``active``: the
    value a gather at ``index`` from an array that holds ``values[j]`` at ``keys[j]`` reads.
    A lane whose index is none of the keys reads the last value. A key whose value has the
    last one's bits needs no select; all alike, the value is the literal."""
    vals = np.asarray(values, np.float32)
    bits = vals.view(np.uint32).tolist()
    n = max(dr.width(index), dr.width(active))
    v = dr.full(Float, float(vals[-1]), n)
    i = UInt32(index)
    for j in range(len(keys) - 2, -1, -1):
        if bits[j] != bits[-1]:
            v = dr.select(i == keys[j], Float(float(vals[j])), v)
    if active is True:
        return v
    return dr.select(Bool(active), v, 0.0)
