"""Volumetric path tracing through participating media (Mitsuba's ``volpath``).

A medium fills the inside or the outside of the shapes whose material names it
(:attr:`drpt.scene.model.Material.interior` / ``exterior``): the medium a ray travels in
follows the boundaries it crosses, as in Mitsuba (after a surface of a *medium transition*
the ray is in the interior where it leaves against the surface's geometric normal, else in
the exterior; a camera ray starts in the sensor's medium, if it has one, else in vacuum).
A ``null`` BSDF is a pure boundary, and a ``thindielectric`` sheet's transmission passes
straight through as Mitsuba's null component.

Each segment in a medium samples a free-flight distance: a color channel is picked
uniformly (one random number per event), ``t = -log(1 - u) / sigma_t[c]``; the sample is
a scattering event if ``t`` comes before the surface the ray hits. The weight divides by
the *mean* density over the three channels (one-sample MIS with the balance heuristic,
"spectral MIS"): ``tr * sigma_s / mean(tr * sigma_t)`` at a scattering event,
``tr / mean(tr)`` when the ray reaches the surface, ``tr = exp(-sigma_t t)``, so each
channel's weight is at most 3 times its albedo and channels with ``sigma_t = 0`` need no
special case. (Mitsuba keeps one channel per path and divides by its density alone: the same
expectation, more variance for chromatic media.) At a scattering event the phase function
(isotropic or Henyey-Greenstein) is sampled exactly (weight 1).

A heterogeneous medium (:class:`Heterogeneous`: a one-channel extinction grid) is sampled by
delta tracking as Mitsuba's: a tentative collision at a distance sampled with the majorant
(``scale`` times the grid's maximum) from where the ray enters the grid's box is real with
probability ``sigma_t(x) / majorant`` (the throughput times the albedo there), else a null
collision and the ray goes on unchanged (two random numbers each). Null collisions run in a
loop of their own inside free flight up to the closest surface (Mitsuba runs each through its
whole path loop): the path's loop, megakernel and wavefront alike, sees only real collisions
and surfaces. Shadow rays use ratio tracking: ``1 - sigma_t(x) / majorant`` at each tentative
collision, one random number each, also in a loop of their own up to the next surface. Scenes
without heterogeneous media trace none of this.

Where every homogeneous medium's extinction is gray (the same in R, G and B:
``MediumTable.gray``), the channel pick and the weights are left out: the sampled distance is
the same for every channel, the transmittance cancels against its density, and the weight is
the albedo at a scattering event, 1 at a surface (``u_ch`` is drawn all the same). Where every
medium has the same coefficients (``MediumTable.uniform``: one homogeneous medium, as in every
corpus scene), the kernels read them as literals instead of gathering them per lane, and a
gray extinction's three channels are then one value (Dr.Jit merges equal expressions).

A ``thindielectric`` sheet hit from vacuum (a camera ray at a medium's sheet boundary)
reflects a few percent of the rays at full weight, and what the mirror direction sees (the
sky, mostly) was the largest part of such a pixel's variance. The emission the mirrored ray
reaches first is counted at the sheet (one closest hit, ``R'`` times the sheet's
``specular_reflectance``: :meth:`VolPathIntegrator.sheet_split`), the path still picks
reflection or transmission as before, and where it reflects the emission its next segment
reaches is not counted again; what the reflected path finds beyond (lit surfaces) is.

Where a ray in a homogeneous medium can reach an emitter before it leaves the medium (an
emitter inside the medium, or the camera's medium: :func:`~.enclosure.media_see_emitters`),
the emission at the end of each segment in the medium is counted on every lane by its
transmittance ``exp(-sigma_t t)`` instead of at full weight on the lanes whose free flight got
there (:attr:`VolPathIntegrator.counts_through`; the closest hit then looks past the sampled
collision). Elsewhere, as in a medium bounded by null surfaces under a sky, that emission is
always zero and none of this is traced.

Next-event estimation (one emitter chosen by the scene's light selection, as in the path
integrator: :meth:`~drpt.render.scene.DeviceScene.sample_emitter`) runs at surfaces and at
scattering events alike (the BSDF or the phase function evaluated toward the emitter
sample, power-heuristic MIS against sampling them, none for delta lights; one shadow ray
per vertex). Vertices whose shadow ray starts in a *blind* medium, one enclosed by closed
surfaces that block shadow rays with every emitter outside their bounding boxes
(:mod:`~drpt.render.integrators.enclosure`, decided from the scene when the kernel is
traced), skip it: its transmittance would be 0. Where every medium is blind, medium events
trace no next-event estimation at all, and where the surfaces too have delta lobes only, no
vertex takes one (:attr:`VolPathIntegrator.traces_nee`): an emitter a sampled ray reaches
then counts in full, its density not looked up. A constant background is not sampled: rays that escape see it, with MIS
weight 1 (the path integrator's convention). The shadow ray passes ``null`` boundaries
(factor 1) and ``thindielectric`` sheets (their transmission ``1 - 2R / (1 + R)``), changing
medium at each transition; any other surface blocks it. (As in Mitsuba, the sky and
directional lights are ``2 max(R, |p - c|)`` away for this estimate, ``(c, R)`` the bounding
sphere of the scene's shapes: in a medium that extends beyond the shapes, such as the
sensor's, the sky is seen through that much of it, while a sampled ray that leaves every
shape in such a medium scatters before it reaches the sky.) Its transmittance through a
homogeneous medium is exact (``exp(-sigma_t d)`` per segment) while the largest channel of
the ray's transmittance so far stays above a threshold (:func:`shadow_tau`, per scene:
:data:`SHADOW_TAU`, or 1 where the camera sees the media only through sheets); beyond that
point a collision distance is sampled with ``min(sigma_t)`` (tracking, which Mitsuba's shadow rays do all the
way): a collision before the next surface ends the ray with transmittance 0, and a ray that
gets past divides by its survival probability ``exp(-min(sigma_t) x)`` (``x`` the tracked
distance), so the estimate is unbiased and never above 1 (a medium with a channel of zero
extinction stays exact). Shadow rays that keep more than the threshold get no extra
variance, while those deep in dense media stop about one mean free path past the threshold
instead of following every boundary to the light. The free-flight and shadow rays look for
surfaces only up to their sampled collision (a shorter ray traverses less of the
accelerator). An emitter a BSDF or phase sample hits afterwards is weighted
against the density next-event estimation has for it from the last real scattering vertex
(null crossings do not count), as Mitsuba does.

Depth as in Mitsuba's volpath: ``depth`` counts real scattering events (surface or
medium, not null crossings); a path ends when ``depth`` reaches ``max_depth`` (-1:
unbounded), and Russian roulette plays once ``depth > rr_depth`` with survival probability
``min(max(throughput) * eta^2, 0.95)`` (or ``--rr-prob``). A scattering event at
``depth = max_depth`` ends the path without next-event estimation. Null crossings are bounded by
:data:`MAX_SHADOW_CROSSINGS` on shadow rays; the loop's own crossings each advance the ray.

Only scenes with media use this module (:meth:`drpt.render.renderer.Renderer._make_integrator`):
a scene without them renders with :class:`~drpt.render.integrators.path.PathIntegrator`,
whose kernel does not change.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, replace

import drjit as dr
import numpy as np
from drjit.auto import PCG32, Array2f, Array3f, Bool, Float, UInt32

from ...errors import Loc, SceneError
from ...materials.bsdf_kinds import BENDING, PARAMS
from ...materials.iors import relative_ior
from ...options import PathOptions
from ...scene.model import Scene
from ..bsdf.thindielectric import reflectance
from ..loops import loops_once
from ..scene import DeviceScene
from ..warp import Frame
from .common import SHADOW_SHRINK, power_heuristic, shadow_segment
from .enclosure import blind_media, media_see_emitters
from .path import PathIntegrator, nothing_seen

#: at most this many boundaries (null or thindielectric) a shadow ray passes; beyond, it is blocked
MAX_SHADOW_CROSSINGS = 64
#: a shadow ray's transmittance through homogeneous media is exact down to this value, tracked below it
SHADOW_TAU = 0.4
#: the same threshold in scenes whose media the camera sees only through thindielectric sheets
#: (:func:`shadow_tau`): 1, tracking from the start, as Mitsuba's shadow rays do
SHADOW_TAU_SHEETS = 1.0

NULL_NONE, NULL_BOUNDARY, NULL_THIN = 0, 1, 2


def _sheet_tint(spec) -> tuple[float, float, float] | None:
    """A ``thindielectric`` material's constant ``specular_reflectance`` as RGB (None: a
    texture); zero for any other BSDF."""
    if spec is None or spec.kind != "thindielectric":
        return (0.0, 0.0, 0.0)
    v = {**PARAMS["thindielectric"], **spec.params}.get("specular_reflectance", 1.0)
    if isinstance(v, (int, float)):
        return (float(v),) * 3
    if isinstance(v, tuple) and len(v) == 3:
        return tuple(float(x) for x in v)
    return None

def shadow_tau(scene: Scene, blind: frozenset[int] = frozenset()) -> float:
    """The scene's threshold below which shadow rays track homogeneous media (decided when
    the kernel is traced): :data:`SHADOW_TAU_SHEETS` when the camera is in vacuum and every
    medium but the ``blind`` ones (0-based, :func:`~drpt.render.integrators.enclosure.blind_media`:
    their shadow rays are not traced) has only ``thindielectric`` surfaces on either side,
    else :data:`SHADOW_TAU`.

    Why: tracking ends most shadow rays deep in a medium at their first sampled collision
    instead of following every boundary to the light (less work), at the price of a 0-or-more
    estimate where the exact one is smooth (more variance). Where a pixel sees a medium only
    through sheets, each camera ray already picks reflection or transmission at random there,
    and that choice, not the shadow estimate, dominates the pixel's variance; where a ``null``
    boundary (or none: the camera's own medium) shows the medium directly, the shadow
    estimate is most of what the pixel sees. Measured on the corpus
    (docs/performance.md, "Shadow tracking per scene"): ``obj_inside_medium`` (sheets only)
    +10% efficiency at 1, ``emitter_inside_medium`` (sheets only) +1%, ``null_envmap`` (null
    boundaries) -18%, ``area_light`` (a null and a sheet) -6%."""
    if getattr(scene, "camera_medium", None) is not None:
        return SHADOW_TAU
    seen = set()
    for m in scene.materials or []:
        sides = {i for i in (m.interior, m.exterior) if i is not None} - set(blind)
        if not sides:
            continue
        if m.bsdf is None or m.bsdf.kind != "thindielectric":
            return SHADOW_TAU
        seen |= sides
    return SHADOW_TAU_SHEETS if seen else SHADOW_TAU


def _vec(a) -> Array3f:
    a = np.ascontiguousarray(np.asarray(a, np.float32).reshape(-1, 3))
    return Array3f(Float(a[:, 0]), Float(a[:, 1]), Float(a[:, 2]))


def hg_pdf(g: Float, cos_fwd: Float) -> Float:
    """Henyey-Greenstein density (per steradian) of scattering by angle ``acos(cos_fwd)``
    from the propagation direction (``g > 0``: forward); ``g = 0`` is isotropic."""
    denom = dr.maximum(1.0 + g * g - 2.0 * g * cos_fwd, 1e-12)
    return (1.0 - g * g) / (4.0 * dr.pi * denom * dr.sqrt(denom))


def hg_sample(g: Float, u: Array2f, d: Array3f) -> Array3f:
    """A direction distributed by :func:`hg_pdf` about the unit propagation direction ``d``
    (exact inversion; isotropic where ``|g| < 1e-3``)."""
    iso = dr.abs(g) < 1e-3
    gg = dr.select(iso, 1.0, g)
    sq = (1.0 - gg * gg) / (1.0 - gg + 2.0 * gg * u.x)
    cos = dr.select(iso, 1.0 - 2.0 * u.x, (1.0 + gg * gg - sq * sq) / (2.0 * gg))
    cos = dr.clip(cos, -1.0, 1.0)
    sin = dr.safe_sqrt(1.0 - cos * cos)
    phi = 2.0 * dr.pi * u.y
    sp, cp = dr.sincos(phi)
    return dr.normalize(Frame(d).to_world(Array3f(sin * cp, sin * sp, cos)))


class MediumTable:
    """The scene's media (homogeneous ones in arrays, heterogeneous ones as
    :class:`Heterogeneous` objects) and, per material, the media on either side of its
    surfaces and how a shadow ray passes it (on the device). Medium ids are 1-based
    (``0``: vacuum)."""

    def __init__(self, scene: Scene):
        media = scene.media
        self.count = len(media)
        # (a heterogeneous medium is vacuum to the homogeneous code: its own in self.hetero)
        self.sigma_t = _vec([m.extinction if m.is_homogeneous else (0.0, 0.0, 0.0) for m in media])
        self.hetero = [Heterogeneous(i + 1, m) for i, m in enumerate(media) if not m.is_homogeneous]
        self.hetero = [h for h in self.hetero if h.majorant > 0.0]
        self.has_hetero = bool(self.hetero)
        self.albedo = _vec([m.albedo for m in media])
        self.g = Float(np.array([m.g if m.phase in ("hg", "blend") else 0.0 for m in media], np.float32))
        self.has_blend = any(m.phase == "blend" for m in media)
        if self.has_blend:  # Mitsuba's blendphase: a second HG lobe and its weight
            self.g2 = Float(np.array([m.g2 if m.phase == "blend" else 0.0 for m in media], np.float32))
            self.blend = Float(np.array([m.blend if m.phase == "blend" else 0.0 for m in media], np.float32))
        mats = scene.materials or []
        interior = [0 if m.interior is None else m.interior + 1 for m in mats]
        exterior = [0 if m.exterior is None else m.exterior + 1 for m in mats]
        transition = [m.is_medium_transition for m in mats]
        kind, eta, trans = [], [], []
        # thin sheets' specular_reflectance (VolPathIntegrator.sheet_split; None: a texture)
        tints = [_sheet_tint(m.bsdf) for m in mats] or [(0.0, 0.0, 0.0)]
        for m in mats:
            spec = m.bsdf
            k = spec.kind if spec is not None else ""
            if k == "null":
                kind.append(NULL_BOUNDARY)
                eta.append(1.0)
                trans.append((1.0, 1.0, 1.0))
            elif k == "thindielectric":
                p = {**PARAMS["thindielectric"], **spec.params}
                t = p.get("specular_transmittance", (1.0, 1.0, 1.0))
                if isinstance(t, (int, float)):
                    t = (float(t),) * 3
                if not (isinstance(t, tuple) and len(t) == 3):
                    raise SceneError(m.loc or Loc(scene.path), "volpath: a thindielectric with a textured "
                                     "specular_transmittance is not supported")
                kind.append(NULL_THIN)
                eta.append(relative_ior(p["int_ior"], p["ext_ior"]))
                trans.append(tuple(float(x) for x in t))
            else:
                kind.append(NULL_NONE)
                eta.append(1.0)
                trans.append((0.0, 0.0, 0.0))
        if not mats:
            interior, exterior, transition, kind, eta, trans = [0], [0], [False], [0], [1.0], [(0.0,) * 3]
        self.interior = UInt32(np.array(interior, np.uint32))
        self.exterior = UInt32(np.array(exterior, np.uint32))
        self.transition = Bool(np.array(transition, bool))
        self.null_kind = UInt32(np.array(kind, np.uint32))
        self.thin_eta = Float(np.array(eta, np.float32))
        self.null_trans = _vec(trans)
        self.sheet_tints = all(t is not None for t in tints)  # (no texture to read)
        self.sheet_tint = _vec([t if t is not None else (0.0, 0.0, 0.0) for t in tints])
        self.has_null = any(k != NULL_NONE for k in kind)
        self.has_thin = NULL_THIN in kind
        # one set of coefficients for every medium (no heterogeneous one): the kernels read
        # them as literals, no gathers (and a gray extinction's channels are then one value)
        homo = {(tuple(m.extinction), tuple(m.albedo), m.g if m.phase == "hg" else 0.0)
                for m in media if m.phase in ("isotropic", "hg")}
        self.uniform = None
        if len(homo) == 1 and all(m.is_homogeneous and m.phase in ("isotropic", "hg") for m in media):
            (st, al, g), = homo
            self.uniform = (tuple(float(np.float32(x)) for x in st), tuple(float(np.float32(x)) for x in al),
                            float(np.float32(g)))
        # every homogeneous extinction the same in R, G and B (a heterogeneous one is a single
        # channel): one channel's free flight samples all three, no spectral MIS
        self.gray = all(m.extinction[0] == m.extinction[1] == m.extinction[2]
                        for m in media if m.is_homogeneous)
        # media where next-event estimation cannot see a light (enclosure.blind_media)
        blind = blind_media(scene)
        self.blind_set = blind
        self.has_blind = bool(blind)
        self.all_blind = self.count > 0 and len(blind) == self.count
        # a ray in a medium may end its segment at an emitter (enclosure.media_see_emitters)
        self.see_emitters = self.count > 0 and media_see_emitters(scene)
        if self.has_blind:
            self.blind = Bool(np.array([False] + [i in blind for i in range(self.count)], bool))

    def coefficients(self, medium: UInt32, active: Bool) -> tuple[Array3f, Array3f, Float]:
        """``(sigma_t, albedo, g)`` of the lanes' media (``sigma_t`` zero in vacuum; the
        albedo and ``g`` there: zeros, or with :attr:`uniform` media its values)."""
        inside = active & (medium > 0)
        if self.uniform is not None:
            st, al, g = self.uniform
            return dr.select(inside, Array3f(*st), 0.0), Array3f(*al), Float(g)
        i = dr.select(inside, medium - 1, 0)
        st = dr.gather(Array3f, self.sigma_t, i, inside)
        al = dr.gather(Array3f, self.albedo, i, inside)
        g = dr.gather(Float, self.g, i, inside)
        return dr.select(inside, st, 0.0), al, g

    def is_blind(self, medium: UInt32, active: Bool) -> Bool:
        """Lanes whose medium is blind (:func:`~.enclosure.blind_media`: no shadow ray from it
        reaches a light); only in scenes with such a medium."""
        return dr.gather(Bool, self.blind, medium, active) & active

    def blend_lobe(self, medium: UInt32, active: Bool) -> tuple[Float, Float]:
        """``(g2, weight)`` of the lanes' blended phase functions (weight 0: one lobe)."""
        inside = active & (medium > 0)
        i = dr.select(inside, medium - 1, 0)
        return dr.gather(Float, self.g2, i, inside), dr.select(inside, dr.gather(Float, self.blend, i, inside), 0.0)

    def after(self, si, d: Array3f, medium: UInt32, active: Bool) -> UInt32:
        """The medium a ray leaving the surface ``si`` along ``d`` is in."""
        on = active & si.valid
        mat = dr.select(on, si.material, 0)
        trans = dr.gather(Bool, self.transition, mat, on) & on
        out = dr.dot(d, si.ng) > 0.0
        target = dr.select(out, dr.gather(UInt32, self.exterior, mat, trans),
                           dr.gather(UInt32, self.interior, mat, trans))
        return dr.select(trans, target, medium)

    def null_kind_of(self, si, active: Bool) -> UInt32:
        on = active & si.valid
        return dr.select(on, dr.gather(UInt32, self.null_kind, dr.select(on, si.material, 0), on), NULL_NONE)

    def null_transmission(self, si, d: Array3f, active: Bool) -> Array3f:
        """What a shadow ray along ``d`` keeps crossing ``si``: 1 through a ``null``
        boundary, ``(1 - R') * specular_transmittance`` through a thindielectric sheet
        (Mitsuba's ``eval_null_transmission``), 0 through anything else."""
        on = active & si.valid
        mat = dr.select(on, si.material, 0)
        kind = dr.gather(UInt32, self.null_kind, mat, on)
        if not self.has_thin:  # (null boundaries pass everything, other surfaces nothing)
            return dr.select(on & (kind == NULL_BOUNDARY), Array3f(1.0), Array3f(0.0))
        eta = dr.gather(Float, self.thin_eta, mat, on)
        t = dr.gather(Array3f, self.null_trans, mat, on)
        r = reflectance(dr.dot(si.ns, d), eta)
        value = dr.select(kind == NULL_THIN, t * (1.0 - r), t)
        return dr.select(on, value, 0.0)


