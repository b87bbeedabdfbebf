"""BVH builder and traversal against the brute-force reference.

``build_accel(kind="bvh")`` is the 4-wide BVH (:mod:`drpt.accel.bvh4`); the
binary one (``"bvh2"``) is checked against brute force alongside it.

Kernels are few and batches wide: each scene is checked with one large batch
of rays per query kind, in both symbolic and evaluated loop modes.
"""

from __future__ import annotations

import numpy as np
import pytest
from drjit.auto import Float

from drpt.accel import build_accel
from drpt.accel.build import build_bvh
from drpt.accel.tree import check_bvh
from support.accel import brute_hits, closed_mesh_rays, make_scene, rays, soup

INF = float("inf")

# Build variants (keyword arguments of build_bvh / build_accel): full SAH, the
# object median, the seed's threshold rule (-SAHeuristic K: SAH in nodes of at
# most 2K primitives; K small enough that both halves of the rule run on the
# test scenes) and minimum leaf sizes (the seed's -resolution with its BVH).
VARIANTS = {
    "sah": dict(method="sah"),
    "median": dict(method="median"),
    "threshold": dict(method="threshold", sah_threshold=64),
    "threshold0": dict(method="threshold", sah_threshold=0),
    "sah-minleaf5": dict(method="sah", min_leaf=5),
    "threshold-minleaf3": dict(method="threshold", sah_threshold=64, min_leaf=3),
    "morton": dict(method="morton"),
    "ploc": dict(method="ploc"),
}


def compare(scene, o, d, tmax=INF, method="sah", leaf_size=4, check_occ=True, ref=None,
            kind="bvh", **build):
    """BVH (``kind``: "bvh", the default 4-wide one, or "bvh2", the binary one)
    closest hit and occlusion vs brute force (``ref``: from
    :func:`brute_hits`, computed when not given); returns the BVH hit (numpy)."""
    O, D = rays(o, d)
    T = Float(np.broadcast_to(np.float32(tmax), (len(o),)).copy())
    bvh = build_accel(scene, kind, method=method, leaf_size=leaf_size, **build)
    g = ref if ref is not None else brute_hits(scene, o, d, tmax)
    h = bvh.intersect(O, D, T)
    ht, gt = h.t.numpy(), g.t.numpy()
    hv, gv = h.valid.numpy(), g.valid.numpy()
    assert np.array_equal(hv, gv)
    assert np.allclose(ht[hv], gt[gv], rtol=1e-5, atol=0)
    assert np.isinf(ht[~hv]).all()
    hp, gp = h.prim.numpy(), g.prim.numpy()
    diff = hp != gp
    # different primitives only at ties (shared edges/vertices, copies): t agrees
    assert np.allclose(ht[diff], gt[diff], rtol=1e-5, atol=0)
    assert not np.isnan(h.u.numpy()).any() and not np.isnan(h.v.numpy()).any()
    same = ~diff & hv
    assert np.allclose(h.u.numpy()[same], g.u.numpy()[same], atol=1e-5)
    if check_occ:
        occ = bvh.occluded(O, D, T).numpy()
        assert np.array_equal(occ, hv)
    return ht, hp, hv, bvh


# ------------------------------------------------------------------ builder only
@pytest.mark.parametrize("variant", VARIANTS)
def test_builder_invariants(variant):
    kw = VARIANTS[variant]
    ml = kw.get("min_leaf", 1)
    rng = np.random.default_rng(0)
    for N in (1, 2, 3, 7, 1000):
        p = soup(rng, N)
        b = build_bvh(p.min(1), p.max(1), max_leaf=4, **kw)
        check_bvh(b, p.min(1), p.max(1))
        counts = b.node_count[b.node_count > 0]
        assert counts.max() <= max(4, 2 * ml - 1)
        # min_leaf honoured: no leaf smaller, unless the whole input is
        assert counts.min() >= min(ml, N)
        assert b.stats["min_leaf_prims"] == counts.min()


