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

Two entry points run the same bounce (``_bounce``): ``sample`` traces one path
per lane; ``sample_sequence``, which the renderer uses, traces several per
lane one after another (path regeneration) and returns their sums.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import drjit as dr
from drjit.auto import Array2f, Array3f, Bool, Float, PCG32, UInt32

from ..lights.area import AreaLights
from ..lights.delta import DeltaLights
from ..material import MaterialTable
from ..surface import SurfaceData
from ..spawn import RayOffset
from ...options import PathOptions
from .common import DirectLight, power_heuristic


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
        active = Bool(active)
        L, beta, eta, depth, prev_pdf, prev_delta = self._start(active)
        while active:
            o, d, L, beta, eta, depth, prev_pdf, prev_delta, active = self._bounce(
                rng, o, d, L, beta, eta, depth, prev_pdf, prev_delta, active)
        return L

    @dr.syntax
    def sample_sequence(self, rng: PCG32, camera_ray: Callable, count: UInt32
                        ) -> tuple[Array3f, Array3f, UInt32]:
        """``count`` paths per lane, one after another (path regeneration).

        A lane starts a path at ``camera_ray(rng) -> (o, d)``; when the path
        ends it adds the sample to its sums and starts the next one, until
        ``count`` are done. A SIMD packet of lanes therefore runs until its
        lanes' *total* work is done, instead of each bounce loop waiting for
        the packet's longest path (Russian roulette makes path lengths vary:
        on the Cornell box the longest path of 16 averages 1.6x the mean).
        Returns the sum of the samples, the sum of their squares (for the
        variance) and how many non-finite samples were dropped (counted, not
        added: there should be none).
        """
        left = UInt32(count)
        active = left > 0
        L, beta, eta, depth, prev_pdf, prev_delta = self._start(active)
        o, d = camera_ray(rng)
        acc, acc2 = Array3f(0.0), Array3f(0.0)
        dropped = UInt32(0)
        while left > 0:
            o, d, L, beta, eta, depth, prev_pdf, prev_delta, active = self._bounce(
                rng, o, d, L, beta, eta, depth, prev_pdf, prev_delta, active)
            if ~active & (left > 0):  # the path ended: bank it, start the next
                finite = dr.isfinite(L.x) & dr.isfinite(L.y) & dr.isfinite(L.z)
                Lf = dr.select(finite, L, 0.0)
                acc += Lf
                acc2 += Lf * Lf
                dropped += dr.select(finite, 0, 1)
                left -= 1
                active = left > 0
                L, beta, eta, depth, prev_pdf, prev_delta = self._start(active)
                o, d = camera_ray(rng)
        return acc, acc2, dropped

    def _start(self, active: Bool):
        """The state of a new path: radiance, throughput, IOR product,
        depth, previous BSDF pdf, previous lobe delta (the camera ray is not
        MIS weighted)."""
        w = dr.width(active)
        return (dr.zeros(Array3f, w), dr.full(Array3f, 1.0, w), dr.full(Float, 1.0, w),
                dr.zeros(UInt32, w), dr.full(Float, 1.0, w), dr.full(Bool, True, w))

    def _bounce(self, rng: PCG32, o: Array3f, d: Array3f, L: Array3f, beta: Array3f,
                eta: Float, depth: UInt32, prev_pdf: Float, prev_delta: Bool, active: Bool):
        """One vertex of the path: emission seen, next-event estimation, BSDF
        sampling and Russian roulette. Returns the updated state (same order
        as the arguments after ``rng``)."""
        accel, mats, lights, offset = self.accel, self.materials, self.lights, self.offset
        opt = self.opt
        has_lights = lights.count > 0
        smooth = not mats.is_specular_only()
        has_nee = has_lights and smooth
        delta = self.direct.delta_lights if smooth else None
        env = self.direct.env
        has_background = max(self.background) > 0.0 and env is None
        inf = dr.largest(Float)

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
        L = L + dr.select(hit_emitter, beta * le * w, 0.0)
        if has_background:
            L = L + dr.select(active & ~si.valid, beta * Array3f(*self.background), 0.0)
        if env is not None:
            escaped = active & ~si.valid
            le_env, pdf_env = env.eval_pdf(d, escaped)
            w_env = dr.select(prev_delta, 1.0, power_heuristic(prev_pdf, pdf_env))
            L = L + dr.select(escaped, beta * le_env * w_env, 0.0)

        active_next = active & si.valid
        if opt.max_depth >= 0:
            active_next &= depth + 1 < opt.max_depth

        # ---- next-event estimation
        u_sel = rng.next_float32()
        u_light = Array2f(rng.next_float32(), rng.next_float32())
        if has_nee:
            L = L + beta * self.direct.area(si, u_sel, u_light, active_next, mis=True)
        if delta is not None:
            L = L + beta * self.direct.delta(si, active_next)
        u_env = Array2f(rng.next_float32(), rng.next_float32())
        if env is not None and smooth:
            L = L + beta * self.direct.env_light(si, u_env, active_next, mis=True)

        # ---- BSDF sampling: continue the path
        u_lobe = rng.next_float32()
        u_bsdf = Array2f(rng.next_float32(), rng.next_float32())
        wo, bs = mats.sample(si, u_lobe, u_bsdf)
        beta = beta * bs.weight
        eta = eta * bs.eta
        prev_pdf = Float(bs.pdf)
        prev_delta = Bool(bs.delta)
        o = offset.origin(si.p, si.ng, wo)
        d = Array3f(wo)
        depth = depth + 1

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
        return o, d, L, beta, eta, depth, prev_pdf, prev_delta, active
