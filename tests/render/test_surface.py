"""Interaction as a Dr.Jit struct (drpt/render/surface.py): ``dr.gather``, ``dr.select`` and
symbolic loops take it whole.

A gather of an interaction equals numpy's indexing of every field, broadcast fields
(``uv``, ``p_error`` left at their default) stay zero, and a
:class:`TangentInteraction` keeps its ``dp_du``, ``dp_dv`` through gathers, selects and
loops while a plain :class:`Interaction` has none (``None``: no tangent code). The
surface data returns the one its materials need. Negative control: a field left out of
``DRJIT_STRUCT`` (a plain attribute) is not carried by a gather. The triangles' packed
records give back each triangle's data, and interactions interpolate it (negative control:
the records read with a wrong stride).
"""

from __future__ import annotations

from types import SimpleNamespace

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Array2f, Array3f, Bool, Float, UInt32

from drpt.render.surface import Interaction, SurfaceData, TangentInteraction, triangle_tangents
from drpt.scene.model import Material, PerspectiveCamera, Scene, Triangles

N = 7


def _v3(rng):
    return Array3f(*(Float(rng.random(N, dtype=np.float32)) for _ in range(3)))


def _interaction(cls=Interaction, seed=1, **kw):
    rng = np.random.default_rng(seed)
    args = (Bool(rng.random(N) < 0.5), Float(rng.random(N, dtype=np.float32)), _v3(rng), _v3(rng), _v3(rng),
            UInt32(rng.integers(0, 100, N).astype(np.uint32)), UInt32(rng.integers(0, 5, N).astype(np.uint32)),
            _v3(rng))
    return cls(*args, **kw)


def _np(v):
    return np.asarray(v.numpy() if hasattr(v, "numpy") else v)


def test_gather_takes_every_field():
    rng = np.random.default_rng(5)
    uv = Array2f(Float(rng.random(N, dtype=np.float32)), Float(rng.random(N, dtype=np.float32)))
    si = _interaction(uv=uv, p_error=Float(rng.random(N, dtype=np.float32)))
    idx = np.array([6, 0, 3, 3, 1], np.uint32)
    g = dr.gather(type(si), si, UInt32(idx))
    assert type(g) is Interaction and g.dp_du is None and g.dp_dv is None
    for name in Interaction.DRJIT_STRUCT:
        assert np.array_equal(_np(getattr(g, name)), _np(getattr(si, name))[..., idx]), name


def test_broadcast_defaults_stay_zero():
    si = _interaction()
    g = dr.gather(Interaction, si, UInt32([2, 4, 5]))
    assert np.array_equal(_np(g.uv), np.zeros((2, 3), np.float32))
    assert np.array_equal(_np(g.p_error), np.zeros(3, np.float32))


def test_tangent_interaction_keeps_its_tangents():
    rng = np.random.default_rng(9)
    du, dv = _v3(rng), _v3(rng)
    si = _interaction(TangentInteraction, dp_du=du, dp_dv=dv)
    idx = np.array([1, 5, 2], np.uint32)
    g = dr.gather(type(si), si, UInt32(idx))
    assert type(g) is TangentInteraction
    assert np.array_equal(_np(g.dp_du), _np(du)[:, idx]) and np.array_equal(_np(g.dp_dv), _np(dv)[:, idx])
    other = _interaction(TangentInteraction, seed=2, dp_du=_v3(rng))  # dp_dv: zero
    m = np.arange(N) % 2 == 0
    s = dr.select(Bool(m), si, other)
    assert np.array_equal(_np(s.dp_du), np.where(m, _np(du), _np(other.dp_du)))
    assert np.array_equal(_np(s.dp_dv), np.where(m, _np(dv), 0.0))
    assert np.array_equal(_np(s.p), np.where(m, _np(si.p), _np(other.p)))


def test_a_loop_carries_it_whole():
    rng = np.random.default_rng(4)
    si = _interaction(TangentInteraction, dp_du=_v3(rng))
    i = dr.zeros(UInt32, N)
    t0, du0 = _np(si.t).copy(), _np(si.dp_du).copy()  # (the loop updates its state objects)

    def body(i, si):
        si.t = si.t + 1.0
        si.dp_du = si.dp_du * 2.0
        return i + 1, si

    i, out = dr.while_loop((i, si), lambda i, si: i < 3, body)
    assert type(out) is TangentInteraction
    assert np.allclose(_np(out.t), t0 + 3.0)
    assert np.array_equal(_np(out.dp_du), du0 * 8.0)


def test_negative_control_a_plain_attribute_is_not_gathered():
    si = _interaction()
    si.extra = Float(np.arange(N, dtype=np.float32))
    g = dr.gather(Interaction, si, UInt32([0, 1]))
    assert not hasattr(g, "extra")


