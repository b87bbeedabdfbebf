"""Interaction as a Dr.Jit struct (drpt/render/surface.py): ``dr.gather``, ``dr.select`` and
symbolic loops take it whole.

A gather of an interaction equals numpy's indexing of every field, broadcast fields
(``uv``, ``p_error`` left at their default) stay zero, and a
:class:`TangentInteraction` keeps its ``dp_du``, ``dp_dv`` through gathers, selects and
loops while a plain :class:`Interaction` has none (``None``: no tangent code). The
surface data returns the one its materials need. Negative control: a field left out of
``DRJIT_STRUCT`` (a plain attribute) is not carried by a gather.
"""

from __future__ import annotations

import drjit as dr
import numpy as np
from drjit.auto import Array2f, Array3f, Bool, Float, UInt32

from drpt.render.surface import Interaction, TangentInteraction

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
