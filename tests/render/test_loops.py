"""drpt.render.loops: each integrator's symbolic loops, and the film's, are recorded once per
trace (``loops_once``), and the image is, bit for bit, the one of the loops recorded with
Dr.Jit's ``OptimizeLoops`` on. Every integrator, mode, sampler and pixel filter (``MATRIX``)
records each loop once per call. (bdpt's subpath loops: ``test_bdpt.py``'s
``test_the_subpath_loops_are_traced_once_and_the_image_is_the_same``.)
"""

from __future__ import annotations

import struct

import drjit as dr
import numpy as np
import pytest
from drjit.auto import UInt32

from drpt.options import SAMPLERS, PathOptions, RenderOptions
from drpt.render.loops import decorated
from drpt.render.renderer import Renderer
from drpt.render.sampler import LDSampler
from drpt.scene import load_scene
from support import REPO, SCENES
from support.loops import recordings

HETERO = """<scene version="3.0.0">
    <integrator type="volpath"><integer name="max_depth" value="6"/></integrator>
    <medium id="m" type="heterogeneous">
        <float name="scale" value="3"/>
        <volume name="sigma_t" type="gridvolume"><string name="filename" value="g.vol"/></volume>
        <rgb name="albedo" value="0.8, 0.7, 0.6"/>
    </medium>
    <sensor type="perspective">
        <transform name="to_world"><lookat origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
    </sensor>
    <emitter type="point"><point name="position" x="2" y="2" z="2"/><rgb name="intensity" value="20"/></emitter>
    <shape type="sphere"><bsdf type="null"/><ref name="interior" id="m"/></shape>
    <shape type="rectangle"><transform name="to_world"><translate z="-2"/><scale x="3" y="3"/></transform>
        <bsdf type="diffuse"/></shape>
</scene>
"""


def _hetero(tmp_path):
    grid = [0.2, 1.0, 0.5, 2.0, 1.5, 0.1, 0.7, 1.2]
    (tmp_path / "g.vol").write_bytes(b"VOL\x03" + struct.pack("<5i", 1, 2, 2, 2, 1)
                                     + struct.pack("<6f", -1, -1, -1, 1, 1, 1) + struct.pack("<8f", *grid))
    (tmp_path / "h.xml").write_text(HETERO)
    return tmp_path / "h.xml"


CAUSTIC = """<scene version="3.0.0">
    <sensor type="perspective"><transform name="to_world"><lookat origin="0, 2, 4" target="0, 0, 0" up="0, 1, 0"/>
        </transform></sensor>
    <shape type="sphere"><point name="center" x="0" y="0.5" z="0"/><float name="radius" value="0.5"/>
        <bsdf type="dielectric"/></shape>
    <shape type="rectangle"><transform name="to_world"><scale value="3"/><rotate x="1" angle="-90"/></transform>
        <bsdf type="diffuse"/></shape>
    <shape type="rectangle"><transform name="to_world"><scale value="0.3"/><rotate x="1" angle="90"/><translate y="2"/>
        </transform><emitter type="area"><rgb name="radiance" value="20"/></emitter></shape>
</scene>
"""


def _caustic(tmp_path):
    (tmp_path / "c.xml").write_text(CAUSTIC)
    return tmp_path / "c.xml"


CASES = {
    # name: (scene, options)
    "path loop": ("cornellbox/cornellbox.txt", {}),
    "path loop, ldsampler": ("cornellbox/cornellbox.txt", {"sampler": "ldsampler"}),
    "path unrolled": ("cornellbox/cornellbox.txt", {"path": PathOptions(max_depth=3)}),
    "path splatted": ("cornellbox/cornellbox.txt", {"filter": "gaussian"}),
    "whitted": ("cornellbox/cornellbox.txt", {"integrator": "whitted"}),
    "AOV guides past glass": (REPO / "tests" / "data" / "xml" / "bsdfs.xml",
                              {"aovs": (("albedo", "guide_albedo"),), "path": PathOptions(max_depth=3)}),
    "wavefront's fused tail": ("cornellbox/cornellbox.txt", {"mode": "wavefront", "wavefront_tail": 64}),
    "ptracer": ("cornellbox/cornellbox.txt", {"integrator": "ptracer"}),
    "ptracer, ldsampler": ("cornellbox/cornellbox.txt", {"integrator": "ptracer", "sampler": "ldsampler"}),
    "volpath": ("cornellbox_media/cornellbox_media.txt", {"integrator": "volpath"}),
    "volpath heterogeneous": (None, {"integrator": "volpath"}),
    "volpath heterogeneous wavefront": (None, {"integrator": "volpath", "mode": "wavefront"}),
    "wavefront, BVH traversal": ("cornellbox/cornellbox.txt", {"mode": "wavefront", "accel": "bvh"}),
    # glass and area lights: bdpt's caustic photons (BDPTIntegrator.trace_photons)
    "bdpt caustic merging": (lambda tmp: _caustic(tmp), {"integrator": "bdpt"}),
}


