"""Whitted-style ray tracing: direct light at rough surfaces, perfect
reflection and refraction at smooth ones.

A camera ray is followed through glass and mirrors (the delta lobes) and
stops at the first other surface, where it gathers

* ``ambient * Kd`` (the scene's ``Background{ambientLight}``),
* direct light from every point and directional light, one sample on an
  emissive triangle (chosen by power), one direction on the environment
  map (by luminance), each with a shadow ray,

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
diffuse -> light). ``tests/test_whitted.py`` checks exactly such scenes.
"""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
from drjit.auto import Array2f, Array3f, Bool, Float, PCG32, UInt32

from .common import DirectLight


@dataclass
class WhittedOptions:
    max_depth: int = 16  # segments; -1 is taken as 16 (mirror halls never end)
    cutoff: float = 1e-3  # stop when max(throughput) falls below this


class WhittedIntegrator:
    def __init__(self, accel, surfaces, materials, area_lights, delta_lights, offset,
                 background, options: WhittedOptions, env=None):
        self.accel, self.surfaces, self.materials, self.offset = accel, surfaces, materials, offset
        self.direct = DirectLight(accel, materials, area_lights, delta_lights, offset, env)
        self.background = tuple(float(c) for c in background.color)
        self.ambient = tuple(float(c) for c in background.ambient)
        self.opt = options

    @dr.syntax
    def sample(self, rng: PCG32, o: Array3f, d: Array3f, active: Bool) -> Array3f:
        mats, direct = self.materials, self.direct
        max_depth = self.opt.max_depth if self.opt.max_depth > 0 else 16
        env = direct.env
        has_background = max(self.background) > 0.0 and env is None
        has_ambient = max(self.ambient) > 0.0
        has_area = direct.area_lights is not None
        has_delta = direct.delta_lights is not None
        inf = dr.largest(Float)

        L = Array3f(0.0)
        beta = Array3f(1.0)
        depth = UInt32(0)
        active = Bool(active)
        while active:
            hit = self.accel.intersect(o, d, Float(inf), active)
            si = self.surfaces.interaction(o, d, hit)
            L += dr.select(active & si.valid, beta * mats.emitted(si), 0.0)
            if has_background:
                L += dr.select(active & ~si.valid, beta * Array3f(*self.background), 0.0)
            if env is not None:
                L += dr.select(active & ~si.valid, beta * env.eval(d, active & ~si.valid), 0.0)

            delta = mats.is_delta(si)
            shade = active & si.valid & ~delta & (depth + 1 < max_depth)
            if has_ambient:
                L += dr.select(shade, beta * Array3f(*self.ambient) * mats.diffuse_color(si, shade), 0.0)
            u_sel = rng.next_float32()
            u_light = Array2f(rng.next_float32(), rng.next_float32())
            if has_area:
                L += beta * direct.area(si, u_sel, u_light, shade, mis=False)
            if has_delta:
                L += beta * direct.delta(si, shade)
            u_env = Array2f(rng.next_float32(), rng.next_float32())
            if env is not None:
                L += beta * direct.env_light(si, u_env, shade, mis=False)

            # Follow mirrors and glass; stop everywhere else.
            u_lobe = rng.next_float32()
            u_dir = Array2f(rng.next_float32(), rng.next_float32())
            wo, bs = mats.sample(si, u_lobe, u_dir)
            beta *= bs.weight
            o = self.offset.origin(si.p, si.ng, wo)
            d = Array3f(wo)
            depth += 1
            active = (active & si.valid & delta & bs.valid & (depth < max_depth)
                      & (dr.max(beta) > self.opt.cutoff))
        return L
