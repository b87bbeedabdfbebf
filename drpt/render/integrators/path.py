"""Unidirectional path tracing with next-event estimation and MIS.

At every vertex the path gathers light two ways: one emitter chosen by the
scene's light selection (an emissive triangle or sphere, a delta light or the
sky) and a direction toward it (next-event estimation, one shadow ray:
:meth:`~drpt.render.scene.DeviceScene.sample_emitter`), and the emitter or sky
the next BSDF-sampled ray happens to hit
(:meth:`~drpt.render.scene.DeviceScene.eval_emitter`). Both estimates are
weighted by the power heuristic, so glossy and diffuse surfaces, small and large
lights are all handled without fireflies from the "wrong" strategy. Both densities
are seen from the vertex itself (:attr:`PathState.ref_p`, :func:`sees_from_vertex`),
not from the next ray's origin, which :mod:`~drpt.render.spawn` moved off the surface.

Depth follows Mitsuba's ``path`` integrator: ``max_depth = 1`` shows only
directly visible emitters, ``2`` adds direct lighting, ``-1`` is unbounded
(Russian roulette ends paths); ``hide_emitters`` (Mitsuba's) drops what the
camera ray itself sees of emitters and the sky, and continues it past the area
emitters it hits (:func:`skip_hidden_emitters`): the camera sees what lies behind
an area light. Russian roulette starts once ``depth >=
rr_depth``: by default a path continues with probability
``min(max(throughput), 0.95)``; with ``rr_prob`` set (the seed's
``-RR_cutdown``) it continues with that fixed probability. Before ``rr_depth`` a path
whose throughput is below ``rr_threshold`` (drpt's own formats; 0, Mitsuba's rule alone,
for a Mitsuba XML scene) continues with probability ``max(throughput) / rr_threshold``:
a path off a dark surface (a tyre, a car's interior) stops early unless it survives, where
its few percent of the light cost a full bounce's queries. Surviving paths are
divided by the probability, so no choice adds bias. As in Mitsuba, the
adaptive probabilities use the throughput times ``eta^2`` (the relative IORs
crossed), so paths inside glass are not killed for their radiance scaling.

Delta lobes (glass, mirrors) have nothing to evaluate: next-event estimation
contributes nothing there and the emitter their ray hits counts in full
(``prev_delta``), except after two smooth refractions where the scene has next-event
estimation through glass (:mod:`~drpt.render.integrators.glass`, :attr:`PathIntegrator.glass_nee`:
an occluded shadow ray followed through a glass body, and MIS between it and the BSDF
sample that passes the glass; :attr:`PathState.glass`); in a scene that also has smooth materials the estimate runs in a
symbolic ``if`` on the lanes off delta-only materials, so that a packet on mirrors and glass
skips it. A scene of only delta materials traces no NEE code, and its
paths are *pixel-coherent* (:attr:`PathIntegrator.pixel_coherent`): the renderer
gives each sample its own lane, so a SIMD packet holds one pixel's nearly identical
paths, and the first bounce's ray queries ask for coherent traversal, not only the camera's.

Two entry points run the same bounce (:meth:`PathIntegrator.bounce`,
``bounce(scene, state, rng) -> state``, the loop state a :class:`PathState`;
public, so that the wavefront integrator's fused tail runs it too):
``sample`` traces one path per lane; ``sample_sequence``, which the renderer
uses, traces several per lane one after another (path regeneration) and
returns their sums. Both tell the scene's instrument
(:mod:`drpt.render.instrument`), if any, about the paths and every bounce.
Every question about the scene goes to the
:class:`~drpt.render.scene.DeviceScene`; its feature flags decide at trace
time which estimators are compiled.

Short paths are written out ("unrolled"): with ``0 < max_depth <=``
:data:`UNROLLED_MAX_DEPTH` (and no instrument attached) a path is its camera ray,
``max_depth - 1`` full vertices (:meth:`PathIntegrator.bounce`, one after another in
straight-line code, no symbolic loop) and a last segment that only looks for what
it can see (:meth:`PathIntegrator.last_segment`): the emitter it hits or the sky it
escapes to, with no next-event estimation, BSDF sample or roulette, which the loop
computes there and throws away. Straight-line code also lets Dr.Jit drop what nothing
reads: the last hit's shading frame and texture lookups, and, where the last segment
can see nothing at all (:func:`nothing_seen`: no emissive surface, no sky or
background; e.g. direct lighting by point, spot or projector lights), the last
BSDF sample and the last ray. Every lane traces its camera ray in the same Embree
query (coherent for the whole packet), on the lanes whose ray reaches a box around a shape
(:attr:`PathIntegrator.cull`); a vertex makes its random numbers and, without emissive
surfaces, its hit's interaction inside its branch (:attr:`PathIntegrator.deferred`), so a
packet of escaped rays pays for neither; the bounce loop's vertices do the same where a lane
traces one path (:attr:`PathIntegrator.loop_branched`). Where a shape is convex, the later rays (and, in
scenes of mirrors only, the loop's) cull likewise, the box of the convex shape they leave left
out (:attr:`PathIntegrator.cull_leaving`). The estimator is the loop's and draws the same
random numbers for a path's live vertices, so one path per lane (:meth:`sample`) gives
the loop's image; :meth:`sample_sequence`'s later paths start at other points of a
PCG32 stream (the loop also draws at its last vertex), so their images differ by noise.
:attr:`PathIntegrator.unrolled` False keeps the loop (A/B measurements).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass

import drjit as dr
from drjit.auto import PCG32, Array3f, Array3f64, Bool, Float, UInt32

from ...accel.boxes import NO_BOX
from ...accel.protocol import INVALID, Hit
from ...options import PathOptions
from ..bsdf import BSDFSample
from ..loops import loops_once
from ..sampler import light_sample, next_2d, next_path, skip_draws
from ..scene import DeviceScene
from .common import DirectLight, power_heuristic
from .glass import GlassNEE, GlassState, applies

#: with :attr:`PathIntegrator.pixel_coherent`, the deepest ray (the camera's is depth 0) whose
#: query asks for Embree's coherent traversal: a pixel's samples leave the first mirror or glass
#: surface nearly parallel, and spread after the next curved one, where the coherent traversal
#: costs more than the default (docs/performance.md, "Coherent queries of mirror and glass
#: paths")
COHERENT_DEPTH = 1

#: the largest ``max_depth`` whose paths are traced as straight-line code (``0 < max_depth``)
UNROLLED_MAX_DEPTH = 3
#: the random numbers a vertex draws from a PCG32 (:meth:`PathIntegrator.bounce`): light
#: selection 1, light point 2, BSDF lobe 1, direction 2, roulette 1
VERTEX_DRAWS = 7


@dataclass
class PathState:
    """One path per lane, as the bounce loop carries it (a Dr.Jit loop state)."""

    o: Array3f  # origin of the next ray
    d: Array3f  # its unit direction
    L: Array3f  # radiance gathered so far
    beta: Array3f  # throughput: product of BSDF weights (and 1 / RR probabilities)
    eta: Float  # product of the relative IORs crossed (for Russian roulette)
    depth: UInt32  # segments traced
    prev_pdf: Float  # BSDF density of the direction d (MIS of the emitter it hits)
    prev_delta: Bool  # d came from a delta lobe (or the camera): no MIS
    active: Bool
    #: the path's last vertex, where ``d`` left from and next-event estimation sampled from:
    #: the point the density of the emitter ``d`` hits is seen from (MIS); ``None`` where
    #: that density does not depend on the point (:func:`sees_from_vertex`)
    ref_p: Array3f | None = None
    #: what the through-glass weight reads (:mod:`~drpt.render.integrators.glass`); ``None``
    #: where the scene has no such technique (:meth:`PathIntegrator.glass_nee`)
    glass: GlassState | None = None
    #: per lane, the box of the convex shape the ray ``d`` leaves outward, which its query
    #: leaves out (:attr:`PathIntegrator.cull_leaving`, :meth:`ShapeBoxes.leaving
    #: <drpt.accel.boxes.ShapeBoxes.leaving>`); ``None`` where the scene's queries do not cull
    leave: UInt32 | None = None


def _zero_sums(Sum: type, n: int, moment: bool) -> tuple:
    """:func:`bank`'s sums at zero: of samples, of their squares, with ``moment`` too of
    their channels' products."""
    return tuple(dr.zeros(Sum, n) for _ in range(2 + moment))


