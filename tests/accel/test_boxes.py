"""Boxes around the shapes (drpt.accel.boxes): every ray that hits a primitive reaches a box
(grazing rays through vertices and edges, rays in the plane of a flat shape, axis-aligned
directions), rays passing beside the shapes are culled, and the boxes are per shape, one
around all, or none (planes)."""

from __future__ import annotations

import numpy as np
from drjit.auto import Array3f, Bool, UInt32

from drpt.accel import boxes as boxes_module
from drpt.accel.boxes import FLAT, MAX_BOXES, MAX_GROUPS, NO_BOX, ShapeBoxes, flat, material_groups, outward_convex
from drpt.scene import model as M
from support.accel import brute_hits, icosphere, make_scene, rays


def _scene():
    """A small icosphere far from the origin, a flat quad in z = 0 and two spheres (shapes
    1, 2, 2 and 3)."""
    v, f = icosphere(2)
    ico = v[f] * 0.3 + np.array([40.0, 3.0, 2.0])
    quad = np.array([[[-1, -1, 0], [1, -1, 0], [1, 1, 0]], [[-1, -1, 0], [1, 1, 0], [-1, 1, 0]]], float)
    tris = np.concatenate([ico, quad])
    sc = make_scene(tris, spheres=([[0.0, 0.0, 3.0], [5.0, 5.0, 1.0]], [0.5, 0.2]))
    sc.triangles.shape_index = np.array([1] * len(ico) + [2, 2], np.int32)
    return sc, ico, quad


def _rays(ico, quad, seed=5):
    """Rays from outside every box toward the icosphere's vertices and edge points, the
    quad's corners and edges, within its plane, along the axes, and in random directions."""
    rng = np.random.default_rng(seed)
    targets = np.concatenate([ico.reshape(-1, 3), (ico[:, 0] + ico[:, 1]) / 2,
                              quad.reshape(-1, 3), (quad[:, 0] + quad[:, 2]) / 2,
                              rng.random((400, 3)) * [4, 4, 0] - [2, 2, 0]])
    o = rng.normal(size=(len(targets), 3)) * 30
    d = targets - o
    # in the quad's plane, toward its edges and corners; along the axes onto its face
    flat_t = np.concatenate([quad.reshape(-1, 3), rng.random((200, 3)) * [2, 2, 0] - [1, 1, 0]])
    flat_o = np.concatenate([np.c_[rng.normal(size=(len(flat_t), 2)) * 20, np.zeros(len(flat_t))]])
    axis_o = np.c_[rng.random((200, 2)) * 2.2 - 1.1, np.full(200, 7.0)]
    axis_d = np.tile([0.0, 0.0, -1.0], (200, 1))
    beside = rng.normal(size=(2000, 3)) * 30
    o = np.concatenate([o, flat_o, axis_o, beside])
    d = np.concatenate([d, flat_t - flat_o, axis_d, rng.normal(size=(2000, 3))])
    return o, d / np.linalg.norm(d, axis=1, keepdims=True)


def test_every_hit_reaches_a_box_and_the_others_are_mostly_culled():
    """Brute force's hits (grazing, in-plane and axis-aligned rays among them) all reach a
    box; of the rays that hit nothing most are culled. Negative control: the boxes shrunk by
    a hundredth drop rays that hit."""
    sc, ico, quad = _scene()
    o, d = _rays(ico, quad)
    hit = brute_hits(sc, o, d).valid.numpy()
    boxes = ShapeBoxes.of(sc)
    assert len(boxes) == 4
    O, D = rays(o, d)
    reach = boxes.reach(O, D).numpy()
    assert hit.sum() > 300
    assert np.all(reach[hit])
    assert reach[~hit].mean() < 0.5
    shrunk = ShapeBoxes(boxes.lo.astype(float) + 0.01, boxes.hi.astype(float) - 0.01)
    assert not np.all(shrunk.reach(O, D).numpy()[hit])


def test_boxes_per_shape_one_around_many_none_with_planes():
    """One box per shape up to MAX_BOXES, one around all beyond; none for a scene with a
    plane (unbounded) or without primitives."""
    c = np.arange(3 * (MAX_BOXES + 1), dtype=float).reshape(-1, 3) * 3
    few = ShapeBoxes.of(make_scene(spheres=(c[:MAX_BOXES], np.ones(MAX_BOXES))))
    many = ShapeBoxes.of(make_scene(spheres=(c, np.ones(len(c)))))
    assert len(few) == MAX_BOXES and len(many) == 1
    assert np.all(many.lo[0] < c.min(0) - 1) and np.all(many.hi[0] > c.max(0) + 1)
    assert ShapeBoxes.of(make_scene(spheres=(c, np.ones(len(c))), planes=([[0.0, 0.0, 1.0]], [0.0]))) is None
    empty = M.Scene(path=None, camera=make_scene().camera, materials=[M.Material("m")])
    assert ShapeBoxes.of(empty) is None
    # a ray along +x from the left of the first sphere (center (0, 3, 6)) reaches its box (two
    # direction components zero), one above it does not, nor one leaving it backwards
    x = Array3f(1.0, 0.0, 0.0)
    assert few.reach(Array3f(-5.0, 3.0, 6.0), x).numpy().all()
    assert not few.reach(Array3f(-5.0, 3.0, 50.0), x).numpy().any()
    assert not few.reach(Array3f(-5.0, 3.0, 6.0), -x).numpy().any()


