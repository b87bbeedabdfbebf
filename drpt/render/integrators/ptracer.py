"""Light tracing (Mitsuba's ``ptracer``): paths start at the emitters and every
vertex is connected to the camera.

Each lane traces one light path. It first shows the camera an emitter
directly (a point on an emissive triangle or a sky direction, chosen by
:meth:`~drpt.render.lights.rays.EmitterRays.sample_visible`: paths of one
segment; skipped with ``hide_emitters`` or ``max_depth = 0``), then leaves an
emitter along a ray drawn by
:meth:`~drpt.render.lights.rays.EmitterRays.sample_ray` with the throughput
``beta`` = emitted power over the ray's density. At every surface it hits,
the vertex is connected to the camera: the contribution

    ``beta * f(wi, wc) |cos_s wc| * corr * W_e / dist^2``

(``wi`` toward the light, ``wc`` toward the camera, ``W_e / dist^2`` the
pinhole camera's importance, :meth:`~drpt.render.camera.RayCamera.connect`)
is splatted at the pixel position the vertex projects to
(:class:`~drpt.render.film.SplatFilm`) if the segment to the camera is
clear. Then the BSDF is sampled to continue the path, ``beta`` times the
sample's weight. Light carries *importance* backwards through the BSDFs:

* refraction: the radiance-mode weight's ``1 / eta^2`` (``BSDFSample.eta``,
  the relative IOR crossed) is undone, ``beta *= weight * eta^2``, as in
  Mitsuba's ``TransportMode::Importance``;
* shading normals: Veach's correction ``corr = |cos_s(wi) cos_g(wo)| /
  |cos_s(wo) cos_g(wi)|`` for the sampled and the camera direction, and such
  a vertex counts only where both directions lie on the same side of the
  shading and the geometric normal.

Depths as in Mitsuba: ``max_depth`` counts segments (the camera connection
included), so ``1`` shows emitters only; Russian roulette after
``rr_depth`` segments with probability ``min(max(beta) eta^2, 0.95)``.

The image of ``N = W H spp`` light paths is ``sum / spp`` of the splats (each
pixel's share of the film's importance is ``1 / (W H)``). Pinhole
perspective cameras only: a thin lens, an orthographic camera or a crop
window is refused. A vertex joined to the camera is evaluated in importance mode
(``eval_bsdf(..., importance=True)``): rough transmission (``roughdielectric``,
``principled``) has its radiance scaling undone, as Mitsuba's
``TransportMode::Importance`` evaluates it; smooth and thin dielectrics and mirrors
are sampled, never evaluated.
"""

from __future__ import annotations

import drjit as dr
from drjit.auto import PCG32, Array3f, Bool, Float, UInt32

from ...errors import DrptError
from ...options import PathOptions
from ..camera import RayCamera
from ..film import SplatFilm
from ..instrument import HIT_LIGHT, SHADOW_CAMERA, SHADOW_EMITTER, SPLAT, count
from ..lights.rays import EmitterRays
from ..loops import loops_once
from ..sampler import next_2d
from ..scene import DeviceScene


def refuse_unsupported(scene, camera, what: str) -> None:
    """Raise :class:`~drpt.errors.DrptError` where ``what`` (an integrator that traces
    paths from the lights, named for the message) cannot render the scene: a camera
    other than a pinhole without a crop window (no point to connect to)."""
    if camera.orthographic or camera.thin_lens or camera.window is not None:
        raise DrptError(f"{what} needs a pinhole perspective camera without a crop window")


#: a connection's shadow ray, traced from the camera toward a surface point, stops short of
#: that point's surface by this fraction of its length (over the cosine there), as well as by
#: twice the point's error bound (:func:`camera_segment`)
CAMERA_STOP = 2.0**-18


def camera_segment(center: Array3f, p: Array3f, ng: Array3f, err: Float, wc: Array3f, dist: Float
                   ) -> tuple[Array3f, Array3f, Float]:
    """The shadow ray of the connection of surface point ``p`` (unit geometric normal ``ng``,
    error bound ``err``: :mod:`drpt.render.spawn`) to the camera's ``center`` (``wc`` the unit
    direction from ``p`` to it, ``dist`` the distance): ``(o, d, tmax)``, traced from the
    center toward ``p``, so that its line passes through ``p`` itself (a ray from ``p`` moved
    off its surface passes beside ``p`` by the offset, which far from the origin moves the
    edges of what it passes), up to ``(2 err + dist CAMERA_STOP) / |cos|`` short of ``p``:
    past ``p``'s own surface, which lies within ``err`` of ``p`` along ``ng`` and which the
    intersection from the center finds within a rounding of the distance. A segment too
    grazing for that (``tmax <= 0``) cannot be tested, so its caller drops the connection
    (counting it as visible would splat it through whatever lies between)."""
    stop = (2.0 * err + dist * CAMERA_STOP) / dr.abs(dr.dot(ng, wc))
    return center + dr.zeros(Array3f, dr.width(p)), -wc, dist - stop


def correction(si, w: Array3f) -> tuple[Float, Bool]:
    """Veach's shading-normal correction for importance leaving ``si`` toward ``w``
    (``si.wi`` toward the light), and whether both directions lie on the same side of
    the shading and the geometric normal."""
    wi_g, wi_s = dr.dot(si.ng, si.wi), dr.dot(si.ns, si.wi)
    w_g, w_s = dr.dot(si.ng, w), dr.dot(si.ns, w)
    ok = (wi_g * wi_s > 0.0) & (w_g * w_s > 0.0)
    corr = dr.abs((wi_s * w_g) / (w_s * wi_g))
    return dr.select(ok, corr, 0.0), ok