def bank(sums: tuple, dropped: UInt32, L: Array3f, Sum: type) -> tuple[tuple, UInt32]:
    """``sums`` (of samples; when there are two or three, of their squares and of the
    products of their channels ``(rg, rb, gb)``, each of type ``Sum``) with the path's
    radiance ``L`` added where it is finite, and ``dropped`` counting the lanes where it is not."""
    finite = dr.isfinite(L.x) & dr.isfinite(L.y) & dr.isfinite(L.z)
    L = Sum(dr.select(finite, L, 0.0))
    out = (sums[0] + L,)
    if len(sums) > 1:
        out += (sums[1] + L * L,)
    if len(sums) > 2:
        out += (sums[2] + Sum(L.x * L.y, L.x * L.z, L.y * L.z),)
    return out, dropped + dr.select(finite, 0, 1)


def nothing_seen(scene: DeviceScene) -> bool:
    """Whether a ray can see nothing in ``scene`` (read at trace time): no emissive
    surface, no background color and no emitter at infinity, the only things
    :meth:`~drpt.render.scene.DeviceScene.eval_emitter` returns radiance for. Then a
    path's last segment adds nothing and is not traced."""
    emits = getattr(scene.materials, "has_emission", True)
    infinite = any(f.infinite and not f.delta for f in scene.emitter_selection.families)
    return not (emits or scene.has_background or infinite)


def sees_from_vertex(scene: DeviceScene) -> bool:
    """Whether the density MIS weighs an emitter hit with depends on the point it is seen
    from (read at trace time): next-event estimation with emissive surfaces (an area
    density's distance, a triangle's solid angle, a sphere's cone) or a light selection
    that varies in space (:attr:`~drpt.render.lights.LightSelection.static` False). The
    path state then carries its last vertex (:attr:`PathState.ref_p`), the point next-event
    estimation sampled from: the next ray starts at that point moved off its surface
    (:mod:`~drpt.render.spawn`), and a density seen from there would weigh the two
    techniques by different points (far from the origin, where the offset is a sizable
    fraction of a light's distance, their weights no longer sum to 1). Elsewhere (only
    delta lights, the sky) nothing is carried."""
    if not (scene.has_emitters and scene.has_smooth_bsdfs):
        return False
    return getattr(scene.materials, "has_emission", True) or not scene.emitter_selection.static


