"""The inline accelerator (drpt.accel.inline) against brute force, and the
``auto`` rule that picks it.

Inline evaluates the very tests of BruteForce, in the same order, on the same
float32 data (as constants instead of gathers), so the hits must agree *bit
for bit*: t, primitive, u and v; the random soups here have no separate
parallelograms, which inline tests as one (tests/geometry/test_parallelogram.py and
the Veach render below)."""

from __future__ import annotations

import re
from pathlib import Path

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Array3f, Float

import drpt.accel.inline as inline
from drpt.accel import InlineList, build_accel, embree_lib, resolve_kind
from drpt.backend import policy
from drpt.options import PathOptions, RenderOptions, with_scene_settings
from drpt.render.renderer import Renderer
from drpt.scene import load_scene
from support.accel import closed_mesh_rays, hits, make_scene, rays, soup

MAX_PRIMS = policy().inline_max_prims

INF = float("inf")


def assert_same_as_brute(scene, o, d, tmax=INF):
    got = hits(build_accel(scene, "inline"), o, d, tmax)
    ref = hits(build_accel(scene, "brute"), o, d, tmax)
    for name, a, b in zip(("t", "prim", "u", "v", "valid", "occluded"), got, ref):
        assert np.array_equal(a, b), f"{name}: {(a != b).sum()} rays differ from brute force"
    assert np.array_equal(got[5], got[4])  # occluded == hit for tmax-bounded rays
    assert not np.isnan(got[2]).any() and not np.isnan(got[3]).any()
    return got


def test_soup_spheres_planes_bitwise_equal(loop_mode):
    rng = np.random.default_rng(11)
    tris = soup(rng, 40, size=1.5)
    tris[:3, 2] = tris[:3, 1]  # degenerate (zero-area) triangles
    sc = make_scene(tris, (rng.random((6, 3)) * 10, rng.random(6) + 0.2),
                    ([[0, 1, 0], [1, 0, 0]], [-0.25, 11.0]))
    R = 20000
    o = rng.random((R, 3)) * 12 - 1
    d = rng.normal(size=(R, 3))
    d[:3000] = np.eye(3)[rng.integers(0, 3, 3000)] * rng.choice([-1, 1], (3000, 1))  # axis-parallel
    tmax = np.where(rng.random(R) < 0.3, rng.random(R) * 5, INF)
    t, prim, u, v, valid, occ = assert_same_as_brute(sc, o, d, tmax)
    F, S = 40, 6
    hit = prim[valid]
    assert (hit < F).any() and ((hit >= F) & (hit < F + S)).any() and (hit >= F + S).any()
    assert valid.mean() > 0.3 and (u[prim < F] > 0).any()


def test_watertight_closed_mesh():
    tris, o, d = closed_mesh_rays(1, seed=12)  # 80 faces (inline even above MAX_PRIMS)
    t, _, _, _, valid, _ = assert_same_as_brute(make_scene(tris), o, d)
    assert valid.all(), f"{(~valid).sum()} rays leaked through the closed mesh"
    assert np.allclose(t, 1.0, atol=5e-2)


@pytest.mark.parametrize("scale", [1e-4, 1.0, 1e4])
def test_scales_and_rays_on_surfaces(scale):
    rng = np.random.default_rng(13)
    tris = soup(rng, 30, scale, size=1.0)
    sc = make_scene(tris, (rng.random((3, 3)) * 10 * scale, (rng.random(3) + 0.2) * scale))
    bary = rng.dirichlet([1, 1, 1], 30)
    on = np.einsum("fk,fkc->fc", bary, tris.astype(np.float32).astype(np.float64))
    o = np.concatenate([on, rng.random((3000, 3)) * 10 * scale])
    d = rng.normal(size=(len(o), 3))
    t, _, _, _, valid, _ = assert_same_as_brute(sc, o, d)
    assert (t[valid] > 0).all() and valid.any()


def test_single_triangle_and_empty_scene():
    tri = np.float64([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]])
    rng = np.random.default_rng(14)
    R = 2000
    o = np.column_stack([rng.random(R) * 1.2 - 0.1, rng.random(R) * 1.2 - 0.1, np.full(R, 2.0)])
    d = np.tile([0.0, 0.0, -1.0], (R, 1))
    t, prim, _, _, valid, _ = assert_same_as_brute(make_scene(tri), o, d)
    inside = (o[:, 0] > 1e-6) & (o[:, 1] > 1e-6) & (o[:, 0] + o[:, 1] < 1 - 1e-6)
    assert valid[inside].all() and np.allclose(t[inside], 2.0) and (prim[valid] == 0).all()
    # a scene with nothing inline: every ray misses
    empty = make_scene(spheres=(np.zeros((0, 3)), np.zeros(0)))
    t, prim, _, _, valid, occ = hits(InlineList(empty), o, d)
    assert not valid.any() and np.isinf(t).all() and not occ.any()


def kernel_code(accel, o, d) -> str:
    """LLVM IR of the kernels that run ``accel.intersect`` on these rays."""
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
        dr.kernel_history()
        O, D = rays(o, d)
        dr.make_opaque(O, D)
        dr.eval(accel.intersect(O, D, Float(INF)))
        ir = [k["ir"].getvalue() for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT]
    return "\n".join(ir)


