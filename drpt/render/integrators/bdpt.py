"""Bidirectional path tracing (Veach 1997, ch. 10; pbrt-v4's ``BDPTIntegrator``).

Each lane traces one light subpath and one camera subpath (the camera sample of
its pixel) and combines them by every connection strategy ``(s, t)``: ``s``
vertices from the light subpath, ``t`` from the camera subpath (the camera
itself is camera vertex 0), a path of ``s + t - 1`` segments:

* ``s = 0``: the camera subpath hits an emissive triangle or sphere, or escapes to
  the sky or the background color;
* ``s = 1``: next-event estimation at a camera vertex (a point sampled on an
  area light as :meth:`~drpt.render.lights.area.AreaLights.sample` draws it for
  the path tracer, every point, spot and directional light, a sky direction);
* ``s >= 2, t >= 2``: a stored light vertex joined to a camera vertex by a
  shadow ray, only those that make a path of at most ``max_depth`` segments
  (:func:`connection_room`). In scenes without Dirac lobes each camera vertex is joined to
  one light vertex, chosen uniformly among them (:func:`choose_vertex`), its contribution
  multiplied by their number (each
  connection strategy's estimate keeps its expectation; the MIS weights count the
  connections' densities over :data:`CONNECTION_CHOICES`): one connection per camera
  vertex instead of one per pair costs fewer shadow rays and BSDF evaluations than it
  adds variance. With glass or mirrors (:attr:`BDPTIntegrator.one_connection` false)
  every pair is joined, in an inner loop;
* ``t = 1``: a light vertex joined to the pinhole camera and splatted at the
  pixel it projects to (:class:`~drpt.render.film.SplatFilm`), as light tracing
  (:mod:`~drpt.render.integrators.ptracer`) does. ``(s, t) = (1, 1)`` is not
  used (emitters the camera sees come from ``s = 0`` with weight 1), as in pbrt.

**Caustic merging** (:attr:`BDPTIntegrator.merging`, ``--bdpt-merge on|off``, on by default).
A path camera S+ D S+ area light (a caustic seen through glass or in a mirror: its one
non-Dirac vertex D has Dirac vertices on both sides) has no connection or splat: only ``s =
0``, the camera subpath hitting the light, samples it, as the path tracer does, and with a
small light rarely (fireflies). With merging these paths, and only these, are estimated by
vertex merging instead, a partition of the path space (the other paths' strategies and MIS
weights are unchanged, and ``s = 0`` had weight 1 on these):

* before each pass, ``N`` light subpaths of a stream of their own leave the area lights and
  follow Dirac vertices to their first non-Dirac vertex; where at least one Dirac vertex came
  first they store a caustic photon there (:meth:`BDPTIntegrator.trace_photons`: position,
  direction back, throughput), kept in a hash grid (:class:`~drpt.render.photons.PhotonGrid`);
* the camera subpath's first non-Dirac vertex, when Dirac vertices precede it, adds ``beta
  sum_p f(wi, wo_p) power_p / (pi r^2 N)`` over the photons within ``r`` whose paths fit in
  ``max_depth`` segments (``f`` without its cosine; :meth:`BDPTIntegrator._merge`);
* the camera subpath's area-light hits whose path is camera S+ D S+ light count 0 (it
  tracks where it is in that pattern), unless it sampled a Dirac lobe at D (plastic's
  coating, a mask's pass-through: merging evaluates D's smooth lobes only, so ``s = 0``
  keeps those paths); each path is counted by exactly one of the two.

``r`` is :data:`MERGE_RADIUS` of the scene's bounding radius at the first sample per pixel
and shrinks by progressive photon mapping's rule (Knaus and Zwicker 2011, :data:`MERGE_ALPHA`)
over the samples per pixel, a pass merging at the mean of its samples' ``r^2``
(:meth:`BDPTIntegrator.merge_radius`: the same image whatever the lanes per pass), so the
estimate is consistent, not unbiased: at any finite spp it is the
caustic's irradiance blurred over disks of radius ``r`` (an ``O(r^2)`` bias where the caustic
is smooth, more at its edges and where another surface lies within ``r``). Scenes without
Dirac lobes or area lights trace none of it; the sky's and the background's caustics seen
through glass keep ``s = 0`` (delta lights' are sampled by no strategy, as in the path
tracer). The strategy images (``--bdpt-strategies``) and the one-strategy test hook
(:attr:`BDPTIntegrator.only`) render without merging.

**hide_emitters** (Mitsuba's): strategies ``(0, 2)`` (the camera sees an emitter, the sky or
the background) weigh 0, and, as in the path tracer, the camera ray passes through the area
emitters it hits (:meth:`~drpt.render.scene.DeviceScene.skip_area_emitters`), as does the
shadow ray of a ``t = 1`` splat: the camera sees what lies behind an area light, lit by it.

The light subpath starts as light tracing's: a source chosen uniformly among
the scene's emitters (:class:`~drpt.render.lights.rays.EmitterRays`), a point
and a direction on it (with a low-discrepancy sampler the source and an area light's
primitive are picked with the point's pair, so the points stay stratified over all of
them); it carries importance (refraction's ``eta^2`` undone, Veach's shading-normal
correction). Its surface vertices that are not pure
Dirac (mirror, smooth glass) are stored in per-lane local arrays
(``dr.alloc_local``, one per field) of ``max_depth - 1`` entries; the camera
subpath then runs as a Dr.Jit loop, and each of its non-Dirac vertices is
connected to one stored light vertex, or to each. Both subpaths play Russian
roulette after ``rr_depth`` segments: the camera subpath as the path tracer does
(probability ``min(max(beta) eta^2, 0.95)``), the light subpath on its throughput relative
to the power it left its emitter with (:func:`light_survival`: a bright light's subpaths
are not kept to the last bounce, nor a dim light's cut at once); the MIS weights ignore
roulette (they still sum to 1 over the strategies of a path, so the estimate stays unbiased).

**Roulette on connections and splats.** A connection's or a ``t = 1`` splat's
MIS-weighted contribution is known before its shadow ray is traced; below a
threshold it is traced with probability ``q = min(1, max(value) / threshold)`` and
divided by ``q`` (:func:`roulette`: the same expectation, and no contribution is
scaled above the threshold, so no fireflies). Small contributions (low weights,
dim paths) then rarely cost a shadow ray and a splat: the shadow rays of connections,
splats and next-event estimation are traced inside a symbolic ``if``
(:func:`occluded_where`), so SIMD packets none of whose lanes kept one skip the query.
The threshold is :data:`ROULETTE_FRACTION` of the image's mean pixel value, which a pilot estimates
before the first pass (``Renderer._calibrate_bdpt``: the path tracer's one sample per
pixel of a band of rows, from a random stream of its own: the same expectation as bdpt's
at a fraction of its kernel's cost; :meth:`BDPTIntegrator.calibrate` rounds it to a power
of 2, so renders in other processes agree). The threshold depends only on the pilot's samples, so the
passes' estimate is unbiased given it.

**MIS weights.** The power heuristic over all strategies of a path, ``w_s =
p_s^2 / sum_i p_i^2``, computed as pbrt computes it (ratios of the forward and
reverse area densities along the path) but accumulated while the subpaths are
traced (Georgiev et al. 2012, "Implementing Vertex Connection and Merging",
whose BPT part this is): each subpath vertex carries two numbers, ``dvcm`` and
``dvc``, from which the sum over the strategies on its side of a connection
follows in O(1):

* at an emitter: ``dvcm = m(p_nee / p_emit)``, ``dvc = m(|cos_g| / p_emit)``
  (``0`` for a point, spot, projector or directional light: the camera cannot hit it), ``m(x) =
  x^2``, ``p_emit`` the light subpath's density of its origin and direction (source
  choice, area density, cosine density), ``p_nee`` next-event estimation's area
  density of the point (1 for delta lights, which it samples every time; 0 for the
  background color, which it does not sample). An infinite emitter (sky, background,
  directional light) has a direction's density for ``p_nee`` and a point on a disk
  of the scene's bounding radius ``R`` for ``p_emit`` (``1 / (pi R^2)``, as
  :class:`~drpt.render.lights.rays.EmitterRays` starts it), no cosine, and its
  first segment no distance to convert;
* at the camera: ``dvcm = m(A cos^3)``, ``dvc = 0`` (``A`` the film's area at
  distance 1: ``1 / (A cos^3)`` is the pixel sample's direction density times
  the ``W H`` light paths per sample per pixel);
* at each hit, from distance ``d`` and incoming geometric cosine ``c``:
  ``dvcm *= m(d^2 / c)``, ``dvc /= m(c)``;
* at each BSDF sample of density ``p`` (reverse density ``p_rev``, outgoing
  geometric cosine ``c_o``): ``dvc = m(c_o / p) (dvc m(p_rev) + dvcm)``, ``dvcm =
  m(1 / p)``; after a Dirac lobe ``dvc *= m(c_o)``, ``dvcm = 0`` (a strategy
  that would connect at that vertex does not exist).

A connection of light vertex ``y`` and camera vertex ``z`` then has weight ``1 /
(1 + w_l + w_c)`` with ``w_l = m(p_z(y)) (dvcm_y + dvc_y m(p_rev,y))``, ``p_z(y)``
the area density of ``y`` sampled from ``z``, and ``w_c`` likewise. The reverse densities
(``p_rev``) come with the evaluation or the sample that needs them, in the same dispatch over
the material kinds (:func:`eval_both`, :func:`sample_both`), not from a second one. Next-event
estimation and emitter hits use the same quantities. Spheres' next-event
estimation samples the cone they subtend; the weights use the uniform area
density the light subpath starts with for every strategy (as pbrt does): still
weights that sum to 1. :func:`mis_weights_reference` computes the same weights
pbrt's way, from a whole path's densities (the tests compare them). Where each camera
vertex is joined to one light vertex, the weights count the connections' densities over
:data:`CONNECTION_CHOICES`: the starting ``dvcm`` and ``dvc`` of both subpaths (the
terms of the strategies that are not connections) are multiplied by ``k =
m(CONNECTION_CHOICES)``, and the weights of those strategies divide their other
subpath's sum by ``k``. With a low-discrepancy sampler the weights count every strategy
with ``s >= 2`` (connections and splats) :data:`LD_LIGHT_SHARE` times against ``s = 0, 1``
(:attr:`BDPTIntegrator.share`): ``k = m(CONNECTION_CHOICES / share)`` (``m(1 / share)``
where every pair is joined), and the camera's starting ``dvcm`` and the splats' weights take
``k m(share)``; any such counts keep weights that sum to 1 (Veach's power heuristic over
``n_i p_i``).

**Limits.** The light subpath is stored, so paths are at most ``max_depth``
segments, and at most :data:`MAX_DEPTH`; ``max_depth = -1`` means
:data:`MAX_DEPTH` (with a warning). Pinhole perspective cameras only (the
``t = 1`` strategy needs the camera's importance). Emitters: emissive triangles
and spheres (textured too), point, spot (textured too), projector and directional
lights (a projector's direction density ``1 / (A cos^3)``: a point uniform on its image
plane of area ``A`` at distance 1), the sky and a background color. A light subpath's vertex is
evaluated in importance mode (rough transmission's radiance scaling undone:
:mod:`~drpt.render.integrators.ptracer`), a camera subpath's in radiance mode.

Debugging: with ``--bdpt-strategies`` (:class:`StrategyFilm`) every contribution is also
added to its strategy's image, as pbrt-v4 writes them.

Image: the renderer runs BDPT as it runs light tracing (a pass splats over the
whole image, :meth:`~drpt.render.renderer.Renderer._trace_light_pass`, one light
subpath per camera sample: ``W H`` per sample per pixel). The ``t = 1`` splats go
into one film, each camera sample's sum of the other strategies into a second one
at its own image position; the pixel is their sum over ``spp``, and the renderer
estimates the two parts' variances apart (a camera part's is that of a mean of
``spp`` samples, the splats' that of a light-traced image).
"""