def _affine(m, p: Array3f, translate: bool = True) -> Array3f:
    """The 4x4 host matrix ``m`` (nested lists) applied to the point (or, without
    ``translate``, the vector) ``p``."""
    return Array3f(*(m[r][0] * p.x + m[r][1] * p.y + m[r][2] * p.z + (m[r][3] if translate else 0.0)
                     for r in range(3)))


def _texture(grid):
    from drjit.auto import TensorXf, Texture3f

    mode = dr.FilterMode.Linear if grid.filter == "trilinear" else dr.FilterMode.Nearest
    wrap = {"clamp": dr.WrapMode.Clamp, "repeat": dr.WrapMode.Repeat, "mirror": dr.WrapMode.Mirror}[grid.wrap]
    return Texture3f(TensorXf(np.ascontiguousarray(grid.data, np.float32)), use_accel=False,
                     filter_mode=mode, wrap_mode=wrap)


class Heterogeneous:
    """One heterogeneous medium (Mitsuba's ``heterogeneous`` with a ``gridvolume``
    extinction): its extinction is the grid's value times ``scale`` inside the world-space
    box of the grid's unit cube (Mitsuba's ``Volume::bbox``, wrap mode outside the cube but
    inside the box) and zero elsewhere; the majorant is ``scale`` times the grid's maximum."""

    def __init__(self, medium_id: int, m):
        grid = m.sigma_t_grid
        self.id = medium_id
        self.scale = float(m.scale)
        self.majorant = self.scale * grid.max
        self.to_local = np.asarray(grid.to_local, np.float64).tolist()
        corners = np.array([[x, y, z, 1.0] for x in (0, 1) for y in (0, 1) for z in (0, 1)]) @ \
            np.linalg.inv(grid.to_local).T
        self.lo, self.hi = corners[:, :3].min(0).tolist(), corners[:, :3].max(0).tolist()
        self.sigma_tex = _texture(grid)
        self.albedo_const = tuple(float(a) for a in m.albedo)
        self.albedo_grid = m.albedo_grid
        if self.albedo_grid is not None:
            self.albedo_tex = _texture(self.albedo_grid)
            self.albedo_to_local = np.asarray(self.albedo_grid.to_local, np.float64).tolist()

    def box(self, o: Array3f, d: Array3f) -> tuple[Float, Float, Bool]:
        """``(mint, maxt, hit)`` of the ray ``(o, d)`` through the medium's box."""
        mint, maxt = Float(-dr.inf), Float(dr.inf)
        for k in range(3):
            ok, dk = o[k], d[k]
            inside = (ok >= self.lo[k]) & (ok <= self.hi[k])
            a, b = (self.lo[k] - ok) / dk, (self.hi[k] - ok) / dk
            zero = dk == 0.0
            mint = dr.maximum(mint, dr.select(zero, dr.select(inside, -dr.inf, dr.inf), dr.minimum(a, b)))
            maxt = dr.minimum(maxt, dr.select(zero, dr.select(inside, dr.inf, -dr.inf), dr.maximum(a, b)))
        return mint, maxt, mint <= maxt

    def sigma_t(self, p: Array3f, active: Bool) -> Float:
        return self.sigma_tex.eval(_affine(self.to_local, p), active)[0] * self.scale

    def albedo(self, p: Array3f, active: Bool) -> Array3f:
        if self.albedo_grid is None:
            return Array3f(*self.albedo_const)
        v = self.albedo_tex.eval(_affine(self.albedo_to_local, p), active)
        return Array3f(v[0], v[0], v[0]) if len(v) == 1 else Array3f(v[0], v[1], v[2])

    def collide(self, o: Array3f, d: Array3f, end: Float, u: Float, active: Bool) -> tuple[Bool, Float]:
        """Lanes whose tentative collision (distance sampled with the majorant from where the
        ray enters the box) comes before ``end``, and its distance."""
        mint, maxt, hit = self.box(o, d)
        t = dr.maximum(mint, 0.0) - dr.log(1.0 - u) / self.majorant
        return active & hit & (t < dr.minimum(maxt, end)), t