def coherent_shadows(scene: DeviceScene) -> bool:
    """Whether the shadow rays of next-event estimation at the camera rays' hits are traced as
    coherent queries (read at trace time): where no emitter at infinity but delta ones (a
    directional light) can be chosen. Such rays start at nearby points toward a light's few
    points (a point, spot or area light), or are parallel, and Embree's coherent traversal is
    faster for them; toward an environment map or a sky their directions spread over the
    sphere, and it is slower (docs/performance.md measures both). The answer is the same."""
    return not any(f.infinite and not f.delta for f in scene.emitter_selection.families)


class PathIntegrator:
    #: trace paths of ``0 < max_depth <= UNROLLED_MAX_DEPTH`` as straight-line code
    #: (the module docstring); False: always the bounce loop (for A/B comparisons)
    unrolled = True
    #: the unrolled path's vertices and last segment run in symbolic ``if`` statements on
    #: their live lanes (:meth:`bounce`'s ``branch``, :meth:`last_segment`); False:
    #: straight-line, masked (for A/B comparisons)
    branched = True
    #: the vertices of the bounce loop without restarts (:meth:`_loop_single`) run in a
    #: symbolic ``if`` on their live lanes as the unrolled path's do (:meth:`bounce`'s
    #: ``branch``): a packet, one pixel's samples, whose rays all escaped skips the vertex.
    #: False: masked straight-line code (A/B comparisons)
    loop_branched = True
    #: the unrolled path's last segment looks for a few emissive triangles first, then traces
    #: a shadow ray up to the one it hits or to the sky, where they, the sky and the background
    #: are all a ray can see (:attr:`emitters_first`); False: the closest hit (A/B comparisons)
    emitter_first = True
    #: in the unrolled path's vertex branches (:attr:`branched`), what only the branch's lanes
    #: use is made in the branch: the vertex's PCG32 draws (the stream moved past them in one
    #: step before it, :func:`~drpt.render.sampler.skip_draws`) and, where nothing before the
    #: branch reads more of the hit than whether there is one (no emissive surfaces), its
    #: interaction (position, normals, material). A packet whose rays all escaped makes
    #: neither; the image is the same bit for bit. False: both before the branch (A/B)
    deferred = True
    #: the unrolled path's camera rays are tested against boxes around the shapes before the
    #: accelerator's query, which only the lanes reaching one run
    #: (:meth:`~drpt.render.scene.DeviceScene.intersect_preliminary`'s ``cull``): the same
    #: hits. False: every camera ray queries the accelerator (A/B)
    cull = True
    #: next-event estimation through glass where the scene needs it (:attr:`glass_nee`);
    #: False: not traced (A/B comparisons, the tests' reference)
    through_glass = True

    def __init__(self, scene: DeviceScene, options: PathOptions):
        self.scene = scene
        self.direct = DirectLight(scene)
        self.opt = options

    @property
    def glass_nee(self) -> GlassNEE | None:
        """Next-event estimation through glass (:mod:`~drpt.render.integrators.glass`) where
        the scene needs it and this class's own bounce traces the paths (read at trace time;
        :func:`~drpt.render.integrators.glass.applies`), else None."""
        own = type(self).bounce is PathIntegrator.bounce
        return GlassNEE(self.scene) if self.through_glass and applies(self.scene, self.opt, own) else None

    @property
    def straight(self) -> bool:
        """Whether paths are traced unrolled (:attr:`unrolled`, a short fixed depth, and no
        instrument, which counts the loop's bounces). A subclass with a bounce of its own
        (volpath: media along every segment, the last one too) keeps the loop."""
        return (self.unrolled and type(self).bounce is PathIntegrator.bounce
                and 0 < self.opt.max_depth <= UNROLLED_MAX_DEPTH and self.scene.instrument is None)

    @property
    def pixel_coherent(self) -> bool:
        """Whether a pixel's paths follow nearly the same surfaces (read at trace time): a
        scene without smooth BSDFs (every vertex a mirror, smooth conductor or glass) traced
        by this class's own bounce (volpath has a rule of its own for its media:
        :attr:`VolPathIntegrator.pixel_coherent <drpt.render.integrators.volpath.VolPathIntegrator.pixel_coherent>`).
        Path lengths then vary
        from pixel to pixel far more than between one pixel's samples, so the renderer gives
        each of a pixel's samples its own lane (:meth:`~drpt.render.renderer.Renderer.render_pass`):
        a SIMD packet's lanes trace one pixel's nearly identical paths and end together, and
        the first bounce's ray queries, not only the camera's, ask for coherent traversal
        (Embree's packet traversal; the same hits, in less time: :data:`COHERENT_DEPTH`)."""
        return not self.scene.has_smooth_bsdfs and type(self).bounce is PathIntegrator.bounce

    def coherent_queries(self, depth):
        """Where a ray of ``depth`` (an ``int`` or the lanes' ``UInt32``; the camera's is 0)
        asks Embree for coherent traversal: the camera's rays, and with :attr:`pixel_coherent`
        the rays to :data:`COHERENT_DEPTH` (a packet's lanes are one pixel's samples)."""
        return depth <= COHERENT_DEPTH if self.pixel_coherent else depth == 0

    @property
    def cull_leaving(self) -> bool:
        """Whether every ray query, not only the camera's, runs on the lanes whose ray reaches
        a shape's box (:attr:`cull`; read at trace time), the box of the convex shape a ray
        leaves outward left out (:attr:`PathState.leave`, :class:`ShadowQuery.skip
        <drpt.render.integrators.common.ShadowQuery>`): where some shape is convex or flat and the
        paths are pixel-coherent (mirrors, smooth conductors, glass only: the bounce loop's
        queries) or unrolled (:attr:`straight`: the vertices' queries, their shadow rays and
        the last segment's), or some shape is flat (a ground: the bounce loop's queries, whose
        rays off the ground mostly pass beside what stands on it). Rays off a mirror sphere that
        pass beside every other shape, the shadow rays and last rays off a lone sphere, and the
        rays off a ground toward the sky then skip the accelerator's query; the same answers
        (docs/performance.md, "Rays that leave a convex shape", "Rays that leave a ground")."""
        boxes = self.scene.boxes
        return (self.cull and boxes is not None and boxes.convex
                and (self.pixel_coherent or self.straight or boxes.flat))

    def unrolled_path(self, rng, state: PathState) -> Array3f:
        """The radiance of the paths starting at ``state`` (``max_depth`` segments at most),
        traced as straight-line code: ``max_depth - 1`` full vertices, then
        :meth:`last_segment`."""
        scene = self.scene
        for i in range(self.opt.max_depth - 1):
            state = self.bounce(scene, state, rng, branch=self.branched, camera=i == 0)
        return self.last_segment(scene, state)

    def last_segment(self, scene: DeviceScene, s: PathState) -> Array3f:
        """``s.L`` plus what the path's last ray (depth ``max_depth - 1``) sees: the
        emission it hits or the sky, as :meth:`bounce` adds it, without the vertex's
        next-event estimation and BSDF sample (a further segment would exceed
        ``max_depth``). Nothing is traced where the ray can see nothing (:func:`nothing_seen`).
        After a vertex (``max_depth > 1``) with :attr:`branched`, the segment runs in a symbolic
        ``if`` on the live lanes (label ``drpt_last``): a packet whose paths all ended skips
        its ray query."""
        if nothing_seen(scene):
            return s.L
        camera = self.opt.max_depth == 1

        def look(L):
            coherent = self.coherent_queries(self.opt.max_depth - 1)
            hit = scene.intersect_preliminary(s.o, s.d, s.active, coherent=coherent, cull=camera and self.cull)
            si = scene.interaction(s.o, s.d, hit)
            if camera:
                si = skip_hidden_emitters(scene, self.opt, si, s, s.active)
            return (add_emission(scene, self.opt, si, s, L, s.active),)

        if self.emitters_first:
            look = functools.partial(self._look_at_emitters, scene, s)
        if camera or not self.branched:  # (every camera ray is live)
            return look(s.L)[0]
        return dr.if_stmt((s.L,), s.active, look, lambda L: (L,), label="drpt_last")[0]

    @property
    def emitters_first(self) -> bool:
        """Whether the unrolled path's last segment (after a vertex) looks for emitters first
        (:meth:`_look_at_emitters`) instead of finding its closest hit: read at trace time,
        with :attr:`emitter_first` on, where the emissive surfaces a ray can see are a few
        triangles (:attr:`~drpt.render.scene.DeviceScene.emissive`: no emissive sphere or
        plane, no more triangles than the backend compiles inline) or none, beside the sky
        and the background if any (a scene where the ray can see nothing traces no last
        segment at all: :func:`nothing_seen`)."""
        scene = self.scene
        if not (self.emitter_first and self.opt.max_depth > 1):
            return False
        return getattr(scene, "emissive", None) is not None or not getattr(scene.materials, "has_emission", True)

    def _look_at_emitters(self, scene: DeviceScene, s: PathState, L: Array3f) -> tuple[Array3f]:
        """``(L plus the emission the ray s.d sees,)``, found emitter first: the nearest
        emissive triangle along the ray (the scene's few, compiled inline; none where the
        scene has no emissive surface), then one shadow ray (any hit) up to it, or to
        infinity where the ray misses them and the scene has a sky or a background. The
        shadow ray up to an emitter ends where the ray crosses the emitter's plane moved
        toward ``s.o`` by the hit point's error bound ``p_error`` (:mod:`~drpt.render.spawn`'s
        offset, ``t - p_error / |cos|``): an occluder farther from the emitter than that bound
        (a few float spacings) blocks it, as the closest hit would find it first; there is no
        relative margin such as next-event estimation's
        :data:`~drpt.render.integrators.common.SHADOW_SHRINK`. Without a sky or background,
        a ray that misses every emitter (most rays, with a small light) traces nothing in
        the scene; with one, every ray traces its shadow ray, an any-hit query, which costs
        less than the closest hit it replaces (docs/performance.md, "The sphere scenes'
        last segment"), and a ray that nothing blocks sees the sky. The estimate is the
        closest hit's up to float rounding (the distance and barycentrics of another
        triangle test, and occluders within ``p_error`` of the emitter); without emissive
        surfaces, the same image bit for bit where the accelerator's any-hit and closest-hit
        queries agree on whether a ray hits (Embree's and drpt's BVH do)."""
        n = dr.width(s.active)
        sky = scene.has_background or any(f.infinite and not f.delta for f in scene.emitter_selection.families)
        if scene.emissive is not None:
            hit = scene.emissive.intersect(s.o, s.d, s.active)
        else:  # (no emissive surface: every ray misses them)
            hit = Hit(dr.full(Float, float("inf"), n), dr.full(UInt32, INVALID, n), dr.zeros(Float, n),
                      dr.zeros(Float, n), dr.zeros(Bool, n))
        near = s.active & hit.valid
        si = scene.interaction(s.o, s.d, hit)
        # (culled by the shapes the ray may reach: :attr:`cull_leaving`)
        occluded = scene.occluded if s.leave is None else functools.partial(scene.occluded, skip=s.leave)

        def before_emitter():  # (where the ray crosses the emitter's plane, less p_error)
            return si.t - si.p_error / dr.maximum(dr.abs(dr.dot(si.ng, s.d)), 1e-30)

        if not sky:
            si.valid = near & ~occluded(s.o, s.d, before_emitter(), near)
            return (add_emission(scene, self.opt, si, s, L, s.active),)
        if scene.emissive is not None:
            tmax = dr.select(near, before_emitter(), dr.largest(Float))
        else:
            tmax = dr.full(Float, dr.largest(Float), n)
        blocked = occluded(s.o, s.d, tmax, s.active, coherent=self.pixel_coherent)
        si.valid = near & ~blocked
        return (add_emission(scene, self.opt, si, s, L, s.active & ~blocked),)

    @loops_once
    def sample(self, rng: PCG32, o: Array3f, d: Array3f, active: Bool) -> Array3f:
        """Radiance arriving at ``o`` from direction ``-d``, one sample per lane (the bounce
        loop recorded once: :func:`~drpt.render.loops.loops_once`)."""
        state = self._start(o, d, Bool(active))
        if self.straight:
            return self.unrolled_path(rng, state)
        return self._loop_sample(rng, state)

    def _loop_branch(self) -> dict:
        """The keywords of :meth:`bounce` in a loop whose lanes do not restart:
        ``branch=True`` with :attr:`loop_branched` where the bounce is this class's (a
        subclass's own, volpath's, has no branch)."""
        own = type(self).bounce is PathIntegrator.bounce
        return {"branch": True} if self.loop_branched and own else {}

    @dr.syntax
    def _loop_sample(self, rng: PCG32, state: PathState) -> Array3f:
        """:meth:`sample` by the bounce loop."""
        scene = self.scene
        inst = scene.instrument
        if inst is not None:
            inst.paths(dr.width(state.active))
        branch = self._loop_branch()
        while state.active:
            if inst is not None:
                inst.bounce(state)
            state = self.bounce(scene, state, rng, **branch)
        return state.L

    @loops_once
    def sample_sequence(self, rng: PCG32, camera_ray: Callable, count: UInt32, wide: bool = False,
                        moment: bool = False, bounces: bool = False, single: bool = False) -> tuple:
        """``count`` paths per lane, one after another (path regeneration).

        A lane starts a path at ``camera_ray(rng) -> (o, d)`` or ``(o, d,
        weight)`` (a pixel filter's sample weight, the path's initial
        throughput; ``None`` for 1); when the path
        ends it adds the sample to its sums and starts the next one, until
        ``count`` are done. A SIMD packet of lanes therefore runs until its
        lanes' *total* work is done, instead of each bounce loop waiting for
        the packet's longest path (Russian roulette makes path lengths vary).
        Returns the sum of the samples, the sum of their squares (for the
        variance) and how many non-finite samples were dropped (counted, not
        added: there should be none). The sums are float32, or with ``wide``
        float64: samples are float32 and finite, but a sum of many (or a
        square) of radiance near the float32 maximum is not (the renderer
        traces a pass whose float32 sums overflowed again with ``wide``).
        With ``moment`` a fourth value follows: the sum of the products of
        each sample's channels ``(rg, rb, gb)`` (for second moments in other
        color spaces; without it the kernel has no such sum). With ``bounces`` the last
        value is the number of bounces the lane traced, its work (adaptive sampling's cost
        estimate, :mod:`drpt.render.adaptive`; without it the kernel has no such counter).
        ``single`` (the caller's promise that ``count`` is at most 1 on every lane: a lane per
        sample) traces the bounce loop without the code that starts a lane's next path, which
        a packet otherwise runs whenever one of its lanes ends its path; the sums are the same.
        The loops are recorded once (:func:`~drpt.render.loops.loops_once`:
        their state as wide as ``count``).
        """
        if self.straight:
            run = self._unrolled_sequence
        else:
            run = self._loop_single if single else self._loop_sequence
        return run(rng, camera_ray, UInt32(count), wide, moment, bounces)

    @dr.syntax
    def _loop_single(self, rng, camera_ray: Callable, left: UInt32, wide: bool, moment: bool,
                     bounces: bool) -> tuple:
        """:meth:`sample_sequence` by the bounce loop where ``left`` is 0 or 1: the lanes'
        paths, then their sums. A loop of its own rather than a switch in
        :meth:`_loop_sequence` that skips only the next path's start: banking inside that
        loop's branch traced 48 operations more and took 1-2% more time (docs/performance.md)."""
        scene = self.scene
        n = dr.width(left)
        o, d, *weight = camera_ray(rng)
        state = self._start(o, d, left > 0, *weight)
        Sum = Array3f64 if wide else Array3f
        steps = (dr.zeros(UInt32, n),) if bounces else ()
        inst = scene.instrument
        if inst is not None:
            inst.paths(dr.width(left))
        branch = self._loop_branch()
        while state.active:
            if inst is not None:
                inst.bounce(state)
            state = self.bounce(scene, state, rng, **branch)
            if bounces:
                steps = (steps[0] + 1,)
        sums, dropped = bank(_zero_sums(Sum, n, moment), dr.zeros(UInt32, n), state.L, Sum)
        return (sums[0], sums[1], dropped, *sums[2:], *steps)

    @dr.syntax
    def _loop_sequence(self, rng, camera_ray: Callable, left: UInt32, wide: bool, moment: bool,
                       bounces: bool) -> tuple:
        """:meth:`sample_sequence` by the bounce loop."""
        scene = self.scene
        n = dr.width(left)
        o, d, *weight = camera_ray(rng)
        state = self._start(o, d, left > 0, *weight)
        Sum = Array3f64 if wide else Array3f
        sums = _zero_sums(Sum, n, moment)
        dropped = dr.zeros(UInt32, n)
        steps = (dr.zeros(UInt32, n),) if bounces else ()
        inst = scene.instrument
        if inst is not None:
            inst.paths(dr.width(left))
        while left > 0:
            if inst is not None:
                inst.bounce(state)
            state = self.bounce(scene, state, rng)
            if bounces:
                steps = (steps[0] + 1,)
            if ~state.active & (left > 0):  # the path ended: bank it, start the next
                sums, dropped = bank(sums, dropped, state.L, Sum)
                left -= 1
                next_path(rng)
                o, d, *weight = camera_ray(rng)
                state = self._start(o, d, left > 0, *weight)
        return (sums[0], sums[1], dropped, *sums[2:], *steps)

    @dr.syntax
    def _unrolled_sequence(self, rng, camera_ray: Callable, left: UInt32, wide: bool, moment: bool,
                           bounces: bool) -> tuple:
        """:meth:`sample_sequence` with each path traced unrolled (:meth:`unrolled_path`):
        a loop over a lane's paths, one whole path per iteration. ``bounces`` counts
        ``max_depth`` per path."""
        n = dr.width(left)
        Sum = Array3f64 if wide else Array3f
        sums = _zero_sums(Sum, n, moment)
        dropped = dr.zeros(UInt32, n)
        steps = (dr.zeros(UInt32, n),) if bounces else ()
        while left > 0:
            o, d, *weight = camera_ray(rng)
            L = self.unrolled_path(rng, self._start(o, d, Bool(True), *weight))
            sums, dropped = bank(sums, dropped, L, Sum)
            if bounces:
                steps = (steps[0] + self.opt.max_depth,)
            left -= 1
            next_path(rng)
        return (sums[0], sums[1], dropped, *sums[2:], *steps)

    def _start(self, o: Array3f, d: Array3f, active: Bool, weight: Float | None = None) -> PathState:
        """A new path along the ray ``(o, d)``: no radiance, throughput
        ``weight`` (``None``: 1), IOR product 1, depth 0, and no MIS for what
        the first ray hits (as after a delta lobe)."""
        w = max(dr.width(active), dr.width(o), dr.width(d))
        beta = dr.full(Array3f, 1.0, w) if weight is None else Array3f(weight, weight, weight)
        return PathState(o=o, d=d, L=dr.zeros(Array3f, w), beta=beta,
                         eta=dr.full(Float, 1.0, w), depth=dr.zeros(UInt32, w),
                         prev_pdf=dr.full(Float, 1.0, w), prev_delta=dr.full(Bool, True, w),
                         active=Bool(active), ref_p=Array3f(o) if sees_from_vertex(self.scene) else None,
                         glass=GlassState.start(o, w) if self.glass_nee is not None else None,
                         leave=dr.full(UInt32, NO_BOX, w) if self.cull_leaving else None)

    def bounce(self, scene: DeviceScene, s: PathState, rng: PCG32, branch: bool = False,
               camera: bool = False) -> PathState:
        """One vertex of the path: the emission the ray sees, next-event
        estimation, BSDF sampling and Russian roulette. With ``branch`` (the unrolled
        path's vertices; the loop's where a lane traces one path, :attr:`loop_branched`)
        the vertex's shading, everything after the emission, runs in a
        symbolic ``if`` on the lanes whose path goes on (label ``drpt_vertex``): a SIMD
        packet whose rays all escaped or ended skips it. The vertex's random numbers are
        drawn in the loop's order (in the branch: :attr:`deferred`), so the image is the same
        either way. ``camera``: the rays are the camera's (the unrolled path's first vertex),
        whose query skips the rays passing beside every shape (:attr:`cull`)."""
        opt = self.opt
        nee = scene.has_emitters and scene.has_smooth_bsdfs
        coherent = self.coherent_queries(s.depth)
        leaving = s.leave is not None
        hit = scene.intersect_preliminary(s.o, s.d, s.active, coherent=coherent, cull=(camera and self.cull) or leaving,
                                          skip=s.leave)
        si = scene.interaction(s.o, s.d, hit)
        si = skip_hidden_emitters(scene, opt, si, s, s.active)

        # ---- emitter hit by the previous ray (or seen by the camera)
        glass = self.glass_nee if s.glass is not None else None
        through = None  # (a path through glass since its last smooth vertex: its MIS weight)
        if glass is not None:
            through = glass.weight(s.glass, si, scene.materials.is_emissive(si, s.active))
        L = add_emission(scene, opt, si, s, s.L, s.active, through)

        active = s.active & si.valid
        if opt.max_depth >= 0:
            active &= s.depth + 1 < opt.max_depth

        # ---- the vertex's random numbers: light selection and emitter, lobe, direction, roulette
        def draw(rng):
            u_sel = rng.next_float32()
            u_light = next_2d(rng)
            if nee:
                u_sel, u_light = light_sample(scene, rng, u_sel, u_light, active)
            return u_sel, u_light, draw_continue(rng)

        # in the branch, what only its lanes use is made there (:attr:`deferred`)
        deferred = branch and self.deferred
        start = skip_draws(rng, VERTEX_DRAWS) if deferred else None
        drawn = draw(rng) if start is None else None
        lazy = deferred and not getattr(scene.materials, "has_emission", True)

        def shade(L):
            u_sel, u_light, u_path = drawn if start is None else draw(start)
            hit_si = scene.interaction(s.o, s.d, hit) if lazy else si
            # ---- next-event estimation: one emitter, one shadow ray
            # (with it, the BSDF's sample: drawn in the same material dispatch as its value)
            sampled = None
            if nee:
                coherent_shadow = (s.depth == 0) if coherent_shadows(scene) else False
                L, *sampled = self._nee(scene, hit_si, s.beta, L, u_sel, u_light, u_path, active,
                                        coherent_shadow, glass)
            # ---- BSDF sampling and Russian roulette: continue the path
            wo, bs, beta, eta, depth, live = continue_path(scene, opt, hit_si, s, None, u_path, sampled)
            out = (scene.spawn(hit_si, wo), Array3f(wo), L, beta, eta, depth, Float(bs.pdf),
                   Bool(bs.delta), active & live) + ((Array3f(hit_si.p),) if carry else ())
            if glass is not None:
                delta = active & scene.materials.is_delta(hit_si)
                out += (GlassNEE.step(s.glass, active & ~delta, delta, hit_si, s.d, wo, bs),)
            if leaving:
                out += (scene.boxes.leaving(hit_si.prim, hit_si.ng, Array3f(wo), active),)
            return out

        carry = s.ref_p is not None  # (the vertex the next hit's density is seen from)
        if branch:
            def skip(L):
                return (Array3f(s.o), Array3f(s.d), L, Array3f(s.beta), Float(s.eta), s.depth + 1,
                        Float(s.prev_pdf), Bool(s.prev_delta), Bool(False)) + ((Array3f(s.ref_p),) if carry else ()) \
                    + ((s.glass,) if glass is not None else ()) \
                    + ((dr.full(UInt32, NO_BOX, dr.width(s.active)),) if leaving else ())

            out = dr.if_stmt((L,), active, shade, skip, label="drpt_vertex")
        else:
            out = shade(L)
        o, d, L, beta, eta, depth, prev_pdf, prev_delta, active, *rest = out
        return PathState(o=o, d=d, L=L, beta=beta, eta=eta, depth=depth, prev_pdf=prev_pdf,
                         prev_delta=prev_delta, active=active, ref_p=rest[0] if carry else None,
                         glass=rest[1 if carry else 0] if glass is not None else None,
                         leave=rest[-1] if leaving else None)


    def _nee(self, scene: DeviceScene, si, beta: Array3f, L: Array3f, u_sel: Float, u_light,
             u_path: tuple, active: Bool, coherent: Bool | bool = False, glass: GlassNEE | None = None) -> tuple:
        """``(L, wo, bs)``: ``L`` plus next-event estimation's MIS-weighted direct light at
        ``si`` (the random numbers already drawn), its shadow ray a coherent query on the
        lanes ``coherent`` (the vertices that camera rays hit), and the BSDF sample that
        continues the path (``u_path``'s lobe and direction numbers,
        :func:`draw_continue`), drawn in the same material dispatch as the BSDF's value
        toward the emitter (:meth:`DirectLight.emitter_query_sample`): each lobe kind
        reads its fields and textures once per vertex. In a scene with both delta-only
        and smooth materials the estimate runs in a symbolic ``if`` on the lanes whose
        material is not delta-only (label ``drpt_nee``): a packet whose lanes are all on
        mirrors or glass, where the estimate is zero, skips the emitter sample, the BSDF
        evaluation and the shadow ray, and samples only the delta-only materials' kinds
        (:meth:`~drpt.render.material.MaterialTable.specular`) in a symbolic ``if`` of its
        own (label ``drpt_specular``) on the active lanes of those materials. With ``glass``
        (:mod:`~drpt.render.integrators.glass`) a shadow ray that glass occludes is followed
        through it, in a symbolic ``if`` on those lanes (label ``drpt_glass_nee``)."""
        mats = scene.materials
        u_lobe, u_bsdf = u_path[0], u_path[1]
        mixed = getattr(mats, "mixes_delta", False)  # (the empty scene's stand-in has none)
        lanes = active & ~mats.is_delta(si) if mixed else active

        def estimate(L):
            if getattr(scene, "delta_each", None) is not None:  # (every delta light by its own shadow ray)
                L = L + beta * self.direct.delta_each(si, lanes, coherent)
            if glass is None:
                q, wo, bs = self.direct.emitter_query_sample(si, u_sel, u_light, u_lobe, u_bsdf, lanes,
                                                             mis=True, coherent=coherent)
                if self.cull_leaving:  # (the shadow ray leaving a convex shape: culled by the others)
                    q.skip = scene.boxes.leaving(si.prim, si.ng, q.d, lanes)
                return L + beta * q.resolve(scene), wo, bs
            es, f, pdf_b, q, wo, bs = self.direct.sample_and_query(si, u_sel, u_light, u_lobe, u_bsdf, lanes,
                                                                   mis=True, coherent=coherent)
            seen, blocked = q.resolve_blocked(scene)
            glassy = blocked & scene.glass_boxes.reach(q.o, es.wo)  # (the rays that may meet glass)

            def through(L):
                return (L + beta * glass.estimate(si, es, f, pdf_b, q.o, glassy),)

            L = dr.if_stmt((L,), glassy, through, lambda L: (L,), label="drpt_glass_nee")[0]
            return L + beta * seen, wo, bs

        if not mixed:
            return estimate(L)

        def specular(L):
            # the active lanes on delta-only materials (the others' paths end here): a
            # packet without one, e.g. of paths that escaped or ended, skips the sampling
            def draw():
                return mats.specular().sample(si, u_lobe, u_bsdf)

            def none():
                return Array3f(0.0, 0.0, 1.0), BSDFSample()

            return (L, *dr.if_stmt((), active & mats.is_delta(si), draw, none, label="drpt_specular"))

        return dr.if_stmt((L,), lanes, estimate, specular, label="drpt_nee")


