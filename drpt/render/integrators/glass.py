"""Next-event estimation through a glass body: light that reaches a surface point through
two smooth refractions (into a pane, a glass table top, and out again), found by the path
tracer's emitter sample as well as by its BSDF sample.

A shadow ray stops at glass, so in the path tracer's two techniques the light behind a pane
is found only by the BSDF sample that happens to pass through it and hit an emitter (with
MIS weight 1: the refractions are Dirac lobes). Under a glass table top lit by ceiling
panels that is most of the floor's light, and most of such a scene's noise. This module
adds a third way to the same paths, *through-glass next-event estimation*, weighted by the
power heuristic against the BSDF sample that finds them:

* **The technique.** Where next-event estimation's shadow ray toward its emitter sample (a
  point ``y`` on an emissive triangle, direction ``d`` from the vertex ``x``, density
  ``p(d)``) is occluded, the ray is followed as the path would be: its closest hit must be
  a smooth dielectric, through which it refracts (the transmitted part of the Fresnel
  split, ``(1 - F) * specular_transmittance * eta_ti^2``, no random choice), the next
  closest hit a smooth dielectric again, out of which it refracts, and the third closest
  hit an emissive triangle, whose radiance it brings back. A parallel slab sends the ray
  on in the direction it entered, moved sideways by less than its thickness, so the
  emitter sample aims it well; any other shape aims it worse, never wrongly (the weights
  below make it unbiased for every shape). The sample counts only where ``y`` is the
  first emissive triangle on the line from ``x`` along ``d`` (:meth:`GlassNEE.line_density`),
  so that ``p(d)`` is the density of ``d`` as the technique draws it.
* **Its density for a BSDF-sampled path.** A path that leaves a smooth vertex ``x`` along
  ``d`` (a non-Dirac lobe, density ``p_bsdf``), refracts twice through smooth dielectrics
  and hits an emissive triangle is a path this technique draws too, with density
  :meth:`GlassNEE.line_density` ``(x, d)``: that of the first emissive triangle on the
  straight line (0 where it meets none). The path state carries ``x``, ``d``, ``p_bsdf``
  and the number of refractions since ``x`` (:class:`GlassState`); the emission such a
  path reaches is weighted ``p_bsdf^2 / (p_bsdf^2 + p^2)``, the through-glass estimate
  ``p^2 / (p_bsdf^2 + p^2)``. The two weights sum to 1 on every such path, so the image's
  expectation is the path tracer's (``tests/render/test_glass_nee.py``: a z-test against
  the path tracer without it, and a control with the BSDF side's weight left at 1).

Traced only where a scene needs it and the weights hold (:func:`applies`, read at trace
time): the path integrator's own bounce, unbounded depth (the technique's path is two
segments longer than the vertex's shadow ray, and a depth limit would have to count them),
a smooth ``dielectric`` among the delta-only materials (the others reflect, ``mirror`` and
``conductor``, or pass straight, ``null`` and ``thindielectric``: then it is not traced),
emissive triangles as the only emitters (no sky, background, delta light or emissive
sphere), few enough to test inline (:attr:`~drpt.render.scene.DeviceScene.emissive`), and a
light selection that does not vary in space. The wavefront integrator's fused tail carries
no :class:`GlassState`, so neither side runs there.
"""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
from drjit.auto import Array2f, Array3f, Bool, Float, UInt32

from ...materials.bsdf_kinds import BENDING
from ..bsdf.dielectric import fresnel_dielectric
from .common import power_heuristic

#: :attr:`GlassState.k` of a path whose segments since its last smooth vertex are not (yet)
#: a through-glass path: no weight to change where it hits an emitter
NONE = 3
#: the delta-only kinds a scene may have for the technique (only ``dielectric`` refracts)
KINDS = BENDING
#: the nearest emissive triangle on the line counts as the sample's own where it is this
#: close to the sample's distance (relative): float rounding of two triangle tests
SAME_POINT = 1e-4


@dataclass
class GlassState:
    """What a path carries for the through-glass weight (a Dr.Jit loop state's field)."""

    x: Array3f = None  # its last smooth vertex, where next-event estimation sampled from
    d: Array3f = None  # the direction it left x along
    pdf: Float = None  # the BSDF's density of d at x
    k: UInt32 = None  # smooth refractions since x (NONE: not a through-glass path)

    DRJIT_STRUCT = {"x": Array3f, "d": Array3f, "pdf": Float, "k": UInt32}

    @staticmethod
    def start(o: Array3f, n: int) -> GlassState:
        """The state of a camera ray (no smooth vertex yet)."""
        return GlassState(Array3f(o), Array3f(0.0, 0.0, 1.0) + Array3f(dr.zeros(Float, n)),
                          dr.zeros(Float, n), dr.full(UInt32, NONE, n))


