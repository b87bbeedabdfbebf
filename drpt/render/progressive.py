"""Progressive rendering: one sample per pixel per frame, for a live view.

:class:`Progressive` refines an image frame by frame and starts over when
its camera or options change (:meth:`Progressive.reset`). Frame ``i`` traces
sample step ``i`` of the pass plan of a render whose ``max_lanes`` is
:func:`frame_lanes` (at most one sample per pixel per pass, so a frame is one
pass, or a few bands of rows when the image is larger than the lane
budget), with :meth:`Renderer.render_pass` (which goes on past the plan's
last pass) and its per-pass seeding; frames are
summed in float64. After ``n`` frames the image is therefore bit-identical
to ``Renderer.render()`` of the same camera with ``spp = n``, the same seed
and ``max_lanes = frame_lanes(...)`` (``tests/view/test_view.py`` checks it).

The camera is a kernel input (:class:`~drpt.render.camera.RayCamera`), so
after a camera move the next frame runs the kernel already compiled for
that image size and integrator.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from ..options import RenderOptions
from ..scene.model import Camera
from .renderer import Renderer


def frame_lanes(width: int, height: int, max_lanes: int) -> int:
    """The ``max_lanes`` of the render that a progressive view of this size
    reproduces: one pass per frame when the image fits the lane budget."""
    return min(width * height, max_lanes)


@dataclass
class Frame:
    image: np.ndarray  # (H, W, 3) float32, linear radiance: the mean of the frames so far
    spp: int  # samples per pixel so far
    seconds: float  # tracing time since the last reset
    width: int
    height: int

    @property
    def samples_per_second(self) -> float:
        return self.spp * self.width * self.height / max(self.seconds, 1e-9)


class Progressive:
    """A refining image of ``renderer``'s scene; not thread-safe (one thread
    calls :meth:`reset` and :meth:`step`)."""

    def __init__(self, renderer: Renderer, camera: Camera | None = None,
                 options: RenderOptions | None = None):
        self.base = renderer
        self.reset(camera if camera is not None else renderer.camera_model,
                   options if options is not None else renderer.opt)

    def reset(self, camera: Camera, options: RenderOptions) -> None:
        """Start over with ``camera`` and ``options`` (their size, seed,
        integrator and depths; ``spp`` is the frame count at which
        :attr:`done` turns true)."""
        W, H = options.width, options.height
        lanes = frame_lanes(W, H, self.base.max_lanes if options.max_lanes is None else options.max_lanes)
        self.options = replace(options, max_lanes=lanes, progress=False, moment=False,
                               aovs=(), denoise=False)  # no AOVs in a view
        self.renderer = self.base.derive(self.options, camera)
        self.camera = camera
        self.plan = self.renderer.plan  # one sample per pixel per step (frame_lanes): bands
        self.acc = np.zeros((H, W, 3), np.float64)
        self.weight: np.ndarray | None = None  # a splatting film's sum(w) per pixel
        self.spp = 0
        self.seconds = 0.0
        self.nonfinite = 0

    @property
    def done(self) -> bool:
        return self.spp >= self.options.spp

    def step(self) -> Frame:
        """Trace one more sample per pixel; the mean so far."""
        t0 = time.perf_counter()
        bands = self.plan.bands
        for b in range(bands):
            p = self.renderer.render_pass(self.spp * bands + b)
            hi = p.lo + p.sum.shape[0]
            self.acc[p.lo:hi] += p.sum
            if p.weight is not None:
                if self.weight is None:
                    self.weight = np.zeros(self.acc.shape[:2] + (1,), np.float64)
                self.weight[p.lo:hi] += p.weight[..., :1]
            self.nonfinite += p.nonfinite
        self.spp += 1
        self.seconds += time.perf_counter() - t0
        return self.frame()

    def frame(self) -> Frame:
        if self.weight is not None:  # a splatting film: weighted sums over the weights
            image = np.where(self.weight > 0, self.acc / np.maximum(self.weight, 1e-30), 0.0)
            image = image.astype(np.float32)
        else:
            image = (self.acc / max(self.spp, 1)).astype(np.float32)
        return Frame(image, self.spp, self.seconds, self.options.width, self.options.height)