from __future__ import annotations

import math

import drjit as dr
from drjit.auto import PCG32, Array2f, Array3f, Bool, Float, Int32, UInt32

from ...errors import DrptError
from ...options import PathOptions
from ..camera import RayCamera
from ..film import SplatFilm
from ..instrument import HIT_CAMERA, HIT_LIGHT, SHADOW_CAMERA, SHADOW_CONNECT, SHADOW_NEE, SPLAT, count
from ..lights.delta import in_light_frame
from ..lights.rays import INV_FOUR_PI, EmitterRays
from ..loops import loops_once
from ..photons import PhotonGrid
from ..sampler import LDSampler, next_2d
from ..scene import DeviceScene
from ..spawn import origin as spawn_origin
from ..surface import Interaction, TangentInteraction
from ..tables import gather
from ..warp import Frame, square_to_cosine_hemisphere, square_to_uniform_sphere
from .common import SHADOW_SHRINK
from .ptracer import camera_segment, correction, refuse_unsupported

#: the longest path BDPT traces (segments); its light vertices are stored per lane
MAX_DEPTH = 16

#: ``--bdpt-strategies`` writes an image per strategy of the paths of at most this many segments
STRATEGY_SEGMENTS = 5

#: the MIS weights count a connection strategy (``s, t >= 2``) as sampled with its
#: density over this (each camera vertex is joined to one of the stored light vertices,
#: about this many): the power heuristic over ``p_i / n_i`` (``n_i`` this for connections,
#: 1 for the others) still sums to 1 over the strategies of a path. Carried as a factor
#: ``k = m(CONNECTION_CHOICES)`` on the subpaths' starting ``dvcm``, ``dvc`` (the terms of
#: the strategies that are not connections) and ``1 / k`` on the weights of those
#: strategies (``nee_weight``, ``emission_weight``, the splat's ``connection_weight``)
CONNECTION_CHOICES = 2.0

#: connections and splats whose contribution is below this fraction of the image's mean
#: pixel value play Russian roulette (:func:`roulette`)
ROULETTE_FRACTION = 0.1

#: with a low-discrepancy sampler (``--sampler ldsampler``...), the camera subpath's first
#: dimension (the light subpath's take fewer: 5 at its emitter and 5 per vertex); the pixel
#: position takes 0 and 1
CAMERA_DIMENSION = 128

#: with a low-discrepancy sampler, the dimensions of each camera vertex: vertex ``k`` draws
#: from ``CAMERA_DIMENSION + (k - 1) * CAMERA_STRIDE`` on (next-event estimation, then the
#: connections: at most 5 + MAX_DEPTH - 1), its BSDF sample and roulette from the last
#: :data:`CAMERA_TAIL` of them, so that every sample of a pixel draws a bounce's decisions
#: from the same dimensions, however many light vertices its connections read
CAMERA_STRIDE = 32

#: the dimensions of a camera vertex's BSDF lobe, direction and Russian roulette
CAMERA_TAIL = 4

#: with a low-discrepancy sampler the MIS weights count every strategy that takes vertices
#: from the light subpath (``s >= 2``: the connections and the ``t = 1`` splats) as this many
#: samples against the camera subpath's own (``s = 0``, ``s = 1``: :attr:`BDPTIntegrator.share`):
#: a pixel's camera samples are stratified, so the strategies the camera subpath samples alone
#: have less variance than their densities say, while the splats that land in a pixel come from
#: the light subpaths of every pixel's samples, each sequence stratified over its own pixel's
#: only, so their number in it is about as random as with independent samples; 0.4 was the
#: best of 1, 0.5, 0.4, 0.33 and 0.25 on the Cornell box (docs/performance.md, "Light
#: subpaths counted less with a low-discrepancy sampler")
LD_LIGHT_SHARE = 0.4

# the worst case fits: the light subpath (its emitter and at most MAX_DEPTH - 1 vertices, 5
# dimensions each, after the pixel's 2) ends before the camera subpath's first dimension,
# and a camera vertex's next-event estimation and connections end before its tail
assert 2 + 5 * MAX_DEPTH <= CAMERA_DIMENSION
assert 5 + MAX_DEPTH - 1 <= CAMERA_STRIDE - CAMERA_TAIL

SUPPORTED_SOURCES = ("area", "point", "spot", "projector", "directional", "sky", "background")

#: caustic merging's radius at the first sample per pixel, as a fraction of the scene's bounding
#: radius (:meth:`BDPTIntegrator.merge_radius`)
MERGE_RADIUS = 0.01

#: progressive photon mapping's alpha (Knaus and Zwicker 2011): the squared radius of sample
#: step ``i + 1`` is step ``i``'s times ``(i + alpha) / (i + 1)``
MERGE_ALPHA = 2.0 / 3.0

#: caustic merging traces one photon subpath per this many camera samples of a pass: on the
#: glass Cornell box a quarter as many photons raised the error 1% and cut the CPU time 8%
#: (17% on the caustic scene, +1% error), a sixteenth raised the error 4% for no more time
#: saved (docs/performance.md)
PHOTON_SHARE = 4


def mis(x: Float) -> Float:
    """The power heuristic's ``x^2``."""
    return x * x


def eval_both(scene: DeviceScene, si: Interaction, wo: Array3f, importance: bool = False
              ) -> tuple[Array3f, Float, Float]:
    """``(f, pdf, pdf_rev)`` at ``si`` toward ``wo``: the BSDF value, its density of ``wo`` and
    the reverse density (of ``si.wi`` seen from ``wo``), which the MIS weights of a
    connection, a splat or next-event estimation read, in one evaluation
    (:meth:`~drpt.render.scene.DeviceScene.eval_bsdf_rev`); ``importance`` at a light
    subpath's vertex (the value in importance mode: rough transmission's radiance scaling
    undone)."""
    return scene.eval_bsdf_rev(si, wo, importance)


def prepare_both(scene: DeviceScene, si: Interaction):
    """:func:`eval_both` of ``si`` toward directions given later: the returned function of
    ``wo`` computes the same values, and what does not depend on ``wo`` (the fields, the
    shading frame) is traced once, here (:meth:`~drpt.render.scene.DeviceScene.prepare_bsdf_rev`):
    the loop joining a camera vertex to each light vertex prepares it outside the loop."""
    return scene.prepare_bsdf_rev(si)