class ParticleTracer:
    """Light tracing over a :class:`~drpt.render.scene.DeviceScene` seen by a pinhole camera."""

    def __init__(self, scene: DeviceScene, rays: EmitterRays, camera: RayCamera, options: PathOptions):
        refuse_unsupported(scene, camera, "light tracing (ptracer)")
        self.scene = scene
        self.rays = rays
        self.camera = camera
        self.opt = options

    def _connect(self, si, beta: Array3f, film: SplatFilm, active: Bool) -> None:
        """Splat vertex ``si`` (throughput ``beta``) into the film through the camera."""
        scene, cam = self.scene, self.camera
        x, y, wc, dist, importance, visible = cam.connect(si.p)
        ok = active & visible
        f, _ = scene.eval_bsdf(si, wc, importance=True)
        corr, sides = correction(si, wc)
        value = beta * f * (corr * importance)
        ok &= sides & (dr.max(value) > 0.0)
        o, d, tmax = camera_segment(cam.center, si.p, si.ng, si.p_error, wc, dist)
        ok &= tmax > 0.0
        count(scene, SHADOW_CAMERA, ok)
        ok &= ~scene.occluded(o, d, tmax, ok)
        count(scene, SPLAT, ok)
        film.put(x, y, value, ok)

    def _visible_emitters(self, rng: PCG32, film: SplatFilm, active: Bool) -> None:
        """Paths of one segment: an emitter point (or sky direction) seen by the camera."""
        scene, cam = self.scene, self.camera
        u_sel = rng.next_float32()
        u_pos = next_2d(rng)
        vp = self.rays.sample_visible(u_sel, u_pos, Array3f(cam.center), active)
        x, y, wc, dist, importance, visible = cam.connect(vp.p)
        cos_l = dr.dot(vp.n, wc)
        at_inf = vp.at_infinity
        value = vp.le * dr.select(at_inf, importance, importance * cos_l)
        ok = vp.valid & visible & (at_inf | (cos_l > 0.0))
        so, d_sh, tmax = camera_segment(cam.center, vp.p, vp.ng, vp.p_error, wc, dist)
        so = dr.select(at_inf, Array3f(cam.center), so)
        d_sh = dr.select(at_inf, -wc, d_sh)
        tmax = dr.select(at_inf, dr.inf, tmax)
        ok &= tmax > 0.0
        count(scene, SHADOW_EMITTER, ok)
        ok &= ~scene.occluded(so, d_sh, tmax, ok)
        count(scene, SPLAT, ok)
        film.put(x, y, value, ok)

    @loops_once
    @dr.syntax
    def trace(self, rng: PCG32, film: SplatFilm, active: Bool) -> UInt32:
        """One light path per lane, splatted into ``film``; returns the number of
        non-finite contributions dropped (per lane). The path loop is recorded once
        (:func:`~drpt.render.loops.loops_once`)."""
        scene, opt = self.scene, self.opt
        max_depth = opt.max_depth
        if scene.instrument is not None:
            scene.instrument.paths(dr.width(active), (HIT_LIGHT, SHADOW_EMITTER, SHADOW_CAMERA, SPLAT))
        if max_depth != 0 and not opt.hide_emitters and self.rays.count > 0:
            self._visible_emitters(rng, film, Bool(active))
        u_sel = rng.next_float32()
        u_pos = next_2d(rng)
        u_dir = next_2d(rng)
        ray = self.rays.sample_ray(u_sel, u_pos, u_dir, Bool(active))
        # ref: the vertex the ray o, d was spawned from (scene.intersect_from)
        o, d, ref, beta = Array3f(ray.o), Array3f(ray.d), Array3f(ray.p), Array3f(ray.weight)
        eta = dr.full(Float, 1.0, dr.width(active))
        depth = dr.full(UInt32, 1, dr.width(active))
        live = Bool(ray.valid)
        if max_depth >= 0:
            live &= depth < max_depth
        dropped = dr.zeros(UInt32, dr.width(active))
        while live:
            count(scene, HIT_LIGHT, live)
            si = scene.intersect_from(o, ref, d, live)
            live &= si.valid
            finite = dr.isfinite(beta.x) & dr.isfinite(beta.y) & dr.isfinite(beta.z)
            dropped += dr.select(live & ~finite, 1, 0)
            live &= finite
            self._connect(si, beta, film, live)

            u_lobe = rng.next_float32()
            u_bsdf = next_2d(rng)
            wo, bs = scene.sample_bsdf(si, u_lobe, u_bsdf)
            corr, sides = correction(si, wo)
            beta = beta * bs.weight * (corr * dr.square(bs.eta))
            eta = eta * bs.eta
            live &= bs.valid & sides & (dr.max(beta) > 0.0)
            depth += 1
            if max_depth >= 0:
                live &= depth < max_depth
            u_rr = rng.next_float32()
            use_rr = depth > opt.rr_depth
            q = dr.minimum(dr.max(beta) * dr.square(eta), 0.95)
            live &= ~use_rr | (u_rr < q)
            beta = dr.select(use_rr, beta / q, beta)
            o = scene.spawn(si, wo)
            d = Array3f(wo)
            ref = Array3f(si.p)
        return dropped