def _optimized(monkeypatch):
    """Every ``loops_once`` function traced with ``OptimizeLoops`` on instead."""
    for cls, name in decorated():
        inner = getattr(cls, name).__wrapped__

        def on(*a, inner=inner, **kw):
            with dr.scoped_set_flag(dr.JitFlag.OptimizeLoops, True):
                return inner(*a, **kw)

        monkeypatch.setattr(cls, name, on)


@pytest.mark.parametrize("case", list(CASES))
def test_loops_are_recorded_once_and_the_image_is_the_same(case, monkeypatch, tmp_path):
    """A render records each loop's body once (nested loops once per recording of their
    outer loop, which is once; the wavefront traces a kernel per bounce, each with its
    loops). Its image equals, bit for bit, the one whose loops are recorded with
    ``OptimizeLoops`` on. Negative control: with the flag on, Dr.Jit records the loops again
    to drop their unchanged state, and the counter sees it (every loop of the wavefront's
    kernels twice as often, or more)."""
    scene_file, extra = CASES[case]
    path = (_hetero(tmp_path) if scene_file is None else scene_file(tmp_path) if callable(scene_file)
            else SCENES / scene_file)  # (or an absolute path)
    opts = RenderOptions(width=16, height=16, spp=4, seed=3, progress=False,
                         **({"path": PathOptions(max_depth=6)} | extra))
    renderer = Renderer(load_scene(path), opts)
    with recordings() as once:
        image = renderer.render().image
    per_bounce = extra.get("mode") == "wavefront"
    # (a first bdpt render traces its pilot, the path tracer's, then its pass: each loop once)
    assert once and (per_bounce or set(once.values()) == {1}), dict(once)
    _optimized(monkeypatch)
    with recordings() as counts:
        assert np.array_equal(renderer.render().image, image)
    if per_bounce:
        assert all(counts[k] >= 2 * v for k, v in once.items()), (dict(counts), dict(once))
    else:
        assert max(counts.values()) >= 2, dict(counts)


def test_decorated_lists_every_loops_once_function():
    """``decorated()`` finds each ``loops_once`` function where it lives (the negative
    control above traces them all with the flag on); a plain function is not listed."""
    import drpt.render.renderer  # noqa: F401 (imports every integrator)
    from drpt.render.integrators.bdpt import BDPTIntegrator
    from drpt.render.integrators.path import PathIntegrator

    found = decorated()
    assert (PathIntegrator, "sample_sequence") in found and len(found) == len(set(found)) >= 8, found
    assert all(hasattr(owner.__dict__[name], "__wrapped__") for owner, name in found)
    assert (BDPTIntegrator, "_trace") not in found


#: (integrator, mode, AOVs) of :data:`MATRIX`: every integrator, the path and volpath
#: integrators' wavefront mode too, and the AOV kernel beside the path tracer's
VARIANTS = (("path", "megakernel", False), ("path", "wavefront", False), ("path", "megakernel", True),
            ("whitted", "megakernel", False), ("volpath", "megakernel", False),
            ("volpath", "wavefront", False), ("ptracer", "megakernel", False), ("bdpt", "megakernel", False))
