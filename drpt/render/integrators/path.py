"""Unidirectional path tracing with next-event estimation and MIS.

At every vertex the path gathers light two ways: a point sampled on an
emissive triangle and a direction sampled on the environment map
(next-event estimation, with shadow rays), and the emitter or sky the next
BSDF-sampled ray happens to hit. Both estimates are weighted by the
power heuristic, so glossy and diffuse surfaces, small and large lights are
all handled without fireflies from the "wrong" strategy.

Depth follows Mitsuba's ``path`` integrator: ``max_depth = 1`` shows only
directly visible emitters, ``2`` adds direct lighting, ``-1`` is unbounded
(Russian roulette ends paths). Russian roulette starts once ``depth >=
rr_depth``: by default a path continues with probability
``min(max(throughput), 0.95)``; with ``rr_prob`` set (the seed's
``-RR_cutdown``) it continues with that fixed probability. Surviving paths are
divided by the probability, so neither choice adds bias. As in Mitsuba, the
adaptive probability uses the throughput times ``eta^2`` (the relative IORs
crossed), so paths inside glass are not killed for their radiance scaling.

Delta lobes (glass, mirrors) have nothing to evaluate: next-event estimation
contributes nothing there and the emitter their ray hits counts in full
(``prev_delta``). A scene of only delta materials traces no NEE code.
"""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
from drjit.llvm import Array2f, Array3f, Bool, Float, PCG32, UInt32

from ..lights.area import AreaLights
from ..lights.delta import DeltaLights
from ..material import MaterialTable
from ..surface import SurfaceData
from ..spawn import RayOffset
from .common import DirectLight, power_heuristic


@dataclass
class PathOptions:
    max_depth: int = -1
    rr_depth: int = 5
    rr_prob: float | None = None  # fixed continuation probability, or adaptive


class PathIntegrator:
    def __init__(self, accel, surfaces: SurfaceData, materials: MaterialTable,
                 lights: AreaLights, offset: RayOffset, background, options: PathOptions,
                 delta_lights: DeltaLights | None = None, env=None):
        self.accel = accel
        self.surfaces = surfaces
        self.materials = materials
        self.lights = lights
        self.delta_lights = delta_lights
        self.direct = DirectLight(accel, materials, lights, delta_lights, offset, env)
        self.offset = offset
        self.background = tuple(float(c) for c in background)
        self.opt = options

    @dr.syntax
    def sample(self, rng: PCG32, o: Array3f, d: Array3f, active: Bool) -> Array3f:
        """Radiance arriving at ``o`` from direction ``-d``, one sample per lane."""
        accel, mats, lights, offset = self.accel, self.materials, self.lights, self.offset
        opt = self.opt
        has_lights = lights.count > 0
        smooth = not mats.is_specular_only()
        has_nee = has_lights and smooth
        delta = self.direct.delta_lights if smooth else None
        env = self.direct.env
        has_background = max(self.background) > 0.0 and env is None
        inf = dr.largest(Float)

        L = Array3f(0.0)
        beta = Array3f(1.0)
        eta = Float(1.0)  # product of relative IORs crossed (Russian roulette)
        depth = UInt32(0)
        prev_pdf = Float(1.0)  # solid-angle pdf of the BSDF sample that led here
        prev_delta = Bool(True)  # camera rays and delta bounces are not MIS-weighted
        active = Bool(active)

        while active:
            hit = accel.intersect(o, d, Float(inf), active)
            si = self.surfaces.interaction(o, d, hit)

            # ---- emitter hit by the previous ray (or seen by the camera)
            hit_emitter = active & si.valid
            le = mats.emitted(si)
            w = Float(1.0)
            if has_nee:
                pdf_a = lights.pdf_area(si.prim, hit_emitter)
                sees_light = hit_emitter & (pdf_a > 0.0)
                pdf_l = dr.select(sees_light, pdf_a * dr.square(si.t) / dr.abs(dr.dot(si.ng, d)), 0.0)
                w = dr.select(prev_delta, 1.0, power_heuristic(prev_pdf, pdf_l))
            L += dr.select(hit_emitter, beta * le * w, 0.0)
            if has_background:
                L += dr.select(active & ~si.valid, beta * Array3f(*self.background), 0.0)
            if env is not None:
                escaped = active & ~si.valid
                le_env, pdf_env = env.eval_pdf(d, escaped)
                w_env = dr.select(prev_delta, 1.0, power_heuristic(prev_pdf, pdf_env))
                L += dr.select(escaped, beta * le_env * w_env, 0.0)

            active_next = active & si.valid
            if opt.max_depth >= 0:
                active_next &= depth + 1 < opt.max_depth

            # ---- next-event estimation
            u_sel = rng.next_float32()
            u_light = Array2f(rng.next_float32(), rng.next_float32())
            if has_nee:
                L += beta * self.direct.area(si, u_sel, u_light, active_next, mis=True)
            if delta is not None:
                L += beta * self.direct.delta(si, active_next)
            u_env = Array2f(rng.next_float32(), rng.next_float32())
            if env is not None and smooth:
                L += beta * self.direct.env_light(si, u_env, active_next, mis=True)

            # ---- BSDF sampling: continue the path
            u_lobe = rng.next_float32()
            u_bsdf = Array2f(rng.next_float32(), rng.next_float32())
            wo, bs = mats.sample(si, u_lobe, u_bsdf)
            beta *= bs.weight
            eta *= bs.eta
            prev_pdf = bs.pdf
            prev_delta = Bool(bs.delta)
            o = offset.origin(si.p, si.ng, wo)
            d = Array3f(wo)
            depth += 1

            # ---- Russian roulette
            u_rr = rng.next_float32()
            if opt.rr_prob is not None:
                q = Float(opt.rr_prob)
            else:
                q = dr.minimum(dr.max(beta) * dr.square(eta), 0.95)
            rr_on = depth >= opt.rr_depth
            survive = u_rr < q
            beta = dr.select(rr_on, beta / q, beta)
            active = active_next & bs.valid & (~rr_on | survive) & (dr.max(beta) > 0.0)

        return L
