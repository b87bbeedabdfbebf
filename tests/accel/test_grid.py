"""Uniform grid (3D-DDA) traversal against the brute-force reference.

Each scene is checked with one wide batch of rays per query kind, for grid
resolutions 1, 7 and automatic, in both symbolic and evaluated loop modes.
"""

from __future__ import annotations

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Float

from drpt.accel.brute import BruteForce
from drpt.accel.grid import MAX_RES, UniformGrid, auto_resolution
from support.accel import icosphere, make_scene, rays, soup

INF = float("inf")
RESOLUTIONS = [1, 7, None]


def compare(scene, o, d, tmax=INF, resolutions=RESOLUTIONS, check_occ=True):
    """Grid closest hits (and occlusion) vs brute force for each resolution.

    Returns the brute-force hit ``(t, prim, valid)`` as numpy arrays."""
    O, D = rays(o, d)
    T = Float(np.broadcast_to(np.float32(tmax), (len(o),)).copy())
    with dr.scoped_set_flag(dr.JitFlag.SymbolicLoops, True):  # evaluated brute force is slow
        g = BruteForce(scene).intersect(O, D, T)
        gt, gp, gv = g.t.numpy(), g.prim.numpy(), g.valid.numpy()
        gu = g.u.numpy()
    for res in resolutions:
        grid = UniformGrid(scene, resolution=res)
        assert grid.nbytes > 0 and grid.stats["refs"] >= grid.stats["prims"]
        h = grid.intersect(O, D, T)
        ht, hp, hv = h.t.numpy(), h.prim.numpy(), h.valid.numpy()
        assert np.array_equal(hv, gv), f"res={res}: {(hv != gv).sum()} validity mismatches"
        assert np.allclose(ht[hv], gt[gv], rtol=1e-5, atol=0)
        assert np.isinf(ht[~hv]).all() and (hp[~hv] == 0xFFFFFFFF).all()
        diff = hp != gp
        # different primitives only at ties (shared edges/vertices, copies): t agrees
        assert np.allclose(ht[diff], gt[diff], rtol=1e-5, atol=0)
        assert not np.isnan(h.u.numpy()).any() and not np.isnan(h.v.numpy()).any()
        same = ~diff & hv
        assert np.allclose(h.u.numpy()[same], gu[same], atol=1e-5)
        if check_occ:
            occ = grid.occluded(O, D, T).numpy()
            assert np.array_equal(occ, hv), f"res={res}: occluded != (t < tmax)"
    return gt, gp, gv


# ------------------------------------------------------------------ build
def test_auto_resolution_and_csr():
    rng = np.random.default_rng(0)
    sc = make_scene(soup(rng, 5000))
    g = UniformGrid(sc)
    nx, ny, nz = g.stats["resolution"]
    assert 10 <= nx <= 40 and 10 <= ny <= 40 and 10 <= nz <= 40
    assert g.stats["cells"] == nx * ny * nz
    off, refs = g.offsets.numpy(), g.refs.numpy()
    assert off[0] == 0 and off[-1] == refs.size == g.stats["refs"]
    assert (np.diff(off.astype(np.int64)) >= 0).all() and refs.max() < 5000
    assert set(refs.tolist()) == set(range(5000))  # every primitive registered
    import drjit as dr

    tri_bytes = 4 * dr.width(g.geo.tri_buf)  # the BVH's triangle buffer layout
    assert tri_bytes >= 36 * 5000
    assert g.nbytes == 4 * (off.size + refs.size) + tri_bytes
    # caps: per-axis maximum, flat boxes get one cell across
    assert (auto_resolution(np.array([1.0, 1.0, 1.0]), 10**9) == MAX_RES).all()
    assert list(auto_resolution(np.array([1.0, 1.0, 1e-3]), 10000)) == [141, 141, 1]
    with pytest.raises(ValueError):
        UniformGrid(sc, resolution=0)


# ------------------------------------------------------------ traversal vs brute
@pytest.mark.slow
def test_random_soup_spheres_plane(loop_mode):
    rng = np.random.default_rng(2)
    tris = soup(rng, 3000)
    tris[:20, 2] = tris[:20, 1]  # degenerate (zero-area) triangles
    sc = make_scene(tris, (rng.random((40, 3)) * 10, rng.random(40) * 0.5 + 0.05),
                    ([[0, 1, 0]], [-0.25]))
    R = 6000
    o = rng.random((R, 3)) * 14 - 2  # inside and outside the grid box
    o[:500] = rng.normal(size=(500, 3)) * 60  # far away
    d = rng.normal(size=(R, 3))
    d[:500] = rng.random((500, 3)) * 10 - o[:500]  # ... aimed at the scene
    ax = np.eye(3)[rng.integers(0, 3, 1500)] * rng.choice([-1, 1], (1500, 1))
    d[1000:2500] = ax  # axis-parallel
    o[1500:2000] = np.round(o[1500:2000] * 7 / 10) * 10 / 7  # ... on res-7 cell boundaries
    d[2500:2700] = ax[:200] + 1e-7 * rng.normal(size=(200, 3))  # nearly axis-parallel
    tmax = np.where(rng.random(R) < 0.3, rng.random(R) * 5, INF)
    gt, gp, gv = compare(sc, o, d, tmax)
    assert gv.mean() > 0.3
    F, S = 3000, 40  # ids cover all three kinds
    assert (gp[gv] < F).any() and ((gp[gv] >= F) & (gp[gv] < F + S)).any()
    assert (gp[gv] == F + S).any()