#: every (integrator, mode, AOVs, sampler, filter): box (one sample, one pixel) and gaussian
#: (splatted into the film, :mod:`drpt.render.film`)
MATRIX = [(*v, sampler, flt) for v in VARIANTS for sampler in SAMPLERS for flt in ("box", "gaussian")]


def _render_counted(integrator, mode, aovs, sampler, flt):
    """The recordings of one 8x8, 4-spp render of the Cornell box (volpath: the one with
    media) with these settings (:func:`support.loops.recordings`)."""
    scene = "cornellbox_media/cornellbox_media.txt" if integrator == "volpath" else "cornellbox/cornellbox.txt"
    opts = RenderOptions(width=8, height=8, spp=4, seed=3, progress=False, path=PathOptions(max_depth=6),
                         integrator=integrator, mode=mode, sampler=sampler, filter=flt,
                         aovs=(("albedo", "guide_albedo"),) if aovs else (),
                         wavefront_tail=64)  # (the wavefront's last bounces: a fused loop)
    renderer = Renderer(load_scene(SCENES / scene), opts)
    with recordings() as counts:
        renderer.render()
    return counts


@pytest.mark.parametrize("integrator, mode, aovs, sampler, flt", MATRIX,
                         ids=["-".join(map(str, c)) for c in MATRIX])
def test_every_integrator_sampler_and_filter_records_each_loop_once_per_call(integrator, mode, aovs,
                                                                           sampler, flt):
    """Each ``while_loop`` call of the render records its body once: every loop (the
    integrator's, the film's, the accelerator's, nested ones) has as many recordings as
    calls (a loop traced twice, such as the film's for the image and for the AOVs, is
    called twice). Negative control: the next test, with a sampler whose ``step`` is one
    value for all lanes, as it was."""
    counts = _render_counted(integrator, mode, aovs, sampler, flt)
    assert counts and not counts.again(), (dict(counts), dict(counts.calls))


def _narrow(self, key=None, index=None, step=None):
    """``LDSampler.__init__`` that keeps a ``step`` (and ``key``) given as one value as it
    is: one entry for all lanes."""
    self.key = UInt32(0) if key is None else UInt32(key)
    self.index = UInt32(0) if index is None else UInt32(index)
    self.step = UInt32(1) if step is None else UInt32(step)
    self.dim = dr.zeros(UInt32, dr.width(self.index))


@pytest.mark.parametrize("integrator, mode, sampler, flt, loop", [
    ("whitted", "megakernel", "ldsampler", "box", "whitted.py"),
    ("path", "megakernel", "stratified", "gaussian", "path.py"),
    ("volpath", "wavefront", "zsobol", "box", "volpath.py"),
])
def test_a_width_1_sampler_step_makes_the_loops_record_twice(integrator, mode, sampler, flt, loop,
                                                             monkeypatch):
    """Negative control of the test above: with the sampler's ``step`` one value for all
    lanes (a loop variable of another width than the loop's, which the body reads and does
    not change), Dr.Jit records the loop holding the sampler again, and the counter sees
    it: Whitted's loop, the splatted path loop, volpath's shadow loop in the wavefront's
    kernels (zsobol's packed state has no step)."""
    monkeypatch.setattr(LDSampler, "__init__", _narrow)
    again = _render_counted(integrator, mode, False, sampler, flt).again()
    assert any(k.startswith(loop) and v[0] >= 2 * v[1] for k, v in again.items()), again


def test_a_sampler_given_one_step_for_all_lanes_holds_one_per_lane():
    """``LDSampler`` (and its subclasses) broadcast a ``step`` or ``key`` of one value to
    the lanes' width, the same values; each field as wide as the loop that carries it."""
    from drpt.render.sampler import ZSobolSampler, strata_sampler

    index = dr.arange(UInt32, 8)
    for kind in (LDSampler, strata_sampler("orthogonal", 4), ZSobolSampler.for_image(4, 4, 4)):
        rng = kind(UInt32(5), index, UInt32(3))
        assert all(dr.width(getattr(rng, name)) == 8 for name in kind.DRJIT_STRUCT), kind
        assert list(rng.step.numpy()) == [3] * 8 and list(rng.key.numpy()) == [5] * 8
        assert list(rng.index.numpy()) == list(range(8))
