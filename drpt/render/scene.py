"""The scene on the device: what integrators ask of geometry, materials and emitters.

:class:`DeviceScene` is built from a parsed :class:`drpt.scene.model.Scene`
and the :class:`~drpt.options.RenderOptions`. It holds the accelerator
(:func:`drpt.accel.build_accel`), the per-primitive surface data
(:class:`~drpt.render.surface.SurfaceData`), the materials
(:class:`~drpt.render.material.MaterialTable`), the emitters (area, delta,
environment: :mod:`drpt.render.lights`) and the background, and answers the
integrators' queries over wide Dr.Jit arrays:

* geometry: :meth:`intersect` (closest hit and its interaction, from
  :meth:`intersect_preliminary` and :meth:`interaction`), :meth:`occluded`,
  :meth:`spawn` (the origin of a ray leaving a surface, moved off it by the
  hit's own rounding-error bound, :mod:`drpt.render.spawn`), :meth:`skip_area_emitters`
  (a ray continued past the emissive surfaces it hits: ``hide_emitters``' camera rays);
* materials: :meth:`emitted`, :meth:`eval_bsdf`, :meth:`sample_bsdf`,
  :meth:`is_delta`, :meth:`diffuse_color`;
* emitters: :meth:`sample_emitter` (one emitter of any family, chosen by the
  scene's :class:`~drpt.render.lights.selection.LightSelection`, and a direction
  toward it: next-event estimation) and :meth:`pdf_emitter` (its density for what a
  BSDF-sampled ray reached, for MIS), :meth:`eval_emitter` (the radiance a ray sees
  and that density, in one query), and :attr:`background`. The family-level queries
  stay for light tracing: :meth:`sample_area_emitter` and :meth:`pdf_area_emitter`
  (the area family's own selection), :meth:`delta_emitters`,
  :meth:`sample_environment`, :meth:`eval_environment`, :meth:`eval_pdf_environment`.
  The sky's next-event density may be MIS-compensated (:func:`env_compensated`: the
  file's ``mis_compensation`` or ``RenderOptions.env_compensation``, path and volpath
  only); the family-level queries keep the map's own luminance density, since light
  tracing has no other technique to cover what compensation leaves out.

Feature flags (plain Python bools, read while a kernel is traced) say what
the scene has, so that kernels contain only the code it needs:
``has_area_lights``, ``has_delta_lights``, ``has_environment`` (a sky that
is not black), ``has_emitters`` (any of the three: next-event estimation has something
to sample), ``has_background`` (a background color above 0 and no
sky), ``has_ambient`` and ``has_smooth_bsdfs`` (some material is not a
delta lobe: without one, next-event estimation is never traced).

A scene without primitives (an empty ``Group``, an OBJ without faces) is
drawn as its background or sky: the accelerator is built as for any scene
(every kind answers "no hit" over zero primitives), the surface and
material tables are stand-ins that answer every query as a miss
(:class:`NoSurfaces`, :class:`NoMaterials`: Dr.Jit cannot gather from an
empty array), and :attr:`DeviceScene.warnings` says so once.

A view restricted to some material kinds (:meth:`DeviceScene.restricted`, the
wavefront's shading queues) shares the device data and recomputes the flags
(:meth:`DeviceScene._set_flags`, their one definition).

Measurement tools observe queries through :attr:`DeviceScene.instrument`
(an :class:`~drpt.render.instrument.Instrument`, None by default): while a
kernel is traced, :meth:`occluded` and the path integrator's bounce call it,
so what it records lands in that kernel; without one no such code is traced.
"""

from __future__ import annotations

import copy

import drjit as dr
import numpy as np
from drjit.auto import Array2f, Array3f, Bool, Float, UInt32

from .. import backend, llvm_tuning
from ..accel import build_accel
from ..accel.boxes import ShapeBoxes
from ..accel.inline import InlineList
from ..accel.protocol import INVALID, Hit
from ..errors import located
from ..options import RenderOptions
from ..scene.model import PerspectiveCamera, Scene, Skybox
from .bsdf import BSDFSample
from .camera import RayCamera
from .instrument import Instrument
from .integrators.enclosure import media_bounded
from .lights import EmitterSample
from .lights.area import AreaLights, toward
from .lights.delta import DeltaLights
from .lights.envmap import (
    EnvironmentLight,
    RotatedEnvironment,
    SkyEmitter,
    UniformSphereSampling,
    check_radius,
)
from .lights.light_bvh import BVHSelection
from .lights.pilot import LIGHT_TRACERS, pilot_selection
from .lights.reach import receivers
from .lights.selection import LightSelection
from .loops import loops_once
from .material import MaterialTable
from .spawn import origin as spawn_origin
from .surface import Interaction, SurfaceData

#: builders of further emitter families, ``build(device_scene, scene) -> Emitter | None``
#: (:class:`drpt.render.lights.Emitter`; None or a family without slots: the scene has none);
#: each family built joins the light selection after the area, delta and sky families
#: (docs/architecture.md, "Adding an emitter")
EMITTER_FAMILIES: list = []

#: the integrators whose next-event estimation of the sky may be MIS-compensated
#: (:func:`env_compensated`): every vertex that samples the sky also samples its BSDF or
#: phase function, and weighs both by MIS
COMPENSATED_INTEGRATORS = ("path", "volpath")