def test_rays_from_inside_a_box_and_tangent_to_spheres_reach_it():
    """A camera inside a shape's box (a room) reaches that box in every direction; rays that
    graze a sphere (aimed at a point of its silhouette) hit it by brute force and reach its box.
    Negative control: with that sphere's box shrunk inside its silhouette, grazing rays that
    hit it are culled."""
    sc, ico, quad = _scene()
    boxes = ShapeBoxes.of(sc)
    rng = np.random.default_rng(9)
    d = rng.normal(size=(500, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    for center in (ico.reshape(-1, 3).mean(0), np.array([0.0, 0.0, 3.0])):  # in the icosphere, a sphere
        O, D = rays(np.tile(center, (len(d), 1)), d)
        assert boxes.reach(O, D).numpy().all()
    # tangent rays: from far away toward points on the silhouette of the sphere at (0, 0, 3), r 0.5
    o = np.tile([0.0, -30.0, 3.0], (400, 1))
    phi = rng.random(400) * 2 * np.pi
    rim = np.c_[0.5 * (1 - 1e-6) * np.cos(phi), np.zeros(400), 3.0 + 0.5 * (1 - 1e-6) * np.sin(phi)]
    t = rim - o
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    hit = brute_hits(sc, o, t).valid.numpy()
    assert hit.mean() > 0.9
    O, T = rays(o, t)
    assert np.all(boxes.reach(O, T).numpy()[hit])
    # shrunk so that the sphere's rim lies outside its box: the grazing rays miss it
    lo, hi = boxes.lo.astype(float), boxes.hi.astype(float)
    lo[2, [0, 2]] += 0.1
    hi[2, [0, 2]] -= 0.1
    away = ShapeBoxes(lo, hi)
    assert not np.all(away.reach(O, T).numpy()[hit])


def _cube(n: int = 1):
    """A unit cube's faces, each an ``n x n`` grid of squares split in two coplanar
    triangles, normals out."""
    g = np.linspace(0.0, 1.0, n + 1)
    tris = []
    for axis in range(3):
        for side in (0.0, 1.0):
            u, w = [a for a in range(3) if a != axis]
            for i in range(n):
                for j in range(n):
                    q = np.zeros((4, 3))
                    q[:, axis] = side
                    q[:, u] = [g[i], g[i + 1], g[i + 1], g[i]]
                    q[:, w] = [g[j], g[j], g[j + 1], g[j + 1]]
                    tris += [q[[0, 1, 2]], q[[0, 2, 3]]]
    tris = np.array(tris)
    n_out = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    flip = np.einsum("ij,ij->i", n_out, tris.mean(1) - 0.5) < 0
    tris[flip] = tris[flip][:, ::-1]
    return tris


def test_outward_convex_tells_closed_convex_shapes_and_their_side():
    """An icosphere and a cube (coplanar triangles) are convex, their normals out (+1), or in
    (-1) with the winding reversed; a vertex pushed in or out (a concave edge), a missing
    triangle (not closed), two spheres as one shape (not a sphere's topology) and a flat quad
    are not (0). Negative control: with no tolerance, a cube of 7 x 7 squares a face rounded to
    6 decimals (as an OBJ file writes it) is not convex either, with the tolerance it is."""
    v, f = icosphere(3)
    ico = v[f] * 2.0 + [1.0, -2.0, 0.5]
    assert outward_convex(ico) == 1 and outward_convex(ico[:, ::-1]) == -1
    assert outward_convex(_cube()) == 1 and outward_convex(_cube()[:, ::-1]) == -1
    for scale in (0.9, 1.1):  # one vertex (corners equal to it) moved toward / away from the center
        moved = ico.copy()
        at = np.all(moved == ico[7, 0], axis=2)
        moved[at] = (moved[at] - [1.0, -2.0, 0.5]) * scale + [1.0, -2.0, 0.5]
        assert outward_convex(moved) == 0
    assert outward_convex(ico[1:]) == 0
    assert outward_convex(np.concatenate([ico, ico + 10.0])) == 0
    assert outward_convex(np.array([[[0, 0, 0], [1, 0, 0], [1, 1, 0]], [[0, 0, 0], [1, 1, 0], [0, 1, 0]]], float)) == 0
    a, b = 0.7, 0.3  # (turned: rounding moves corners off their faces' planes)
    turn = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]]) @ \
        np.array([[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]])
    rounded = np.round(_cube(7) @ turn.T * 1.7 + 0.123456789, 6)
    assert outward_convex(rounded) == 1
    boxes_module.CONVEX_EPS, eps = 0.0, boxes_module.CONVEX_EPS
    try:
        assert outward_convex(rounded) == 0
    finally:
        boxes_module.CONVEX_EPS = eps


