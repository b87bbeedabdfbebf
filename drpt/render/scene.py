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
  hit's own rounding-error bound, :mod:`drpt.render.spawn`);
* materials: :meth:`emitted`, :meth:`eval_bsdf`, :meth:`sample_bsdf`,
  :meth:`is_delta`, :meth:`diffuse_color`;
* emitters: :meth:`sample_area_emitter` and :meth:`pdf_area_emitter` (the
  same density, for MIS), :meth:`delta_emitters`,
  :meth:`sample_environment`, :meth:`eval_environment`,
  :meth:`eval_pdf_environment`, and :attr:`background`.

Feature flags (plain Python bools, read while a kernel is traced) say what
the scene has, so that kernels contain only the code it needs:
``has_area_lights``, ``has_delta_lights``, ``has_environment`` (a sky that
is not black), ``has_background`` (a background color above 0 and no
sky), ``has_ambient`` and ``has_smooth_bsdfs`` (some material is not a
delta lobe: without one, next-event estimation is never traced).

A scene without primitives (an empty ``Group``, an OBJ without faces) is
drawn as its background or sky: the accelerator is built as for any scene
(every kind answers "no hit" over zero primitives), the surface and
material tables are stand-ins that answer every query as a miss
(:class:`NoSurfaces`, :class:`NoMaterials`: Dr.Jit cannot gather from an
empty array), and :attr:`DeviceScene.warnings` says so once.

