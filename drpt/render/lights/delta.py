"""Point and directional lights: delta lights, reached only by shadow rays.

A point light at ``x`` with ``color`` and attenuation ``(c, l, q)`` gives a
surface at distance ``d`` facing it the irradiance
``E = color / (c + l d + q d^2)`` (the default ``(0, 0, 1)`` is the physical
inverse-square law); a directional light gives ``E = color`` from
``-direction`` everywhere. A shading point then receives ``f * |cos| * E``.
Next-event estimation reaches them as slots of the scene's light selection (one
light per sample, divided by its probability; the lights' code is unrolled at trace
time). BSDF sampling can never hit them, so there is no MIS for them.

A spot light (Mitsuba's ``spot``) is a point light whose intensity is
multiplied by the falloff of the angle ``theta`` between its axis and the
direction toward the shading point: 1 for ``theta <= beam_width``,
``(cutoff - theta) / (cutoff - beam_width)`` up to ``cutoff_angle``, 0
beyond (Mitsuba's ``falloff_curve``, with the cone tested on ``cos theta >
cos cutoff`` as there). A spot's ``texture`` multiplies its intensity by the
image at ``uv = 0.5 + 0.5 (x, y) / (z tan(cutoff))`` of the direction toward
the shading point in the light's frame (Mitsuba's ``direction_to_uv``).

A projector (Mitsuba's ``projector``, :class:`~drpt.scene.model.ProjectorLight`)
maps a shading point at local ``(x, y, z)`` to the uv of its perspective
projection and gives ``pi * scale * value(uv) * dist / z^3`` (Mitsuba's
``sample_direction``: ``value * pi * scale / (z^2 cos)``, ``cos = z / dist``),
zero behind it and outside the image.

Textures are looked up as Mitsuba's ``bitmap`` (:class:`drpt.render.texture.Bitmap`);
a scene without textured spots or projectors traces none of this.

As an :class:`~drpt.render.lights.Emitter` each light is one slot (in the order points,
spots, projectors, directionals: that of :meth:`DeltaLights.samples`), with its power
for the light selection: ``4 pi I`` for a point light (its attenuation aside), pbrt's
``2 pi I ((1 - cos beam) + (cos beam - cos cutoff) / 2)`` for a spot, ``pi scale A v``
for a projector (``A`` its image's area at distance 1, ``v`` its mean value), ``pi R^2
E`` for a directional light (``R`` the radius of the scene's bounding sphere); luminances
of the colors, textures counted by their mean; each the part that reaches the lit
geometry (:mod:`drpt.render.lights.reach`: a directional light's ``pi R^2`` that
geometry's cross-section along it, the others times their share of directions toward it).
"""

from __future__ import annotations

import math

import drjit as dr
import numpy as np
from drjit.auto import Array2f, Array3f, Bool, Float, UInt32

from ...scene.model import DirectionalLight, PointLight, ProjectorLight, Scene, SpotLight
from ..texture import Bitmap
from . import EmitterSample
from .reach import receivers

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def _lum(c) -> float:
    return float(np.asarray(c, float).reshape(3) @ LUMINANCE)


def _mean_lum(bitmap: Bitmap) -> float:
    """The mean luminance of a :class:`~drpt.render.texture.Bitmap`'s texels."""
    a = np.asarray(bitmap.tex.value().numpy(), float)
    if a.ndim == 3 and a.shape[-1] >= 3:
        return float((a[..., :3] @ LUMINANCE).mean())
    return float(a.mean())


class DeltaSample:
    def __init__(self, wo, dist, irradiance):
        self.wo: Array3f = wo  # unit direction toward the light
        self.dist: Float = dist  # distance to the light (inf: directional)
        self.irradiance: Array3f = irradiance  # E on a surface facing the light


