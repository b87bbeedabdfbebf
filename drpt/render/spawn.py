"""Ray origins that leave a surface without hitting it again.

A hit point computed in float32 is off the true surface by a few ulps of the
coordinates involved. New rays start from ``p`` pushed along the geometric
normal, to the side the ray leaves toward, by

    ``(max(|p.x|, |p.y|, |p.z|) + floor) * 2**-17``

where ``floor`` is 1% of the scene's bounding-box diagonal. The relative term
covers the float32 rounding of ``p`` (2**-17 is ~64 ulps), the floor covers
points near the origin whose error comes from larger vertex coordinates. Both
scale with the scene, so scenes at 1e-4 and 1e4 scale behave the same.
"""

from __future__ import annotations

import drjit as dr
import numpy as np
from drjit.auto import Array3f

from ..scene.model import Scene

REL = 2.0**-17


class RayOffset:
    def __init__(self, scene: Scene):
        lo, hi = scene.bounds()
        diag = float(np.linalg.norm(hi - lo)) if np.all(np.isfinite(lo)) else 1.0
        self.floor = 0.01 * diag if diag > 0 else 1e-3

    def origin(self, p: Array3f, ng: Array3f, d: Array3f) -> Array3f:
        mag = (dr.max(dr.abs(p)) + self.floor) * REL
        return p + ng * dr.mulsign(mag, dr.dot(ng, d))
