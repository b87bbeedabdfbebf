"""Rays leaving the emitters, for light tracing (:mod:`drpt.render.integrators.ptracer`).

:class:`EmitterRays` treats the scene's emitters as a list of *sources*: the
emissive triangles and spheres together (a primitive chosen by the light sampler
and a point uniformly on it, :meth:`~drpt.render.lights.area.AreaLights.sample`
without a reference point), each point and
spot light, each directional light, and the sky or constant background. A
light path picks one source uniformly (Mitsuba picks one emitter uniformly
too; its weight is the number of sources) and draws its first ray from it,
with the ray's *weight*: emitted power over the density of the ray,

* emissive triangle or sphere: a point ``y`` with area density ``pdf_A``, a direction
  cosine-distributed about the front (shading) normal: ``Le * pi / pdf_A``;
* point light of intensity ``I``: a uniform direction, ``I * 4 pi``;
* spot light: a direction uniform in the cutoff cone,
  ``I * falloff * texture(uv) * 2 pi (1 - cos cutoff)`` (a textured spot's
  image at the direction's uv in the light's frame, as
  :class:`~drpt.render.lights.delta.DeltaLights` looks it up);
* projector: a direction through a uniform point ``uv`` of its image, whose
  intensity is ``pi scale value(uv) / cos^3 theta`` and whose density is
  ``cos^3 theta / A`` (``A`` the image's area on the plane at distance 1):
  ``pi scale A value(uv)``;
* textured emissive triangles: the texture's radiance at the point (the
  triangle chosen by the texture's mean, as for next-event estimation);
* directional light of irradiance ``E`` and the sky: rays enter the scene's
  bounding sphere (center ``c``, radius ``R``) from a disk of radius ``R``
  perpendicular to their direction: ``E * pi R^2`` and ``Le(w) * pi R^2 /
  pdf(w)`` (``w`` the sky direction sampled by luminance).

:meth:`EmitterRays.sample_surface_point` draws the point an emitter shows
the camera directly (light tracing's paths of one segment): a point on an
emissive triangle, or a direction toward the sky, with their weights.

Point lights with a non-physical attenuation (the seed's ``(c, l, q)`` other
than ``(0, 0, 1)``) emit no well-defined power: light tracing refuses them.
"""

from __future__ import annotations

import math

import drjit as dr
import numpy as np
from drjit.auto import Array2f, Array3f, Bool, Float, UInt32

from ...errors import DrptError, Loc, SceneError
from ...scene.model import PointLight
from ..spawn import origin as spawn_origin
from ..warp import (
    Frame,
    square_to_cosine_hemisphere,
    square_to_uniform_cone,
    square_to_uniform_disk_concentric,
    square_to_uniform_sphere,
)

INV_FOUR_PI = 1.0 / (4.0 * math.pi)


def _to_world(frame, v: Array3f) -> Array3f:
    """A light's local vector ``v`` in world space (``frame``: a row-major rotation
    whose columns are the local axes)."""
    f = [float(a) for a in frame]
    return Array3f(f[0] * v.x + f[1] * v.y + f[2] * v.z,
                   f[3] * v.x + f[4] * v.y + f[5] * v.z,
                   f[6] * v.x + f[7] * v.y + f[8] * v.z)


class LightRay:
    """A ray leaving an emitter: origin ``o`` (on an area emitter: its point ``p`` moved off
    the surface, :func:`drpt.render.spawn.origin`; elsewhere ``p`` itself), unit direction
    ``d`` and ``weight`` (power over density, times the source count). Its hit is
    :meth:`DeviceScene.intersect_from(o, p, d) <drpt.render.scene.DeviceScene.intersect_from>`,
    as seen from ``p``."""

    def __init__(self, o, d, weight, valid, p=None):
        self.o: Array3f = o
        self.d: Array3f = d
        self.weight: Array3f = weight
        self.valid: Bool = valid
        self.p: Array3f = o if p is None else p


class VisiblePoint:
    """What an emitter shows the camera directly. On an emissive triangle: the point
    ``p``, its front (shading) normal ``n``, ``ng`` and ``p_error`` for spawning the
    ray toward the camera, and ``le`` the radiance over the area density. For the sky
    (``at_infinity``): ``p`` is the camera's center plus the unit direction toward the
    sky (so the camera's importance at ``p`` is per unit solid angle) and ``le`` the
    radiance over the solid-angle density. Both times the source count."""

    def __init__(self, p, n, ng, p_error, le, valid, at_infinity):
        self.p, self.n, self.ng, self.p_error = p, n, ng, p_error
        self.le: Array3f = le
        self.valid: Bool = valid
        self.at_infinity: Bool = at_infinity