def test_rays_leaving_a_convex_shape_reach_every_other_shape_they_hit():
    """Rays leaving the icosphere (convex, shape 1) outward from points on it hit none of its
    triangles by brute force; with its box left out (``leaving``), every ray that hits another
    shape still reaches that shape's box and sphere, and most of those that hit nothing are
    culled. Rays leaving inward keep the box. Negative controls: the shapes' spheres shrunk by
    5% lose rays that hit; the rays leaving inward, with the box left out as if they left
    outward, are culled though they hit the icosphere."""
    sc, ico, quad = _scene()
    boxes = ShapeBoxes.of(sc)
    assert list(boxes.outward) == [1, FLAT, 1, 1] and boxes.convex and boxes.flat
    rng = np.random.default_rng(3)
    k = rng.integers(0, len(ico), 3000)
    b = rng.dirichlet([1, 1, 1], 3000)
    p = np.einsum("ti,tij->tj", b, ico[k])
    n = np.cross(ico[k, 1] - ico[k, 0], ico[k, 2] - ico[k, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    d = rng.normal(size=(3000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    out = np.einsum("ij,ij->i", d, n) > 0
    d[:1000] = (np.array([0.0, 0.0, 3.0]) - p[:1000])  # (toward the sphere at (0, 0, 3))
    d[:1000] /= np.linalg.norm(d[:1000], axis=1, keepdims=True)
    out = np.einsum("ij,ij->i", d, n) > 0
    o = p + n * 1e-4 * np.where(out, 1.0, -1.0)[:, None]
    hit = brute_hits(sc, o, d)
    prim, valid = hit.prim.numpy(), hit.valid.numpy()
    assert not np.any(valid & out & (prim < len(ico)))  # (leaving outward: never the icosphere)
    O, D = rays(o, d)
    skip = boxes.leaving(UInt32(k.astype(np.uint32)), Array3f(*np.asarray(n, np.float32).T), D, Bool(True)).numpy()
    assert np.all(skip[out] == 0) and np.all(skip[~out] == NO_BOX)
    reach = boxes.reach(O, D, UInt32(skip)).numpy()
    assert np.all(reach[valid]) and valid[out].sum() > 300
    assert (~reach[out & ~valid]).mean() > 0.5
    tight = ShapeBoxes.of(sc)  # (the spheres around the shapes shrunk: rays that hit are lost)
    tight.radius = tight.radius * 0.95
    assert not np.all(tight.reach(O, D, UInt32(skip)).numpy()[valid])
    back = valid & ~out & (prim < len(ico))  # (leaving inward: they hit the icosphere again)
    assert back.sum() > 300
    forced = np.zeros(len(skip), np.uint32)  # (as if they left it outward)
    assert (~boxes.reach(O, D, UInt32(forced)).numpy()[back]).mean() > 0.5


def test_flat_shapes_are_left_to_either_side():
    """A quad, a single triangle and a fan of coplanar triangles are flat; a quad with a corner
    raised by a millionth of its size is not (nor a cube). Rays leaving the scene's flat quad
    to either side from points on it hit none of its triangles by brute force; ``leaving``
    names its box for them and for no ray in its plane, and every ray that hits another
    shape still reaches that shape's box. Negative control: a quad bent along its diagonal by a
    thousandth is not flat, and a ray leaving its flat half upward meets its raised half,
    which a flat box would have culled."""
    sc, ico, quad = _scene()
    assert flat(quad) and flat(quad[:1]) and flat(quad * 1e3 + [5e3, -2e4, 0.0])
    fan = np.array([[[0, 0, 0], [np.cos(a), np.sin(a), 0], [np.cos(a + 0.5), np.sin(a + 0.5), 0]]
                    for a in np.arange(0, 6, 0.5)]) @ _turn().T + [0.3, 7.0, -2.0]
    assert flat(fan)
    bent = quad.copy()
    bent[1, 2, 2] = 2e-6  # (the corner (-1, 1) of the second triangle only)
    assert not flat(bent) and not flat(_cube())
    boxes = ShapeBoxes.of(sc)
    assert boxes.outward[1] == FLAT
    rng = np.random.default_rng(11)
    k = rng.integers(0, 2, 3000)
    p = np.einsum("ti,tij->tj", rng.dirichlet([1, 1, 1], 3000), quad[k])
    d = rng.normal(size=(3000, 3))
    d[:500] = np.array([0.0, 0.0, 3.0]) - p[:500]  # (toward the sphere above the quad)
    d[500:800, 2] = 0.0  # (in the quad's plane: not leaving it)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    side = np.sign(d[:, 2])
    o = p + np.c_[np.zeros((3000, 2)), 1e-5 * side]
    hit = brute_hits(sc, o, d)
    prim, valid = hit.prim.numpy(), hit.valid.numpy()
    ids = len(ico) + k
    O, D = rays(o, d)
    skip = boxes.leaving(UInt32(ids.astype(np.uint32)), Array3f(0.0, 0.0, 1.0), D, Bool(True)).numpy()
    assert np.all(skip[side != 0] == 1) and np.all(skip[side == 0] == NO_BOX)
    assert not np.any(valid & (side != 0) & (prim >= len(ico)) & (prim < len(ico) + 2))
    reach = boxes.reach(O, D, UInt32(skip)).numpy()
    assert np.all(reach[valid]) and valid[:500].sum() > 400
    # a quad bent up along its diagonal by a thousandth: a ray leaving its flat half upward,
    # grazing, meets the raised half
    valley = quad.copy()
    valley[1, 2, 2] = 1e-3  # (the corner (-1, 1): a shallow valley along y = x)
    assert not flat(valley)
    start, target = np.array([0.5, -0.5, 1e-6]), np.array([-0.9, 0.8, 5e-4])
    to = (target - start) / np.linalg.norm(target - start)
    again = brute_hits(make_scene(valley), start[None], to[None])
    assert to[2] > 0 and again.valid.numpy()[0] and again.prim.numpy()[0] == 1


def _turn():
    a, b = 0.7, 0.3
    return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]]) @ \
        np.array([[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]])


def _groups(p, material):
    """:func:`material_groups` of the triangles ``p`` (``(T, 3, 3)``)."""
    return material_groups(p.min(1), p.max(1), material)


def test_material_groups_merge_overlapping_parts_and_keep_a_ground_apart():
    """drpt's own format (no shapes): a car's parts (body, four wheels, a bumper: materials 0, 1,
    2) become one group, the ground under it (material 3) another, and a room's walls and
    its ceiling light one; two far-apart objects stay apart; more than MAX_GROUPS materials are
    one group. ``ShapeBoxes.of`` then boxes each group, the ground's flat. Negative control:
    the ground shrunk to the car's own size merges with it (their common box costs no more)."""
    cube = _cube(2) * 2.0 - 1.0  # (a cube [-1, 1]^3 of coplanar triangles)
    body = cube * [2.0, 0.6, 0.8] + [0.0, 0.9, 0.0]
    wheels = np.concatenate([cube * 0.3 + [x, 0.3, z] for x in (-1.4, 1.4) for z in (-0.8, 0.8)])
    bumper = cube * [0.1, 0.1, 0.8] + [1.9, 0.5, 0.0]
    ground = np.array([[[-100, 0, -100], [100, 0, -100], [100, 0, 100]],
                       [[-100, 0, -100], [100, 0, 100], [-100, 0, 100]]], float)
    tris = np.concatenate([body, wheels, bumper, ground])
    mat = np.r_[np.zeros(len(body)), np.ones(len(wheels)), np.full(len(bumper), 2), [3, 3]].astype(np.int64)
    g = _groups(tris, mat)
    assert len(set(g[mat < 3])) == 1 and len(set(g[mat == 3])) == 1 and g[0] != g[-1]
    small = tris.copy()
    small[-2:] *= [0.03, 1.0, 0.01]  # (a 6 x 2 ground: inside the car's extent, nearly)
    assert len(set(_groups(small, mat))) == 1
    room = cube * 5.0
    light = cube[:2] * [1.0, 1.0, 0.0] + [0.0, 0.0, 4.99]
    assert len(set(_groups(np.concatenate([room, light]), np.r_[np.zeros(len(room)), [1, 1]]))) == 1
    apart = _groups(np.concatenate([cube, cube + 50.0]), np.r_[np.zeros(len(cube)), np.ones(len(cube))])
    assert len(set(apart)) == 2
    many = np.concatenate([cube + 10.0 * i for i in range(MAX_GROUPS + 1)])
    assert len(set(_groups(many, np.repeat(np.arange(MAX_GROUPS + 1), len(cube))))) == 1
    sc = make_scene(tris)
    sc.triangles.material = mat.astype(np.int32)
    sc.materials = [M.Material(f"m{i}") for i in range(4)]
    boxes = ShapeBoxes.of(sc)
    assert len(boxes) == 2 and list(boxes.outward) == [0, FLAT]
    assert list(boxes.first) == [0, len(tris) - 2] and list(boxes.end) == [len(tris) - 2, len(tris)]