def _transmittance(sigma_t: Array3f, dist: Float) -> Array3f:
    """``exp(-sigma_t dist)`` per channel, 1 where ``sigma_t`` is 0 (also for an infinite ``dist``)."""
    return dr.select(sigma_t > 0.0, dr.exp(-sigma_t * dist), 1.0)


def reach(t: Float) -> Float:
    """How far a closest-hit query need look for a ray whose medium collision was sampled
    at ``t``: only surfaces before it matter (a shorter ray traverses less); the largest
    float where ``t`` is infinite."""
    return dr.select(t < dr.largest(Float), t, dr.largest(Float))


def _survivor_weight(sigma_t: Array3f, sig_r: Float, seg: Float, exact: Float) -> Array3f:
    """``exp(-sigma_t seg)`` divided by the probability that a shadow ray survives ``seg``:
    ``exp(-sig_r max(seg - exact, 0))``."""
    excess = dr.select(sig_r > 0.0, dr.maximum(seg - exact, 0.0), 0.0)
    return dr.select(sigma_t > 0.0, dr.exp(sig_r * excess - sigma_t * seg), 1.0)


@dataclass
class Flight:
    """What free-flight sampling decided for the lanes' segment
    (:meth:`VolPathIntegrator.free_flight`), and which events the lanes may have:
    ``medium`` and ``surface`` are Python flags, fixed when a kernel is traced (the
    megakernel: both; the wavefront's medium queue: ``medium`` only, its surface queues:
    ``surface`` only). The code of an event no lane has is not traced, and a field only
    such an event reads may be None."""

    beta: Array3f  # the throughput after the segment
    depth: UInt32  # a real medium scattering event counted
    scatter: Bool  # a real medium scattering event at p_med
    scatter_live: Bool  # ... below the depth limit: the path scatters there
    surf: Bool  # the ray reached the surface si, or escaped
    p_med: Array3f
    in_medium: Bool
    g: Float  # the medium's Henyey-Greenstein asymmetry
    medium: bool = True
    surface: bool = True
    #: with :attr:`VolPathIntegrator.counts_through`: the throughput times the transmittance
    #: up to the surface beyond (in_medium lanes), what its emission is counted with
    through: Array3f | None = None