def test_auto_rule_picks_sah_small_ploc_large(monkeypatch):
    """"auto" (the default) is full SAH up to AUTO_SAH_MAX primitives, PLOC
    above it, and SAH whenever min_leaf > 1 (PLOC has none)."""
    import drpt.accel.build as build_rules

    monkeypatch.setattr(build_rules, "AUTO_SAH_MAX", 500)
    rng = np.random.default_rng(5)
    small, large = soup(rng, 500), soup(rng, 501)
    assert build_bvh(small.min(1), small.max(1)).stats["method"] == "sah"
    b = build_bvh(large.min(1), large.max(1))
    check_bvh(b, large.min(1), large.max(1))
    assert b.stats["method"] == "ploc"
    m = build_bvh(large.min(1), large.max(1), method="ploc")
    assert np.array_equal(b.prim_order, m.prim_order) and np.array_equal(b.node_a, m.node_a)
    assert build_bvh(large.min(1), large.max(1), min_leaf=2).stats["method"] == "sah"
    assert build_accel(make_scene(large), "bvh").stats["method"] == "ploc"


def test_morton_codes_interleave_bits():
    """Morton codes against the definition (bit k of x, y, z at 3k+2, 3k+1, 3k),
    with a flat axis (quantized to 0)."""
    from drpt.accel.tree import morton30

    rng = np.random.default_rng(3)
    c = rng.random((5000, 3)) * [1.0, 7.0, 0.01]
    c[:, 1] = 2.5
    c[0, 0], c[1, 0] = 0.0, 1.0  # both ends of x: q = 0 and 1023
    ext = np.ptp(c, axis=0)
    q = np.where(ext > 0, (c - c.min(0)) * 1023.0 / np.where(ext > 0, ext, 1.0), 0.0)
    q = np.clip(q.astype(np.int64), 0, 1023)
    expect = np.zeros(len(c), np.int64)
    for bit in range(10):
        for a in range(3):
            expect |= ((q[:, a] >> bit) & 1) << (3 * bit + 2 - a)
    codes = morton30(c)
    assert np.array_equal(codes, expect)
    assert codes.max() < 2**30 and codes[1] & 0b100 << 27


def _subtree_sizes(b):
    """Primitives under every node (children follow parents in BFS order)."""
    size = b.node_count.astype(np.int64)
    for i in range(b.node_a.size - 1, -1, -1):
        if size[i] == 0 and i != 1:
            a = int(b.node_a[i])
            size[i] = size[a] + size[a + 1]
    return size