class EmitterRays:
    def __init__(self, device_scene, scene):
        self.scene = device_scene
        emissive = {i for i, m in enumerate(scene.materials) if max(m.emission) > 0.0}
        if len(scene.planes) and emissive & set(int(m) for m in scene.planes.material):
            raise DrptError("light tracing (ptracer) does not start paths on emissive planes (infinite: "
                            "no finite power): use the path integrator, or a finite emitter")
        lo, hi = scene.bounds()
        if not np.all(np.isfinite(lo)):
            lo = hi = np.zeros(3)
        self.center = (lo + hi) / 2.0
        self.radius = max(float(np.linalg.norm(hi - lo)) / 2.0, 1e-6) * (1.0 + 1e-4)
        dl = device_scene.delta_lights
        for light in dl.points:
            if tuple(float(a) for a in light.attenuation) != (0.0, 0.0, 1.0):
                raise SceneError(getattr(light, "loc", None) or Loc(scene.path),
                                 "light tracing needs physical point lights: attenuation "
                                 f"{tuple(light.attenuation)} is not (0, 0, 1)")
        self.sources: list[tuple[str, object]] = []
        if device_scene.has_area_lights:
            self.sources.append(("area", None))
        self.sources += [("point", light) for light in dl.points if isinstance(light, PointLight)]
        self.sources += [("spot", light) for light in dl.spots]
        self.sources += [("projector", light) for light in getattr(dl, "projectors", [])]
        self.sources += [("directional", light) for light in dl.directionals]
        if device_scene.has_environment:
            self.sources.append(("sky", None))
        elif device_scene.has_background:
            self.sources.append(("background", None))
        self.count = len(self.sources)

    # ------------------------------------------------------------ helpers
    def _select(self, u: Float) -> tuple[UInt32, Float]:
        """A source index, chosen uniformly, and ``u`` rescaled to [0, 1) for reuse."""
        n = self.count
        k = dr.minimum(UInt32(u * n), n - 1)
        return k, dr.minimum(u * n - Float(k), 0.99999994)

    def _disk_origin(self, d: Array3f, u: Array2f) -> Array3f:
        """A point on the disk of radius R through the bounding sphere's center,
        perpendicular to ``d``, moved back by R against ``d``."""
        frame = Frame(d)
        p = square_to_uniform_disk_concentric(u) * self.radius
        c = Array3f(*map(float, self.center))
        return c + frame.to_world(Array3f(p.x, p.y, -self.radius))

    # ------------------------------------------------------------ rays
    def sample_ray(self, u_sel: Float, u_pos: Array2f, u_dir: Array2f, active: Bool) -> LightRay:
        n = dr.width(active)
        if self.count == 0:  # a scene without emitters: no light path
            return LightRay(dr.zeros(Array3f, n), dr.full(Array3f, [0.0, 0.0, 1.0], n),
                            dr.zeros(Array3f, n), dr.zeros(Bool, n))
        k, u_reuse = self._select(u_sel)
        o = dr.zeros(Array3f, n)
        p = dr.zeros(Array3f, n)
        d = dr.full(Array3f, [0.0, 0.0, 1.0], n)
        weight = dr.zeros(Array3f, n)
        for i, (kind, light) in enumerate(self.sources):
            mine = active & (k == i)
            if kind == "area":
                oi, di, wi, pi = self._area_ray(u_reuse, u_pos, u_dir, mine)
            else:
                oi, di, wi = self._source_ray(kind, light, u_reuse, u_pos, u_dir, mine)
                pi = oi
            o = dr.select(mine, oi, o)
            p = dr.select(mine, pi, p)
            d = dr.select(mine, di, d)
            weight = dr.select(mine, wi, weight)
        weight = weight * float(self.count)
        valid = active & (dr.max(weight) > 0.0)
        return LightRay(o, d, weight, valid, p)

    def _area_ray(self, u_sel, u_pos, u_dir, active):
        """An emissive triangle's or sphere's ray: ``(o, d, weight, p)``, ``p`` the point
        on the emitter and ``o`` it moved off the surface."""
        ls = self.scene.area_lights.sample(u_sel, u_pos, active)
        local = square_to_cosine_hemisphere(u_dir)
        d = Frame(ls.n).to_world(local)
        o = spawn_origin(ls.p, ls.ng, ls.p_error, d)
        w = dr.select(ls.pdf_area > 0.0, ls.le * (dr.pi / ls.pdf_area), 0.0)
        return o, d, w, ls.p

    def _source_ray(self, kind, light, u_sel, u_pos, u_dir, active):
        """The ray of a source other than the area emitters (which :meth:`_area_ray` draws):
        ``(o, d, weight)``."""
        if kind in ("point", "spot"):
            o = Array3f(*map(float, light.position))
            color = Array3f(*map(float, light.color))
            if kind == "point":
                return o, square_to_uniform_sphere(u_dir), color * (4.0 * math.pi)
            cutoff = math.radians(light.cutoff_angle)
            beam = math.radians(light.beam_width)
            local = square_to_uniform_cone(u_dir, math.cos(cutoff))
            if getattr(light, "frame", None) is not None:
                d = _to_world(light.frame, local)
            else:
                axis = np.asarray(light.direction, float)
                d = Frame(Array3f(*map(float, axis / np.linalg.norm(axis)))).to_world(local)
            theta = dr.safe_acos(local.z)
            falloff = Float(1.0)
            if cutoff > beam:
                falloff = dr.select(local.z >= math.cos(beam), 1.0, (cutoff - theta) / (cutoff - beam))
            falloff = dr.select(theta <= cutoff, dr.maximum(falloff, 0.0), 0.0)
            w = color * falloff * (2.0 * math.pi * (1.0 - math.cos(cutoff)))
            if getattr(light, "texture", None) is not None:
                k = 0.5 / math.tan(cutoff)
                uv = Array2f(0.5 + k * local.x / local.z, 0.5 + k * local.y / local.z)
                w = w * self.scene.delta_lights._bitmaps[id(light)].eval(uv, active & (falloff > 0.0))
            return o, d, w
        if kind == "projector":
            o = Array3f(*map(float, light.position))
            t = math.tan(math.radians(light.fov_x) / 2.0)
            # the uv of Mitsuba's projector (drpt/render/lights/delta.py) inverted at z = 1
            x = (0.5 - u_dir.x) * (2.0 * t)
            y = (0.5 - u_dir.y) * (2.0 * t / light.aspect)
            d = _to_world(light.frame, dr.normalize(Array3f(x, y, 1.0)))
            plane = 4.0 * t * t / light.aspect
            if isinstance(light.irradiance, tuple):
                value = Array3f(*map(float, light.irradiance))
            else:
                value = self.scene.delta_lights._bitmaps[id(light)].eval(Array2f(u_dir), active)
            return o, d, value * (math.pi * float(light.scale) * plane)
        area = math.pi * self.radius * self.radius
        if kind == "directional":
            w = np.asarray(light.direction, float)
            w = w / np.linalg.norm(w)
            d = Array3f(*map(float, w))
            return self._disk_origin(d, u_pos), d, Array3f(*map(float, light.color)) * area
        if kind == "sky":
            w_sky, le, pdf = self.scene.sample_environment(u_dir, active)
            d = -w_sky
            weight = dr.select(pdf > 0.0, le * (area / pdf), 0.0)
            return self._disk_origin(d, u_pos), d, weight
        # the constant background: a uniform sky
        w_sky = square_to_uniform_sphere(u_dir)
        d = -w_sky
        bg = Array3f(*map(float, self.scene.background))
        return self._disk_origin(d, u_pos), d, bg * (area * 4.0 * math.pi)

    # ------------------------------------------------------------ seen by the camera
    def sample_visible(self, u_sel: Float, u_pos: Array2f, camera_center: Array3f,
                       active: Bool) -> VisiblePoint:
        """An emitter point (or sky direction) for the camera to see directly: a source
        chosen uniformly; delta lights give nothing (``valid`` False)."""
        k, u_reuse = self._select(u_sel)
        n = dr.width(active)
        p = dr.zeros(Array3f, n)
        nf = dr.zeros(Array3f, n)
        ng = dr.zeros(Array3f, n)
        err = dr.zeros(Float, n)
        le = dr.zeros(Array3f, n)
        at_inf = dr.zeros(Bool, n)
        for i, (kind, _light) in enumerate(self.sources):
            mine = active & (k == i)
            if kind == "area":
                ls = self.scene.area_lights.sample(u_reuse, u_pos, mine)
                p = dr.select(mine, ls.p, p)
                nf = dr.select(mine, ls.n, nf)
                ng = dr.select(mine, ls.ng, ng)
                err = dr.select(mine, ls.p_error, err)
                le = dr.select(mine & (ls.pdf_area > 0.0), ls.le / ls.pdf_area, le)
            elif kind in ("sky", "background"):
                if kind == "sky":
                    w_sky, rad, pdf = self.scene.sample_environment(u_pos, mine)
                else:
                    w_sky = square_to_uniform_sphere(u_pos)
                    rad, pdf = Array3f(*map(float, self.scene.background)), Float(INV_FOUR_PI)
                p = dr.select(mine, camera_center + w_sky, p)
                nf = dr.select(mine, -w_sky, nf)
                le = dr.select(mine & (pdf > 0.0), rad / pdf, le)
                at_inf |= mine
        le = le * float(self.count)
        valid = active & (dr.max(le) > 0.0)
        return VisiblePoint(p, nf, ng, err, le, valid, at_inf)