def test_surface_data_returns_the_interaction_its_materials_need(cornell):
    from drpt.options import RenderOptions
    from drpt.render.scene import DeviceScene
    from drpt.render.surface import SurfaceData
    from drpt.scene import load_scene

    model = load_scene(cornell)
    scene = DeviceScene(model, RenderOptions(width=4, height=4, spp=1))
    assert scene.materials.tangents == 0
    o = dr.full(Array3f, [0.0, 0.0, 0.0], 2)
    d = Array3f(Float([0.0, 0.3]), Float([0.0, 0.1]), Float([-1.0, -1.0]))
    hit = scene.intersect_preliminary(o, d, dr.full(Bool, True, 2))
    si = scene.interaction(o, d, hit)
    assert type(si) is Interaction and si.dp_du is None
    for tangents in (1, 2):  # as for anisotropic materials, then bump maps
        si = SurfaceData(model, tangents=tangents).interaction(o, d, hit)
        assert type(si) is TangentInteraction and dr.width(si.dp_du) == 2


def _mesh(rng, faces, normals=True, uvs=True):
    """A scene of ``faces`` random triangles, with per-corner normals and uvs where asked."""
    n = rng.normal(size=(faces, 3, 3))
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    tris = Triangles(rng.uniform(-3, 3, (faces, 3, 3)), rng.integers(0, 2, faces).astype(np.int32),
                     normals=n if normals else None, uvs=rng.random((faces, 3, 2)) if uvs else None)
    cam = PerspectiveCamera((0, 0, 5), (0, 0, -1), (0, 1, 0), 40)
    return Scene(path=None, camera=cam, materials=[Material("a"), Material("b")], triangles=tris)


@pytest.mark.parametrize("normals, uvs, tangents", [(True, True, 2), (True, False, 0), (False, True, 1),
                                                    (False, False, 0)])
def test_triangle_records_hold_each_triangles_data(normals, uvs, tangents):
    """The packed records (``SurfaceData.tri_data``, read by packet gathers) give back every
    triangle's corner, edges (from the float32 corners), vertex normals, uvs and tangents,
    for masked lanes zeros; an interaction at a hit interpolates them. Negative control: the
    records read with a stride one row short give other values."""
    rng = np.random.default_rng(11)
    model = _mesh(rng, 37, normals, uvs)
    surf = SurfaceData(model, with_uv=True, tangents=tangents)
    assert surf.tri_rows * 8 >= surf.tri_floats and surf.tri_floats % 3 in (0, 2)
    idx = rng.integers(0, 37, 64).astype(np.uint32)
    active = rng.random(64) < 0.8
    rec = surf.triangle(UInt32(idx), Bool(active), normals=True, uv=True)
    p = np.asarray(model.triangles.positions, np.float32).astype(np.float64)
    want = {"p0": p[:, 0], "e1": p[:, 1] - p[:, 0], "e2": p[:, 2] - p[:, 0]}
    for name, w in want.items():
        got = _np(getattr(rec, name)).T
        assert np.array_equal(got[active], w[idx[active]].astype(np.float32))
        assert not got[~active].any()
    assert (rec.n is not None) == normals and (rec.uv is not None) == uvs
    if normals:
        for k in range(3):
            assert np.array_equal(_np(rec.n[k]).T[active],
                                  model.triangles.normals[idx[active], k].astype(np.float32))
    if uvs:
        for k in range(3):
            assert np.array_equal(_np(rec.uv[k]).T[active], model.triangles.uvs[idx[active], k].astype(np.float32))
    # an interaction at barycentrics (u, v) of a triangle interpolates the same data
    u, v = rng.random(64, dtype=np.float32) * 0.5, rng.random(64, dtype=np.float32) * 0.5
    hit = SimpleNamespace(valid=Bool(active), prim=UInt32(idx), t=Float(np.ones(64, np.float32)),
                          u=Float(u), v=Float(v))
    si = surf.interaction(dr.zeros(Array3f, 64), dr.full(Array3f, [0.0, 0.0, 1.0], 64), hit)
    if uvs:
        t = model.triangles.uvs[idx].astype(np.float32)
        uv = t[:, 0] * (1 - u - v)[:, None] + t[:, 1] * u[:, None] + t[:, 2] * v[:, None]
        assert np.allclose(_np(si.uv).T[active], uv[active], atol=1e-6)
    if tangents:
        dp_du, dp_dv = triangle_tangents(model.triangles.positions, model.triangles.uvs)
        assert np.array_equal(_np(si.dp_du).T[active], dp_du[idx[active]].astype(np.float32))
        if tangents > 1:
            assert np.array_equal(_np(si.dp_dv).T[active], dp_dv[idx[active]].astype(np.float32))
    # negative control: a stride one row short reads other triangles' floats
    if surf.tri_rows > 1:
        surf.tri_rows -= 1
        wrong = surf.triangle(UInt32(idx), Bool(active))
        assert not np.array_equal(_np(wrong.e2).T[active], want["e2"][idx[active]].astype(np.float32))