def test_inline_kernel_reads_no_geometry_memory():
    """The point of inline: no gathers in the kernel (the data are constants);
    the positive control is brute force on the same scene, which gathers."""
    rng = np.random.default_rng(15)
    sc = make_scene(soup(rng, 8), (rng.random((2, 3)) * 10, rng.random(2) + 0.2))
    accel = build_accel(sc, "inline")
    assert accel.nbytes == 0 and accel.stats["prims"] == 10
    o, d = rng.random((64, 3)), rng.normal(size=(64, 3))
    code = kernel_code(accel, o, d)
    # Dr.Jit's gathers: llvm.masked.gather, or its packet gathers @gather_<n>x...
    # (not the "+fast-gather" target feature, drpt.llvm_tuning)
    gathers = re.compile(r"llvm\.masked\.gather|@gather_")
    assert "define" in code and not gathers.search(code)
    assert gathers.search(kernel_code(build_accel(sc, "brute"), o, d))


def test_auto_picks_inline_for_tiny_scenes_only():
    rng = np.random.default_rng(16)
    small = make_scene(soup(rng, MAX_PRIMS - 2), (rng.random((1, 3)), np.ones(1)),
                       ([[0, 1, 0]], [0.0]))
    big = make_scene(soup(rng, MAX_PRIMS + 1))
    assert resolve_kind(small) == "inline" and isinstance(build_accel(small), InlineList)
    assert resolve_kind(big) == ("embree" if embree_lib.reason() is None else "bvh")
    assert not isinstance(build_accel(big), InlineList)
    assert resolve_kind(small, "bvh") == "bvh" and resolve_kind(big, "inline") == "inline"
    with pytest.raises(ValueError, match="unknown accelerator"):
        build_accel(small, "kd")


@pytest.mark.parametrize("command", ["render", "bench", "profile"])
def test_help_texts_state_the_limit(command, capsys):
    """The --help of render, bench and profile names the limit resolve_kind uses."""
    from drpt.cli import build_parser

    with pytest.raises(SystemExit):
        build_parser().parse_args([command, "--help"])
    text = " ".join(capsys.readouterr().out.split())  # argparse wraps lines anywhere
    assert f"{MAX_PRIMS} primitives" in text


ROOT = Path(__file__).resolve().parents[2]
#: Veach's MIS scene (seven rectangles, four spheres; the bounce loop) and the Cornell box at
#: max_depth 3 (its ceiling light one parallelogram, in the scene's accelerator and in the
#: emissive list that the unrolled path's last segment looks at first)
#: (file, parallelograms, options, the negative control's shift: about 1/30 of the smallest one)
RECTANGLE_SCENES = {"veach": (ROOT / "tests" / "data" / "xml" / "veach_mis.xml", 7, {}, 1e-3),
                    "cornell": (ROOT / "scenes" / "cornellbox" / "cornellbox.txt", 1,
                                {"path": PathOptions(max_depth=3)}, 0.05)}


def _render_rectangles(monkeypatch, name: str, parallelograms: bool, shift: bool = False) -> np.ndarray:
    """One of :data:`RECTANGLE_SCENES` at 48x36, 4 spp, seed 1, its rectangles tested as
    parallelograms or as triangles; ``shift`` moves every parallelogram test's rays along x
    by the scene's shift (the negative control)."""
    path, quads, fields, dx = RECTANGLE_SCENES[name]
    monkeypatch.setattr(InlineList, "parallelograms", parallelograms)
    if shift:
        test = inline.intersect_parallelogram
        monkeypatch.setattr(inline, "intersect_parallelogram",
                            lambda o, d, q, b: test(o + Array3f(dx, 0.0, 0.0), d, q, b))
    # (independent streams: the control's shifted rectangles send paths other ways, which the
    # default low-discrepancy sampler's correlated draws would hide in the Cornell box)
    opts, scene = with_scene_settings(RenderOptions(progress=False, width=48, height=36, spp=4, seed=1,
                                                    sampler="independent", **fields),
                                      load_scene(path), given={"size", "spp", "seed"})
    r = Renderer(scene, opts)
    assert isinstance(r.scene.accel, InlineList) and len(r.scene.accel.quads) == (quads if parallelograms else 0)
    if name == "cornell":
        assert r.integrator.emitters_first and len(r.scene.emissive._list.quads) == int(parallelograms)
    return r.render().image


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(RECTANGLE_SCENES))
def test_parallelograms_render_the_triangles_image(monkeypatch, name):
    """The same random numbers give the same image within float rounding with the
    rectangles tested as parallelograms: the hit points differ by rounding, so most
    pixels are equal or within 1e-4 (a path that grazes an edge may go another way); in
    the Cornell box the emitter-first look at the ceiling light does not find the light
    occluding itself. Negative control: the parallelograms' rays moved along x by about a
    thirtieth of the smallest rectangle (a shifted rectangle) differ beyond that: in most
    pixels (Veach's), or in the image's mean (the Cornell box's light, seen directly)."""
    tri = _render_rectangles(monkeypatch, name, False)
    monkeypatch.undo()
    quad = _render_rectangles(monkeypatch, name, True)
    monkeypatch.undo()
    moved = _render_rectangles(monkeypatch, name, True, shift=True)

    def close(img):
        rel = np.abs(img - tri) / np.maximum(np.abs(tri), 1e-3)
        return (rel.max(-1) < 1e-4).mean(), abs(img.mean() / tri.mean() - 1.0)

    share, bias = close(quad)
    assert share > 0.97 and bias < 1e-4, (share, bias)
    share, bias = close(moved)
    assert share < 0.9 or bias > 1e-3, (share, bias)