#: the most emissive surfaces :meth:`DeviceScene.skip_area_emitters` passes along one ray
MAX_EMITTER_SKIPS = 16

#: the most delta lights that ``--delta-lights each`` reaches by shadow rays of their own
DELTA_EACH_MAX = 4

EMPTY_SCENE_WARNING = ("the scene has no primitives (no triangles, spheres or planes): "
                       "the image shows only its background or sky")


def wants_delta_each(options, media: bool) -> bool:
    """Whether ``options`` ask for the delta lights' own shadow rays (``--delta-lights each``)
    and name an integrator that traces them: the megakernel path tracer, and ``volpath`` in a
    scene without media (``media``: whether it has any). :meth:`DeviceScene.set_delta_each`
    then decides whether the scene allows it."""
    return options.delta_lights == "each" and options.mode != "wavefront" and (
        options.integrator == "path" or (options.integrator == "volpath" and not media))


class NoSurfaces:
    """The surface data of a scene without primitives: every hit is a miss."""

    def interaction(self, o: Array3f, d: Array3f, hit) -> Interaction:
        n = dr.width(hit.valid)
        return Interaction(dr.zeros(Bool, n), Float(hit.t), Array3f(o),
                           dr.full(Array3f, [0.0, 0.0, 1.0], n), dr.full(Array3f, [0.0, 0.0, 1.0], n),
                           dr.full(UInt32, INVALID, n), dr.zeros(UInt32, n), -d)


class NoMaterials:
    """The material table of a scene without primitives: nothing to shade or emit
    (no lane ever hits a surface)."""

    textures = None
    notes: list[str] = []
    has_emission = False
    has_emission_texture = False

    def is_specular_only(self) -> bool:
        return True  # no BSDF to sample lights for: next-event estimation is not traced

    def emitted(self, si: Interaction) -> Array3f:
        return dr.zeros(Array3f, dr.width(si.valid))

    def eval_pdf(self, si: Interaction, wo: Array3f, importance: bool = False) -> tuple[Array3f, Float]:
        n = dr.width(si.valid)
        return dr.zeros(Array3f, n), dr.zeros(Float, n)

    def eval_pdf_rev(self, si: Interaction, wo: Array3f, importance: bool = False
                     ) -> tuple[Array3f, Float, Float]:
        n = dr.width(si.valid)
        return dr.zeros(Array3f, n), dr.zeros(Float, n), dr.zeros(Float, n)

    def eval_pdf_sample(self, si: Interaction, wo: Array3f, u1: Float, u2: Array2f):
        return (*self.eval_pdf(si, wo), *self.sample(si, u1, u2))

    def sample(self, si: Interaction, u1: Float, u2: Array2f, rev: bool = False):
        n = dr.width(si.valid)
        up = dr.full(Array3f, [0.0, 0.0, 1.0], n)
        bs = BSDFSample(wo=Array3f(up), weight=dr.zeros(Array3f, n), pdf=dr.zeros(Float, n),
                        valid=dr.zeros(Bool, n), delta=dr.zeros(Bool, n), eta=dr.full(Float, 1.0, n))
        return (up, bs, dr.zeros(Float, n)) if rev else (up, bs)

    def is_delta(self, si: Interaction) -> Bool:
        return dr.zeros(Bool, dr.width(si.valid))

    def diffuse_color(self, si: Interaction, active: Bool) -> Array3f:
        return dr.zeros(Array3f, dr.width(si.valid))

    albedo = diffuse_color


class EmissiveList:
    """The scene's emissive triangles as an inline accelerator of their own
    (:class:`~drpt.accel.inline.InlineList`: each triangle's test compiled into the kernel
    with its vertices as constants): :meth:`intersect` finds the nearest emissive surface
    along a ray without traversing the scene, and returns it with its global primitive id."""

    def __init__(self, ids: np.ndarray, positions: np.ndarray, surroundings: tuple = (None, None)):
        """``ids``, ``positions``: the emissive triangles; ``surroundings``: the rest of the
        scene, ``(triangles (M, 3, 3), planes (normals, offsets) or None)``, which the
        list's parallelograms must not touch (as in the scene's own accelerator:
        :func:`~drpt.geometry.parallelogram.parallelogram_pairs`)."""
        class _Prims(list):  # the part of a Scene InlineList reads
            positions = None

        tris = _Prims(range(len(ids)))
        tris.positions = positions
        self.count = len(ids)
        self._list = InlineList(type("EmissiveScene", (), {"triangles": tris, "spheres": [], "planes": [],
                                                          "surroundings": surroundings}))
        self._ids = UInt32(np.asarray(ids, np.uint32))

    def intersect(self, o: Array3f, d: Array3f, active: Bool):
        """The nearest emissive triangle hit by ``(o, d)`` (a :class:`~drpt.accel.protocol.Hit`
        whose ``prim`` is the scene's primitive id)."""
        hit = self._list.intersect(o, d, Float(dr.largest(Float)), active)
        hit.prim = dr.select(hit.valid, dr.gather(UInt32, self._ids, hit.prim, hit.valid), INVALID)
        return hit


