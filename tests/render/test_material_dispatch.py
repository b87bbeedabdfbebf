"""The material table's dispatch over lobe kinds (``MaterialTable.dispatch``): each kind
in its own symbolic ``dr.if_stmt`` ("kinds", the default) computes exactly what every
kind under a lane mask ("masked") computes. Images are compared bit for bit (same
random numbers, same arithmetic per lane); the negative control shows that the
comparison sees a difference as small as another seed's. The op-count tests show that
the two dispatches do trace different kernels where a scene has several kinds (so the
equality is not that of one kernel with itself) and the same kernel where it has one."""

from __future__ import annotations

import drjit as dr
import numpy as np
import pytest

from drpt.options import RenderOptions
from drpt.render.material import MaterialTable
from drpt.render.renderer import Renderer
from drpt.scene import load_scene
from support.corpus import corpus_scene


@pytest.fixture(scope="module")
def mixed(tmp_path_factory):
    """materials_cornell: diffuse walls, principled sphere and box, rough and smooth glass
    (four lobe kinds)."""
    from drpt.tools.scenegen import materials_cornell

    out = tmp_path_factory.mktemp("materials_cornell")
    materials_cornell.main(out)
    return out / "materials_cornell.txt"


def render(path, dispatch: str, monkeypatch, seed: int = 0, size: int = 24, spp: int = 4, **options):
    """The render's image and AOVs (``None`` without) with ``MaterialTable.dispatch`` set."""
    monkeypatch.setattr(MaterialTable, "dispatch", dispatch)
    r = Renderer(load_scene(path), RenderOptions(width=size, height=size, spp=spp, seed=seed,
                                                 progress=False, **options))
    res = r.render()
    return res.image, res.aov


def largest_kernel_ops(path, dispatch: str, monkeypatch, **options) -> int:
    """The operation count of the largest JIT kernel of a small render."""
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        dr.kernel_history_clear()
        render(path, dispatch, monkeypatch, size=8, spp=1, **options)
        hist = dr.kernel_history([dr.KernelType.JIT])
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    return max(k["operation_count"] for k in hist)


def assert_same(a, b):
    assert a.shape == b.shape
    assert np.array_equal(a, b), f"{np.count_nonzero(a != b)} values differ, largest by {np.max(np.abs(a - b))}"


@pytest.fixture
def scene(request, mixed, scenes_dir):
    """The scene file a test's ``options`` name: "mixed", or "newscene" (diffuse and
    Cook-Torrance: two kinds that light tracing and bdpt accept)."""
    return mixed if request.param == "mixed" else scenes_dir / "newscene" / "newscene.txt"


#: what runs the table's queries: the megakernel path tracer (eval_pdf, sample), the
#: wavefront integrator's fused tail (the path bounce on the whole table; its shading
#: queues are one kind each here), Whitted (sample, diffuse_color), the albedo AOV (albedo),
#: bdpt and light tracing (eval_pdf at both ends of a connection, sample)
USERS = {"path": ("mixed", {}), "wavefront": ("mixed", {"mode": "wavefront", "wavefront_tail": 256}),
         "whitted": ("mixed", {"integrator": "whitted"}), "albedo": ("mixed", {"aovs": (("albedo", "albedo"),)}),
         "bdpt": ("newscene", {"integrator": "bdpt"}), "ptracer": ("newscene", {"integrator": "ptracer"})}
_USERS = pytest.mark.parametrize(("scene", "options"), USERS.values(), ids=USERS.keys(), indirect=["scene"])


@_USERS
def test_per_kind_images_equal_masked(scene, monkeypatch, options):
    masked, aov_m = render(scene, "masked", monkeypatch, **options)
    kinds, aov_k = render(scene, "kinds", monkeypatch, **options)
    assert masked.mean() > 0.01  # something was rendered
    assert_same(masked, kinds)
    if aov_m is not None:
        assert aov_m.max() > 0.0
        assert_same(aov_m, aov_k)


@pytest.mark.slow
def test_evaluated_loops_and_conditionals_equal_masked(mixed, monkeypatch):
    """With Dr.Jit's loops and conditionals evaluated (a kernel per step, each branch
    run on its lanes' mask) the per-kind dispatch still computes the masked one's image."""
    with dr.scoped_set_flag(dr.JitFlag.SymbolicLoops, False), \
            dr.scoped_set_flag(dr.JitFlag.SymbolicConditionals, False):
        masked, _ = render(mixed, "masked", monkeypatch, size=16, spp=2)
        kinds, _ = render(mixed, "kinds", monkeypatch, size=16, spp=2)
    assert masked.mean() > 0.01
    assert_same(masked, kinds)


def test_negative_control_another_seed_differs(mixed, monkeypatch):
    """The bit comparison detects a change in what the lanes compute: the same
    scene and dispatch with another seed differs."""
    a, _ = render(mixed, "kinds", monkeypatch, seed=0)
    b, _ = render(mixed, "kinds", monkeypatch, seed=1)
    with pytest.raises(AssertionError):
        assert_same(a, b)


@_USERS
def test_several_kinds_trace_branches(scene, monkeypatch, options):
    """Where a scene has several kinds the two dispatches trace different kernels (the
    branches' own frames and merges make the per-kind one larger): the image comparisons
    above compare two kernels, not one with itself."""
    masked = largest_kernel_ops(scene, "masked", monkeypatch, **options)
    kinds = largest_kernel_ops(scene, "kinds", monkeypatch, **options)
    assert kinds > masked


def test_one_kind_kernel_unchanged(cornell, monkeypatch):
    """A one-kind scene (the Cornell box: diffuse only) has no branch: its kernel is the
    masked dispatch's, operation for operation."""
    assert largest_kernel_ops(cornell, "kinds", monkeypatch) == largest_kernel_ops(cornell, "masked", monkeypatch)


def test_unknown_dispatch_refused(cornell, monkeypatch):
    """A misspelt dispatch is refused while tracing (Dr.Jit wraps the error raised in a
    loop: look along the chain of causes)."""
    with pytest.raises(Exception) as info:  # noqa: PT011 - the cause is checked below
        render(cornell, "switch", monkeypatch, size=4, spp=1)
    e, messages = info.value, []
    while e is not None:
        messages.append(str(e))
        e = e.__cause__ or e.__context__
    assert any("dispatch must be 'kinds' or 'masked'" in m for m in messages), messages


@pytest.mark.slow
@pytest.mark.parametrize("name", ["test_arealight_path.xml", "test_bumpmap_path.xml"])
def test_sphere_grid_equal_masked(monkeypatch, name):
    """Mitsuba's sphere grid (eleven materials of nine kinds, a ``mask`` blend, textures,
    two-sided and one-sided components; the bump map's scene: perturbed frames)."""
    path = corpus_scene(f"bsdf_spheres/{name}")
    masked, _ = render(path, "masked", monkeypatch, size=32, spp=2)
    kinds, _ = render(path, "kinds", monkeypatch, size=32, spp=2)
    assert masked.mean() > 0.0
    assert_same(masked, kinds)