Each query is a method called through ``self``, so
:mod:`drpt.tools.profile` can time it by replacing the method on an
instance (:meth:`intersect` then counts as traversal plus interaction).
"""

from __future__ import annotations

import drjit as dr
from drjit.auto import Array2f, Array3f, Bool, Float, UInt32

from ..accel.protocol import INVALID
from ..options import RenderOptions
from ..scene.model import Scene, Skybox
from .bsdf import BSDFSample
from .lights.area import AreaLights
from .lights.delta import DeltaLights
from .lights.envmap import EnvironmentLight, RotatedEnvironment, UniformSphereSampling, check_radius
from .material import MaterialTable
from .spawn import origin as spawn_origin
from .surface import Interaction, SurfaceData


class EmitterSample:
    """A direction from a shading point toward a sampled emitter point:
    unit ``wo``, the radiance ``le`` arriving along it, its solid-angle
    density ``pdf`` and ``valid`` (the point faces the shading point and has
    a positive density). ``p`` is the emitter point moved off the light
    toward the shading point by its rounding-error bound
    (:func:`drpt.render.spawn.origin`): the end of the shadow ray."""

    def __init__(self, wo, p, le, pdf, valid):
        self.wo: Array3f = wo
        self.p: Array3f = p
        self.le: Array3f = le
        self.pdf: Float = pdf
        self.valid: Bool = valid


EMPTY_SCENE_WARNING = ("the scene has no primitives (no triangles, spheres or planes): "
                       "the image shows only its background or sky")


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

    def is_specular_only(self) -> bool:
        return True  # no BSDF to sample lights for: next-event estimation is not traced

    def emitted(self, si: Interaction) -> Array3f:
        return dr.zeros(Array3f, dr.width(si.valid))

    def eval_pdf(self, si: Interaction, wo: Array3f) -> tuple[Array3f, Float]:
        n = dr.width(si.valid)
        return dr.zeros(Array3f, n), dr.zeros(Float, n)

    def sample(self, si: Interaction, u1: Float, u2: Array2f) -> tuple[Array3f, BSDFSample]:
        n = dr.width(si.valid)
        up = dr.full(Array3f, [0.0, 0.0, 1.0], n)
        return up, BSDFSample(wo=Array3f(up), weight=dr.zeros(Array3f, n), pdf=dr.zeros(Float, n),
                              valid=dr.zeros(Bool, n), delta=dr.zeros(Bool, n),
                              eta=dr.full(Float, 1.0, n))

    def is_delta(self, si: Interaction) -> Bool:
        return dr.zeros(Bool, dr.width(si.valid))

    def diffuse_color(self, si: Interaction, active: Bool) -> Array3f:
        return dr.zeros(Array3f, dr.width(si.valid))

    albedo = diffuse_color


class DeviceScene:
    def __init__(self, scene: Scene, options: RenderOptions):
        from .. import llvm_tuning
        from ..accel import build_accel

        llvm_tuning.apply()  # as the CLI's backend check does, for API users too

        self.accel = build_accel(scene, kind=options.accel, resolution=options.grid_resolution,
                                 method=options.bvh_method, min_leaf=options.bvh_min_leaf,
                                 sah_threshold=options.sah_threshold)
        self.is_empty = len(scene.triangles) + len(scene.spheres) + len(scene.planes) == 0
        if self.is_empty:
            self.materials, self.surfaces = NoMaterials(), NoSurfaces()
        else:
            self.materials = MaterialTable(scene, options.bsdf)
            uv_aov = any(k == "uv" for _, k in getattr(options, "aovs", ()))
            self.surfaces = SurfaceData(scene, with_uv=self.materials.textures is not None or uv_aov,
                                        tangents=self.materials.tangents)
        self.area_lights = AreaLights(scene, self.surfaces, self.materials, sampler=options.light_sampler)
        self.delta_lights = DeltaLights(scene)
        self.warnings: list[str] = list(self.materials.notes)
        if self.is_empty:
            self.warnings.append(EMPTY_SCENE_WARNING)
        self.environment = None  # the sky as loaded (possibly black)
        skies = [light for light in scene.lights if isinstance(light, Skybox)]
        if skies:
            if len(skies) > 1:
                self.warnings.append(f"{len(skies)} Skybox lights: using the first")
            sky = skies[0]
            self.environment = EnvironmentLight.from_file(sky.path, scale=getattr(sky, "scale", 1.0))
            self.warnings += self.environment.warnings
            if options.env_sampling == "uniform":
                self.environment = UniformSphereSampling(self.environment)
            if getattr(sky, "rotation", None) is not None:
                self.environment = RotatedEnvironment(self.environment, sky.rotation)
            lo, hi = scene.bounds()
            msg = check_radius(lo, hi, skies[0].radius)
            if msg:
                self.warnings.append(msg)
        self.background = tuple(float(c) for c in scene.background.color)
        self.ambient = tuple(float(c) for c in scene.background.ambient)

        self.has_area_lights = self.area_lights.count > 0
        self.has_delta_lights = self.delta_lights.count > 0
        self.has_environment = self.environment is not None and not self.environment.is_black
        self.has_background = max(self.background) > 0.0 and not self.has_environment
        self.has_ambient = max(self.ambient) > 0.0
        self.has_smooth_bsdfs = not self.materials.is_specular_only()

    # ------------------------------------------------------------ geometry
    def intersect(self, o: Array3f, d: Array3f, active: Bool) -> Interaction:
        """The closest hit of rays ``(o, d)`` (``si.valid`` False on a miss)."""
        return self.interaction(o, d, self.intersect_preliminary(o, d, active))

    def intersect_preliminary(self, o: Array3f, d: Array3f, active: Bool):
        """The accelerator's closest hit (:class:`drpt.accel.Hit`), any distance."""
        return self.accel.intersect(o, d, Float(dr.largest(Float)), active)

    def interaction(self, o: Array3f, d: Array3f, hit) -> Interaction:
        """Position, normals, material and uv of a hit (:class:`~drpt.render.surface.Interaction`)."""
        return self.surfaces.interaction(o, d, hit)

    def occluded(self, o: Array3f, d: Array3f, tmax: Float, active: Bool) -> Bool:
        """Lanes whose ray ``(o, d)`` hits anything at ``0 < t < tmax``."""
        return self.accel.occluded(o, d, tmax, active)

    def spawn(self, si: Interaction, d: Array3f) -> Array3f:
        """The origin of a ray leaving ``si`` toward ``d`` without hitting it again."""
        return spawn_origin(si.p, si.ng, si.p_error, d)

    # ------------------------------------------------------------ materials
    def emitted(self, si: Interaction) -> Array3f:
        """Radiance leaving ``si`` toward ``si.wi`` (zero on back faces)."""
        return self.materials.emitted(si)

    def eval_bsdf(self, si: Interaction, wo: Array3f) -> tuple[Array3f, Float]:
        """``f * |cos|`` toward world ``wo`` and the density of sampling it."""
        return self.materials.eval_pdf(si, wo)

    def sample_bsdf(self, si: Interaction, u1: Float, u2: Array2f):
        """A world direction and its :class:`~drpt.render.bsdf.BSDFSample`."""
        return self.materials.sample(si, u1, u2)

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
    def sample_area_emitter(self, si: Interaction, u_select: Float, u: Array2f,
                            active: Bool) -> EmitterSample:
        """A point on an emissive triangle or sphere (chosen by the light sampler) seen
        from ``si``, with its solid-angle density: ``pdf_area * r^2 / |cos theta_light|``
        on a triangle, the cone's density on a sphere seen from outside.
        Only the front of an emitter (its shading normal's side) emits."""
        lights = self.area_lights
        ls = lights.sample(u_select, u, active,
                           ref=si.p if lights.has_spheres or lights.bvh is not None else None)
        to_light = ls.p - si.p
        dist2 = dr.squared_norm(to_light)
        wo = to_light * dr.rsqrt(dist2)
        front = dr.dot(ls.n, wo) < 0.0  # the light emits toward the shading point
        cos_light = dr.abs(dr.dot(ls.ng, wo))
        valid = active & front & (cos_light > 0.0) & (ls.pdf_area > 0.0)
        pdf = ls.pdf_area * dist2 / cos_light
        if ls.solid_angle is not None:
            pdf = dr.select(ls.solid_angle, ls.pdf_area, pdf)
        p_end = spawn_origin(ls.p, ls.ng, ls.p_error, -wo)
        return EmitterSample(wo, p_end, ls.le, pdf, valid)

    def pdf_area_emitter(self, si: Interaction, d: Array3f, active: Bool) -> Float:
        """The density :meth:`sample_area_emitter` has for the point ``si`` a
        ray of unit direction ``d`` hit (0 where ``si`` is not a sampled emitter)."""
        lights = self.area_lights
        ref = si.p - d * si.t  # where the ray came from
        prob = lights.bvh_pmf(si.prim, ref, active & si.valid) if lights.bvh is not None else None
        pdf_a = lights.pdf_area(si.prim, active, prob)
        sees_light = active & (pdf_a > 0.0)
        pdf = dr.select(sees_light, pdf_a * dr.square(si.t) / dr.abs(dr.dot(si.ng, d)), 0.0)
        if lights.has_spheres:
            is_sph, pdf_s = lights.pdf_sphere(si.prim, si.p, ref, d, si.t, active & si.valid, prob)
            pdf = dr.select(is_sph, pdf_s, pdf)
        return pdf

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
