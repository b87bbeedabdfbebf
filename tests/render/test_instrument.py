"""Instruments (drpt/render/instrument.py): what a scene's instrument sees lands in the kernel.

* Without an instrument, or with the base class (whose methods do nothing), the path
  kernel has the same operation count and the image the same bits; a counting
  instrument adds its scatter-adds (more operations) and leaves the image as it was.
* A counting instrument on the megakernel, where a pass gives each lane one path
  (16x16 at 2 spp: below ``min_lanes``, so the megakernel traces the wavefront's very
  paths), counts exactly the bounces and shadow rays that the wavefront integrator
  counts on the host from its buffers (live paths per bounce, shadow-ray batches).
  Negative control: a depth limit changes the counts.
* ptracer and bdpt: likewise no code without a counting instrument and the same image
  with one; the shadow rays they count by kind are exactly those the scene traced.
"""

from __future__ import annotations

from dataclasses import replace

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Bool, UInt32

from drpt.options import PathOptions, RenderOptions
from drpt.render.instrument import Instrument
from drpt.render.integrators.wavefront import WaveStats
from drpt.render.renderer import Renderer
from drpt.scene import load_scene


class Counts(Instrument):
    def __init__(self):
        self.iters, self.shadows, self.traced = [], [], []

    def paths(self, lanes):
        self.n = lanes
        self.iters.append(dr.zeros(UInt32, lanes))
        self.shadows.append(dr.zeros(UInt32, lanes))
        dr.eval(self.iters[-1], self.shadows[-1])  # counters in memory, before the loop
        self.traced.append(lanes)

    def bounce(self, state):
        dr.scatter_add(self.iters[-1], UInt32(1), dr.arange(UInt32, self.n), state.active | dr.zeros(Bool, self.n))

    def occluded(self, o, d, tmax, active):
        dr.scatter_add(self.shadows[-1], UInt32(1), dr.arange(UInt32, self.n), active | dr.zeros(Bool, self.n))

    def totals(self):
        return sum(int(c.numpy().sum()) for c in self.iters), sum(int(c.numpy().sum()) for c in self.shadows)


@pytest.fixture(scope="module")
def renderer(cornell):
    return Renderer(load_scene(cornell), RenderOptions(width=16, height=16, spp=2, seed=5, progress=False))


def _render(r, instrument):
    r.scene.instrument = instrument
    try:
        with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
            dr.kernel_history_clear()
            img = r.render().image
            ops = max(k.get("operation_count", 0) for k in dr.kernel_history()
                      if k.get("type") == dr.KernelType.JIT)
    finally:
        r.scene.instrument = None
    return img, ops


def test_no_instrument_no_code(renderer):
    img, ops = _render(renderer, None)
    img_base, ops_base = _render(renderer, Instrument())
    counts = Counts()
    img_c, ops_c = _render(renderer, counts)
    assert ops_base == ops and np.array_equal(img_base, img)
    assert ops_c > ops and np.array_equal(img_c, img)  # the counters are in the kernel
    assert counts.traced == [16 * 16 * 2]  # one pass, one path kernel


def _wavefront(r):
    wr = r.derive(replace(r.opt, mode="wavefront"))
    wr.integrator.stats = WaveStats()
    wr.render()
    st = wr.integrator.stats
    return sum(sum(v) for v in st.live), st.stages["shadow rays"].rays


def test_counts_equal_the_wavefronts(renderer):
    counts = Counts()
    _render(renderer, counts)
    bounces, shadows = counts.totals()
    assert bounces > 16 * 16 * 2 and shadows > 0
    assert (bounces, shadows) == _wavefront(renderer)
    # negative control: two segments per path at most (camera ray, one bounce)
    short = renderer.derive(replace(renderer.opt, path=PathOptions(max_depth=2)))
    c2 = Counts()
    _render(short, c2)
    assert c2.totals()[0] < bounces and c2.totals() == _wavefront(short)


class KindCounts(Counts):
    """Counts plus the light-tracing integrators' queries by kind."""

    def paths(self, lanes, kinds=()):
        super().paths(lanes)
        self.kinds = {k: dr.zeros(UInt32, lanes) for k in kinds}
        dr.eval(*self.kinds.values())

    def count(self, kind, active):
        dr.scatter_add(self.kinds[kind], UInt32(1), dr.arange(UInt32, self.n), active | dr.zeros(Bool, self.n))


@pytest.mark.slow
@pytest.mark.parametrize("integrator", ["ptracer", "bdpt"])
def test_light_tracing_no_instrument_no_code(cornell, integrator):
    """ptracer's and bdpt's kernels carry the counters only with a counting instrument
    (the base class's no-op methods trace nothing), and the image is the same."""
    r = Renderer(load_scene(cornell), RenderOptions(width=8, height=8, spp=2, seed=5, integrator=integrator,
                                                    path=PathOptions(max_depth=4), progress=False))
    img, ops = _render(r, None)
    img_base, ops_base = _render(r, Instrument())
    counts = KindCounts()
    img_c, ops_c = _render(r, counts)
    assert ops_base == ops and np.array_equal(img_base, img)
    assert ops_c > ops and np.array_equal(img_c, img)
    shadows = sum(int(c.numpy().sum()) for k, c in counts.kinds.items() if k.startswith("shadow"))
    assert shadows == counts.totals()[1] > 0  # every shadow ray named, none twice
