"""Materials on the device: per-material parameters and the BSDF dispatch.

Every surface is two-sided: the shading frame is flipped to the viewer's
side before a lobe is evaluated. Emission is one-sided: a material with
``emission`` radiates only toward the front, the side its shading normal
(equal to the geometric normal for flat faces) points to — the same rule as
Mitsuba's ``area`` emitter.

This issue's renderer models every material by its diffuse albedo ``kd``;
specular lobes (Phong, Cook-Torrance, glass, mirror) arrive with the
materials work and will be traced only when a scene has them.
"""

from __future__ import annotations

import drjit as dr
import numpy as np
from drjit.llvm import Array2f, Array3f, Bool, Float

from ..scene.model import Scene
from .bsdf import diffuse
from .surface import Interaction, _vec
from .warp import Frame


class MaterialTable:
    def __init__(self, scene: Scene):
        mats = scene.materials
        self.kd = _vec(np.array([m.kd for m in mats], float))
        self.emission = _vec(np.array([m.emission for m in mats], float))
        self.has_emission = any(m.is_emissive for m in mats)

    def frame(self, si: Interaction) -> tuple[Frame, Bool]:
        """Shading frame facing the viewer, and whether the viewer was behind ns."""
        flip = dr.dot(si.ns, si.wi) < 0.0
        return Frame(dr.select(flip, -si.ns, si.ns)), flip

    def emitted(self, si: Interaction) -> Array3f:
        """Radiance leaving ``si`` toward ``si.wi`` (zero on back faces)."""
        if not self.has_emission:
            return Array3f(0.0)
        le = dr.gather(Array3f, self.emission, si.material, si.valid)
        front = si.valid & (dr.dot(si.ns, si.wi) > 0.0)
        return dr.select(front, le, 0.0)

    def eval_pdf(self, si: Interaction, frame: Frame, wo: Array3f) -> tuple[Array3f, Float]:
        """``f * cos`` and the sampling density (solid angle) for world ``wo``."""
        kd = dr.gather(Array3f, self.kd, si.material, si.valid)
        wi_l, wo_l = frame.to_local(si.wi), frame.to_local(wo)
        return diffuse.eval(kd, wi_l, wo_l), diffuse.pdf(wi_l, wo_l)

    def sample(self, si: Interaction, frame: Frame, u: Array2f):
        """Sample ``wo``: (world wo, weight f*cos/pdf, pdf, valid)."""
        kd = dr.gather(Array3f, self.kd, si.material, si.valid)
        wo_l, weight, pdf, valid = diffuse.sample(kd, frame.to_local(si.wi), u)
        return frame.to_world(wo_l), weight, pdf, valid & si.valid