def env_compensated(sky: Skybox, options: RenderOptions, scene: Scene | None = None) -> bool:
    """Whether next-event estimation samples ``sky`` with MIS compensation
    (:meth:`~drpt.render.lights.envmap.EnvironmentLight.compensated`): as its file says
    (``Skybox.mis_compensation``), else as ``options.env_compensation``; and only for the
    integrators that weigh that sample against BSDF and phase samples by MIS
    (:data:`COMPENSATED_INTEGRATORS`), in a ``scene`` whose media (if any) all lie inside
    closed shapes (:func:`~drpt.render.integrators.enclosure.media_bounded`). Compensation
    leaves directions below the map's mean to those samples: Whitted's direct light (no
    MIS), the light tracers (which leave the sky by :meth:`DeviceScene.sample_environment`,
    the map's own luminance density) and volpath in a medium that reaches beyond the shapes
    (where a sampled ray scatters before it reaches the sky, so next-event estimation alone
    sees it, with its MIS weight: Mitsuba's convention) keep the uncompensated density."""
    wanted = getattr(sky, "mis_compensation", None)
    if wanted is None:
        wanted = options.env_compensation == "on"
    if not (wanted and options.integrator in COMPENSATED_INTEGRATORS):
        return False
    return scene is None or not scene.media or media_bounded(scene)


def emitting(scene: Scene) -> np.ndarray:
    """Per material of ``scene``, whether it emits (a radiance above 0 or a textured one)."""
    return np.array([m.is_emissive or getattr(m, "emission_texture", None) is not None
                     for m in scene.materials], bool)


def emissive_inline(scene: Scene) -> EmissiveList | None:
    """An :class:`EmissiveList` of ``scene``'s emissive triangles, or None where there are
    none, emissive spheres or planes, or more triangles than the backend compiles inline
    (:func:`drpt.backend.policy`'s ``inline_max_prims``, the rule of ``--accel auto``: a
    list that short costs a ray less than a traversal; read when the scene is built)."""
    emits = emitting(scene)
    if not len(emits) or not emits.any():
        return None
    if any(len(g) and emits[np.asarray(g.material, np.int64)].any() for g in (scene.spheres, scene.planes)):
        return None
    tris = scene.triangles
    if not len(tris):
        return None
    ids = np.nonzero(emits[np.asarray(tris.material, np.int64)])[0]
    if not 0 < len(ids) <= backend.policy().inline_max_prims:
        return None
    positions = np.asarray(tris.positions)
    rest = np.ones(len(positions), bool)
    rest[ids] = False
    planes = (scene.planes.normal, scene.planes.offset) if len(scene.planes) else None
    return EmissiveList(ids, positions[ids], (positions[rest], planes))


