"""Point and directional lights: delta lights, reached only by shadow rays.

A point light at ``x`` with ``color`` and attenuation ``(c, l, q)`` gives a
surface at distance ``d`` facing it the irradiance
``E = color / (c + l d + q d^2)`` (the default ``(0, 0, 1)`` is the physical
inverse-square law); a directional light gives ``E = color`` from
``-direction`` everywhere. A shading point then receives ``f * |cos| * E``.
Every delta light is sampled at every vertex (they are few; the loop is
unrolled at trace time). BSDF sampling can never hit them, so there is no
MIS for them.

A spot light (Mitsuba's ``spot``) is a point light whose intensity is
multiplied by the falloff of the angle ``theta`` between its axis and the
direction toward the shading point: 1 for ``theta <= beam_width``,
``(cutoff - theta) / (cutoff - beam_width)`` up to ``cutoff_angle``, 0
beyond (Mitsuba's ``falloff_curve``, with the cone tested on ``cos theta >
cos cutoff`` as there).
"""

from __future__ import annotations

import math

import drjit as dr
import numpy as np
from drjit.auto import Array3f, Float

from ...scene.model import DirectionalLight, PointLight, Scene, SpotLight


class DeltaSample:
    def __init__(self, wo, dist, irradiance):
        self.wo: Array3f = wo  # unit direction toward the light
        self.dist: Float = dist  # distance to the light (inf: directional)
        self.irradiance: Array3f = irradiance  # E on a surface facing the light


class DeltaLights:
    def __init__(self, scene: Scene):
        self.points = [l for l in scene.lights if isinstance(l, PointLight)]
        self.directionals = [l for l in scene.lights if isinstance(l, DirectionalLight)]
        self.spots = [l for l in scene.lights if isinstance(l, SpotLight)]
        self.count = len(self.points) + len(self.directionals) + len(self.spots)

    def samples(self, p: Array3f):
        """One :class:`DeltaSample` per light, for shading points ``p``."""
        for light in self.points:
            to = Array3f(*map(float, light.position)) - p
            d2 = dr.squared_norm(to)
            d = dr.sqrt(d2)
            c, l, q = (float(x) for x in light.attenuation)
            att = c + l * d + q * d2
            E = Array3f(*map(float, light.color)) / dr.maximum(att, 1e-30)
            yield DeltaSample(to / d, d, dr.select(d > 0.0, E, 0.0))
        for light in self.spots:
            to = Array3f(*map(float, light.position)) - p
            d2 = dr.squared_norm(to)
            d = dr.sqrt(d2)
            axis = np.asarray(light.direction, float)
            axis /= np.linalg.norm(axis)
            cos_t = -dr.dot(to, Array3f(*map(float, axis))) / d
            cutoff = math.radians(light.cutoff_angle)
            beam = math.radians(light.beam_width)
            ramp = (cutoff - dr.safe_acos(cos_t)) / (cutoff - beam) if cutoff > beam else Float(1.0)
            falloff = dr.select(cos_t >= math.cos(beam), 1.0, ramp)
            falloff = dr.select(cos_t > math.cos(cutoff), falloff, 0.0)
            E = Array3f(*map(float, light.color)) * falloff / dr.maximum(d2, 1e-30)
            yield DeltaSample(to / d, d, dr.select(d > 0.0, E, 0.0))
        for light in self.directionals:
            w = -np.asarray(light.direction, float)
            w /= np.linalg.norm(w)
            yield DeltaSample(Array3f(*map(float, w)), Float(dr.inf),
                              Array3f(*map(float, light.color)))