def smooth_view(scene: DeviceScene) -> DeviceScene:
    """The scene as bdpt's BSDF evaluations see it: they all run at vertices whose material
    is not made only of Dirac lobes (the ``connectible`` ones: connections, splats,
    next-event estimation, merging), where a Dirac lobe evaluates to 0, so a view of the
    non-Dirac kinds (:meth:`~drpt.render.scene.DeviceScene.restricted`) gives the same values.
    With one such kind and one component per material (glass or mirrors beside one smooth
    kind) no lane gathers its kind nor branches on it; other scenes are returned as they are."""
    kinds = getattr(scene.materials, "kinds", ())
    smooth = [kind for kind in kinds if not scene.materials.lobes[kind].DELTA]
    return scene.restricted(smooth) if smooth and len(smooth) < len(kinds) else scene


def sample_both(scene: DeviceScene, si: Interaction, u_lobe: Float, u_bsdf: Array2f):
    """``(wo, bs, pdf_rev)``: a BSDF sample at ``si`` and its reverse density (of ``si.wi``
    seen from ``wo``, which :func:`scatter_update` reads), in one dispatch
    (:meth:`~drpt.render.scene.DeviceScene.sample_bsdf_rev`)."""
    return scene.sample_bsdf_rev(si, u_lobe, u_bsdf)


def scatter_update(dvcm: Float, dvc: Float, pdf: Float, pdf_rev: Float, cos_out: Float,
                   delta: Bool) -> tuple[Float, Float]:
    """The MIS quantities after a BSDF sample of density ``pdf`` (reverse ``pdf_rev``,
    outgoing geometric cosine ``cos_out``); a Dirac lobe (``delta``) cancels its own."""
    inv = dr.select(pdf > 0.0, dr.rcp(pdf), 0.0)
    dvc_new = dr.select(delta, dvc * mis(cos_out), mis(cos_out * inv) * (dvc * mis(pdf_rev) + dvcm))
    dvcm_new = dr.select(delta, 0.0, mis(inv))
    return dvcm_new, dvc_new


def segment_length2(si: Interaction, ref: Array3f) -> Float:
    """The squared length of a subpath's segment from its previous vertex ``ref`` (the true
    point: the emitter's sampled point, the camera's position, the last hit) to the hit
    ``si``. Not ``si.t``: the ray left from ``ref`` moved off its surface (the spawn offset,
    which grows with the coordinates' magnitude), while connections and next-event
    estimation measure their densities between the true vertices; converting the subpaths'
    densities to area measure by another length would make the MIS weights of the
    strategies not sum to 1."""
    return dr.squared_norm(si.p - ref)


def hit_update(dvcm: Float, dvc: Float, dist2: Float, cos_in: Float) -> tuple[Float, Float]:
    """The MIS quantities at a hit at squared distance ``dist2``, incoming geometric
    cosine ``cos_in``."""
    inv = dr.select(cos_in > 0.0, dr.rcp(cos_in), 0.0)
    return dvcm * mis(dist2 * inv), dvc * mis(inv)


def _term(p: Float, rest: Float) -> Float:
    """``m(p) * rest``, 0 where ``p`` is (a strategy that cannot sample the path, whatever
    ``rest`` overflowed to)."""
    return dr.select(p != 0.0, mis(p) * rest, 0.0)


def connection_weight(pdf_l: Float, dvcm_l: Float, dvc_l: Float, rev_l: Float,
                      pdf_c: Float, dvcm_c: Float, dvc_c: Float, rev_c: Float, k_l: float = 1.0) -> Float:
    """Weight of joining a light vertex to a camera vertex: ``pdf_l`` the area density of
    the light vertex sampled from the camera vertex, ``rev_l`` the light vertex's BSDF
    density toward its predecessor seen from the camera vertex (and the other way round);
    for the ``t = 1`` splat (``pdf_c = 0``) ``k_l`` is :attr:`BDPTIntegrator.k` (see
    :data:`CONNECTION_CHOICES`)."""
    wl = _term(pdf_l, dvcm_l + _term(rev_l, dvc_l)) / k_l
    wc = _term(pdf_c, dvcm_c + _term(rev_c, dvc_c))
    w = dr.rcp(1.0 + wl + wc)
    return dr.select(dr.isfinite(w), w, 0.0)


def nee_weight(pdf_bsdf: Float, pdf_light: Float, emit: Float, cos_c: Float, cos_l: Float,
               dvcm: Float, dvc: Float, rev: Float, k: float = 1.0) -> Float:
    """Weight of next-event estimation (``s = 1``) at a camera vertex: ``pdf_bsdf`` the
    BSDF's density toward the light point (0 for a delta light), ``pdf_light`` the point's
    density as a solid angle (for a delta light: ``dist^2``, its area density 1), ``emit``
    the light subpath's density of that point and direction, ``cos_c`` and ``cos_l`` the
    geometric cosines at the camera vertex and the light, ``rev`` the BSDF's density
    toward the camera vertex's predecessor seen from the light; ``k``:
    :attr:`BDPTIntegrator.k`."""
    wl = mis(pdf_bsdf / pdf_light)
    wc = _term(emit * cos_c / (pdf_light * cos_l), dvcm + _term(rev, dvc)) / k
    w = dr.rcp(1.0 + wl + wc)
    return dr.select(dr.isfinite(w), w, 0.0)


def emission_weight(pdf_nee: Float, emit: Float, dvcm: Float, dvc: Float, k: float = 1.0) -> Float:
    """Weight of a camera subpath hitting an emitter (``s = 0``) after at least one
    bounce: ``pdf_nee`` next-event estimation's area density of the point, ``emit`` the
    light subpath's density of it and of the direction back along the ray; ``k``:
    :attr:`BDPTIntegrator.k`."""
    w = dr.rcp(1.0 + _term(pdf_nee, dvcm) + _term(emit, dvc) / k)
    return dr.select(dr.isfinite(w), w, 0.0)


def connection_room(k: UInt32, depth: int) -> UInt32:
    """How many of the stored light vertices camera vertex ``k`` (the camera is vertex 0)
    can be joined to within a path of at most ``depth`` segments: light vertex ``j`` has a
    subpath of at least ``j + 1`` segments, and joined to camera vertex ``k`` it makes a path
    of ``depth_j + k + 1``, so only ``j < depth - k - 1`` can (the later ones, always too
    long, cost a BSDF evaluation each, and with one vertex chosen they would be chosen in
    vain)."""
    return dr.select(k + 1 < depth, UInt32(depth) - k - 1, 0)


def choose_vertex(u: Float, stored: UInt32, room: UInt32) -> tuple[UInt32, UInt32]:
    """The light vertex a camera vertex is joined to: index ``i`` uniform among the first
    ``m = min(stored, room)`` stored ones (by ``u``), and ``m``, the inverse of its
    probability, by which the connection's contribution is multiplied (``m = 0``: none)."""
    m = dr.minimum(stored, room)
    return dr.minimum(UInt32(u * Float(m)), dr.maximum(m, 1) - 1), m


def light_survival(beta: Array3f, power: Float, eta: Float) -> Float:
    """The light subpath's Russian roulette: the probability of going on, ``min(max(beta) /
    power * eta^2, 0.95)``, its throughput relative to ``power``, the largest channel of its
    throughput as it left the emitter. The path tracer's rule on ``max(beta)`` alone would
    read the light's radiometric scale (a subpath from a light of radiance 10 would survive
    at 0.95 to the last bounce, one from a dim light would die at once); relative to the
    emitted power it reads what the surfaces reflected, as the camera subpath's does."""
    rel = dr.select(power > 0.0, dr.max(beta) / power, 0.0)
    return dr.minimum(rel * dr.square(eta), 0.95)


@dr.syntax
def occluded_where(scene: DeviceScene, o: Array3f, d: Array3f, tmax: Float, active: Bool) -> Bool:
    """``scene.occluded`` for the ``active`` lanes, inside a symbolic ``if``: the LLVM
    backend compiles it to a branch taken only by SIMD packets with an active lane, so a
    shadow ray that few lanes need (a rouletted connection or splat, a light vertex
    beyond the path length) is not traced, masked, for every packet. False elsewhere."""
    hit = dr.zeros(Bool, dr.width(active))
    if active:
        hit = scene.occluded(o, d, tmax, active)
    return hit


def roulette(value: Array3f, ok: Bool, u: Float, threshold: Float) -> tuple[Array3f, Bool]:
    """Russian roulette on a contribution before its shadow ray is traced: kept with
    probability ``q = min(1, max(value) / threshold)`` (``u < q``) and divided by ``q``, so
    its expectation is unchanged; ``threshold = 0`` keeps every contribution as it is."""
    q = dr.select(threshold > 0.0, dr.minimum(dr.max(value) / threshold, 1.0), 1.0)
    ok = ok & (u < q)
    return dr.select(ok, value / dr.select(ok, q, 1.0), 0.0), ok