class DeviceScene:
    def __init__(self, scene: Scene, options: RenderOptions):
        llvm_tuning.apply()  # as the CLI's backend check does, for API users too

        self.accel = build_accel(scene, kind=options.accel, resolution=options.grid_resolution,
                                 method=options.bvh_method, min_leaf=options.bvh_min_leaf,
                                 sah_threshold=options.sah_threshold)
        #: boxes around the shapes (:mod:`drpt.accel.boxes`) for the queries that cull the
        #: rays missing them (``intersect_preliminary``'s ``cull``: camera rays); None without
        #: planes' bounds, where the primitives are compiled inline (their own tests cost as
        #: little), or where a box holds the camera (a room: every camera ray reaches it)
        self.boxes = None if isinstance(self.accel, InlineList) else ShapeBoxes.of(scene)
        cam = scene.camera
        if self.boxes is not None and isinstance(cam, PerspectiveCamera) and \
                self.boxes.hold(cam.center, float(cam.aperture_radius)):
            self.boxes = None
        self.is_empty = len(scene.triangles) + len(scene.spheres) + len(scene.planes) == 0
        if self.is_empty:
            self.materials, self.surfaces = NoMaterials(), NoSurfaces()
        else:
            self.materials = MaterialTable(scene, options.bsdf)
            uv_aov = any(k == "uv" for _, k in getattr(options, "aovs", ()))
            self.surfaces = SurfaceData(scene, with_uv=self.materials.textures is not None or uv_aov,
                                        tangents=self.materials.tangents)
        lit = receivers(scene)  # the lit geometry, for the emitters' power (drpt.render.lights.reach)
        self.area_lights = AreaLights(scene, self.surfaces, self.materials, sampler=options.light_sampler,
                                      triangle_sampling=options.triangle_sampling,
                                      integrator=options.integrator, lit=lit)
        #: the emissive surfaces alone, where they are few triangles
        #: (:func:`emissive_inline`), else None
        self.emissive = emissive_inline(scene)
        #: boxes around the triangles of each smooth-dielectric material (only a ``dielectric``
        #: lobe), else None: the path tracer follows through glass only the occluded shadow
        #: rays that reach one (:mod:`drpt.render.integrators.glass`)
        glass = [i for i, ks in enumerate(getattr(self.materials, "material_kinds", ())) if ks == ("dielectric",)]
        self.glass_boxes = ShapeBoxes.of_materials(scene, glass) if glass else None
        self.delta_lights = DeltaLights(scene, lit)
        self.warnings: list[str] = list(self.materials.notes)
        if self.is_empty:
            self.warnings.append(EMPTY_SCENE_WARNING)
        #: the sky as loaded (possibly black), sampled by its luminance: its radiance, and the
        #: density of the light tracers (:meth:`sample_environment`)
        self.environment = None
        nee_environment = None  # the sky's next-event sampling, where compensated
        skies = [light for light in scene.lights if isinstance(light, Skybox)]
        if skies:
            if len(skies) > 1:
                self.warnings.append(located(f"{len(skies)} Skybox lights: using the first",
                                             getattr(skies[1], "loc", None)))
            sky = skies[0]
            self.environment = EnvironmentLight.from_file(sky.path, scale=getattr(sky, "scale", 1.0))
            self.warnings += self.environment.warnings
            if options.env_sampling == "uniform":
                self.environment = UniformSphereSampling(self.environment)
            elif env_compensated(sky, options, scene):
                nee_environment = self.environment.compensated()
            if getattr(sky, "rotation", None) is not None:
                self.environment = RotatedEnvironment(self.environment, sky.rotation)
                if nee_environment is not None:
                    nee_environment = RotatedEnvironment(nee_environment, sky.rotation)
            lo, hi = scene.bounds()
            msg = check_radius(lo, hi, skies[0].radius)
            if msg:
                self.warnings.append(located(msg, getattr(sky, "loc", None)))
        self.background = tuple(float(c) for c in scene.background.color)
        self.ambient = tuple(float(c) for c in scene.background.ambient)
        #: an :class:`~drpt.render.instrument.Instrument` that measurement tools attach
        #: (``drpt profile``); None: queries trace no instrumentation code
        self.instrument: Instrument | None = None
        self._set_flags()

        # the emitters behind one interface, and the one selection over them
        self.sky = None
        if self.has_environment:
            lo, hi = scene.bounds()
            radius = float(np.linalg.norm(hi - lo)) / 2.0 if np.all(np.isfinite(lo)) else 1.0
            # its power over the lit geometry's cross-section (drpt.render.lights.reach)
            self.sky = SkyEmitter(nee_environment or self.environment,
                                  radius if lit is None else float(np.sqrt(lit.cross_section / np.pi)))
        others = [self.area_lights] + ([self.sky] if self.sky is not None else [])
        others += [f for f in (build(self, scene) for build in EMITTER_FAMILIES) if f is not None]
        #: the delta lights that the path tracer's next-event estimation reaches each by a
        #: shadow ray of its own at every vertex, outside the light selection (``--delta-lights
        #: each``, :meth:`~drpt.render.integrators.common.DirectLight.delta_each`), else None
        #: (they are in the selection). Only a delta light's own shadow ray finds it (BSDF
        #: sampling never does), and the selection's ``1 / p`` multiplies the square of its
        #: estimate: on a glossy surface its highlight's. So they leave the selection where
        #: the megakernel path tracer renders (not its wavefront form, the light tracers or
        #: volpath in media), other emitters remain to select among, and no shadow ray is
        #: followed through glass (:mod:`~drpt.render.integrators.glass`).
        self.delta_each = None
        #: whether the scene allows it: delta lights and other emitters, no glass to follow, and
        #: at most DELTA_EACH_MAX delta lights (each is a shadow ray per vertex and its code is
        #: traced once per light: with many, the selection's one shadow ray is the cheaper)
        self._each_ok = (0 < self.delta_lights.count <= DELTA_EACH_MAX and any(f.count > 0 for f in others)
                         and self.glass_boxes is None)
        self._selection_args = (scene, others, options)
        self._selections: dict = {}  # whether the delta lights are out -> the selection
        self.set_delta_each(wants_delta_each(options, bool(scene.media)))

    def set_delta_each(self, on: bool) -> None:
        """Take the delta lights out of the light selection (:attr:`delta_each`: the path
        tracer reaches each by a shadow ray of its own) where ``on`` and the scene allows
        it, else put them in it. The renderer calls it with the integrator it builds (only
        the megakernel path tracer reaches them so), which reads both at trace time; each
        selection is built once."""
        out = bool(on) and self._each_ok
        if out not in self._selections:
            scene, others, options = self._selection_args
            families = others[:1] + ([] if out else [self.delta_lights]) + others[1:]
            rule = options.light_sampler
            if rule == "bvh" and self.area_lights.count > 0:
                selection = BVHSelection(families, self.area_lights, self.area_lights.bvh(scene))
            else:  # (bvh without area emitters: nothing for a BVH to choose among, mixed's rule)
                selection = LightSelection(families, "mixed" if rule in ("bvh", "pilot") else rule)
            if rule == "pilot" and not self.is_empty and options.integrator not in LIGHT_TRACERS:
                # measured through the scene's camera (light tracers pick as mixed: no pilot)
                self.set_light_selection(selection)
                selection = pilot_selection(self, RayCamera(scene.camera, options.width, options.height),
                                            options.width, options.height)
            self._selections[out] = selection
        self.delta_each = self.delta_lights if out else None
        if getattr(self, "emitter_selection", None) is not self._selections[out]:
            self.set_light_selection(self._selections[out])  # (binding the tables is host work)

    def _set_flags(self) -> None:
        """The feature flags, from the scene's emitters and the materials it traces
        (the one place they are computed: :meth:`__init__` and :meth:`restricted`)."""
        self.has_area_lights = self.area_lights.count > 0
        self.has_delta_lights = self.delta_lights.count > 0
        self.has_environment = self.environment is not None and not self.environment.is_black
        self.has_background = max(self.background) > 0.0 and not self.has_environment
        self.has_ambient = max(self.ambient) > 0.0
        self.has_smooth_bsdfs = not self.materials.is_specular_only()

    def set_light_selection(self, selection) -> None:
        """Use ``selection`` (a :class:`~drpt.render.lights.selection.LightSelection` or
        another object with its interface) for :meth:`sample_emitter`: a static one's
        probabilities are bound into the families' density tables, a spatially varying
        one's (``static`` False) multiplied in at run time. Kernels traced before keep
        the old selection."""
        self.emitter_selection = selection
        for i, family in enumerate(selection.families):
            family.bind(selection.family_probabilities(i) if selection.static else None)
        self.has_emitters = selection.count > 0

    def restricted(self, kinds) -> DeviceScene:
        """A view of this scene for lanes whose materials have components of the lobe
        kinds ``kinds`` only: the same device data (nothing is built or uploaded
        again), a material table that traces only those lobes
        (:meth:`MaterialTable.restricted <drpt.render.material.MaterialTable.restricted>`),
        and the feature flags recomputed for it (a view of delta lobes only traces no
        next-event estimation). The wavefront integrator's shading queues run on such
        views."""
        view = copy.copy(self)
        view.materials = self.materials.restricted(kinds)
        view._set_flags()
        return view

    # ------------------------------------------------------------ geometry
    def intersect(self, o: Array3f, d: Array3f, active: Bool, tmax: Float | None = None,
                  coherent: Bool | bool = False) -> Interaction:
        """The closest hit of rays ``(o, d)`` (``si.valid`` False on a miss), closer than
        ``tmax`` if given (a shorter ray traverses less of the accelerator); ``coherent``:
        the lanes of camera rays (a traversal hint, :meth:`drpt.accel.protocol.Accelerator.intersect`)."""
        return self.interaction(o, d, self.intersect_preliminary(o, d, active, tmax, coherent=coherent))

    def intersect_from(self, o: Array3f, p: Array3f, d: Array3f, active: Bool) -> Interaction:
        """The closest hit of the ray leaving the surface point ``p`` along ``d``, traced from
        ``o``, ``p`` moved off its surface (:meth:`spawn`), and then taken as the parallel ray
        from ``p`` itself meets the primitive it hit
        (:meth:`SurfaceData.seen_from <drpt.render.surface.SurfaceData.seen_from>`): the hit
        does not move with the spawn offset, which grows with the coordinates' magnitude
        (far from the origin a sizable fraction of a nearby light's distance). ``si.t`` is
        measured from ``p``. Where ``o`` is ``p`` (a delta light, the camera), the hit of
        :meth:`intersect`."""
        origin, hit = self.surfaces.seen_from(o, d, self.intersect_preliminary(o, d, active), p)
        return self.interaction(origin, d, hit)

    @loops_once
    def intersect_preliminary(self, o: Array3f, d: Array3f, active: Bool, tmax: Float | None = None,
                              coherent: Bool | bool = False, cull: bool = False, skip: UInt32 | None = None):
        """The accelerator's closest hit (:class:`drpt.accel.Hit`), any distance or closer than ``tmax``
        (a traversal loop recorded once: :func:`~drpt.render.loops.loops_once`). With ``cull``
        (rays that often pass beside every shape: camera rays) and the scene's :attr:`boxes`,
        the query runs in a symbolic ``if`` (label ``drpt_cull``) on the lanes whose ray reaches
        a shape's box; the others are misses (the protocol's: ``t`` inf, ``prim`` INVALID),
        so a packet of rays passing beside everything skips the query; the same hits. ``skip``:
        per lane, the box of the convex shape the ray leaves (:meth:`ShapeBoxes.leaving
        <drpt.accel.boxes.ShapeBoxes.leaving>`), which the ray cannot meet again: not counted."""
        tmax = Float(dr.largest(Float)) if tmax is None else tmax
        if not (cull and self.boxes is not None):
            return self.accel.intersect(o, d, tmax, active, coherent)
        reach = Bool(active) & self.boxes.reach(o, d, skip)
        n = dr.width(reach)

        def query(o, d, reach):
            return self.accel.intersect(o, d, tmax, reach, coherent)

        def miss(o, d, reach):
            return Hit(dr.full(Float, float("inf"), n), dr.full(UInt32, INVALID, n), dr.zeros(Float, n),
                       dr.zeros(Float, n), dr.zeros(Bool, n))

        return dr.if_stmt((Array3f(o), Array3f(d), reach), reach, query, miss, label="drpt_cull")

    def interaction(self, o: Array3f, d: Array3f, hit) -> Interaction:
        """Position, normals, material and uv of a hit (:class:`~drpt.render.surface.Interaction`)."""
        return self.surfaces.interaction(o, d, hit)

    @loops_once
    def occluded(self, o: Array3f, d: Array3f, tmax: Float, active: Bool,
                 coherent: Bool | bool = False, skip: UInt32 | None = None) -> Bool:
        """Lanes whose ray ``(o, d)`` hits anything at ``0 < t < tmax`` (a traversal loop
        recorded once); ``coherent``: the lanes whose rays are coherent, a traversal hint
        (:meth:`drpt.accel.protocol.Accelerator.occluded`), the same answer. With ``skip`` (per
        lane, the box of the convex shape the ray leaves, :meth:`ShapeBoxes.leaving
        <drpt.accel.boxes.ShapeBoxes.leaving>`) and the scene's :attr:`boxes`, the query runs
        in a symbolic ``if`` (label ``drpt_cull``) on the lanes whose ray reaches another
        shape; the others are not occluded: the same answer."""
        if self.instrument is not None:
            self.instrument.occluded(o, d, tmax, active)
        if skip is None or self.boxes is None:
            return self.accel.occluded(o, d, tmax, active, coherent)
        reach = Bool(active) & self.boxes.reach(o, d, skip)

        def query(o, d, tmax, reach):
            return self.accel.occluded(o, d, tmax, reach, coherent)

        return dr.if_stmt((Array3f(o), Array3f(d), Float(tmax), reach), reach, query,
                          lambda o, d, tmax, reach: dr.zeros(Bool, dr.width(reach)), label="drpt_cull")

    def spawn(self, si: Interaction, d: Array3f) -> Array3f:
        """The origin of a ray leaving ``si`` toward ``d`` without hitting it again."""
        return spawn_origin(si.p, si.ng, si.p_error, d)

    def skip_area_emitters(self, o: Array3f, d: Array3f, si: Interaction, active: Bool,
                           coherent: Bool | bool = False) -> Interaction:
        """``si``, the closest hit of rays ``(o, d)``, where it is on an emissive surface
        (``active`` lanes) replaced by the first hit past all emissive surfaces along the
        ray (a miss if none): Mitsuba's ``skip_area_emitters``, which ``hide_emitters`` runs
        on camera rays so that the camera sees what lies behind an area light. Each step
        spawns past the emitter it hit and intersects again, at most
        :data:`MAX_EMITTER_SKIPS` times (a lane still on an emitter then keeps that hit).
        The result's ``t`` is measured from ``o``."""
        if not self.materials.has_emission:
            return si  # (no emissive surface in the scene: nothing traced)
        skip = self.materials.is_emissive(si, active)

        def body(cur, live, k):
            nxt = self.intersect(self.spawn(cur, d), d, live, coherent=coherent)
            cur = dr.select(live, nxt, cur)
            return cur, self.materials.is_emissive(nxt, live) & (k + 1 < MAX_EMITTER_SKIPS), k + 1

        out, _, _ = dr.while_loop((si, Bool(skip), dr.zeros(UInt32, dr.width(skip))),
                                  lambda cur, live, k: live, body)
        out.t = dr.select(skip & out.valid, dr.norm(out.p - o), out.t)
        return dr.select(skip, out, si)

    # ------------------------------------------------------------ materials
    def emitted(self, si: Interaction) -> Array3f:
        """Radiance leaving ``si`` toward ``si.wi`` (zero on back faces)."""
        return self.materials.emitted(si)

    def eval_bsdf(self, si: Interaction, wo: Array3f, importance: bool = False) -> tuple[Array3f, Float]:
        """``f * |cos|`` toward world ``wo`` and the density of sampling it; with
        ``importance`` in importance mode (a light subpath's vertex:
        :meth:`~drpt.render.material.MaterialTable.eval_pdf`)."""
        return self.materials.eval_pdf(si, wo, importance)

    def eval_bsdf_rev(self, si: Interaction, wo: Array3f, importance: bool = False
                      ) -> tuple[Array3f, Float, Float]:
        """:meth:`eval_bsdf` and the reverse density (of sampling ``si.wi`` seen from
        ``wo``), in one evaluation (:meth:`~drpt.render.material.MaterialTable.eval_pdf_rev`)."""
        return self.materials.eval_pdf_rev(si, wo, importance)

    def prepare_bsdf_rev(self, si: Interaction, importance: bool = False):
        """:meth:`eval_bsdf_rev` of ``si`` as a function of ``wo``, what does not depend on
        ``wo`` traced once (:meth:`~drpt.render.material.MaterialTable.prepare_rev`)."""
        return self.materials.prepare_rev(si, importance)

    def sample_bsdf(self, si: Interaction, u1: Float, u2: Array2f):
        """A world direction and its :class:`~drpt.render.bsdf.BSDFSample`."""
        return self.materials.sample(si, u1, u2)

    def sample_bsdf_rev(self, si: Interaction, u1: Float, u2: Array2f):
        """:meth:`sample_bsdf` and the reverse density of the sampled direction (of ``si.wi``
        seen from it; 0 after a Dirac lobe), in one dispatch
        (:meth:`~drpt.render.material.MaterialTable.sample`'s ``rev``): ``(wo, bs, pdf_rev)``."""
        return self.materials.sample(si, u1, u2, rev=True)

    def eval_sample_bsdf(self, si: Interaction, wo: Array3f, u1: Float, u2: Array2f):
        """:meth:`eval_bsdf` toward ``wo`` and :meth:`sample_bsdf` from ``(u1, u2)`` in one
        material dispatch: ``(f, pdf, wo_sampled, sample)``."""
        return self.materials.eval_pdf_sample(si, wo, u1, u2)

    def is_delta(self, si: Interaction) -> Bool:
        """Lanes whose material is a delta lobe (glass, mirror)."""
        return self.materials.is_delta(si)

    def diffuse_color(self, si: Interaction, active: Bool) -> Array3f:
        """The diffuse color (Kd or its texture)."""
        return self.materials.diffuse_color(si, active)

    def albedo(self, si: Interaction, active: Bool) -> Array3f:
        """The diffuse reflectance, Mitsuba's ``eval_diffuse_reflectance`` (the albedo AOV)."""
        return self.materials.albedo(si, active)

    # ------------------------------------------------------------ emitters
    def sample_emitter(self, si: Interaction, u_sel: Float, u2: Array2f, active: Bool) -> EmitterSample:
        """One emitter chosen by the light selection from ``u_sel`` and a direction
        from ``si.p`` toward it from ``u2`` (:class:`~drpt.render.lights.EmitterSample`):
        ``pdf`` is the solid-angle density times the selection's probability (a delta
        light's: the probability alone, with ``delta`` set). Only the families the
        scene has are traced; lanes of a scene without emitters are invalid."""
        sel = self.emitter_selection
        n = dr.width(active)
        if sel.count == 0:
            z = dr.zeros(Float, n)
            return EmitterSample(Array3f(0.0, 0.0, 1.0) + Array3f(z), Array3f(si.p), Array3f(z), z,
                                 dr.zeros(Bool, n))
        ref = si.p
        k, pmf = sel.sample(u_sel, ref, active)
        fams = sel.families
        infinite = any(f.infinite for f in fams)
        out = None
        for family, off in zip(fams, sel.offsets):
            mine, slot = active, k
            if off > 0:  # (slots are numbered family by family)
                mine = mine & (k >= off)
                slot = dr.select(mine, k - off, 0)
            if off + family.count < sel.count:
                mine = mine & (k < off + family.count)
            s = family.sample_direction(ref, slot, u2, mine)
            if infinite and s.dist is None:
                s.dist = dr.norm(s.p - ref)
            if out is None:
                out = s
                continue
            merged = [dr.select(mine, getattr(s, f), getattr(out, f)) for f in ("wo", "p", "le", "pdf", "valid")]
            dist = dr.select(mine, s.dist, out.dist) if infinite else None
            delta = dr.select(mine, Bool(s.delta), Bool(out.delta)) if any(f.delta for f in fams) else False
            out = EmitterSample(*merged, dist, delta)
        if not sel.static:  # (pmf 0: the BVH found no emitter with importance at ref)
            out.pdf = out.pdf * pmf
            out.valid = out.valid & (pmf > 0.0)
        return out

    def pdf_emitter(self, si: Interaction, d: Array3f, active: Bool) -> Float:
        """The density :meth:`sample_emitter` has for what a ray of unit direction ``d``
        reached: the area emitter point ``si`` (``si.t`` from where the ray started) or,
        where the ray escaped, the sky; 0 elsewhere (no emitter, an emissive plane, a
        background color)."""
        return self.eval_emitter(si, d, active, radiance=False)[1]

    def eval_emitter(self, si: Interaction, d: Array3f, active: Bool | None, radiance: bool = True,
                     density: bool = True, ref: Array3f | None = None) -> tuple[Array3f | None, Float | None]:
        """What a ray of unit direction ``d`` sees at ``si`` (``active`` lanes; ``None``:
        every lane): the radiance an emitter sends back along it (surface emission where it
        hit, the background or the infinite emitters where it escaped; zero elsewhere) and
        :meth:`pdf_emitter`, with one lookup of each infinite emitter. ``radiance`` or
        ``density`` False: ``None`` in its place (and none of its code traced). ``ref``: the
        point the density is seen from, the path's previous vertex, which next-event
        estimation sampled from (None: where the ray started, ``si.p - d * si.t``, which is
        that vertex moved off its surface by :mod:`~drpt.render.spawn`'s offset); it matters
        where the density depends on the point (emissive triangles by solid angle, spheres'
        cones, a light BVH's selection), and MIS weighs the two techniques right only with
        the point next-event estimation used.

        The lookups run in a symbolic ``if`` on the lanes that hit an emissive surface or
        escaped (the others see nothing: zero radiance, zero density), so that a SIMD packet
        none of whose rays reached a light skips them: in a room lit by small lights and a
        window, most packets."""
        hit = si.valid if active is None else active & si.valid
        escaped = ~si.valid if active is None else active & ~si.valid
        n = dr.width(hit)

        def nothing(*_):
            return (dr.zeros(Array3f, n),) * radiance + (dr.zeros(Float, n),) * density

        def lookup(si, d, hit, escaped, *ref):
            le, pdf = self._eval_emitter(si, d, hit, escaped, radiance, density, *ref)
            return tuple(v for v in (le, pdf) if v is not None)

        refs = () if ref is None or not density else (ref,)
        emits = getattr(self.materials, "has_emission", True)
        sky = self.has_background or any(f.infinite and not f.delta for f in self.emitter_selection.families)
        if not (emits or sky):
            out = list(nothing())
        elif not self._costly_emitter_lookups():  # (the branch would cost more than it skips)
            out = list(lookup(si, d, hit, escaped, *refs))
        else:
            sees = self.materials.is_emissive(si, hit) if emits else Bool(False)
            sees = sees | escaped if sky else sees
            out = list(dr.if_stmt((si, d, hit, escaped, *refs), sees, lookup, nothing, label="drpt_eval_emitter"))
        return (out.pop(0) if radiance else None), (out.pop(0) if density else None)

    def _costly_emitter_lookups(self) -> bool:
        """Whether :meth:`eval_emitter`'s lookups are worth a symbolic ``if``: an environment
        (a texture lookup), emissive spheres (a cone's density), textured emission or a
        light selection that depends on the point. Constant emission on triangles with a
        static selection is a few gathers, cheaper than the branch (the Cornell box's path
        kernel: 3% more CPU time with it, docs/performance.md)."""
        sel = self.emitter_selection
        return (any(f.infinite and not f.delta for f in sel.families)
                or self.area_lights.has_spheres
                or self.materials.has_emission_texture
                or not sel.static)

    def _eval_emitter(self, si: Interaction, d: Array3f, hit: Bool, escaped: Bool, radiance: bool,
                      density: bool, ref: Array3f | None = None) -> tuple[Array3f | None, Float | None]:
        """:meth:`eval_emitter`'s lookups for the lanes ``hit`` (a surface) and ``escaped``."""
        sel = self.emitter_selection
        le = None
        if radiance:  # (a scene without emissive materials traces no surface emission)
            emits = getattr(self.materials, "has_emission", True)
            le = dr.select(hit, self.emitted(si), 0.0) if emits else dr.zeros(Array3f, dr.width(hit))
            if self.has_background:
                le = dr.select(escaped, Array3f(*self.background), le)
        pdf = Float(0.0) if density else None
        # (no sum to add to yet: surface densities are 0 where a ray escaped, and the reverse)
        le_zero, pdf_zero, pdf_escaped_zero = not (radiance and self.has_background), True, True
        for family, off in zip(sel.families, sel.offsets):
            if family.delta:  # (never reached by a ray)
                continue
            if not family.infinite:  # a surface: its radiance is its material's emission
                if density:
                    pdf_f = family.pdf_direction(si, d, hit, ref)
                    if not sel.static:
                        mine = hit & (pdf_f > 0.0)  # where the ray came from:
                        src = si.p - d * si.t if ref is None else ref
                        pdf_f = dr.select(mine, pdf_f * sel.pmf(family.slot_of(si.prim, mine) + off,
                                                                src, mine), 0.0)
                    pdf = pdf_f if pdf_zero else pdf + pdf_f
                    pdf_zero = False
                continue
            # at infinity: seen by the rays that escape
            le_f, pdf_f = family.eval_direction(d, escaped, density=density)
            if density:
                if not sel.static:
                    pdf_f = pdf_f * sel.pmf(UInt32(off), si.p - d * si.t if ref is None else ref, escaped)
                pdf = dr.select(escaped, pdf_f if pdf_escaped_zero else pdf + pdf_f, pdf)
                pdf_escaped_zero = False
            if radiance:
                le = dr.select(escaped, le_f if le_zero else le + le_f, le)
                le_zero = False
        return le, pdf

    def sample_area_emitter(self, si: Interaction, u_select: Float, u: Array2f,
                            active: Bool) -> EmitterSample:
        """A point on an emissive triangle or sphere (chosen by the light sampler) seen
        from ``si``, with its solid-angle density: ``pdf_area * r^2 / |cos theta_light|``
        on a triangle, the cone's density on a sphere seen from outside.
        Only the front of an emitter (its shading normal's side) emits."""
        lights = self.area_lights
        ls = lights.sample(u_select, u, active, ref=si.p if lights.has_spheres else None)
        return toward(si.p, ls, active)

    def pdf_area_emitter(self, si: Interaction, d: Array3f, active: Bool) -> Float:
        """The density :meth:`sample_area_emitter` has for the point ``si`` a
        ray of unit direction ``d`` hit (0 where ``si`` is not a sampled emitter)."""
        lights = self.area_lights
        return lights._pdf_hit(si, d, active, lights.pdf_area_table, getattr(lights, "sph_prob", None))

    def delta_emitters(self, p: Array3f):
        """One ``DeltaSample`` per point and directional light, seen from ``p``."""
        return self.delta_lights.samples(p)

    def sample_environment(self, u: Array2f, active: Bool) -> tuple[Array3f, Array3f, Float]:
        """A direction toward the sky, its radiance and solid-angle density."""
        return self.environment.sample(u, active)

    def eval_environment(self, d: Array3f, active: Bool) -> Array3f:
        """Radiance of the sky seen along unit ``d``."""
        return self.environment.eval(d, active)

    def eval_pdf_environment(self, d: Array3f, active: Bool) -> tuple[Array3f, Float]:
        """Radiance of the sky along ``d`` and the density of sampling ``d``."""
        return self.environment.eval_pdf(d, active)