def skip_hidden_emitters(scene: DeviceScene, opt: PathOptions, si, s, active: Bool | None):
    """``si`` with ``hide_emitters``' camera rays (depth 0, ``active`` lanes; ``None``:
    every lane) continued past the area emitters they hit
    (:meth:`~drpt.render.scene.DeviceScene.skip_area_emitters`), as Mitsuba's ``path``
    does: the camera sees what lies behind an area light. Traced only with
    ``hide_emitters`` in a scene with emissive surfaces. Shared by the megakernel and the
    wavefront integrator."""
    if not (opt.hide_emitters and scene.materials.has_emission):
        return si
    camera = s.depth == 0 if active is None else active & (s.depth == 0)
    return scene.skip_area_emitters(s.o, s.d, si, camera, coherent=True)


def add_emission(scene: DeviceScene, opt: PathOptions, si, s, L: Array3f, active: Bool | None,
                 through: tuple | None = None) -> Array3f:
    """``L`` plus what the ray ``s.d`` of path state ``s`` sees at ``si``: the
    emitter it hits (MIS-weighted against the previous BSDF sample unless that
    was a delta lobe), or the background and the sky it escapes to, times
    ``s.beta``. ``active`` masks the lanes (``None``: every lane is a live path).
    ``through``: ``(lanes, w)``, the lanes whose path reached the emitter through glass
    and their weight against next-event estimation through it
    (:meth:`~drpt.render.integrators.glass.GlassNEE.weight`). Shared by the megakernel and
    the wavefront integrator: one estimator."""
    nee = scene.has_emitters and scene.has_smooth_bsdfs
    seen = None if active is None else Bool(active)  # (None: every lane)
    if opt.hide_emitters:  # Mitsuba's hide_emitters: the camera sees no emitter or sky
        seen = s.depth > 0 if seen is None else seen & (s.depth > 0)
    # (zero where not seen; the density seen from the path's last vertex, where it carries one)
    le, pdf_l = scene.eval_emitter(si, s.d, seen, density=nee, ref=getattr(s, "ref_p", None))
    if not nee:
        return L + s.beta * le
    # MIS against next-event estimation (none after a delta lobe or the camera)
    w = dr.select(s.prev_delta, 1.0, power_heuristic(s.prev_pdf, pdf_l))
    if through is not None:
        w = dr.select(through[0], through[1], w)
    return L + s.beta * le * w