@pytest.mark.slow
def test_large_triangles_span_many_cells(loop_mode):
    # big triangles crossing many cells + small ones: a hit found beyond the
    # current cell's exit must not stop the walk
    rng = np.random.default_rng(7)
    tris = np.concatenate([soup(rng, 30, size=4.0), soup(rng, 300, size=0.2)])
    sc = make_scene(tris)
    R = 4000
    o = rng.random((R, 3)) * 12 - 1
    d = rng.normal(size=(R, 3))
    compare(sc, o, d, resolutions=[7, 32, None])
    try:  # the variant that steps one cell per outer iteration
        UniformGrid.skip_empty = False
        compare(sc, o, d, resolutions=[32])
    finally:
        UniformGrid.skip_empty = True


@pytest.mark.slow
@pytest.mark.parametrize("scale", [1e-4, 1e4])
def test_scaled_scenes(scale):
    rng = np.random.default_rng(3)
    sc = make_scene(soup(rng, 2000, scale), (rng.random((10, 3)) * 10 * scale, rng.random(10) * scale))
    R = 4000
    o = rng.random((R, 3)) * 10 * scale
    d = rng.normal(size=(R, 3))
    d[:500] = np.eye(3)[rng.integers(0, 3, 500)]
    compare(sc, o, d)


@pytest.mark.slow
def test_watertight_closed_mesh(loop_mode):
    v, f = icosphere(3)  # 1280 faces sharing vertices bitwise
    rng = np.random.default_rng(4)
    v = v * 3 + np.float64([0.1, -0.2, 0.3])
    sc = make_scene(v[f])
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    w = rng.random((len(e), 1))
    targets = np.concatenate([v, (v[e[:, 0]] + v[e[:, 1]]) / 2, v[e[:, 0]] * w + v[e[:, 1]] * (1 - w)])
    centers = np.float64([0.1, -0.2, 0.3]) + rng.normal(size=(3, 3)) * 0.3
    centers[0] = [0.1, -0.2, 0.3]
    o = np.repeat(centers, len(targets), axis=0)
    d = np.tile(targets, (3, 1)) - o
    gt, gp, gv = compare(sc, o, d, check_occ=False)
    assert gv.all(), f"{(~gv).sum()} rays leaked through the closed mesh"
    assert np.allclose(gt, 1.0, atol=2e-2)  # hits at the targets (up to faceting)
    # axis-parallel rays from the center through the mesh (vertices on the axes)
    O, D = rays(np.tile(centers[:1], (6, 1)), np.concatenate([np.eye(3), -np.eye(3)]))
    for res in RESOLUTIONS:
        assert UniformGrid(sc, resolution=res).intersect(O, D, Float(INF)).valid.numpy().all()


@pytest.mark.slow
def test_rays_starting_on_surfaces():
    rng = np.random.default_rng(5)
    tris = soup(rng, 500)
    sc = make_scene(tris, (rng.random((5, 3)) * 10, rng.random(5) + 0.2))
    bary = rng.dirichlet([1, 1, 1], 500)
    o = np.einsum("fk,fkc->fc", bary, tris.astype(np.float32).astype(np.float64))
    d = rng.normal(size=(500, 3))
    gt, gp, gv = compare(sc, o, d)
    assert (gt[gv] > 0).all()


@pytest.mark.slow
def test_single_triangle_flat_box(loop_mode):
    tri = np.float64([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]])  # flat scene box (z extent 0)
    R = 1000
    rng = np.random.default_rng(6)
    o = np.column_stack([rng.random(R) * 1.2 - 0.1, rng.random(R) * 1.2 - 0.1, np.full(R, 2.0)])
    d = np.tile([0.0, 0.0, -1.0], (R, 1))
    d[500:] += rng.normal(size=(500, 3)) * 0.05
    sc = make_scene(tri)
    gt, gp, gv = compare(sc, o, d)
    expect = (o[:, 0] >= 0) & (o[:, 1] >= 0) & (o[:, 0] + o[:, 1] <= 1)
    border = np.abs(o[:, 0] + o[:, 1] - 1) < 1e-6
    assert np.array_equal(gv[:500][~border[:500]], expect[:500][~border[:500]])
    # rays in the triangle's plane (parallel to the flat axis) and a point-like scene
    o2 = np.column_stack([rng.random(200) * 1.2 - 0.1, rng.random(200) * 1.2 - 0.1, np.zeros(200)])
    compare(sc, o2, rng.normal(size=(200, 3)) * [1, 1, 0])
    compare(make_scene(np.zeros((1, 3, 3)) + 0.5), rng.random((200, 3)), rng.normal(size=(200, 3)))


def test_empty_and_planes_only():
    sc = make_scene(planes=([[0, 0, 1]], [1.0]))
    O, D = rays([[0, 0, 0], [0, 0, 0]], [[0, 0, 1], [0, 0, -1]])
    g = UniformGrid(sc)
    h = g.intersect(O, D, Float(INF))
    assert h.valid.numpy().tolist() == [True, False] and h.prim.numpy()[0] == 0
    assert g.occluded(O, D, Float(0.5)).numpy().tolist() == [False, False]
    h = UniformGrid(make_scene()).intersect(O, D, Float(INF))
    assert not h.valid.numpy().any()


def test_active_mask_and_copies():
    tri = np.float64([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]])
    sc = make_scene(np.repeat(tri, 1000, axis=0))  # 1000 identical copies in one cell
    O, D = rays([[0.2, 0.2, 1.0]] * 4, [[0, 0, -1]] * 4)
    from drjit.auto import Bool
    g = UniformGrid(sc)
    h = g.intersect(O, D, Float(INF), Bool([True, False, True, False]))
    assert h.valid.numpy().tolist() == [True, False, True, False]
    assert np.allclose(h.t.numpy()[[0, 2]], 1.0)
    occ = g.occluded(O, D, Float([2.0, 2.0, 0.5, 0.5]), Bool([True, False, True, True]))
    assert occ.numpy().tolist() == [True, False, False, False]