def _either(fl: Flight, mask: Bool, medium, surface):
    """``dr.select(mask, medium(), surface())``, or only the one of the two that ``fl``'s
    lanes can need (``medium`` and ``surface`` are callables: the other is not traced)."""
    if not fl.surface:
        return medium()
    if not fl.medium:
        return surface()
    return dr.select(mask, medium(), surface())


class VolShadowQuery:
    """Next-event estimation at a scattering vertex waiting for the transmittance ``tr`` of
    its shadow segment (from ``o`` along unit ``d`` up to ``tmax``, starting in
    ``medium``): it adds ``a * tr * b`` where ``ok``, the factors kept apart so that the
    product rounds as one expression in the megakernel's order."""

    def __init__(self, a: Array3f, b: Float, o: Array3f, d: Array3f, tmax: Float, medium: UInt32, ok: Bool):
        self.a, self.b, self.o, self.d, self.tmax, self.medium, self.ok = a, b, o, d, tmax, medium, ok

    def resolve(self, tr: Array3f) -> Array3f:
        return dr.select(self.ok, self.a * tr * self.b, 0.0)


@dataclass
class VolPathState:
    """One path per lane (a Dr.Jit loop state)."""

    o: Array3f
    d: Array3f
    L: Array3f
    beta: Array3f
    eta: Float
    depth: UInt32  # real scattering events (surface or medium)
    prev_pdf: Float  # density of d at the last real scattering event (MIS)
    prev_delta: Bool  # Mitsuba's specular_chain: the emitter d hits counts in full
    ref_p: Array3f  # the last real scattering event (the MIS density of the emitter d hits)
    medium: UInt32  # 1-based medium id of the ray, 0 in vacuum
    active: Bool


