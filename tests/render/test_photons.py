"""The photon hash grid (:mod:`drpt.render.photons`): a query visits exactly the photons
within the radius, each once (against brute force)."""

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Array3f, Bool, Float, UInt32

from drpt.render.photons import PhotonGrid


def brute(photons: np.ndarray, valid: np.ndarray, queries: np.ndarray, r: float):
    d2 = ((queries[:, None, :] - photons[None, :, :]) ** 2).sum(-1)
    return (d2 < r * r) & valid[None, :]


def query(grid: PhotonGrid, ids: UInt32, queries: np.ndarray):
    """Per query: the number of photons visited, the sum of their ids and of ``(id % 61)^2``
    (sums exact in float32 at these sizes)."""
    x = Array3f(*(Float(queries[:, i]) for i in range(3)))

    def fn(i, p, keep):
        pid = dr.gather(UInt32, ids, i, keep)
        return Array3f(1.0, Float(pid), dr.square(Float(pid % 61)))

    out = grid.gather(x, dr.full(Bool, True, len(queries)), fn)
    return np.stack([out[i].numpy() for i in range(3)], -1)


@pytest.mark.parametrize("r", [0.02, 0.07, 0.3])
def test_a_query_visits_exactly_the_photons_within_the_radius(r):
    rng = np.random.default_rng(5)
    n = 4000
    # clustered and spread photons, negative coordinates too; some not valid
    photons = np.concatenate([rng.normal(0.0, 0.1, (n // 2, 3)), rng.uniform(-1.0, 1.0, (n // 2, 3))])
    photons = photons.astype(np.float32)
    valid = rng.uniform(size=n) < 0.8
    queries = np.concatenate([rng.normal(0.0, 0.1, (300, 3)), rng.uniform(-1.2, 1.2, (300, 3))]).astype(np.float32)
    ids = np.arange(n, dtype=np.uint32)
    grid = PhotonGrid(Array3f(*(Float(photons[:, i]) for i in range(3))), Bool(valid), r,
                      {"id": UInt32(ids)})
    assert grid.count[0] == valid.sum()
    got = query(grid, grid.fields["id"], queries)
    inside = brute(photons.astype(np.float64), valid, queries.astype(np.float64), r)
    # (float32 against float64 distances: leave out photons within 1e-5 of the sphere)
    d = np.sqrt(((queries[:, None, :].astype(np.float64) - photons[None, :, :]) ** 2).sum(-1))
    clear = ~(np.abs(d - r) < 1e-5).any(1)
    want = np.stack([inside.sum(1), (inside * ids).sum(1), (inside * (ids % 61).astype(np.float64) ** 2).sum(1)], -1)
    assert clear.sum() > 550
    assert inside[clear].sum(1).max() > 5  # (queries that find many photons)
    np.testing.assert_array_equal(got[clear], want[clear])


def test_cells_sharing_a_bucket_are_told_apart():
    """A table much smaller than the cells in use (forced): every bucket holds photons of
    several cells, and a query still visits only its own cells' photons."""
    rng = np.random.default_rng(7)
    n = 2000
    photons = rng.uniform(-2.0, 2.0, (n, 3)).astype(np.float32)
    valid = np.ones(n, bool)
    grid = PhotonGrid(Array3f(*(Float(photons[:, i]) for i in range(3))), Bool(valid), 0.25,
                      {"id": UInt32(np.arange(n, dtype=np.uint32))})
    # rebuild with an 8-bucket table
    small = PhotonGrid.__new__(PhotonGrid)
    small.radius, small.table = 0.25, 8
    small.inv_cell, small.r2, small.mask = Float(2.0), Float(0.0625), UInt32(7)
    from drpt.render.photons import bucket, cell_of

    h = bucket(cell_of(Array3f(*(Float(photons[:, i]) for i in range(3))), small.inv_cell), small.mask)
    order = np.argsort(h.numpy(), kind="stable")
    small.size = UInt32(np.bincount(h.numpy(), minlength=8).astype(np.uint32))
    small.start = dr.prefix_sum(small.size)
    small.p = Array3f(*(Float(photons[order, i]) for i in range(3)))
    ids = UInt32(order.astype(np.uint32))
    queries = rng.uniform(-2.0, 2.0, (200, 3)).astype(np.float32)
    got = query(small, ids, queries)
    want = brute(photons.astype(np.float64), valid, queries.astype(np.float64), 0.25)
    np.testing.assert_array_equal(got[:, 0], want.sum(1))
    assert query(grid, grid.fields["id"], queries)[:, 0].tolist() == got[:, 0].tolist()


def test_the_negative_control_a_wrong_radius_fails():
    """The brute-force check above can fail: a grid queried with cells of half the size
    (a ball that reaches beyond its 8 cells) misses photons."""
    rng = np.random.default_rng(9)
    n = 3000
    photons = rng.uniform(-1.0, 1.0, (n, 3)).astype(np.float32)
    grid = PhotonGrid(Array3f(*(Float(photons[:, i]) for i in range(3))), Bool(np.ones(n, bool)), 0.1,
                      {"id": UInt32(np.arange(n, dtype=np.uint32))})
    queries = rng.uniform(-1.0, 1.0, (300, 3)).astype(np.float32)
    want = brute(photons.astype(np.float64), np.ones(n, bool), queries.astype(np.float64), 0.1).sum(1)
    grid.inv_cell = Float(10.0)  # cells of 0.1 wide: the ball spans 3 per axis
    grid.r2 = Float(0.01)
    # the sort was by the old cells: the buckets no longer match either
    got = query(grid, grid.fields["id"], queries)[:, 0]
    assert (got < want).any()


def _heavy_kernels(build) -> int:
    """How many kernels ``build()`` launches that hold the inputs' computation (more than
    ``HEAVY`` operations), from Dr.Jit's kernel history (load-free)."""
    dr.eval()  # (nothing queued from before)
    dr.kernel_history()  # (cleared)
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
        build()
        history = dr.kernel_history()
    return sum(1 for k in history if k["type"] == dr.KernelType.JIT and k["operation_count"] > HEAVY)


#: well below the operations of :func:`_expensive`'s chain, well above the grid's own kernels (42)
HEAVY = 400


def _expensive(n: int):
    """Unevaluated photon positions, validity and a field behind a chain of about 3600
    operations (as bdpt's photon subpaths reach the grid: traced, not evaluated)."""
    x = dr.arange(Float, n) * (1.0 / n)
    for _ in range(100):
        x = dr.fma(dr.sin(x), 0.5, x * 0.25) + 0.125
    return Array3f(x, x * 2.0, -x), x > 0.3, {"v": x + 1.0}


def test_the_photons_are_computed_once():
    """The grid evaluates its photons' positions, validity and fields in the kernel that counts
    them, so a chain that computed them (bdpt's photon subpaths) runs in one kernel, not
    again in the kernel that writes the sorted copies. Control: the same chain evaluated in
    two steps (the counts first, the fields after) is counted twice."""
    n = 1000

    def grid():
        p, valid, fields = _expensive(n)
        PhotonGrid(p, valid, 0.05, fields)

    assert _heavy_kernels(grid) == 1

    def two_steps():
        p, valid, fields = _expensive(n)
        dr.eval(dr.sum(UInt32(valid)))
        dr.eval(p, fields)

    assert _heavy_kernels(two_steps) == 2