class DeltaLights:
    delta = True

    def __init__(self, scene: Scene, lit="scene"):
        """``lit``: the scene's lit geometry (:func:`~drpt.render.lights.reach.receivers`;
        ``"scene"``: computed here)."""
        self.points = [l for l in scene.lights if isinstance(l, PointLight)]
        self.directionals = [l for l in scene.lights if isinstance(l, DirectionalLight)]
        self.spots = [l for l in scene.lights if isinstance(l, SpotLight)]
        self.projectors = [l for l in scene.lights if isinstance(l, ProjectorLight)]
        self.count = len(self.points) + len(self.directionals) + len(self.spots) + len(self.projectors)
        # the images of textured spots and projectors, by light
        self._bitmaps = {id(l): Bitmap(l.texture) for l in self.spots if l.texture is not None}
        self._bitmaps.update({id(l): Bitmap(l.irradiance) for l in self.projectors
                              if not isinstance(l.irradiance, tuple)})
        self.infinite = bool(self.directionals)
        lo, hi = scene.bounds()
        self._radius = float(np.linalg.norm(hi - lo)) / 2.0 if np.all(np.isfinite(lo)) else 1.0
        rec = receivers(scene) if lit == "scene" else lit
        #: the sphere of the lit geometry (:mod:`drpt.render.lights.reach`; None: the powers
        #: are the emitted ones) and its cross-section along each directional light
        self._receivers = None if rec is None else rec.bare()
        self._across = [math.pi * self._radius ** 2 if rec is None else rec.across(l.direction)
                        for l in self.directionals]
        self.bind(None)

    # ------------------------------------------------------------ Emitter interface
    def power(self) -> np.ndarray:
        """Each light's power (W) that reaches the lit geometry, estimated as the module's
        docs say."""
        rec = self._receivers
        out = [4.0 * math.pi * _lum(l.color) * (1.0 if rec is None else float(rec.isotropic(l.position)[0]))
               for l in self.points]
        for l in self.spots:
            cb, cc = math.cos(math.radians(l.beam_width)), math.cos(math.radians(l.cutoff_angle))
            tex = 1.0 if l.texture is None else _mean_lum(self._bitmaps[id(l)])
            cone = (1.0 - cb) + (cb - cc) / 2.0  # the cone's steradians over 2 pi
            reach = 1.0 if rec is None else rec.cone(l.position, cone / 2.0)
            out.append(2.0 * math.pi * cone * _lum(l.color) * tex * reach)
        for l in self.projectors:
            t = math.tan(math.radians(l.fov_x) / 2.0)
            v = _lum(l.irradiance) if isinstance(l.irradiance, tuple) else _mean_lum(self._bitmaps[id(l)])
            reach = 1.0 if rec is None else rec.cone(l.position, min(4.0 * t * t / l.aspect, 4.0 * math.pi)
                                                     / (4.0 * math.pi))
            out.append(math.pi * float(l.scale) * 4.0 * t * t / l.aspect * v * reach)
        out += [a * _lum(l.color) for a, l in zip(self._across, self.directionals)]
        return np.maximum(np.nan_to_num(np.array(out, float), nan=0.0, posinf=0.0), 0.0)

    def units(self) -> tuple[np.ndarray, np.ndarray]:
        """Every light is its own emitter."""
        return np.arange(self.count), np.ones(self.count)

    def bind(self, prob: np.ndarray | None) -> None:
        """The lights' selection probabilities, the ``pdf`` of :meth:`sample_direction`
        (``None``: 1 each)."""
        self._prob = None if prob is None else [float(x) for x in prob]

    def sample_direction(self, ref: Array3f, slot: UInt32, u: Array2f, active: Bool) -> EmitterSample:
        """The light of ``slot`` seen from ``ref``: its direction, distance and irradiance;
        ``pdf`` is the bound probability (a delta emitter has no density to sample)."""
        out = None
        for i, ds in enumerate(self.samples(ref)):
            prob = Float(1.0 if self._prob is None else self._prob[i])
            finite = i < self.count - len(self.directionals)
            p = ref + ds.wo * ds.dist if finite else ref  # (unused at infinity)
            s = EmitterSample(ds.wo, p, ds.irradiance, prob, active & (dr.max(ds.irradiance) > 0.0),
                              Float(ds.dist), True)
            if out is None:
                out = s
                continue
            mine = slot == i
            out = EmitterSample(*(dr.select(mine, getattr(s, f), getattr(out, f))
                                  for f in ("wo", "p", "le", "pdf", "valid", "dist")), True)
        return out

    def pdf_direction(self, si, d: Array3f, active: Bool, ref: Array3f | None = None) -> Float:
        """0: a ray never hits a delta light."""
        return dr.zeros(Float, dr.width(d))

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
            if light.texture is not None:
                x, y, z = in_light_frame(light.frame, -to)
                k = 0.5 / math.tan(cutoff)
                lit = falloff > 0.0
                uv = Array2f(0.5 + k * x / z, 0.5 + k * y / z)
                E = E * dr.select(lit, self._bitmaps[id(light)].eval(uv, lit), 0.0)
            yield DeltaSample(to / d, d, dr.select(d > 0.0, E, 0.0))
        for light in self.projectors:
            to = Array3f(*map(float, light.position)) - p
            d = dr.norm(to)
            x, y, z = in_light_frame(light.frame, -to)
            t = math.tan(math.radians(light.fov_x) / 2.0)
            uv = Array2f(0.5 - (0.5 / t) * x / z, 0.5 - (0.5 * light.aspect / t) * y / z)
            ok = (z > 0.0) & (uv.x >= 0.0) & (uv.x <= 1.0) & (uv.y >= 0.0) & (uv.y <= 1.0)
            if isinstance(light.irradiance, tuple):
                value = Array3f(*map(float, light.irradiance))
            else:
                value = self._bitmaps[id(light)].eval(uv, ok)
            E = value * (math.pi * float(light.scale)) * d / (z * z * z)
            yield DeltaSample(to / d, d, dr.select(ok & (d > 0.0), E, 0.0))
        for light in self.directionals:
            w = -np.asarray(light.direction, float)
            w /= np.linalg.norm(w)
            yield DeltaSample(Array3f(*map(float, w)), Float(dr.inf),
                              Array3f(*map(float, light.color)))


def in_light_frame(frame, v: Array3f):
    """``(x, y, z)`` of world vector ``v`` in a light's frame (a row-major rotation whose
    columns are the local axes): the columns' dot products."""
    f = [float(a) for a in frame]
    return tuple(v.x * f[k] + v.y * f[3 + k] + v.z * f[6 + k] for k in range(3))