def test_threshold_rule_median_above_2k_sah_below():
    rng = np.random.default_rng(7)
    p = soup(rng, 20000)
    K = 100
    b = build_bvh(p.min(1), p.max(1), method="threshold", sah_threshold=K)
    check_bvh(b, p.min(1), p.max(1))
    st = b.stats
    assert 0 < st["sah_max_prims"] <= 2 * K < st["median_min_prims"]
    assert st["sah_nodes"] > 0 and st["median_nodes"] > 0
    # in the tree: every inner node above 2K splits at the object median, and
    # the SAH below it does not (always)
    size = _subtree_sizes(b)
    inner = np.flatnonzero((b.node_count == 0) & (np.arange(size.size) != 1))
    left = size[b.node_a[inner].astype(np.int64)]
    big = size[inner] > 2 * K
    assert big.sum() == st["median_nodes"]
    assert np.array_equal(left[big], size[inner][big] // 2)
    assert (left[~big] != size[inner][~big] // 2).mean() > 0.3
    # K = 0 is the median everywhere (the seed's SAH_NUM=0), a huge K is SAH
    m = build_bvh(p.min(1), p.max(1), method="median")
    t0 = build_bvh(p.min(1), p.max(1), method="threshold", sah_threshold=0)
    assert np.array_equal(t0.node_a, m.node_a) and np.array_equal(t0.prim_order, m.prim_order)
    assert t0.stats["sah_nodes"] == 0
    s = build_bvh(p.min(1), p.max(1), method="sah")
    tb = build_bvh(p.min(1), p.max(1), method="threshold", sah_threshold=10**6)
    assert np.array_equal(tb.node_a, s.node_a) and np.array_equal(tb.prim_order, s.prim_order)
    assert s.stats["median_nodes"] == tb.stats["median_nodes"] == 0


@pytest.mark.parametrize("kw", [dict(method="nope"), dict(method="sah", sah_threshold=5),
                                dict(method="threshold", sah_threshold=-1),
                                dict(method="median", min_leaf=0)])
def test_builder_rejects_bad_options(kw):
    p = soup(np.random.default_rng(8), 10)
    with pytest.raises(ValueError):
        build_bvh(p.min(1), p.max(1), **kw)


@pytest.mark.parametrize("variant", VARIANTS)
def test_builder_identical_and_tiny_boxes(variant):
    kw = VARIANTS[variant]
    ml = kw.get("min_leaf", 1)
    rng = np.random.default_rng(1)
    p = np.repeat(soup(rng, 1), 100_000, axis=0)
    b = build_bvh(p.min(1), p.max(1), max_leaf=4, **kw)
    check_bvh(b, p.min(1), p.max(1))
    assert b.depth <= 64 and b.node_count.max() <= max(4, 2 * ml - 1)
    assert b.node_count[b.node_count > 0].min() >= ml
    pts = rng.random((5000, 3)) * 1e-4  # zero-size boxes
    b = build_bvh(pts, pts, max_leaf=2, **kw)
    check_bvh(b, pts, pts)


# ------------------------------------------------------------- traversal vs brute
@pytest.mark.slow
def test_random_soup_spheres_plane(loop_mode):
    rng = np.random.default_rng(2)
    tris = soup(rng, 3000)
    tris[:20, 2] = tris[:20, 1]  # degenerate (zero-area) triangles
    sc = make_scene(tris, (rng.random((40, 3)) * 10, rng.random(40) * 0.5 + 0.05),
                    ([[0, 1, 0]], [-0.25]))
    R = 6000
    o = rng.random((R, 3)) * 12 - 1
    d = rng.normal(size=(R, 3))
    d[:1000] = np.eye(3)[rng.integers(0, 3, 1000)] * rng.choice([-1, 1], (1000, 1))  # axis-parallel
    tmax = np.where(rng.random(R) < 0.3, rng.random(R) * 5, INF)
    ref = brute_hits(sc, o, d, tmax)
    # every build variant; the evaluated (wavefront) loop runs the same kernel
    # on other data, so two variants (small and large leaves) cover it there,
    # and the binary BVH
    variants = VARIANTS if loop_mode else ["sah", "threshold-minleaf3"]
    runs = [("bvh", v) for v in variants] + [("bvh2", v) for v in ("sah", "threshold-minleaf3")]
    for kind, name in runs:
        ht, hp, hv, bvh = compare(sc, o, d, tmax, ref=ref, kind=kind, **VARIANTS[name])
        assert hv.mean() > 0.3
        assert bvh.stats["max_depth"] <= 64 and bvh.nbytes > 0
    # primitive ids cover all three kinds
    F, S = 3000, 40
    assert (hp[hv] < F).any() and ((hp[hv] >= F) & (hp[hv] < F + S)).any() and (hp[hv] == F + S).any()


@pytest.mark.parametrize("scale", [1e-4, 1e4])
def test_scaled_scenes(scale):
    rng = np.random.default_rng(3)
    sc = make_scene(soup(rng, 2000, scale), (rng.random((10, 3)) * 10 * scale, rng.random(10) * scale))
    R = 4000
    compare(sc, rng.random((R, 3)) * 10 * scale, rng.normal(size=(R, 3)), check_occ=False)


@pytest.mark.slow
def test_watertight_closed_mesh(loop_mode):
    tris, o, d = closed_mesh_rays(3, seed=4)  # 1280 faces
    ht, hp, hv, _ = compare(make_scene(tris), o, d, check_occ=False)
    assert hv.all(), f"{(~hv).sum()} rays leaked through the closed mesh"
    assert np.allclose(ht, 1.0, atol=2e-2)  # hits at the targets (up to faceting)


def test_rays_starting_on_surfaces():
    rng = np.random.default_rng(5)
    tris = soup(rng, 500)
    sc = make_scene(tris, (rng.random((5, 3)) * 10, rng.random(5) + 0.2))
    bary = rng.dirichlet([1, 1, 1], 500)
    o = np.einsum("fk,fkc->fc", bary, tris.astype(np.float32).astype(np.float64))
    d = rng.normal(size=(500, 3))
    ht, hp, hv, _ = compare(sc, o, d)
    assert (ht[hv] > 0).all()


@pytest.mark.slow
def test_single_triangle_and_copies():
    """One triangle against brute force; a million copies of it (every ray that
    hits visits them all: few rays) build and traverse, closest hit and any hit."""
    tri = np.float64([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]])
    rng = np.random.default_rng(6)
    for n, R in ((1, 1000), (1_000_000, 32)):
        o = np.column_stack([rng.random(R) * 1.2 - 0.1, rng.random(R) * 1.2 - 0.1,
                             np.full(R, 2.0)])
        d = np.tile([0.0, 0.0, -1.0], (R, 1))
        expect = (o[:, 0] >= 0) & (o[:, 1] >= 0) & (o[:, 0] + o[:, 1] <= 1)
        border = np.abs(o[:, 0] + o[:, 1] - 1) < 1e-6
        sc = make_scene(np.repeat(tri, n, axis=0))
        if n == 1:
            ht, _, hv, _ = compare(sc, o, d)
        else:
            bvh = build_accel(sc, "bvh")
            assert bvh.stats["max_depth"] <= 64
            h = bvh.intersect(*rays(o, d), Float(np.full(R, np.float32(INF))))
            ht, hv = h.t.numpy(), h.valid.numpy()
            occ = bvh.occluded(*rays(o, d), Float(np.full(R, np.float32(INF)))).numpy()
            assert np.array_equal(occ, hv)
        assert np.array_equal(hv[~border], expect[~border])
        assert np.allclose(ht[hv], 2.0)


@pytest.mark.slow
@pytest.mark.parametrize("variant", VARIANTS)
def test_degenerate_input_builds_and_traverses(variant):
    """100k copies of one triangle, and zero-area triangles, with every variant."""
    tri = np.float64([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]])
    rng = np.random.default_rng(9)
    R = 64  # every ray that hits visits all copies: keep it small
    o = np.column_stack([rng.random(R) * 1.2 - 0.1, rng.random(R) * 1.2 - 0.1, np.full(R, 2.0)])
    d = np.tile([0.0, 0.0, -1.0], (R, 1))
    expect = (o[:, 0] >= 0) & (o[:, 1] >= 0) & (o[:, 0] + o[:, 1] <= 1)
    border = np.abs(o[:, 0] + o[:, 1] - 1) < 1e-6
    bvh = build_accel(make_scene(np.repeat(tri, 100_000, axis=0)), "bvh", **VARIANTS[variant])
    assert bvh.stats["max_depth"] <= 64
    h = bvh.intersect(*rays(o, d), Float(INF))
    hv = h.valid.numpy()
    assert np.array_equal(hv[~border], expect[~border])
    assert np.allclose(h.t.numpy()[hv], 2.0)
    # zero-area triangles (collinear or collapsed) among a few real ones
    flat = soup(rng, 3000)
    flat[:1000, 2] = flat[:1000, 1]
    flat[1000:2000, 2] = (flat[1000:2000, 0] + flat[1000:2000, 1]) / 2
    flat[2000:2990, 1:] = flat[2000:2990, :1]
    sc = make_scene(flat)
    R = 2000
    o, d = rng.random((R, 3)) * 12 - 1, rng.normal(size=(R, 3))
    compare(sc, o, d, **VARIANTS[variant])
