"""A hash grid over photons, built and queried with Dr.Jit (no per-photon Python).

:class:`PhotonGrid` holds ``n`` photons (positions and whatever per-photon fields the caller
stores) sorted by the cell of a uniform grid of cell size ``2 r`` that each falls in, a cell
found through a hash table of ``T`` buckets (a power of 2): a counting sort, the photons'
buckets counted with ``dr.scatter_inc`` (whose old value is each photon's place in its
bucket), the counts' exclusive prefix sum giving each bucket's start. The photons' arrays
are evaluated in the kernel that counts them, so whatever computed them (bdpt's photon
subpaths) runs once, not again in the kernel that writes their sorted copies. Cells that share a
bucket share its range; a query tells them apart by the cell each photon lies in.

:meth:`PhotonGrid.gather` visits, per lane, the photons within distance ``r`` of a point,
exactly those (each once), in a symbolic loop: the ``2 x 2 x 2`` cells of size ``2 r`` that
cover the ball (the ball reaches at most one cell boundary per axis), each cell's bucket
range, each photon in it kept when it lies in that cell and strictly within ``r``. The
loop's iterations per lane are 8 plus the photons in the 8 buckets (their own cell's and
those of the cells that share a bucket).
"""

from __future__ import annotations

from collections.abc import Callable

import drjit as dr
from drjit.auto import Array3f, Array3i, Bool, Float, Int32, UInt32

#: the hash's multipliers (Teschner et al. 2003), one per axis
HASH = (73856093, 19349663, 83492791)


def cell_of(p: Array3f, inv_cell: Float) -> Array3i:
    """The grid cell containing ``p`` (cells of size ``1 / inv_cell``)."""
    return Array3i(dr.floor(p * inv_cell))


def bucket(c: Array3i, mask: UInt32) -> UInt32:
    """The hash table's bucket of cell ``c`` (``mask``: the table's size minus 1)."""
    u = [UInt32(c[i]) * HASH[i] for i in range(3)]
    return (u[0] ^ u[1] ^ u[2]) & mask


class PhotonGrid:
    """``n`` photons sorted by grid cell: :attr:`p` their positions (the ``valid`` ones
    first, by bucket), :attr:`fields` the caller's per-photon arrays in the same order,
    :attr:`start` and :attr:`size` each bucket's range in them. ``radius`` is the query
    radius (the cells are ``2 radius`` wide). Built from width-``n`` arrays; the photons
    that are not ``valid`` are left out (the sorted arrays keep ``n`` entries, the rest
    unused). Everything is evaluated when the constructor returns."""

    def __init__(self, p: Array3f, valid: Bool, radius: float, fields: dict | None = None):
        n = dr.width(valid)
        self.radius = float(radius)
        self.table = 1 << max(8, (max(n, 1) - 1).bit_length())
        # kernel inputs, not literals: a pass with another radius traces the same kernel
        self.inv_cell = dr.opaque(Float, 1.0 / (2.0 * self.radius))
        self.r2 = dr.opaque(Float, self.radius * self.radius)
        self.mask = dr.opaque(UInt32, self.table - 1)
        valid = Bool(valid)
        h = bucket(cell_of(p, self.inv_cell), self.mask)
        counts = dr.zeros(UInt32, self.table)
        slot = dr.scatter_inc(counts, h, valid)
        # the photons and their fields with the counts, in one kernel: evaluated later, the
        # sorted copies below would trace the caller's photon subpaths again
        dr.eval(counts, slot, p, valid, fields or {})
        self.size = counts
        self.start = dr.prefix_sum(counts)  # (exclusive)
        dst = dr.gather(UInt32, self.start, h, valid) + slot
        self.p = dr.zeros(Array3f, n)
        dr.scatter(self.p, p, dst, valid)
        self.fields = {}
        for name, value in (fields or {}).items():
            out = dr.zeros(type(value), n)
            dr.scatter(out, value, dst, valid)
            self.fields[name] = out
        self.count = dr.sum(UInt32(valid))
        dr.eval(self.start, self.p, self.fields, self.count)

    def read(self, name: str, i: UInt32, active: Bool):
        """Field ``name`` of the photons ``i`` (sorted order)."""
        value = self.fields[name]
        return dr.gather(type(value), value, i, active)

    def gather(self, x: Array3f, active: Bool, fn: Callable[[UInt32, Array3f, Bool], Array3f]) -> Array3f:
        """The sum of ``fn(i, p_i, keep)`` over the photons ``i`` (sorted order) at positions
        ``p_i`` within :attr:`radius` of ``x`` (``|p_i - x| < radius``), per ``active`` lane.
        ``fn`` is called in a symbolic loop, once per iteration, with ``keep`` false on the
        iterations that visit no photon within the radius; it must return 0 there."""
        n = dr.width(active)
        base = cell_of(x - self.radius, self.inv_cell)
        state = (dr.zeros(UInt32, n), dr.zeros(UInt32, n), dr.zeros(UInt32, n), dr.zeros(Array3i, n),
                 dr.zeros(Array3f, n), Bool(active))

        def cond(c, j, end, cur, acc, live):
            return live & ((c < 8) | (j < end))

        def body(c, j, end, cur, acc, live):
            take = live & (j < end)
            pj = dr.gather(Array3f, self.p, j, take)
            keep = take & dr.all(cell_of(pj, self.inv_cell) == cur) & (dr.squared_norm(pj - x) < self.r2)
            acc += dr.select(keep, fn(j, pj, keep), 0.0)
            j = dr.select(take, j + 1, j)
            load = live & ~take & (c < 8)
            nxt = base + Array3i(Int32(c & 1), Int32((c >> 1) & 1), Int32((c >> 2) & 1))
            h = bucket(nxt, self.mask)
            s = dr.gather(UInt32, self.start, h, load)
            e = s + dr.gather(UInt32, self.size, h, load)
            cur = dr.select(load, nxt, cur)
            j = dr.select(load, s, j)
            end = dr.select(load, e, end)
            c = dr.select(load, c + 1, c)
            return c, j, end, cur, acc, live

        return dr.while_loop(state, cond, body)[4]