class VolPathIntegrator(PathIntegrator):
    """Mitsuba's ``volpath`` (see the module's docs). Its
    ``sample`` and ``sample_sequence`` are :class:`PathIntegrator`'s."""

    #: count the emission at the end of a segment in a homogeneous medium by its
    #: transmittance (:attr:`counts_through`); False: where the free flight got there (A/B)
    count_through = True
    #: count the emission mirrored by thin sheets seen from vacuum at the sheet
    #: (:meth:`sheet_split`); False: the path's own reflection only (for A/B comparisons)
    split_sheets = True

    def __init__(self, scene: DeviceScene, options: PathOptions, model: Scene):
        super().__init__(scene, options)
        self.media = MediumTable(model)
        self.shadow_tau = shadow_tau(model, self.media.blind_set)
        cm = getattr(model, "camera_medium", None)
        self.camera_medium = 0 if cm is None else cm + 1
        # Mitsuba's sky, for next-event estimation, is 2 max(R, |p - c|) away from the point p,
        # (c, R) the bounding sphere of the scene's shapes (what a medium attenuates on the way)
        lo, hi = model.bounds()
        if np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)):
            self.sky_center = tuple(float(x) for x in (lo + hi) / 2)
            self.sky_radius = float(np.linalg.norm(hi - lo) / 2)
        else:
            self.sky_center, self.sky_radius = (0.0, 0.0, 0.0), 0.0

    @property
    def pixel_coherent(self) -> bool:
        """Whether a pixel's paths stay together for their first segments (read at trace
        time): every surface a mirror, smooth conductor or glass (media, if any, behind
        refracting boundaries), as :attr:`PathIntegrator.pixel_coherent` asks of the path
        tracer's scenes, and no ``null`` or ``thindielectric`` surface, through which the
        paths go straight on into a medium that scatters each at its own place. There the
        renderer gives each sample its own lane and the rays to :data:`~.path.COHERENT_DEPTH`
        ask for coherent traversal; a fog behind ``null`` boundaries keeps path regeneration,
        which balances its paths' lengths (docs/performance.md, "Coherent queries of mirror
        and glass paths")."""
        kinds = set(getattr(self.scene.materials, "kinds", ()))
        return bool(kinds) and kinds <= BENDING  # (all Dirac lobes: no smooth BSDF)

    def coherent_queries(self, depth):
        """:meth:`PathIntegrator.coherent_queries` where :attr:`pixel_coherent`; elsewhere no
        query asks for coherent traversal (volpath's camera rays gained nothing by it:
        docs/performance.md, "The sphere scenes' last segment", tried and not kept)."""
        return super().coherent_queries(depth) if self.pixel_coherent else False

    def _start(self, o: Array3f, d: Array3f, active: Bool, weight: Float | None = None) -> VolPathState:
        w = dr.width(active)
        beta = dr.full(Array3f, 1.0, w) if weight is None else Array3f(weight, weight, weight)
        return VolPathState(o=o, d=d, L=dr.zeros(Array3f, w), beta=beta, eta=dr.full(Float, 1.0, w),
                            depth=dr.zeros(UInt32, w), prev_pdf=dr.full(Float, 1.0, w),
                            prev_delta=dr.full(Bool, not self.opt.hide_emitters, w),
                            ref_p=Array3f(o), medium=dr.full(UInt32, self.camera_medium, w),
                            active=Bool(active))

    @property
    def shadow_draws(self) -> bool:
        """Whether :meth:`shadow` draws random numbers (ratio tracking in heterogeneous
        media, tracking below the scene's :func:`shadow_tau` in homogeneous ones): the wavefront then
        traces it inside its queues, between next-event estimation and the next direction,
        as the megakernel does (with a threshold 0 and only homogeneous media, in one
        batch after them)."""
        return self.media.has_hetero or self.shadow_tau > 0.0

    @loops_once
    @dr.syntax
    def shadow(self, o: Array3f, d: Array3f, tmax: Float, medium: UInt32, active: Bool,
               rng: PCG32 | None = None) -> Array3f:
        """The transmittance of the segment from ``o`` along unit ``d`` up to ``tmax``
        (``inf``: to the sky), starting in ``medium``: media, null boundaries and
        thindielectric sheets pass light, other surfaces block it. Homogeneous media
        attenuate exactly, or, with ``rng``, exactly while the transmittance stays above
        the scene's :func:`shadow_tau` and by tracking beyond it (see the module's docs: an unbiased
        estimate); heterogeneous ones by ratio tracking (``rng``: one number per step, only
        in scenes with such media)."""
        scene, media = self.scene, self.media
        track = rng is not None and self.shadow_tau > 0.0
        tr = dr.full(Array3f, 1.0, dr.width(active))
        live = Bool(active)
        o, d, tmax, medium = Array3f(o), Array3f(d), Float(tmax), UInt32(medium)
        crossings = UInt32(0)
        while live:
            sigma_t, _, _ = media.coefficients(medium, live)
            end = Float(tmax)
            sig_r, exact, collide = Float(0.0), Float(0.0), Bool(False)
            if track:  # a collision sampled past the exact stretch ends the ray (inf or NaN in vacuum: none)
                sig_r = dr.minimum(dr.minimum(sigma_t.x, sigma_t.y), sigma_t.z)
                if self.shadow_tau >= 1.0:  # (tracked from the start)
                    exact = Float(0.0)
                else:
                    exact = dr.maximum(dr.log(dr.max(tr) * (1.0 / self.shadow_tau)), 0.0) / sig_r
                t_c = exact - dr.log(1.0 - rng.next_float32()) / sig_r
                collide = live & (t_c < tmax)
                end = dr.select(collide, t_c, tmax)
            # (only surfaces before the collision matter: a shorter ray traverses less)
            si = scene.intersect(o, d, live, reach(end))
            ahead = live & si.valid & (si.t < tmax)
            seg = dr.select(ahead, si.t, tmax)
            blocked = Bool(ahead)
            if track:
                tr = dr.select(live, tr * _survivor_weight(sigma_t, sig_r, seg, exact), tr)
                tr = dr.select(collide & ~ahead, 0.0, tr)
            else:
                tr = dr.select(live, tr * _transmittance(sigma_t, seg), tr)
            if media.has_hetero:  # ratio tracking up to the surface, in a loop of its own
                o, tr, tmax, seg = self._ratio_track(o, d, tr, tmax, seg, medium, live, rng)
            tr = dr.select(blocked, tr * media.null_transmission(si, d, blocked), tr)
            medium = media.after(si, d, medium, blocked)
            o2 = scene.spawn(si, d)
            tmax = dr.select(blocked, tmax - dr.dot(o2 - o, d), tmax)
            o = dr.select(blocked, o2, o)
            crossings = dr.select(blocked, crossings + 1, crossings)
            tr = dr.select(blocked & (crossings >= MAX_SHADOW_CROSSINGS), 0.0, tr)
            live = blocked & (dr.max(tr) > 0.0) & (crossings < MAX_SHADOW_CROSSINGS)
        return tr

    @dr.syntax
    def _ratio_track(self, o: Array3f, d: Array3f, tr: Array3f, tmax: Float, seg: Float, medium: UInt32,
                     active: Bool, rng: PCG32):
        """Ratio tracking through the heterogeneous medium ``medium`` from ``o`` up to ``seg``
        along ``d``: each tentative collision (sampled with the majorant, one random number)
        multiplies ``tr`` by ``1 - sigma_t / majorant``. Returns ``o``, ``tr``, ``tmax`` and
        ``seg`` moved to the last collision (the surface at ``seg`` stays where it was). Its own
        loop: a tentative collision costs no surface interaction."""
        o, tr, tmax, seg = Array3f(o), Array3f(tr), Float(tmax), Float(seg)
        stepping = Bool(active)
        while stepping:
            u = rng.next_float32()
            step = Bool(False)
            for h in self.media.hetero:
                hit, t = h.collide(o, d, seg, u, stepping & (medium == h.id))
                p = o + d * t
                tr = dr.select(hit, tr * dr.maximum(1.0 - h.sigma_t(p, hit) / h.majorant, 0.0), tr)
                o = dr.select(hit, p, o)
                tmax = dr.select(hit, tmax - t, tmax)
                seg = dr.select(hit, seg - t, seg)
                step = step | hit
            stepping = step & (dr.max(tr) > 0.0)
        return o, tr, tmax, seg

    def bounce(self, scene: DeviceScene, s: VolPathState, rng: PCG32) -> VolPathState:
        """One segment and the event at its end (the megakernel's loop body), as the five
        steps the wavefront integrator also runs, each on its own stage's lanes
        (:mod:`drpt.render.integrators.volwavefront`): :meth:`roulette`, the closest hit,
        :meth:`free_flight`, :meth:`emitted`, :meth:`nee_query` with :meth:`shadow`, and
        :meth:`next_ray`."""
        active, beta = self.roulette(s, rng)
        draw = self.flight_draw(s, active, rng)
        si = scene.intersect(s.o, s.d, active, self.query_reach(draw[2]),
                             coherent=self.coherent_queries(s.depth))
        fl = self.free_flight(s, si, active, beta, rng, draw)
        si = self.skip_emitters(scene, s, si, fl)
        L = s.L + self.emitted(scene, s, si, fl)
        si = self.past_collision(si, fl)
        on_surface = fl.surf & si.valid
        split = self.sheet_split(s, si, fl, on_surface)
        if split is not None:
            L = L + split[0]
        phase = self.phase(s, fl)
        q = self.nee_query(scene, s, si, fl, on_surface, phase, rng)
        if q is not None:  # one emitter, one shadow ray through the media
            L = L + q.resolve(self.shadow(q.o, q.d, q.tmax, q.medium, q.ok, rng))
        return self.next_ray(scene, s, si, fl, on_surface, phase, L, rng,
                             split=None if split is None else split[1])

    def roulette(self, s: VolPathState, rng: PCG32) -> tuple[Bool, Array3f]:
        """Russian roulette and the depth limit, at the top of a bounce as in Mitsuba's
        volpath (one random number): the lanes that go on, and their throughput."""
        opt = self.opt
        u_rr = rng.next_float32()
        if opt.rr_prob is not None:  # (--rr-prob: a fixed continuation probability)
            q = Float(opt.rr_prob)
        else:
            q = dr.minimum(dr.max(s.beta) * dr.square(s.eta), 0.95)
        perform_rr = s.depth > opt.rr_depth
        active = s.active & (dr.max(s.beta) > 0.0) & ((u_rr < q) | ~perform_rr)
        beta = dr.select(perform_rr, s.beta / q, s.beta)
        if opt.max_depth >= 0:
            active = active & (s.depth < opt.max_depth)
        return active, beta

    def flight_draw(self, s: VolPathState, active: Bool, rng: PCG32) -> tuple[Float, Float, Float]:
        """The free-flight draw, before the closest hit: ``(u_ch, u_t, t)``, two random
        numbers and the collision distance they sample in the ray's medium (spectral MIS:
        a channel ``u_ch`` picks, ``inf`` in vacuum). The closest hit need look no further
        than ``t`` (:func:`reach`); :meth:`free_flight` takes the draw."""
        u_ch, u_t = rng.next_float32(), rng.next_float32()
        in_medium = active & (s.medium > 0)
        sigma_t, _, _ = self.media.coefficients(s.medium, in_medium)
        if self.media.gray:  # (u_ch drawn all the same: the same stream)
            return u_ch, u_t, -dr.log(1.0 - u_t) / sigma_t.x
        ch = dr.minimum(UInt32(u_ch * 3.0), 2)
        m = dr.select(ch == 0, sigma_t.x, dr.select(ch == 1, sigma_t.y, sigma_t.z))
        return u_ch, u_t, -dr.log(1.0 - u_t) / m  # inf where m = 0

    def free_flight(self, s: VolPathState, si, active: Bool, beta: Array3f, rng: PCG32,
                    draw: tuple[Float, Float, Float]) -> Flight:
        """Free-flight sampling along the ray up to ``si`` in the ray's medium with
        :meth:`flight_draw`'s ``draw`` (spectral MIS over the channels; delta tracking in
        heterogeneous media, one more random number)."""
        opt, media = self.opt, self.media
        _, u_t, t = draw
        beta_in = beta
        in_medium = active & (s.medium > 0)
        sigma_t, albedo, g = media.coefficients(s.medium, in_medium)
        t_surf = dr.select(si.valid, si.t, dr.inf)
        scatter = in_medium & (t < t_surf)
        if media.gray:  # the transmittance and the density cancel: 1 at the surface, albedo at a collision
            beta = dr.select(scatter, beta * albedo, beta)
        else:
            dist = dr.select(scatter, t, t_surf)
            tr = _transmittance(sigma_t, dist)
            pdf = dr.select(scatter, tr * sigma_t, tr)
            mean_pdf = (pdf.x + pdf.y + pdf.z) * (1.0 / 3.0)
            ratio = dr.select(mean_pdf > 0.0, tr / mean_pdf, 0.0)
            beta = dr.select(in_medium, beta * ratio, beta)
            beta = dr.select(scatter, beta * sigma_t * albedo, beta)
        p_med = s.o + s.d * t
        if media.has_hetero:  # delta tracking against the majorant, null collisions in its own loop
            real, p_h, beta = self._delta_track(s.o, s.d, t_surf, u_t, in_medium, s.medium, beta, rng)
            p_med = dr.select(real, p_h, p_med)
            scatter = scatter | real
        through = None
        if self.counts_through:  # (the throughput before this segment's weights)
            through = dr.select(in_medium, beta_in * _transmittance(sigma_t, t_surf), 0.0)
        depth = dr.select(scatter, s.depth + 1, s.depth)
        scatter_live = scatter & (depth < opt.max_depth) if opt.max_depth >= 0 else Bool(scatter)
        surf = active & ~scatter
        return Flight(beta=beta, depth=depth, scatter=scatter, scatter_live=scatter_live,
                      surf=surf, p_med=p_med, in_medium=in_medium, g=g, through=through)

    @loops_once
    @dr.syntax
    def _delta_track(self, o: Array3f, d: Array3f, t_surf: Float, u: Float, active: Bool, medium: UInt32,
                     beta: Array3f, rng: PCG32):
        """Delta tracking through the heterogeneous medium ``medium`` from ``o`` along ``d``
        up to ``t_surf``, null collisions included, in a loop of its own (the first tentative
        collision drawn with ``u``, each further one with a new number, and one number per
        tentative collision to accept it with ``sigma_t / majorant``). Returns the lanes
        that found a real collision, its point, and ``beta`` times
        the albedo there."""
        real = Bool(False)
        p = Array3f(o)
        end = Float(t_surf)
        going = Bool(active)
        while going:
            u_null = rng.next_float32()
            step = Bool(False)
            for h in self.media.hetero:
                cand, t_h = h.collide(p, d, end, u, going & (medium == h.id))
                p_h = p + d * t_h
                hit = cand & (u_null * h.majorant < h.sigma_t(p_h, cand))
                beta = dr.select(hit, beta * h.albedo(p_h, hit), beta)
                p = dr.select(cand, p_h, p)
                end = dr.select(cand, end - t_h, end)
                real = real | hit
                step = step | (cand & ~hit)
            going = step
            u = rng.next_float32()
        return real, p, beta

    def skip_emitters(self, scene: DeviceScene, s: VolPathState, si, fl: Flight):
        """``si`` with ``hide_emitters``' camera rays that reach an area emitter (``fl.surf``
        lanes at depth 0) continued past all area emitters along them
        (:meth:`~drpt.render.scene.DeviceScene.skip_area_emitters`), as Mitsuba's
        ``volpath`` does after free-flight sampling (the segment past the emitter adds no
        medium interaction). Traced only with ``hide_emitters`` in a scene with emissive
        surfaces."""
        if not (self.opt.hide_emitters and scene.materials.has_emission):
            return si
        return scene.skip_area_emitters(s.o, s.d, si, fl.surf & (fl.depth == 0), coherent=True)

    def emitted(self, scene: DeviceScene, s: VolPathState, si, fl: Flight) -> Array3f:
        """What the ray's throughput brings back from the emitter or sky it reaches
        (``fl.surf`` lanes), MIS-weighted against next-event estimation from the last real
        scattering vertex (null crossings do not count)."""
        nee = self.traces_nee
        hide = (s.depth == 0) if self.opt.hide_emitters else Bool(False)  # (the segment's depth)
        seen = fl.surf & ~hide
        weight = fl.beta
        if fl.through is not None:  # in a medium: by its transmittance, whether the ray got there or not
            seen = (seen & ~fl.in_medium) | (fl.in_medium & ~hide)
            weight = dr.select(fl.in_medium, fl.through, fl.beta)
        # (the density seen from that vertex, the point next-event estimation sampled from)
        le, pdf_l = scene.eval_emitter(si, s.d, seen, density=nee, ref=s.ref_p)
        w = Float(1.0)
        if nee:
            w = dr.select(s.prev_delta, 1.0, power_heuristic(s.prev_pdf, pdf_l))
        if self.splits_sheets:  # (counted at the sheet already: sheet_split)
            w = dr.select(s.prev_pdf < 0.0, 0.0, w)
        return dr.select(seen, weight * le * w, 0.0)

    @property
    def traces_nee(self) -> bool:
        """Whether any vertex of the scene's paths can take a next-event estimate (read at
        trace time): emitters, and surfaces with a smooth BSDF or a medium that is not blind
        (:meth:`nee_query` traces none otherwise). Without it, every emitter a sampled ray
        reaches counts in full: its previous real vertex was a delta lobe, or a scattering
        event in a blind medium, whose next segment ends on the enclosure (no emitter), so
        :meth:`emitted` looks up no density."""
        scene = self.scene
        return scene.has_emitters and (scene.has_smooth_bsdfs or not self.media.all_blind)

    @property
    def counts_through(self) -> bool:
        """Whether a ray in a medium counts the emission of what lies at the end of its
        segment by the transmittance up to it (read at trace time: :attr:`count_through`
        on, homogeneous media only, and a medium in which a ray can reach an emitter:
        :func:`~.enclosure.media_see_emitters`; elsewhere the term is always 0, a
        medium bounded by null surfaces under a sky included). The closest hit then
        looks the whole way (:meth:`query_reach`), and :meth:`emitted` adds, for every
        lane in a medium, the throughput times ``exp(-sigma_t t)`` times the emission at
        the hit or the sky (zero at an infinite distance), where the sampled free flight
        added it at full weight on the lanes that got there: the same expectation, without
        the variance of whether this ray got there. The lanes that scattered first go on
        as before (:meth:`past_collision`)."""
        return (self.count_through and self.media.see_emitters and not self.media.has_hetero
                and not nothing_seen(self.scene))

    def query_reach(self, t: Float) -> Float | None:
        """How far the closest hit of a segment whose medium collision was sampled at
        ``t`` looks: :func:`reach`, or the whole way (None) with :attr:`counts_through`."""
        return None if self.counts_through else reach(t)

    def past_collision(self, si, fl: Flight):
        """``si`` as the rest of the bounce sees it: with :attr:`counts_through` (the hit
        found past a sampled collision) no hit on the lanes that scattered."""
        if fl.through is None:
            return si
        si = copy.copy(si)
        si.valid = si.valid & ~fl.scatter
        return si

    @property
    def splits_sheets(self) -> bool:
        """Whether :meth:`sheet_split` is traced (read at trace time): :attr:`split_sheets`
        on, a scene with ``thindielectric`` sheets of constant ``specular_reflectance``,
        and something a ray can see (an emissive surface, a background or an emitter at
        infinity)."""
        return (self.split_sheets and self.media.has_thin and self.media.sheet_tints
                and not nothing_seen(self.scene))

    def sheet_split(self, s: VolPathState, si, fl: Flight, on_surface: Bool) -> tuple[Array3f, Bool] | None:
        """The emission seen in the mirror direction of a ``thindielectric`` sheet hit from
        vacuum, counted at the sheet: ``(term, split)``, ``term`` the throughput times the
        sheet's reflectance ``R' = 2R / (1 + R)`` times its ``specular_reflectance`` times
        what the mirrored ray reaches first (an emitter, the background or the sky: one
        closest hit), for the lanes ``split``: a sheet hit on a ``fl.surf`` lane in vacuum
        whose mirrored ray stays in vacuum and may still add emission (``depth + 1 <
        max_depth``).

        The path still picks reflection or transmission at random (the same numbers, the
        same weights); where it reflects, the emission its next segment reaches is left
        out (:meth:`next_ray` marks the lane with ``prev_pdf = -1``, :meth:`emitted` skips
        it; a null crossing clears the mark), so the estimate keeps its expectation and
        loses the variance of that choice for the reflected light. Where a camera sees a
        medium through a sheet, the sky the sheet mirrors (a few percent of the rays, at
        full weight) is most of a pixel's noise. (Smooth ``dielectric`` surfaces are not
        split: on the corpus water spheres the extra ray cost more than the variance it
        saved, docs/performance.md.) None where :attr:`splits_sheets` is off (nothing
        traced)."""
        if not (fl.surface and self.splits_sheets):
            return None
        media, opt, scene = self.media, self.opt, self.scene
        wi = -s.d
        cos = dr.dot(si.ns, wi)  # (the BSDF's shading frame: wi.z)
        wr = si.ns * (2.0 * cos) - wi  # the mirror direction
        on = on_surface & (s.medium == 0)
        split = on & (media.null_kind_of(si, on) == NULL_THIN)
        if opt.max_depth >= 0:
            split = split & (fl.depth + 1 < opt.max_depth)
        split = split & (media.after(si, wr, s.medium, split) == 0)
        mat = dr.select(split, si.material, 0)
        r = reflectance(cos, dr.gather(Float, media.thin_eta, mat, split))
        tint = dr.gather(Array3f, media.sheet_tint, mat, split)
        si_r = scene.intersect(scene.spawn(si, wr), wr, split)
        le, _ = scene.eval_emitter(si_r, wr, split, density=False)
        return dr.select(split, fl.beta * tint * r * le, 0.0), split

    def phase(self, s: VolPathState, fl: Flight):
        """``(pdf, lobes)``: the density ``wo -> pdf`` of the phase function of the ray's
        medium (scattering from ``s.d``) and a blended phase function's second lobe ``(g2,
        weight)`` (None without blends); ``(None, None)`` where no lane has a medium event."""
        if not fl.medium:
            return None, None
        g = fl.g
        if self.media.has_blend:
            g2, wb = self.media.blend_lobe(s.medium, fl.in_medium)

            def phase_pdf(wo):
                c = dr.dot(wo, s.d)
                return (1.0 - wb) * hg_pdf(g, c) + wb * hg_pdf(g2, c)
            return phase_pdf, (g2, wb)

        def phase_pdf(wo):
            return hg_pdf(g, dr.dot(wo, s.d))
        return phase_pdf, None

    def nee_query(self, scene: DeviceScene, s: VolPathState, si, fl: Flight, on_surface: Bool, phase,
                  rng: PCG32) -> VolShadowQuery | None:
        """Next-event estimation at the scattering vertex (surface or medium), before its
        shadow segment's transmittance: one emitter sample (three random numbers, drawn in
        scenes without emitters too), the BSDF or the phase function toward it, the power
        heuristic. None in a scene without emitters. Lanes whose shadow ray would start in a
        blind medium (:func:`~.enclosure.blind_media`) get none; where every medium is blind,
        the code for medium events is not traced (nor any, in a queue of medium events)."""
        opt, media = self.opt, self.media
        if fl.medium and media.all_blind:  # (drawn below all the same: the same stream)
            fl = replace(fl, medium=False) if fl.surface else None
        if fl is None:
            rng.next_float32(), rng.next_float32(), rng.next_float32()
            return None
        if fl.surface:
            nee_ok = on_surface & (fl.depth + 1 < opt.max_depth) if opt.max_depth >= 0 else Bool(on_surface)
            if fl.medium:
                nee_ok = nee_ok | fl.scatter_live  # (no in-place operators: they would change on_surface)
        else:
            nee_ok = Bool(fl.scatter_live)
        vertex = copy.copy(si)
        vertex.p = _either(fl, fl.scatter, lambda: fl.p_med, lambda: si.p)
        u_sel = rng.next_float32()
        u_light = Array2f(rng.next_float32(), rng.next_float32())
        if not scene.has_emitters or not (fl.medium or scene.has_smooth_bsdfs):
            return None  # (no emitter; or surfaces of delta lobes only: the estimate is 0)
        phase_pdf = phase[0]
        es = scene.sample_emitter(vertex, u_sel, u_light, nee_ok)
        f_s = pdf_s = ph = None
        if fl.surface:
            f_s, pdf_s = scene.eval_bsdf(si, es.wo)
        if fl.medium:
            ph = phase_pdf(es.wo)
        f = _either(fl, fl.scatter, lambda: Array3f(ph), lambda: f_s)
        pdf_b = _either(fl, fl.scatter, lambda: ph, lambda: pdf_s)
        ok = nee_ok & es.valid & (dr.max(f) > 0.0)
        o = _either(fl, fl.scatter, lambda: fl.p_med, lambda: scene.spawn(si, es.wo))
        med = _either(fl, fl.scatter, lambda: s.medium, lambda: media.after(si, es.wo, s.medium, on_surface))
        if media.has_blind:
            ok = ok & ~media.is_blind(med, ok)
        d_sh, dist = shadow_segment(o, es)
        if es.dist is not None:  # the sky (and directional lights) 2 max(R, |p - c|) away
            sky = 2.0 * dr.maximum(self.sky_radius, dr.norm(vertex.p - Array3f(*self.sky_center)))
            dist = dr.select(dr.isinf(dist), sky, dist)
        w = power_heuristic(es.pdf, pdf_b) if es.delta is not True else Float(1.0)
        if isinstance(es.delta, Bool):
            w = dr.select(es.delta, 1.0, w)
        return VolShadowQuery(fl.beta * f * es.le, w / es.pdf, o, d_sh, dist * SHADOW_SHRINK, med, ok)

    def next_ray(self, scene: DeviceScene, s: VolPathState, si, fl: Flight, on_surface: Bool, phase,
                 L: Array3f, rng: PCG32, split: Bool | None = None) -> VolPathState:
        """The path's next state: the BSDF sampled at a surface (a null boundary or a thin
        sheet's transmission passed without a scattering event), the phase function at a
        medium event (three random numbers). ``split``: :meth:`sheet_split`'s lanes, whose
        reflection gets ``prev_pdf = -1`` (its emission counted); a null crossing clears
        the mark (what lies beyond it was not counted)."""
        media = self.media
        phase_pdf, lobes = phase
        u_lobe = rng.next_float32()
        u2 = Array2f(rng.next_float32(), rng.next_float32())
        beta, eta, depth = fl.beta, s.eta, fl.depth
        if fl.surface:
            wo, bs = scene.sample_bsdf(si, u_lobe, u2)
        if fl.medium:
            g_lobe = dr.select(u_lobe < lobes[1], lobes[0], fl.g) if lobes is not None else fl.g  # (Mitsuba's)
            wo_ph = hg_sample(g_lobe, Array2f(u2.x, u2.y), s.d)
            wo_ph_pdf = phase_pdf(wo_ph)
        ref_p, prev_pdf, prev_delta, medium = s.ref_p, s.prev_pdf, s.prev_delta, s.medium
        if fl.surface:
            if media.has_null:
                kind = media.null_kind_of(si, on_surface)
                passed = dr.dot(wo, si.ng) * dr.dot(s.d, si.ng) > 0.0
                null = on_surface & (kind != NULL_NONE) & passed
            else:
                null = Bool(False)
            real = on_surface & ~null
            beta = dr.select(on_surface, beta * bs.weight, beta)
            eta = dr.select(on_surface, s.eta * bs.eta, s.eta)
            depth = dr.select(real, depth + 1, depth)
        new_d = _either(fl, fl.scatter_live, lambda: wo_ph, lambda: Array3f(wo))
        new_o = _either(fl, fl.scatter_live, lambda: fl.p_med, lambda: scene.spawn(si, wo))
        if fl.surface:
            medium = media.after(si, wo, s.medium, on_surface)
            ref_p = dr.select(real, si.p, s.ref_p)
            prev_pdf = dr.select(real, Float(bs.pdf), s.prev_pdf)
            if split is not None:  # (reflected: back to the side the ray came from)
                mirrored = split & (dr.dot(wo, si.ng) * dr.dot(s.d, si.ng) < 0.0)
                prev_pdf = dr.select(mirrored, -1.0, dr.select(prev_pdf < 0.0, 0.0, prev_pdf))
            prev_delta = dr.select(real, Bool(bs.delta), s.prev_delta)
        live = None
        if fl.medium:
            ref_p = dr.select(fl.scatter_live, fl.p_med, ref_p)
            prev_pdf = dr.select(fl.scatter_live, wo_ph_pdf, prev_pdf)
            prev_delta = dr.select(fl.scatter_live, False, prev_delta)
            live = fl.scatter_live
        if fl.surface:
            live = on_surface & bs.valid if live is None else live | (on_surface & bs.valid)
        return VolPathState(o=new_o, d=new_d, L=L, beta=beta, eta=eta, depth=depth, prev_pdf=prev_pdf,
                            prev_delta=prev_delta, ref_p=ref_p, medium=medium, active=live)