def mis_weights_reference(pdf_fwd: list[float], pdf_rev: list[float], delta: list[bool],
                          p_nee: float, light_is_delta: bool, n_light_paths: float = 1.0,
                          connection_scale: float = 1.0) -> list[float]:
    """The power-heuristic weights of every strategy ``s = 0 .. k`` of one path of ``k``
    segments, computed pbrt's way (plain floats, for the tests).

    Vertices ``x_0`` (on the light) .. ``x_k`` (the camera). ``pdf_fwd[i]``: area
    density of ``x_i`` sampled from the light side (``x_0``: the light subpath's origin
    density), ``pdf_rev[i]``: from the camera side (``x_k``'s is unused, ``x_{k-1}``'s
    includes the pixel density), ``delta[i]``: ``x_i`` scattered by a Dirac lobe;
    ``p_nee``: next-event estimation's area density of ``x_0``. Strategy ``s`` takes
    ``x_0 .. x_{s-1}`` from the light; ``s = 1`` samples ``x_0`` by ``p_nee``, ``s = k``
    (``t = 1``) is counted ``n_light_paths`` times, the connections (``2 <= s <= k - 1``)
    ``connection_scale`` times; ``s = k + 1`` (``t = 0``) and ``(1, 1)`` do not exist.
    Returns ``[w_0, .., w_k]``."""
    k = len(pdf_fwd) - 1

    def density(s):
        if s == 1 and k == 1:
            return 0.0  # (1, 1) is not used
        if s == 0 and light_is_delta:
            return 0.0
        p = 1.0
        for i in range(s):
            p *= (p_nee if s == 1 else pdf_fwd[0]) if i == 0 else pdf_fwd[i]
        for i in range(s, k):
            p *= pdf_rev[i]
        if s == k:
            p *= n_light_paths
        elif s >= 2:
            p *= connection_scale
        # a connection between x_{s-1} and x_s needs both to be non-Dirac
        if s >= 1 and (delta[s - 1] or delta[s]):
            return 0.0
        return p

    ps = [density(s) for s in range(k + 1)]
    total = sum(p * p for p in ps)
    return [p * p / total if total > 0 else 0.0 for p in ps]


def strategies(segments: int) -> list[tuple[int, int]]:
    """The ``(s, t)`` of paths of ``1 .. segments`` segments, in :class:`StrategyFilm`'s order
    (by length, then ``s``); ``(1, 1)`` is among them but never used."""
    return [(s, d + 2 - s) for d in range(segments) for s in range(d + 2)]