def applies(scene, options, own_bounce: bool) -> bool:
    """Whether the path tracer traces through-glass next-event estimation on ``scene``
    (read at trace time; the module docstring lists the conditions)."""
    mats = scene.materials
    if not (own_bounce and options.max_depth < 0 and scene.has_emitters and scene.has_smooth_bsdfs):
        return False
    delta = set(getattr(mats, "_delta_kinds", ()))
    if "dielectric" not in delta or not delta <= KINDS:
        return False
    sel = scene.emitter_selection
    lights = getattr(scene, "area_lights", None)
    families_ok = all(f is lights for f in sel.families if f.count > 0)
    return (families_ok and lights is not None and not lights.has_spheres and sel.static
            and scene.emissive is not None and not scene.has_background
            and getattr(scene, "glass_boxes", None) is not None)


class GlassNEE:
    """The technique and its weight on one :class:`~drpt.render.scene.DeviceScene`."""

    def __init__(self, scene):
        self.scene = scene

    def line_density(self, x: Array3f, d: Array3f, active: Bool) -> tuple[Float, Float]:
        """``(p, t)``: the density next-event estimation has for direction ``d`` at ``x``
        through the first emissive triangle on the line (0 where there is none), and
        that triangle's distance (inf where none)."""
        scene = self.scene
        hit = scene.emissive.intersect(x, d, active)
        on = active & hit.valid
        si = scene.interaction(x, d, hit)
        return dr.select(on, scene.pdf_emitter(si, d, on), 0.0), dr.select(on, hit.t, dr.inf)

    def _refract(self, si, d: Array3f, active: Bool) -> tuple[Array3f, Array3f, Bool]:
        """``(wo, weight, through)``: the refraction of the ray ``d`` at its hit ``si``
        (a smooth dielectric's transmitted direction and ``(1 - F)`` times its sampled
        weight), ``through`` on the lanes of ``active`` where ``si`` is a delta-only
        material that refracts the ray (not a mirror, not total internal reflection)."""
        mats = self.scene.materials
        on = active & si.valid & mats.is_delta(si)
        n = dr.width(on)
        # u = 1 picks refraction wherever the Fresnel reflectance is below 1
        wo, bs = mats.specular().sample(si, dr.full(Float, 1.0, n), Array2f(0.5, 0.5))
        cos_i = dr.abs(dr.dot(si.wi, si.ns))
        f = fresnel_dielectric(cos_i, bs.eta)[0]
        through = on & bs.valid & (dr.dot(wo, si.ng) * dr.dot(d, si.ng) > 0.0) & (f < 1.0)
        return wo, bs.weight * (1.0 - f), through

    def estimate(self, si, es, f: Array3f, pdf_b: Float, so: Array3f, active: Bool) -> Array3f:
        """The through-glass estimate at the smooth vertex ``si`` (before the path's
        throughput) of emitter sample ``es`` (its ``wo``, ``p``, ``pdf``), given the BSDF's
        ``f * |cos|`` and density toward it and the shadow ray's origin ``so``, on the
        lanes ``active`` (whose shadow ray was occluded): MIS-weighted, zero where the ray
        does not reach an emissive triangle through two refractions."""
        scene = self.scene
        d = es.wo
        p_line, t_line = self.line_density(si.p, d, active)
        dist = dr.norm(es.p - si.p)
        on = active & (t_line >= dist * (1.0 - SAME_POINT))  # y is the line's first emitter
        si1 = scene.intersect(so, d, on)
        wo1, w1, on = self._refract(si1, d, on)
        si2 = scene.intersect(scene.spawn(si1, wo1), wo1, on)
        wo2, w2, on = self._refract(si2, wo1, on)
        si3 = scene.intersect(scene.spawn(si2, wo2), wo2, on)
        le = scene.eval_emitter(si3, wo2, on, density=False)[0]
        w = power_heuristic(es.pdf, pdf_b)
        value = f * w1 * w2 * le * (w / es.pdf)
        return dr.select(on & (es.pdf > 0.0), value, 0.0)

    def weight(self, g: GlassState, si, hit_emitter: Bool) -> tuple[Bool, Float]:
        """``(lanes, w)``: the lanes of ``hit_emitter`` whose path reached the emitter hit
        ``si`` through two refractions since its last smooth vertex, and the BSDF sample's
        MIS weight there against the through-glass technique."""
        lanes = hit_emitter & si.valid & (g.k == 2)
        p, _ = self.line_density(g.x, g.d, lanes)
        return lanes, power_heuristic(g.pdf, p)

    @staticmethod
    def step(g: GlassState, smooth: Bool, delta: Bool, si, d_in: Array3f, wo: Array3f, bs) -> GlassState:
        """The state after a vertex at ``si`` (ray ``d_in`` in, ``wo`` out, sample ``bs``):
        a smooth vertex (``smooth``: its material is not delta-only) that sampled a
        non-Dirac lobe starts it afresh; a refraction at a delta-only material (``delta``)
        counts one more; anything else makes it no through-glass path."""
        fresh = smooth & ~bs.delta
        refracts = delta & (dr.dot(wo, si.ng) * dr.dot(d_in, si.ng) > 0.0) & (g.k < 2)
        k = dr.select(fresh, 0, dr.select(refracts, g.k + 1, UInt32(NONE)))
        return GlassState(dr.select(fresh, si.p, g.x), dr.select(fresh, wo, g.d),
                          dr.select(fresh, bs.pdf, g.pdf), UInt32(k))


__all__ = ["GlassNEE", "GlassState", "KINDS", "NONE", "applies"]