def draw_continue(rng) -> tuple:
    """:func:`continue_path`'s random numbers ``(u_lobe, u_bsdf, u_rr)``, in its order."""
    u_lobe = rng.next_float32()
    u_bsdf = next_2d(rng)
    return u_lobe, u_bsdf, rng.next_float32()


def continue_path(scene: DeviceScene, opt: PathOptions, si, s, rng: PCG32 | None, u: tuple | None = None,
                  sampled: tuple | None = None):
    """Sample the BSDF at ``si`` and play Russian roulette for path state ``s``
    (three random numbers: lobe, direction, roulette; drawn from ``rng``, or ``u``
    as :func:`draw_continue` drew them; ``sampled``: the BSDF's ``(wo, bs)`` already drawn
    from ``u``'s lobe and direction numbers). Returns ``(wo, bs, beta,
    eta, depth, live)``: the new direction and sample, the throughput (divided
    by the survival probability where roulette played), the product of relative
    IORs, the depth, and the lanes whose path goes on. Shared by the megakernel
    and the wavefront integrator."""
    u_lobe, u_bsdf, u_rr = draw_continue(rng) if u is None else u
    wo, bs = scene.sample_bsdf(si, u_lobe, u_bsdf) if sampled is None else sampled
    beta = s.beta * bs.weight
    eta = s.eta * bs.eta
    depth = s.depth + 1
    scaled = dr.max(beta) * dr.square(eta)  # (the throughput both roulette rules read)
    if opt.rr_prob is not None:
        q = Float(opt.rr_prob)
    else:
        q = dr.minimum(scaled, 0.95)
    rr_on = depth >= opt.rr_depth
    if opt.rr_threshold > 0.0:  # (before rr_depth: below the threshold only)
        early = scaled * (1.0 / opt.rr_threshold)
        q = dr.select(rr_on, q, early)
        rr_on |= early < 1.0
    survive = u_rr < q
    beta = dr.select(rr_on & survive, beta / q, beta)  # (q > 0 where a path survives)
    live = bs.valid & (~rr_on | survive) & (dr.max(beta) > 0.0)
    return wo, bs, beta, eta, depth, live
