"""Whitted-style ray tracing: direct light at rough surfaces, perfect
reflection and refraction at smooth ones.

A camera ray is followed through glass and mirrors (the delta lobes) and
stops at the first other surface, where it gathers

* ``ambient * Kd`` (the scene's ``Background{ambientLight}``),
* direct light: one emitter (an emissive triangle or sphere, a point, spot or
  directional light, the environment map) chosen by the scene's light selection,
  one direction toward it and a shadow ray,

shaded with the material's full BSDF (so Phong materials show highlights).
Emitters seen directly or through mirrors and glass count with their own
radiance; rays that escape see the environment map, or else the
background color.

Refraction: instead of spawning both a reflected and a refracted ray, the
dielectric picks one with probability equal to its Fresnel weight; with
several samples per pixel this converges to the same image as Whitted's
branching recursion, without an exponential ray tree. Paths end after
``max_depth`` segments (Mitsuba's convention, as in the path tracer) or when
their throughput falls below ``cutoff``.

What Mitsuba can reproduce: Mitsuba's ``path`` integrator also follows
diffuse bounces, so the two agree only where no path with a diffuse bounce
*before* the last vertex carries light, e.g. delta lights, convex diffuse
objects that cannot see other diffuse objects, mirrors, a black
background, no ambient term, and ``max_depth`` 3 (camera -> mirror ->
diffuse -> light). ``tests/render/integrators/test_whitted.py`` checks exactly such scenes.
"""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
from drjit.auto import PCG32, Array3f, Bool, UInt32

from ..loops import loops_once
from ..sampler import light_sample, next_2d
from ..scene import DeviceScene
from .common import DirectLight


@dataclass
class WhittedOptions:
    max_depth: int = 16  # segments; -1 is taken as 16 (mirror halls never end)
    cutoff: float = 1e-3  # stop when max(throughput) falls below this


class WhittedIntegrator:
    def __init__(self, scene: DeviceScene, options: WhittedOptions):
        self.scene = scene
        self.direct = DirectLight(scene)
        self.opt = options

    @loops_once
    @dr.syntax
    def sample(self, rng: PCG32, o: Array3f, d: Array3f, active: Bool) -> Array3f:
        scene, direct = self.scene, self.direct
        max_depth = self.opt.max_depth if self.opt.max_depth > 0 else 16

        L = dr.zeros(Array3f, dr.width(d))  # as wide as the rays, though nothing adds to it (an empty scene)
        beta = Array3f(1.0)
        depth = UInt32(0)
        active = Bool(active)
        while active:
            si = scene.intersect(o, d, active)
            L += dr.select(active & si.valid, beta * scene.emitted(si), 0.0)
            if scene.has_background:
                L += dr.select(active & ~si.valid, beta * Array3f(*scene.background), 0.0)
            if scene.has_environment:
                L += dr.select(active & ~si.valid,
                               beta * scene.eval_environment(d, active & ~si.valid), 0.0)

            delta = scene.is_delta(si)
            shade = active & si.valid & ~delta & (depth + 1 < max_depth)
            if scene.has_ambient:
                L += dr.select(shade, beta * Array3f(*scene.ambient) * scene.diffuse_color(si, shade),
                               0.0)
            u_sel = rng.next_float32()
            u_light = next_2d(rng)
            if scene.has_emitters:  # one emitter of any kind, one shadow ray
                u_sel, u_light = light_sample(scene, rng, u_sel, u_light, shade)
                L += beta * direct.emitter(si, u_sel, u_light, shade, mis=False)

            # Follow mirrors and glass; stop everywhere else.
            u_lobe = rng.next_float32()
            u_dir = next_2d(rng)
            wo, bs = scene.sample_bsdf(si, u_lobe, u_dir)
            beta *= bs.weight
            o = scene.spawn(si, wo)
            d = Array3f(wo)
            depth += 1
            active = (active & si.valid & delta & bs.valid & (depth < max_depth)
                      & (dr.max(beta) > self.opt.cutoff))
        return L