class StrategyFilm:
    """``--bdpt-strategies``: each strategy's weighted contributions, summed per pixel (the
    pixel containing the image position: no pixel filter), one image per ``(s, t)`` of
    :func:`strategies`. Their sum is the image (for paths of at most ``segments``)."""

    def __init__(self, width: int, height: int, segments: int):
        self.width, self.height, self.segments = width, height, segments
        self.count = segments * (segments + 3) // 2
        self.sum = [dr.zeros(Float, self.count * width * height) for _ in range(3)]

    def put(self, s, t, x: Float, y: Float, value: Array3f, active: Bool) -> None:
        W, H = self.width, self.height
        d = UInt32(s) + UInt32(t) - 2
        ix, iy = Int32(dr.floor(x)), Int32(dr.floor(y))
        ok = active & (d < self.segments) & (ix >= 0) & (ix < W) & (iy >= 0) & (iy < H)
        index = ((d * (d + 3)) // 2 + UInt32(s)) * (W * H) + UInt32(iy * W + ix)
        for c in range(3):
            dr.scatter_reduce(dr.ReduceOp.Add, self.sum[c], value[c], index, ok)

    def arrays(self):
        """The sums, ``(count, H, W, 3)`` float64."""
        import numpy as np

        dr.eval(self.sum)
        return np.stack([c.numpy() for c in self.sum], -1).reshape(
            self.count, self.height, self.width, 3).astype(np.float64)


class LightVertices:
    """The stored light-subpath vertices of each lane: one ``dr.alloc_local`` array per
    field, ``size`` entries."""

    def __init__(self, size: int, tangents: bool):
        self.size = size
        self.p = dr.alloc_local(Array3f, size)
        self.ng = dr.alloc_local(Array3f, size)
        self.ns = dr.alloc_local(Array3f, size)
        self.wi = dr.alloc_local(Array3f, size)
        self.uv = dr.alloc_local(Array2f, size)
        self.err = dr.alloc_local(Float, size)
        self.prim = dr.alloc_local(UInt32, size)
        self.material = dr.alloc_local(UInt32, size)
        self.beta = dr.alloc_local(Array3f, size)
        self.dvcm = dr.alloc_local(Float, size)
        self.dvc = dr.alloc_local(Float, size)
        self.depth = dr.alloc_local(UInt32, size)
        self.tangents = tangents
        if tangents:
            self.dp_du = dr.alloc_local(Array3f, size)
            self.dp_dv = dr.alloc_local(Array3f, size)

    def write(self, i: UInt32, si: Interaction, beta: Array3f, dvcm: Float, dvc: Float,
              depth: UInt32) -> None:
        self.p[i] = si.p
        self.ng[i] = si.ng
        self.ns[i] = si.ns
        self.wi[i] = si.wi
        self.uv[i] = Array2f(si.uv)
        self.err[i] = si.p_error
        self.prim[i] = si.prim
        self.material[i] = si.material
        self.beta[i] = beta
        self.dvcm[i] = dvcm
        self.dvc[i] = dvc
        self.depth[i] = depth
        if self.tangents:
            self.dp_du[i] = si.dp_du
            self.dp_dv[i] = si.dp_dv

    def read(self, i: UInt32, valid: Bool):
        fields = (Bool(valid), Float(0.0), self.p[i], self.ng[i], self.ns[i], self.prim[i],
                  self.material[i], self.wi[i], self.uv[i], self.err[i])
        si = (TangentInteraction(*fields, self.dp_du[i], self.dp_dv[i]) if self.tangents
              else Interaction(*fields))
        return si, self.beta[i], self.dvcm[i], self.dvc[i], self.depth[i]


class BDPTIntegrator:
    """Bidirectional path tracing over a :class:`~drpt.render.scene.DeviceScene` seen by a
    pinhole camera."""

    def __init__(self, scene: DeviceScene, rays: EmitterRays, camera: RayCamera, options: PathOptions,
                 merge: bool = True, low_discrepancy: bool = False):
        refuse_unsupported(scene, camera, "bidirectional path tracing (bdpt)")
        for kind, _ in rays.sources:
            if kind not in SUPPORTED_SOURCES:
                raise DrptError(f"bidirectional path tracing (bdpt) does not support {kind} lights: use the "
                                "path integrator")
        self.warnings: list[str] = []
        depth = options.max_depth
        if depth < 0:
            depth = MAX_DEPTH
            self.warnings.append(f"bdpt traces paths of at most {MAX_DEPTH} segments "
                                 f"(--max-depth -1 taken as {MAX_DEPTH})")
        elif depth > MAX_DEPTH:
            raise DrptError(f"bidirectional path tracing (bdpt) traces at most {MAX_DEPTH} segments: "
                            f"--max-depth {depth} is too deep")
        self.depth = depth
        self.scene = scene
        self.rays = rays
        self.camera = camera
        self.opt = options
        self.pick = 1.0 / rays.count if rays.count else 0.0
        # the order of DeltaLights.samples (and of the sources): points, spots, projectors, directionals
        self.deltas = [light for kind, light in rays.sources
                       if kind in ("point", "spot", "projector", "directional")]
        #: a test hook: ``(s, t)``, the one strategy that counts, with weight 1 (None: all,
        #: MIS-weighted); the image is then that strategy's unweighted estimate
        self.only: tuple[int, int] | None = None
        #: whether each camera vertex is joined to one light vertex (:func:`choose_vertex`),
        #: or to every one: in scenes with Dirac lobes (glass, mirrors) a connection can be the
        #: only strategy that samples a caustic path well, and choosing among the vertices
        #: multiplies such paths' contributions (rare fireflies that cost more than the
        #: connections saved)
        kinds = getattr(scene.materials, "kinds", ())
        self.one_connection = not any(scene.materials.lobes[kind].DELTA for kind in kinds)
        #: how many samples the MIS weights count each strategy that takes light-subpath
        #: vertices as, against the camera subpath's own: :data:`LD_LIGHT_SHARE` where the
        #: camera samples come from a ``low_discrepancy`` sampler, else 1
        self.share = LD_LIGHT_SHARE if low_discrepancy else 1.0
        #: the MIS weights' factor for connections: ``m(c / share)``, ``c`` =
        #: :data:`CONNECTION_CHOICES` with :attr:`one_connection`, else 1 (see
        #: :data:`CONNECTION_CHOICES`); the splats' weights and the camera subpath's starting
        #: ``dvcm`` take ``k m(share)`` (the splats counted ``share`` times, as the connections)
        self.k = mis((CONNECTION_CHOICES if self.one_connection else 1.0) / self.share)
        #: the scene seen by the BSDF evaluations of connections, splats, next-event estimation
        #: and merging (:func:`smooth_view`)
        self.smooth = smooth_view(scene)
        #: whether paths camera S+ D S+ area light are estimated by merging caustic photons
        #: (:meth:`photons`) instead of the camera subpath hitting the light: ``merge`` in
        #: scenes with Dirac lobes, area lights and a non-Dirac surface, else False (nothing
        #: of it traced)
        self.merging = (merge and not self.one_connection and scene.has_area_lights
                        and scene.has_smooth_bsdfs and any(kind == "area" for kind, _ in rays.sources))
        #: the contribution below which connections and splats play Russian roulette
        #: (:func:`roulette`; 0: none), set by :meth:`calibrate`; None before
        self.threshold: float | None = None
        self.has_sky = any(kind == "sky" for kind, _ in rays.sources)
        self.has_background = any(kind == "background" for kind, _ in rays.sources)
        #: a light subpath leaving an infinite emitter starts on a disk of the scene's
        #: bounding sphere's radius R, perpendicular to its direction: area density 1 / (pi R^2)
        self.disk_pdf = 1.0 / (math.pi * rays.radius * rays.radius)

    def calibrate(self, mean: float) -> None:
        """Set :attr:`threshold` from ``mean``, an estimate of the image's mean pixel value
        (luminance): :data:`ROULETTE_FRACTION` of it, rounded to a power of 2 (renders
        that estimate it in other processes, whose float sums differ in the last bits,
        still agree)."""
        t = ROULETTE_FRACTION * mean
        self.threshold = 2.0 ** round(math.log2(t)) if t > 0.0 and math.isfinite(t) else 0.0

    # ------------------------------------------------------------ emitter densities
    def _delta_emit(self, light, d: Array3f | None = None):
        """The light subpath's density of leaving a delta light: a point light's direction
        (uniform sphere), a spot's (uniform cone, textured or not), a directional light's
        origin (the disk), times the source's choice; a projector's direction ``d`` (unit,
        away from it: a point drawn uniformly on its image plane at distance 1, of area ``A``,
        is the direction density ``1 / (A cos^3)``, ``cos`` the angle to its axis), per lane."""
        if getattr(light, "fov_x", None) is not None:
            t = math.tan(math.radians(light.fov_x) / 2.0)
            plane = 4.0 * t * t / light.aspect
            cos = in_light_frame(light.frame, d)[2]
            return dr.select(cos > 0.0, self.pick / (plane * cos * cos * cos), 0.0)
        if getattr(light, "cutoff_angle", None) is not None:
            return self.pick / (2.0 * math.pi * (1.0 - math.cos(math.radians(light.cutoff_angle))))
        if getattr(light, "position", None) is None:
            return self.pick * self.disk_pdf
        return self.pick / (4.0 * math.pi)

    def origin_pdf(self, prim: UInt32, active: Bool) -> Float:
        """Area density of an emitter point on primitive ``prim`` as the light sampler draws
        it without a reference point (0 on non-emitters)."""
        lights = self.scene.area_lights
        pdf = lights.pdf_area(prim, active) if lights.has_triangles else Float(0.0)
        if lights.has_spheres:
            s = self.scene.surfaces
            is_sph = active & (prim >= lights.n_tri) & (prim < lights.n_tri + s.n_sph)
            j = dr.select(is_sph, prim - lights.n_tri, 0)
            prob = gather(Float, lights.sph_prob, j, is_sph)
            r = gather(Float, s.sph_r, j, is_sph)
            pdf = dr.select(is_sph, prob / (4.0 * dr.pi * r * r), pdf)
        return pdf

    # ------------------------------------------------------------ light subpath start
    def _emit(self, rng: PCG32, active: Bool, area_only: bool = False):
        """The light subpath's first ray: ``(o, d, p, beta, dvcm, dvc, infinite, valid)``
        (``p``: the emitter's sampled point, the vertex ``o`` was spawned from; ``infinite``:
        it leaves the directional light, the sky or the background); with ``area_only`` the
        lanes that chose another kind of source are not ``valid``."""
        rays, n = self.rays, dr.width(active)
        u_sel = rng.next_float32()
        u_pos = next_2d(rng)
        u_dir = next_2d(rng)
        ld = isinstance(rng, LDSampler)
        if ld:
            # the source (and an area light's primitive) from the stratified point's first
            # value, rescaled (sample reuse): the origins stay stratified over all the
            # emitters' surfaces; u_sel is left to the other kinds' own choices
            k, x = rays._select(u_pos.x)
            u_reuse, u_pos = u_sel, Array2f(x, u_pos.y)
        else:
            k, u_reuse = rays._select(u_sel)
        o = dr.zeros(Array3f, n)
        p = dr.zeros(Array3f, n)
        d = dr.full(Array3f, [0.0, 0.0, 1.0], n)
        beta = dr.zeros(Array3f, n)
        dvcm = dr.zeros(Float, n)
        dvc = dr.zeros(Float, n)
        infinite = dr.zeros(Bool, n)
        for i, (kind, light) in enumerate(rays.sources):
            if area_only and kind != "area":
                continue
            mine = active & (k == i)
            if kind == "area":
                u_area, u_point = self.scene.area_lights.reuse(u_pos, mine) if ld else (u_reuse, u_pos)
                ls = self.scene.area_lights.sample(u_area, u_point, mine)
                local = square_to_cosine_hemisphere(u_dir)
                di = Frame(ls.n).to_world(local)
                oi = spawn_origin(ls.p, ls.ng, ls.p_error, di)
                pi = ls.p
                emit = self.pick * ls.pdf_area * local.z / math.pi
                ok = mine & (emit > 0.0)
                inv = dr.select(ok, dr.rcp(emit), 0.0)
                bi = ls.le * (local.z * inv)
                vcm = self.k * mis(ls.pdf_area * inv)
                vc = self.k * mis(dr.abs(dr.dot(ls.ng, di)) * inv)
            elif kind in ("sky", "background"):
                # next-event estimation samples the sky's direction by the same density (the
                # background not at all); no cosine at an infinite emitter
                if kind == "sky":
                    w_sky, le, pdf = self.scene.sample_environment(u_dir, mine)
                else:
                    w_sky = square_to_uniform_sphere(u_dir)
                    le, pdf = Array3f(*map(float, self.scene.background)), Float(INV_FOUR_PI)
                di = -w_sky
                oi = rays._disk_origin(di, u_pos)
                pi = oi  # (not read: the first segment from infinity has no length)
                emit = self.pick * pdf * self.disk_pdf
                ok = mine & (emit > 0.0)
                inv = dr.select(ok, dr.rcp(emit), 0.0)
                bi = le * inv
                vcm = self.k * mis(pdf * inv) if kind == "sky" else Float(0.0)
                vc = self.k * mis(inv)
                infinite |= mine
            else:
                oi, di, w = rays._source_ray(kind, light, u_reuse, u_pos, u_dir, mine)
                pi = oi
                emit = self._delta_emit(light, di)
                bi = w * float(rays.count)
                vcm = (Float(self.k * mis(1.0 / emit)) if isinstance(emit, float)
                       else self.k * mis(dr.select(emit > 0.0, dr.rcp(emit), 0.0)))
                vc = Float(0.0)
                if kind == "directional":
                    infinite |= mine
            o = dr.select(mine, oi, o)
            p = dr.select(mine, pi, p)
            d = dr.select(mine, di, d)
            beta = dr.select(mine, bi, beta)
            dvcm = dr.select(mine, vcm, dvcm)
            dvc = dr.select(mine, vc, dvc)
        valid = active & (dr.max(beta) > 0.0)
        return o, d, p, beta, dvcm, dvc, infinite, valid

    # ------------------------------------------------------------ strategies
    def _weight(self, w: Float, s, t) -> Float:
        """The MIS weight ``w`` of strategy ``(s, t)``, or with :attr:`only` 1 for that
        strategy and 0 for the others."""
        if self.only is None:
            return w
        return dr.select((UInt32(s) == self.only[0]) & (UInt32(t) == self.only[1]), 1.0, 0.0)

    def _splat(self, si: Interaction, beta: Array3f, dvcm: Float, dvc: Float, film: SplatFilm,
               active: Bool, depth: UInt32, strategies: StrategyFilm | None, u_rr: Float,
               threshold: Float) -> None:
        """``t = 1``: light vertex ``si`` joined to the camera, splatted into ``film`` (after
        :func:`roulette` with ``u_rr`` and ``threshold``)."""
        scene, cam = self.scene, self.camera
        x, y, wc, dist, importance, visible = cam.connect(si.p)
        ok = active & visible
        f, _, rev = eval_both(self.smooth, si, wc, importance=True)
        corr, sides = correction(si, wc)
        pdf_cam = importance * dr.abs(dr.dot(si.ng, wc))
        w = self._weight(connection_weight(pdf_cam, dvcm, dvc, rev, Float(0.0), Float(0.0), Float(0.0),
                                           Float(0.0), self.k * mis(self.share)), depth + 1, 1)
        value = beta * f * (corr * importance * w)
        ok &= sides & (dr.max(value) > 0.0) & dr.isfinite(dr.max(value))
        value, ok = roulette(value, ok, u_rr, threshold)
        o, d, tmax = camera_segment(cam.center, si.p, si.ng, si.p_error, wc, dist)
        ok &= tmax > 0.0
        count(scene, SHADOW_CAMERA, ok)
        ok &= ~self._camera_occluded(o, d, tmax, ok)
        count(scene, SPLAT, ok)
        film.put(x, y, value, ok)
        if strategies is not None:
            strategies.put(depth + 1, 1, x, y, value, ok)

    def _camera_occluded(self, o: Array3f, d: Array3f, tmax: Float, active: Bool) -> Bool:
        """Whether the segment of ray ``(o, d)`` up to ``tmax`` from the camera
        (:func:`~drpt.render.integrators.ptracer.camera_segment`) is blocked. With
        ``hide_emitters`` in a scene with emissive surfaces, camera rays pass through area
        emitters (:meth:`_camera_hit`), so only what is not emissive blocks this segment."""
        scene = self.scene
        if not (self.opt.hide_emitters and scene.materials.has_emission):
            return occluded_where(scene, o, d, tmax, active)
        si = scene.intersect(o, d, active)
        si = scene.skip_area_emitters(o, d, si, active & si.valid)
        return active & si.valid & (si.t < tmax)

    def _camera_hit(self, o: Array3f, d: Array3f, si: Interaction, k: UInt32, live: Bool) -> Interaction:
        """``si``, the camera subpath's hit, continued past the area emitters that the camera
        ray (``k == 1``) hits with ``hide_emitters``, as the path tracer's
        (:func:`~drpt.render.integrators.path.skip_hidden_emitters`): the camera sees what
        lies behind an area light. Traced only with ``hide_emitters`` in a scene with
        emissive surfaces."""
        if not (self.opt.hide_emitters and self.scene.materials.has_emission):
            return si
        return self.scene.skip_area_emitters(o, d, si, live & (k == 1), coherent=True)

    def _emission(self, si: Interaction, d: Array3f, beta: Array3f, dvcm: Float, dvc: Float,
                  t: UInt32, active: Bool) -> Array3f:
        """``s = 0``: the emitter the camera subpath's ray ``d`` hits at ``si``."""
        scene = self.scene
        le = scene.emitted(si)
        pdf_a = self.origin_pdf(si.prim, active)
        cos_e = dr.maximum(dr.dot(si.ns, si.wi), 0.0)
        emit = self.pick * pdf_a * cos_e / math.pi
        w = dr.select(t == 2, 0.0 if self.opt.hide_emitters else 1.0,
                      emission_weight(pdf_a, emit, dvcm, dvc, self.k))
        w = self._weight(w, 0, t)
        return dr.select(active, beta * le * w, 0.0)

    def _nee_area(self, si: Interaction, dvcm: Float, dvc: Float, rng: PCG32, active: Bool,
                  t: UInt32) -> Array3f:
        """``s = 1`` for the area lights: a point drawn as the path tracer draws it."""
        scene = self.scene
        lights = scene.area_lights
        if isinstance(rng, LDSampler):  # the primitive from the point's pair (sample reuse)
            u_sel, u = lights.reuse(next_2d(rng), active)
        else:
            u_sel = rng.next_float32()
            u = next_2d(rng)
        ls = lights.sample(u_sel, u, active, ref=si.p if lights.has_spheres else None)
        _, face = lights._select(u_sel, active)
        to = ls.p - si.p
        dist2 = dr.squared_norm(to)
        wo = to * dr.rsqrt(dist2)
        cos_front = -dr.dot(ls.n, wo)
        cos_l = dr.abs(dr.dot(ls.ng, wo))
        pdf = ls.pdf_area * dist2 / cos_l
        if ls.solid_angle is not None:
            pdf = dr.select(ls.solid_angle, ls.pdf_area, pdf)
        ok = active & (cos_front > 0.0) & (cos_l > 0.0) & (ls.pdf_area > 0.0)
        pdf_a = self.origin_pdf(face, active)
        pdf_w = pdf_a * dist2 / cos_l  # the density the weights use (uniform on a sphere)
        f, fwd, rev = eval_both(self.smooth, si, wo)
        emit = self.pick * pdf_a * cos_front / math.pi
        cos_c = dr.abs(dr.dot(si.ng, wo))
        w = self._weight(nee_weight(fwd, pdf_w, emit, cos_c, cos_l, dvcm, dvc, rev, self.k), 1, t)
        value = f * ls.le * (w / pdf)
        ok &= (dr.max(value) > 0.0) & dr.isfinite(dr.max(value))
        so = scene.spawn(si, wo)
        end = spawn_origin(ls.p, ls.ng, ls.p_error, -wo)
        seg = end - so
        dist = dr.norm(seg)
        count(scene, SHADOW_NEE, ok)
        ok &= ~occluded_where(scene, so, seg / dr.maximum(dist, 1e-30), dist * SHADOW_SHRINK, ok)
        return dr.select(ok, value, 0.0)

    def _nee_delta(self, si: Interaction, dvcm: Float, dvc: Float, active: Bool, t: UInt32) -> Array3f:
        """``s = 1`` for the point and spot lights: each, every time."""
        scene = self.scene
        total = dr.zeros(Array3f, dr.width(active))
        for light, ds in zip(self.deltas, scene.delta_emitters(si.p)):
            f, _, rev = eval_both(self.smooth, si, ds.wo)
            cos_c = dr.abs(dr.dot(si.ng, ds.wo))
            # the light's area density is 1 (a Dirac): as a solid angle dist^2, or 1 for a
            # directional light (infinitely far: no distance, no cosine)
            far = getattr(light, "position", None) is None
            pdf_light = Float(1.0) if far else dr.square(ds.dist)
            w = self._weight(nee_weight(Float(0.0), pdf_light, Float(self._delta_emit(light, -ds.wo)), cos_c,
                                        Float(1.0), dvcm, dvc, rev, self.k), 1, t)
            value = f * ds.irradiance * w
            ok = active & (dr.max(value) > 0.0) & dr.isfinite(dr.max(value))
            so = scene.spawn(si, ds.wo)
            count(scene, SHADOW_NEE, ok)
            ok &= ~scene.occluded(so, ds.wo, ds.dist * SHADOW_SHRINK, ok)
            total += dr.select(ok, value, 0.0)
        return total

    def _nee_sky(self, si: Interaction, dvcm: Float, dvc: Float, rng: PCG32, active: Bool,
                 t: UInt32) -> Array3f:
        """``s = 1`` for the sky: a direction drawn by its density (as the path tracer's)."""
        scene = self.scene
        wo, radiance, pdf = scene.sample_environment(next_2d(rng), active)
        f, fwd, rev = eval_both(self.smooth, si, wo)
        emit = self.pick * pdf * self.disk_pdf
        w = self._weight(nee_weight(fwd, pdf, emit, dr.abs(dr.dot(si.ng, wo)), Float(1.0), dvcm, dvc, rev,
                                    self.k), 1, t)
        value = f * radiance * (w / dr.maximum(pdf, 1e-30))
        ok = active & (pdf > 0.0) & (dr.max(value) > 0.0) & dr.isfinite(dr.max(value))
        count(scene, SHADOW_NEE, ok)
        ok &= ~scene.occluded(scene.spawn(si, wo), wo, Float(dr.inf), ok)
        return dr.select(ok, value, 0.0)

    def _escaped(self, d: Array3f, beta: Array3f, dvcm: Float, dvc: Float, t: UInt32,
                 active: Bool) -> Array3f:
        """``s = 0`` for the sky or the background the camera subpath's ray ``d`` escapes to
        (no distance or cosine to convert at an infinite emitter)."""
        if self.has_sky:
            le, pdf = self.scene.eval_pdf_environment(d, active)
        else:
            le, pdf = Array3f(*map(float, self.scene.background)), Float(0.0)  # no NEE of it
        emit = self.pick * (pdf if self.has_sky else INV_FOUR_PI) * self.disk_pdf
        w = dr.select(t == 2, 0.0 if self.opt.hide_emitters else 1.0,
                      emission_weight(pdf, emit, dvcm, dvc, self.k))
        w = self._weight(w, 0, t)
        return dr.select(active, beta * le * w, 0.0)

    def _connect(self, si: Interaction, beta: Array3f, dvcm: Float, dvc: Float,
                 lv: Interaction, beta_l: Array3f, dvcm_l: Float, dvc_l: Float, active: Bool,
                 s: UInt32, t: UInt32, u_rr: Float, threshold: Float, eval_c=None) -> Array3f:
        """``s >= 2, t >= 2``: camera vertex ``si`` joined to light vertex ``lv`` (after
        :func:`roulette` with ``u_rr`` and ``threshold``); ``eval_c``: :func:`prepare_both`'s
        function of ``si`` (None: :func:`eval_both`)."""
        scene = self.scene
        to = lv.p - si.p
        dist2 = dr.squared_norm(to)
        w = to * dr.rsqrt(dist2)
        f_c, fwd_c, rev_c = eval_both(self.smooth, si, w) if eval_c is None else eval_c(w)
        f_l, fwd_l, rev_l = eval_both(self.smooth, lv, -w, importance=True)
        corr, sides = correction(lv, -w)
        inv_d2 = dr.rcp(dist2)
        pdf_l = fwd_c * dr.abs(dr.dot(lv.ng, w)) * inv_d2
        pdf_c = fwd_l * dr.abs(dr.dot(si.ng, w)) * inv_d2
        weight = self._weight(connection_weight(pdf_l, dvcm_l, dvc_l, rev_l, pdf_c, dvcm, dvc, rev_c), s, t)
        value = beta * f_c * beta_l * f_l * (corr * inv_d2 * weight)
        ok = active & sides & (dist2 > 0.0) & (dr.max(value) > 0.0) & dr.isfinite(dr.max(value))
        value, ok = roulette(value, ok, u_rr, threshold)
        so = scene.spawn(si, w)
        end = spawn_origin(lv.p, lv.ng, lv.p_error, -w)
        seg = end - so
        dist = dr.norm(seg)
        count(scene, SHADOW_CONNECT, ok)
        ok &= ~occluded_where(scene, so, seg / dr.maximum(dist, 1e-30), dist * SHADOW_SHRINK, ok)
        return dr.select(ok, value, 0.0)

    # ------------------------------------------------------------ caustic merging
    def merge_radius(self, first: int, k: int) -> float:
        """The merging radius of a pass of samples ``first .. first + k - 1`` (sample indices
        per pixel, from 0). Per sample ``s`` the squared radius follows progressive photon
        mapping's rule (Knaus and Zwicker 2011): ``r_0^2 = (MERGE_RADIUS R)^2`` (``R`` the
        scene's bounding radius), ``r_{s+1}^2 = r_s^2 (s + 1 + alpha) / (s + 2)``
        (:data:`MERGE_ALPHA`), so ``r_s^2 = r_0^2 Gamma(s + 1 + alpha) / (Gamma(1 + alpha)
        Gamma(s + 2))``, falling as ``s^(alpha - 1)``. A pass merges with one radius: the
        one whose square is the mean of ``r_s^2`` over its samples, so the image's ``O(r^2)``
        bias, the mean of its samples', depends on the spp alone, not on how the samples
        are split into passes (lanes per pass, bands, chunks, workers, resumes)."""
        a = MERGE_ALPHA

        def total(m: int) -> float:  # sum of r_s^2 / r_0^2 over s < m, in closed form
            return math.expm1(math.lgamma(m + 1 + a) - math.lgamma(m + 1) - math.lgamma(1 + a)) / a

        r2 = (total(first + k) - total(first)) / k
        return MERGE_RADIUS * self.rays.radius * math.sqrt(r2)

    @loops_once
    @dr.syntax
    def trace_photons(self, rng: PCG32, active: Bool):
        """One light subpath per lane, from the area lights only, followed through Dirac
        vertices to its first non-Dirac one, where it stops: a caustic photon there when at
        least one Dirac vertex came before. Returns ``(p, wo, power, depth, valid)``: the
        position, the direction back along the last segment, the subpath's throughput
        (radiant flux per subpath, as the light subpath's ``beta``), its segments; photons of
        more than ``max_depth - 2`` segments (no camera subpath of 2 could meet them) are
        not kept."""
        scene = self.scene
        n = dr.width(active)
        # ref: the vertex the ray o, d was spawned from (scene.intersect_from, as the light subpaths)
        o, d, ref, beta, _dvcm, _dvc, _inf, live = self._emit(rng, Bool(active), area_only=True)
        depth = dr.full(UInt32, 1, n)
        after_dirac = dr.zeros(Bool, n)
        p = dr.zeros(Array3f, n)
        wo_p = dr.zeros(Array3f, n)
        power = dr.zeros(Array3f, n)
        depth_p = dr.zeros(UInt32, n)
        valid = dr.zeros(Bool, n)
        while live:
            si = scene.intersect_from(o, ref, d, live)
            live &= si.valid & dr.isfinite(dr.max(beta))
            delta = scene.is_delta(si)
            store = live & ~delta & after_dirac
            p = dr.select(store, si.p, p)
            wo_p = dr.select(store, -d, wo_p)
            power = dr.select(store, beta, power)
            depth_p = dr.select(store, depth, depth_p)
            valid |= store
            live &= delta & (depth + 2 < self.depth)
            u_lobe = rng.next_float32()
            u_bsdf = next_2d(rng)
            wo, bs = scene.sample_bsdf(si, u_lobe, u_bsdf)
            corr, sides = correction(si, wo)
            beta = beta * bs.weight * (corr * dr.square(bs.eta))
            live &= bs.valid & sides & (dr.max(beta) > 0.0)
            after_dirac |= live
            depth += 1
            o = scene.spawn(si, wo)
            d = Array3f(wo)
            ref = Array3f(si.p)
        return p, wo_p, power, depth_p, valid

    @staticmethod
    def photon_paths(n: int) -> int:
        """The photon subpaths of a pass of ``n`` camera samples: ``n / PHOTON_SHARE``."""
        return max(1, n // PHOTON_SHARE)

    def photons(self, rng: PCG32, m: int, first: int, k: int) -> PhotonGrid:
        """The caustic photons of ``m`` light subpaths (:meth:`trace_photons`, ``rng`` of
        ``m`` lanes) in a :class:`~drpt.render.photons.PhotonGrid` of radius
        :meth:`merge_radius` of the pass's samples ``first .. first + k - 1``, evaluated;
        its ``scale`` (a kernel input) is ``1 / (pi r^2 m)``."""
        p, wo, power, depth, valid = self.trace_photons(rng, dr.full(Bool, True, m))
        r = self.merge_radius(first, k)
        grid = PhotonGrid(p, valid, r, {"wo": wo, "power": power, "depth": depth})
        grid.scale = dr.opaque(Float, 1.0 / (math.pi * r * r * m))
        return grid

    def _merge(self, si: Interaction, grid: PhotonGrid, room: UInt32, active: Bool) -> Array3f:
        """Camera vertex ``si`` merged with the caustic photons within the grid's radius whose
        paths fit in ``room`` segments: ``sum f(wi, wo_p) power_p / (pi r^2 N)``, ``f`` the
        BSDF without its cosine (the photons' density over the surface holds the geometric
        cosine), per ``active`` lane."""
        scene = self.smooth

        def one(i: UInt32, _p: Array3f, keep: Bool) -> Array3f:
            wo = grid.read("wo", i, keep)
            ok = keep & (grid.read("depth", i, keep) <= room)
            f, _ = scene.eval_bsdf(si, wo)
            cos = dr.abs(dr.dot(si.ng, wo))
            value = f * grid.read("power", i, ok) * dr.select(cos > 0.0, dr.rcp(cos), 0.0)
            return dr.select(ok, value, 0.0)

        return grid.gather(si.p, active, one) * grid.scale

    # ------------------------------------------------------------ the subpaths
    def trace(self, rng: PCG32, film: SplatFilm, camera_film: SplatFilm, px: Float, py: Float,
              active: Bool, strategies: StrategyFilm | None = None,
              photons: PhotonGrid | None = None) -> UInt32:
        """One light subpath and one camera sample through image position ``(px, py)`` per
        lane: the ``t = 1`` strategies splatted into ``film``, the sum of the others into
        ``camera_film`` at ``(px, py)``, and with ``strategies`` each contribution also
        into its strategy's image; returns the non-finite contributions dropped (per
        lane). With ``photons`` (:meth:`photons`; not with ``strategies`` or :attr:`only`)
        paths camera S+ D S+ area light are estimated by merging at their D vertex, and
        the camera subpath's hits of the light that end such paths count 0.

        Traced with Dr.Jit's ``OptimizeLoops`` off: the two subpath loops carry state that
        does not change (the pixel position, the roulette's threshold and the emitted
        power, the random streams' increments), and with the flag on Dr.Jit records each
        loop body a second time to drop those variables, which doubles the Python tracing
        that every pass pays. The LLVM backend removes such loop-invariant phis itself, so
        the kernel computes the same values (the images are the same, to the bit)."""
        with dr.scoped_set_flag(dr.JitFlag.OptimizeLoops, False):
            return self._trace(rng, film, camera_film, px, py, active, strategies, photons)

    @dr.syntax
    def _trace(self, rng: PCG32, film: SplatFilm, camera_film: SplatFilm, px: Float, py: Float,
               active: Bool, strategies: StrategyFilm | None,
               photons: PhotonGrid | None = None) -> UInt32:
        """:meth:`trace`'s body (traced once per loop with ``OptimizeLoops`` off)."""
        scene, opt, cam = self.scene, self.opt, self.camera
        n = dr.width(active)
        # the roulette's threshold is a kernel input, so that renders of other thresholds
        # trace one kernel; one entry per lane, as wide as the loops, which carry it
        # unchanged (a width-1 loop variable makes Dr.Jit record the loop again)
        threshold = dr.opaque(Float, self.threshold if self.threshold else 0.0, n)
        D = self.depth
        NL = D - 1
        has_deltas = len(self.deltas) > 0 and scene.has_smooth_bsdfs
        dropped = dr.zeros(UInt32, n)
        stored = dr.zeros(UInt32, n)
        lverts = None
        if scene.instrument is not None:
            scene.instrument.paths(n, (HIT_LIGHT, HIT_CAMERA, SHADOW_CAMERA, SHADOW_NEE, SHADOW_CONNECT, SPLAT))
        if NL > 0 and self.rays.count > 0 and scene.has_smooth_bsdfs:
            lverts = LightVertices(NL, getattr(scene.materials, "tangents", False))
            # ref: the subpath's previous vertex, which the ray o, d was spawned from
            o, d, ref, beta, dvcm, dvc, infinite, live = self._emit(rng, Bool(active))
            power = dr.max(beta)  # the subpath's emitted power: its roulette's unit
            eta = dr.full(Float, 1.0, n)
            depth = dr.full(UInt32, 1, n)
            while live:
                count(scene, HIT_LIGHT, live)
                si = scene.intersect_from(o, ref, d, live)
                live &= si.valid
                finite = dr.isfinite(beta.x) & dr.isfinite(beta.y) & dr.isfinite(beta.z)
                dropped += dr.select(live & ~finite, 1, 0)
                live &= finite
                # the first segment from an infinite emitter has no length to convert
                dist2 = dr.select(infinite, 1.0, segment_length2(si, ref))
                infinite = dr.zeros(Bool, n)
                dvcm, dvc = hit_update(dvcm, dvc, dist2, dr.abs(dr.dot(si.ng, d)))
                connectible = live & ~scene.is_delta(si)
                if connectible:
                    lverts.write(dr.minimum(stored, NL - 1), si, beta, dvcm, dvc, depth)
                    stored += 1
                self._splat(si, beta, dvcm, dvc, film, connectible, depth, strategies, rng.next_float32(),
                            threshold)

                u_lobe = rng.next_float32()
                u_bsdf = next_2d(rng)
                wo, bs, rev = sample_both(scene, si, u_lobe, u_bsdf)
                corr, sides = correction(si, wo)
                dvcm, dvc = scatter_update(dvcm, dvc, bs.pdf, rev, dr.abs(dr.dot(si.ng, wo)), bs.delta)
                beta = beta * bs.weight * (corr * dr.square(bs.eta))
                eta = eta * bs.eta
                live &= bs.valid & sides & (dr.max(beta) > 0.0)
                depth += 1
                live &= depth < D
                u_rr = rng.next_float32()
                use_rr = depth > opt.rr_depth
                q = light_survival(beta, power, eta)
                live &= ~use_rr | (u_rr < q)
                beta = dr.select(use_rr, beta / q, beta)
                o = scene.spawn(si, wo)
                d = Array3f(wo)
                ref = Array3f(si.p)

        # ---- the camera subpath
        o, d = cam.ray(px, py)
        ref = dr.zeros(Array3f, n) + o  # the camera's position (as wide as the loop)
        cos_cam = dr.dot(d, cam.f)
        area = 4.0 * dr.sqrt(dr.squared_norm(cam.r) * dr.squared_norm(cam.u))
        # (k m(share): the splats' count against the connections, CONNECTION_CHOICES's alone)
        dvcm = self.k * mis(self.share) * mis(area * cos_cam * cos_cam * cos_cam)
        dvc = dr.zeros(Float, n)
        beta = dr.full(Array3f, 1.0, n)
        eta = dr.full(Float, 1.0, n)
        L = dr.zeros(Array3f, n)
        k = dr.full(UInt32, 1, n)
        live = Bool(active) & (D > 0)
        record = strategies is not None
        merge = photons is not None and not record and self.only is None
        # merging: where the camera subpath is, 0: S* (only Dirac vertices so far), 1: S+ D
        # (merged at D), 2: S+ D S+ (an area light hit now ends a path that merging
        # estimates), 3: other (also S+ D with a Dirac lobe sampled at D); S and D by the
        # material (scene.is_delta), as the photons' vertices are
        phase = dr.zeros(UInt32, n)

        ld = isinstance(rng, LDSampler)
        while live:
            if ld:  # vertex k's dimensions (CAMERA_STRIDE)
                rng.dim = CAMERA_DIMENSION + (k - 1) * CAMERA_STRIDE
            count(scene, HIT_CAMERA, live)
            si = self._camera_hit(o, d, scene.intersect(o, d, live), k, live)
            if self.has_sky or self.has_background:
                c = self._escaped(d, beta, dvcm, dvc, k + 1, live & ~si.valid)
                L += c
                if record:
                    strategies.put(0, k + 1, px, py, c, active)
            live &= si.valid
            dvcm, dvc = hit_update(dvcm, dvc, segment_length2(si, ref), dr.abs(dr.dot(si.ng, d)))
            if scene.has_area_lights:
                c = self._emission(si, d, beta, dvcm, dvc, k + 1, live & ~(phase == 2) if merge else live)
                L += c
                if record:
                    strategies.put(0, k + 1, px, py, c, active)
            connectible = live & ~scene.is_delta(si) & (k < D)
            if merge:
                first = connectible & (phase == 0) & (k >= 2)
                if first:
                    L += beta * self._merge(si, photons, D - k, first)
                start = dr.select(~connectible, UInt32(0), dr.select(k >= 2, UInt32(1), UInt32(3)))
                phase = dr.select(phase == 0, start, dr.select(connectible | (phase == 3), UInt32(3), UInt32(2)))
            nee = dr.zeros(Array3f, n)
            if scene.has_area_lights and scene.has_smooth_bsdfs:
                nee += self._nee_area(si, dvcm, dvc, rng, connectible, k + 1)
            if has_deltas:
                nee += self._nee_delta(si, dvcm, dvc, connectible, k + 1)
            if self.has_sky and scene.has_smooth_bsdfs:
                nee += self._nee_sky(si, dvcm, dvc, rng, connectible, k + 1)
            L += beta * nee
            if record:
                strategies.put(1, k + 1, px, py, beta * nee, active)
            room = connection_room(k, D)
            if lverts is not None and self.one_connection:
                i, m = choose_vertex(rng.next_float32(), stored, room)
                pick = connectible & (m > 0)
                lv, beta_l, dvcm_l, dvc_l, depth_l = lverts.read(i, pick)
                c = self._connect(si, beta, dvcm, dvc, lv, beta_l * Float(m), dvcm_l, dvc_l,
                                  pick & (depth_l + k < D), depth_l + 1, k + 1, rng.next_float32(),
                                  threshold)
                L += c
                if record:
                    strategies.put(depth_l + 1, k + 1, px, py, c, active)
            elif lverts is not None:
                i = dr.zeros(UInt32, n)
                # si is read, not changed: outside the loop's state (its width-1 fields would
                # make Dr.Jit record the loop again)
                usable = dr.minimum(stored, room)
                # the camera vertex's fields and frame, once for all its connections
                eval_c = prepare_both(self.smooth, si)
                while dr.hint(connectible & (i < usable), exclude=[si]):
                    lv, beta_l, dvcm_l, dvc_l, depth_l = lverts.read(i, connectible)
                    c = self._connect(si, beta, dvcm, dvc, lv, beta_l, dvcm_l, dvc_l,
                                      connectible & (depth_l + k < D), depth_l + 1, k + 1,
                                      rng.next_float32(), threshold, eval_c)
                    L += c
                    if record:
                        strategies.put(depth_l + 1, k + 1, px, py, c, active)
                    i += 1

            if ld:  # the same dimensions whatever the connections drew
                rng.dim = CAMERA_DIMENSION + k * CAMERA_STRIDE - CAMERA_TAIL
            u_lobe = rng.next_float32()
            u_bsdf = next_2d(rng)
            wo, bs, rev = sample_both(scene, si, u_lobe, u_bsdf)
            dvcm, dvc = scatter_update(dvcm, dvc, bs.pdf, rev, dr.abs(dr.dot(si.ng, wo)), bs.delta)
            if merge:
                # a Dirac lobe sampled at the merged vertex (plastic's coating, a mask's
                # pass-through): merging evaluates the smooth lobes only, so the path is not
                # one it estimates, and s = 0 keeps it
                phase = dr.select((phase == 1) & bs.delta, UInt32(3), phase)
            beta = beta * bs.weight
            eta = eta * bs.eta
            live &= bs.valid & (dr.max(beta) > 0.0)
            k += 1
            live &= k <= D
            u_rr = rng.next_float32()
            use_rr = k > opt.rr_depth
            q = dr.minimum(dr.max(beta) * dr.square(eta), 0.95)
            live &= ~use_rr | (u_rr < q)
            beta = dr.select(use_rr, beta / q, beta)
            o = scene.spawn(si, wo)
            d = Array3f(wo)
            ref = Array3f(si.p)
        finite = dr.isfinite(L.x) & dr.isfinite(L.y) & dr.isfinite(L.z)
        dropped += dr.select(active & ~finite, 1, 0)
        camera_film.put(px, py, L, active & finite)
        return dropped
