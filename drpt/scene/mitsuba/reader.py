"""The Mitsuba XML scene reader: from Mitsuba's scene graph to a drpt :class:`Scene`.

See :mod:`drpt.scene.mitsuba` for what is supported and how each plugin maps.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np

from ...aovs import parse_aovs
from ...errors import DrptError, Loc, SceneError, SceneWarning, located
from ...imageio import read_image
from ...materials.spec import MeshAttribute, Texture
from ..model import (
    MAX_COORDINATE,
    MAX_DEPTH,
    MAX_SAMPLES,
    MAX_SIZE,
    MAX_SPP,
    Background,
    DirectionalLight,
    FilmWindow,
    GridVolume,
    Material,
    Medium,
    OrthographicCamera,
    PerspectiveCamera,
    PointLight,
    ProjectorLight,
    RenderSettings,
    Scene,
    Skybox,
    Spheres,
    SpotLight,
    Triangles,
    mitsuba_sample_count,
    vertical_fov,
)
from . import geometry as geo
from .materials import BSDFSpec, Materials, default_bsdf, legacy_fields
from .nodes import Node, State

#: Parameters a plugin reads that change nothing drpt's image depends on
#: (storage formats, noise-only choices, Mitsuba bookkeeping): read silently.
_SILENT = {
    "film": ("pixel_format", "component_format", "file_format", "banner", "compensate",
             "sample_border"),
    # (scramble_seed, of older files' samplers, shapes only the noise)
    "sampler": ("scramble_seed",),
    "integrator": ("samples_per_pass", "block_size", "emitter_samples", "bsdf_samples",
                   "shading_samples"),
    "sensor": ("near_clip", "far_clip", "shutter_open", "shutter_close"),
    "shape": ("silhouette_sampling_weight",),
    # (mis_compensation: read by envmap, which Mitsuba alone reads it for)
    "emitter": ("sampling_weight", "mis_compensation"),
}

RFILTERS = {"box": (), "tent": ("radius",), "gaussian": ("stddev",)}
#: a heterogeneous medium's majorant times its box's diagonal at most (the tentative
#: collisions a ray takes across it: beyond, rendering would all but hang)
MAX_MAJORANT_DEPTH = 1e5
SAMPLERS = ("independent", "stratified", "multijitter", "orthogonal", "ldsampler")
FOV_AXES = ("x", "y", "diagonal", "smaller", "larger")


def _material(name: str, loc: Loc, spec: BSDFSpec, emission=(0.0, 0.0, 0.0)) -> Material:
    texture = None
    if isinstance(emission, Texture):  # a textured area emitter: its mean radiance for the power
        texture = emission
        img = read_image(texture.path, linear=not texture.raw)
        img = np.repeat(img, 3, axis=2) if img.shape[2] == 1 else img[..., :3]
        emission = tuple(float(x) for x in img.reshape(-1, 3).mean(0))
    return Material(name, emission=emission, loc=loc, bsdf=spec, emission_texture=texture,
                    **legacy_fields(spec))


class Reader:
    def __init__(self, path: str | Path, defines: dict[str, str] | None = None, *,
                 ignore_unsupported: bool = False, strict: bool = False):
        self.path = Path(path).expanduser().resolve()
        if not self.path.is_file():
            what = "not a regular file" if self.path.exists() else "no such file"
            raise SceneError(Loc(path), what)
        self.ignore_unsupported = ignore_unsupported
        self.strict = strict
        self.state = State(self.path, dict(defines or {}))
        self.materials = Materials(self)
        self.unread_params: list[str] = []
        self.not_read: list[str] = []  # what drpt left out or replaced, one line each
        self.defines = {k: str(v) for k, v in (defines or {}).items()}
        self.warnings: list[SceneWarning] = []
        # outputs
        self.mat_list: list[Material] = []
        self.mat_index: dict[tuple, int] = {}
        self.meshes: list[tuple[geo.Mesh, int]] = []
        self.spheres: list[tuple[np.ndarray, float, int, np.ndarray]] = []  # center, radius, material, rotation
        # the top-level shape of each entry of meshes / spheres (1-based, file order) and
        # whether a mesh is a Mitsuba mesh (else an analytic shape: prim_index 0);
        # shape_meshes: whether each top-level shape is a Mitsuba mesh (for _shape_ranks)
        self.shape_count = 0
        self.shape_meshes: list[bool] = []
        self.mesh_shapes: list[tuple[int, bool]] = []
        self.sphere_shapes: list[int] = []
        self.lights: list = []
        self.media: list[Medium] = []
        self.medium_index: dict[int, int] = {}  # medium node -> index into media
        self.camera_medium: int | None = None
        self.background = (0.0, 0.0, 0.0)
        self.camera = None
        self.settings = RenderSettings()

    # ------------------------------------------------------------ reporting
    def warn(self, loc: Loc, message: str) -> None:
        """A warning about the file at ``loc``, given once the whole file is read."""
        self.warnings.append(SceneWarning(loc, message))

    def unsupported(self, node: Node, what: str, fallback: str | None = None) -> None:
        """Refuse ``what`` at ``node`` (a SceneError), or with ``--ignore-unsupported``
        warn and go on (the caller uses ``fallback``, or leaves the node out)."""
        if not self.ignore_unsupported:
            raise node.error(f"unsupported {what} (--ignore-unsupported renders without it)")
        message = f"unsupported {what}: " + (f"using {fallback}" if fallback else "left out")
        self.warn(node.loc, message)
        self.not_read.append(located(message, node.loc))

    def drpt_ignores(self, node: Node, name: str, why: str) -> None:
        """A parameter the plugin reads that drpt does not honor."""
        node.read.add(name)
        self.unsupported(node, f"parameter '{name}' of {node.label} ({why})", fallback="its default")

    def check_unread(self, node: Node) -> None:
        silent = _SILENT.get(node.kind, ())
        for name in silent:
            node.get(name)
        names = node.unread()
        if not names:
            return
        # the warning names only what Mitsuba's plugin refuses too; a parameter that Mitsuba
        # reads and drpt does not is an unsupported one (it would change Mitsuba's image)
        refused = node.mitsuba_unread()
        if refused is not None:
            for name in [n for n in names if n not in refused]:
                self.drpt_ignores(node, name, "Mitsuba reads it, drpt does not")
            names = [n for n in names if n in refused]
            if not names:
                return
        listed = ", ".join(f"'{n}'" for n in names)
        if self.strict:
            raise node.error(f"{node.label} does not read parameter{'s' if len(names) > 1 else ''} "
                             f"{listed} (without --strict drpt ignores them)")
        self.unread_params.append(f"{listed} of {node.label} at {node.loc}")
        self.not_read.append(located(f"parameter{'s' if len(names) > 1 else ''} {listed} of "
                                     f"{node.label}: not read", node.loc))

    # ------------------------------------------------------------ the scene
    def read(self) -> Scene:
        root = self.state.root
        sensors = []
        integrators = []
        for child in root.children():
            kind = child.kind
            if kind == "sensor":
                sensors.append(child)
            elif kind == "integrator":
                integrators.append(child)
            elif kind == "shape":
                if child.plugin != "shapegroup":
                    self.shape_count += 1  # an instance is one of Mitsuba's shapes
                    self.shape_meshes.append(child.plugin in geo.MESH_PLUGINS)
                    self.shape(child, np.eye(4))
            elif kind == "emitter":
                self.emitter(child)
            elif kind in ("bsdf", "texture", "medium"):
                pass  # definitions, read where a shape refers to them
            else:
                self.unsupported(child, f"{child.label}")
        if not sensors:
            raise root.error("the scene has no <sensor> (camera)") if root.line else \
                SceneError(Loc(self.path, 1), "the scene has no <sensor> (camera)")
        if len(sensors) > 1:
            self.warn(sensors[1].loc, f"{len(sensors)} sensors: drpt renders the first "
                      f"({sensors[0].loc}), as Mitsuba's render() does by default")
        self.sensor(sensors[0])
        if integrators:
            self.integrator(integrators[0])
        # Mitsuba's Embree scene: robust triangle tests only where the file asks
        self.settings.embree_robust = bool(root.bool("embree_use_robust_intersections", False))
        self.check_unread(root)
        self.settings.defines = dict(self.defines)
        self.settings.not_read = tuple(self.not_read)
        scene = self._scene()
        self._report()
        return scene

    def _report(self) -> None:
        if self.unread_params:
            self.warn(Loc(self.path), "ignored parameters their plugins do not read (Mitsuba 3 refuses "
                      f"them; --strict makes this an error): {'; '.join(self.unread_params)}")
        for w in [*self.state.notes, *self.warnings]:
            warnings.warn(w, stacklevel=3)

    def _shape_ranks(self) -> np.ndarray:
        """File ordinal -> the shape's 1-based place in Mitsuba's ``scene.shapes()``: the
        shapes that are not meshes (spheres, disks, cylinders, instances) in file order, then
        the meshes in file order. (Mitsuba loads meshes in parallel: their order among
        themselves varies from load to load, and matches drpt's only for one mesh.)"""
        order = sorted(range(len(self.shape_meshes)), key=lambda i: (self.shape_meshes[i], i))
        rank = np.zeros(len(self.shape_meshes) + 1, np.int32)
        rank[np.array(order, np.int64) + 1] = np.arange(1, len(order) + 1)
        return rank

    def _scene(self) -> Scene:
        rank = self._shape_ranks()
        if self.meshes:
            pos = np.concatenate([m.positions for m, _ in self.meshes])
            mat = np.concatenate([np.full(len(m), k, np.int32) for m, k in self.meshes])
            normals = None
            if any(m.normals is not None for m, _ in self.meshes):
                normals = np.concatenate([m.normals if m.normals is not None else _face_normals(m.positions)
                                          for m, _ in self.meshes])
            uvs = None
            if any(m.uvs is not None for m, _ in self.meshes):
                uvs = np.concatenate([m.uvs if m.uvs is not None else np.zeros((len(m), 3, 2))
                                      for m, _ in self.meshes])
            shape = np.concatenate([np.full(len(m), i, np.int64) for i, (m, _) in enumerate(self.meshes)])
            tris = Triangles(pos, mat, normals, uvs, shape=shape)
            tris.shape_index = np.concatenate([np.full(len(m), rank[i], np.int32)
                                               for (m, _), (i, _) in zip(self.meshes, self.mesh_shapes)])
            tris.prim_index = np.concatenate([np.arange(len(m), dtype=np.int32) if real
                                              else np.zeros(len(m), np.int32)
                                              for (m, _), (_, real) in zip(self.meshes, self.mesh_shapes)])
            names = sorted({k for mesh, _ in self.meshes for k in (mesh.attributes or {})})
            for name in names:  # meshes without the attribute never read it: zeros
                c = next(mesh.attributes[name].shape[2] for mesh, _ in self.meshes
                         if name in (mesh.attributes or {}))
                tris.attributes[name] = np.concatenate(
                    [(mesh.attributes or {}).get(name, np.zeros((len(mesh), 3, c))) for mesh, _ in self.meshes])
            bad = ~np.isfinite(pos) | (np.abs(pos) > MAX_COORDINATE)
            if bad.any():
                raise SceneError(Loc(self.path), f"{int(bad.any(axis=(1, 2)).sum())} triangles have "
                                 f"coordinates beyond {MAX_COORDINATE:g} or not finite")
        else:
            tris = Triangles.empty()
        if self.spheres:
            rot = np.array([q for *_, q in self.spheres], float)
            spheres = Spheres(np.array([c for c, *_ in self.spheres], float),
                              np.array([r for _, r, *_ in self.spheres], float),
                              np.array([k for _, _, k, _ in self.spheres], np.int32),
                              rotation=None if np.allclose(rot, np.eye(3)) else rot,
                              shape_index=rank[np.array(self.sphere_shapes, np.int64)])
        else:
            spheres = Spheres.empty()
        scene = Scene(path=self.path, camera=self.camera, materials=self.mat_list, triangles=tris,
                      spheres=spheres, lights=self.lights,
                      background=Background(color=self.background), settings=self.settings,
                      media=self.media, camera_medium=self.camera_medium)
        return scene

    # ------------------------------------------------------------ sensor
    def sensor(self, node: Node) -> None:
        if node.plugin not in ("perspective", "thinlens", "orthographic"):
            self.unsupported(node, f"sensor '{node.plugin}' (drpt has perspective, thinlens and "
                             "orthographic cameras)", fallback="a perspective camera")
        film = sampler = None
        for c in node.children():
            if c.kind == "film":
                film = c
            elif c.kind == "sampler":
                sampler = c
            else:
                self.unsupported(c, f"{c.label} inside {node.label}")
        if node.is_ref("medium"):  # the medium camera rays start in
            self.camera_medium = self.medium(node.ref("medium"), f"medium of {node.label}")
        width, height = 768, 576  # Mitsuba's hdrfilm defaults
        crop = (0, 0, width, height)
        self.settings.rfilter, self.settings.rfilter_params = "gaussian", {"stddev": 0.5}
        if film is not None:
            width, height, crop = self.film(film)
        # the image is the crop window (Mitsuba's output size); the fov is the film's
        self.settings.width, self.settings.height = crop[2], crop[3]
        self.settings.spp = 4  # Mitsuba's default sampler
        if sampler is not None:
            if sampler.plugin not in SAMPLERS:
                self.unsupported(sampler, f"sampler '{sampler.plugin}'", fallback="independent samples")
                self.settings.sampler = "independent"
            else:
                self.settings.sampler = sampler.plugin
            if sampler.has("seed"):
                seed = sampler.int("seed", 0)
                if seed is None or not 0 <= seed < 1 << 64:
                    raise sampler.error(f"{sampler.label}: seed must be between 0 and 2^64 - 1, "
                                        f"got {seed}")
                self.settings.seed = seed
            spp = sampler.int("sample_count", 4)
            if spp is None or not 0 < spp <= MAX_SPP:
                raise sampler.error(f"{sampler.label}: sample_count must be between 1 and {MAX_SPP}, "
                                    f"got {spp}")
            rounded = mitsuba_sample_count(sampler.plugin, spp)
            if rounded != spp:
                if rounded > MAX_SPP:
                    raise sampler.error(f"{sampler.label}: sample_count {spp} rounds up to {rounded} "
                                        f"(as Mitsuba rounds it), beyond {MAX_SPP}")
                self.warn(sampler.loc, f"sampler '{sampler.plugin}': sample_count {spp} rounded up "
                          f"to {rounded}, as Mitsuba does")
            self.settings.spp = rounded
            if crop[2] * crop[3] * rounded > MAX_SAMPLES:
                raise sampler.error(f"{sampler.label}: {crop[2]} x {crop[3]} pixels x {rounded} samples is "
                                    f"more than drpt's 2^60")
            if sampler.plugin in ("stratified", "multijitter", "orthogonal"):
                self.settings.jitter = sampler.bool("jitter", True)
            if sampler.plugin == "orthogonal":
                strength = sampler.int("strength", 2)
                res = math.isqrt(rounded)
                if strength is None or strength < 2 or res ** strength > 1 << 31:
                    raise sampler.error(f"{sampler.label}: strength must be at least 2, with "
                                        f"{res}^strength rows at most 2^31, got {strength}")
                self.settings.strength = strength
            self.check_unread(sampler)

        aspect = width / height
        if node.plugin == "orthographic":
            if crop != (0, 0, width, height):
                self.unsupported(node, "crop window of an orthographic sensor", fallback="the whole film")
            self.camera = orthographic_from_matrix(node, node.transform("to_world"), aspect,
                                                   node.float("near_clip", 1e-2))
            self.check_unread(node)
            return
        fov, axis = field_of_view(node)
        fov_y = vertical_fov(fov, axis, aspect)
        self.settings.fov = (fov, axis)
        if not 0.0 < fov_y < 180.0 or not math.isfinite(fov_y):
            raise node.error(f"{node.label}: field of view {fov:g} ({axis}) is not in (0, 180) degrees")
        ppo = (0.0, 0.0)
        if node.plugin == "perspective":  # (Mitsuba's thinlens has none: it does not read them)
            ppo = (node.float("principal_point_offset_x", 0.0), node.float("principal_point_offset_y", 0.0))
            if not all(math.isfinite(v) for v in ppo):
                raise node.error(f"{node.label}: principal_point_offset must be finite, got {ppo}")
        window = None
        if ppo != (0.0, 0.0) or crop != (0, 0, width, height):
            window = FilmWindow(width, height, crop[0], crop[1], crop[2], crop[3], ppo[0], ppo[1])
        lens = {}
        if node.plugin == "thinlens":
            radius = node.float("aperture_radius", 0.0)
            # Mitsuba's focus distance defaults to the far clip plane (1e4)
            focus = node.float("focus_distance", node.float("far_clip", 1e4))
            if not (radius >= 0 and math.isfinite(radius)) or not (focus > 0 and math.isfinite(focus)):
                raise node.error(f"{node.label}: needs aperture_radius >= 0 and focus_distance > 0")
            if radius:
                lens = {"aperture_radius": radius, "focus_distance": focus}
        m = node.transform("to_world")
        self.camera = camera_from_matrix(node, m, fov_y, **lens)
        near = node.float("near_clip", 1e-2)
        if not (math.isfinite(near) and near >= 0):
            raise node.error(f"{node.label}: near_clip must be >= 0, got {near}")
        self.camera.near_clip = near
        if window is not None:
            self.camera.window = window
        self.check_unread(node)

    def film(self, node: Node) -> tuple[int, int, tuple[int, int, int, int]]:
        if node.plugin != "hdrfilm":
            self.unsupported(node, f"film '{node.plugin}'", fallback="an hdrfilm")
        width = node.int("width", 768)
        height = node.int("height", 576)
        if width is None or height is None or not (0 < width <= MAX_SIZE and 0 < height <= MAX_SIZE):
            raise node.error(f"{node.label}: width and height must be between 1 and {MAX_SIZE}, "
                             f"got {width} x {height}")
        cx, cy = node.int("crop_offset_x", 0), node.int("crop_offset_y", 0)
        cw, ch = node.int("crop_width", width), node.int("crop_height", height)
        if cx < 0 or cy < 0 or cw <= 0 or ch <= 0 or cx + cw > width or cy + ch > height:
            raise node.error(f"{node.label}: crop window ({cx}, {cy}) + ({cw}, {ch}) is outside the "
                             f"{width} x {height} film")
        for c in node.children():
            if c.kind == "reconstructionfilter":
                if c.plugin not in RFILTERS:
                    self.unsupported(c, f"reconstruction filter '{c.plugin}'", fallback="gaussian")
                    continue
                params = {}
                for name in RFILTERS[c.plugin]:
                    v = c.float(name)
                    if v is not None:
                        if not (v > 0 and math.isfinite(v)):
                            raise c.error(f"{c.label}: {name} must be positive, got {v}")
                        params[name] = v
                self.settings.rfilter, self.settings.rfilter_params = c.plugin, params
                self.check_unread(c)
            else:
                self.unsupported(c, f"{c.label} inside {node.label}")
        self.check_unread(node)
        return width, height, (cx, cy, cw, ch)

    # ------------------------------------------------------------ integrator
    def integrator(self, node: Node) -> None:
        s = self.settings
        if node.plugin == "moment":
            # Mitsuba's moment: renders its first nested integrator's image and records
            # the XYZ value and its square of every nested one's samples as AOVs
            nested = [(k, c) for k, c in node.objects() if c.kind == "integrator"]
            for _, c in node.objects():
                if c.kind != "integrator":
                    raise c.error(f"{c.label} inside {node.label} (it takes integrators)")
            if not nested:
                raise node.error(f"{node.label} needs a nested integrator")
            for _, c in nested[1:]:
                self.unsupported(c, f"a second integrator inside {node.label} (drpt records the "
                                 "moments of the first)")
            self.check_unread(node)
            s.moment = nested[0][0]
            self.integrator(nested[0][1])
            return
        if node.plugin == "aov":
            # Mitsuba's aov: its first nested integrator renders the image; the AOVs named
            # by ``aovs`` (name:type pairs) become EXR layers (drpt.aovs)
            nested = [(k, c) for k, c in node.objects() if c.kind == "integrator"]
            for _, c in node.objects():
                if c.kind != "integrator":
                    raise c.error(f"{c.label} inside {node.label} (it takes integrators)")
            for _, c in nested[1:]:
                self.unsupported(c, f"a second integrator inside {node.label} (drpt renders "
                                 "the first)")
            try:
                s.aovs = parse_aovs(node.str("aovs", "") or "", f"{node.label}: aovs")
            except DrptError as e:
                raise node.error(str(e)) from None
            self.check_unread(node)
            if nested:
                s.aov_image = nested[0][0]
                self.integrator(nested[0][1])
            return
        if node.plugin not in ("path", "direct", "ptracer", "volpath", "volpathmis"):
            self.unsupported(node, f"integrator '{node.plugin}' (drpt has path, volpath, volpathmis, "
                             "direct and ptracer)", fallback="path")
            return
        # Mitsuba's volpathmis: drpt's volpath, whose free-flight sampling already is spectral MIS
        # over the channels and whose shadow rays get the transmittance exactly (the same
        # expectation as volpathmis's tracked, spectrally weighted estimate)
        s.integrator = {"ptracer": "ptracer", "volpath": "volpath", "volpathmis": "volpath"}.get(node.plugin, "path")
        if node.plugin in ("path", "ptracer", "volpath", "volpathmis"):
            s.max_depth = node.int("max_depth", -1)
            s.origin["max_depth"] = node.loc
            s.rr_depth = node.int("rr_depth", 5)
            if s.max_depth is not None and not -1 <= s.max_depth <= MAX_DEPTH:
                raise node.error(f"{node.label}: max_depth must be -1 or between 0 and {MAX_DEPTH}, "
                                 f"got {s.max_depth}")
            if s.rr_depth is not None and not 0 < s.rr_depth <= MAX_DEPTH:
                raise node.error(f"{node.label}: rr_depth must be between 1 and {MAX_DEPTH}, "
                                 f"got {s.rr_depth}")
        else:
            # Mitsuba's direct: emitters seen by the camera plus direct lighting, the same
            # expectation as path with max_depth 2 (its sample counts only change the noise)
            s.max_depth = 2
            s.rr_depth = 5
        s.hide_emitters = node.bool("hide_emitters", False)
        if node.has("timeout"):
            self.drpt_ignores(node, "timeout", "drpt renders all samples")
        for c in node.children():
            self.unsupported(c, f"{c.label} inside {node.label}")
        self.check_unread(node)

    # ------------------------------------------------------------ shapes
    def _shape_parts(self, node: Node) -> tuple[BSDFSpec, Node | None, tuple]:
        bsdf_node = None
        spec = None
        emission = (0.0, 0.0, 0.0)
        for c in node.children():
            if c.kind == "bsdf":
                if spec is not None:
                    raise c.error(f"{node.label} has more than one BSDF")
                bsdf_node, spec = c, self.materials.spec(c)
            elif c.kind == "emitter":
                if c.plugin != "area":
                    raise c.error(f"{c.label} cannot be attached to a shape (only 'area' can)")
                emission = self.area(c)
            else:
                self.unsupported(c, f"{c.label} inside {node.label}")
        media = tuple(self.medium(node.ref(name), f"{name} of {node.label}") if node.is_ref(name) else None
                      for name in ("interior", "exterior"))
        if spec is None:
            # Mitsuba's default: diffuse 0.5, black on a shape with an area emitter
            spec = default_bsdf(black=isinstance(emission, Texture) or max(emission) > 0)
        return spec, bsdf_node, (emission, media)

    def medium(self, node: Node, where: str) -> int | None:
        """The index in :attr:`media` of the medium ``node`` (read once), or ``None`` where
        drpt cannot render it and ``--ignore-unsupported`` leaves it out."""
        if node.index in self.medium_index:
            return self.medium_index[node.index]
        if node.kind != "medium":
            raise node.error(f"{node.label} as the {where} (it takes a medium)")
        if node.plugin not in ("homogeneous", "heterogeneous"):
            self.unsupported(node, f"{node.label} ({where}; drpt has homogeneous and heterogeneous media)")
            self.medium_index[node.index] = None
            return None
        values, grids = {}, {}
        for name, default in (("sigma_t", (1.0, 1.0, 1.0)), ("albedo", (0.75, 0.75, 0.75))):
            values[name] = default
            if not node.is_ref(name):
                values[name] = node.color(name, default)
                continue
            vol = node.ref(name)
            if vol.kind == "volume" and vol.plugin == "constvolume":
                values[name] = vol.color("value", (1.0, 1.0, 1.0))
                self.check_unread(vol)
            elif vol.kind == "volume" and vol.plugin == "gridvolume" and node.plugin == "heterogeneous":
                grid = self.grid_volume(vol)
                if name == "sigma_t" and grid.data.shape[3] != 1:
                    self.unsupported(vol, f"{vol.label} with {grid.data.shape[3]} channels as 'sigma_t' "
                                     "(drpt's heterogeneous extinction has one)", fallback="1")
                    continue
                grids[name] = grid
            else:
                self.unsupported(vol, f"{vol.label} as '{name}' of {node.label}", fallback=str(default))
        sigma_t, albedo = values["sigma_t"], values["albedo"]
        if "albedo" in grids and not (grids["albedo"].data.min() >= 0.0 and grids["albedo"].data.max() <= 1.0):
            raise node.error(f"{node.label}: the albedo grid's values must be in [0, 1]")
        if "sigma_t" in grids and not (np.isfinite(grids["sigma_t"].data).all()
                                       and grids["sigma_t"].data.min() >= 0.0):
            raise node.error(f"{node.label}: the sigma_t grid's values must be finite and >= 0")
        scale = node.float("scale", 1.0)
        if not all(math.isfinite(x) and x >= 0 for x in sigma_t):
            raise node.error(f"{node.label}: sigma_t must be finite and >= 0, got {tuple(sigma_t)}")
        if not all(0.0 <= x <= 1.0 for x in albedo):
            raise node.error(f"{node.label}: albedo must be in [0, 1], got {tuple(albedo)}")
        if not (math.isfinite(scale) and scale >= 0):
            raise node.error(f"{node.label}: scale must be finite and >= 0, got {scale}")
        if not all(math.isfinite(x * scale) and x * scale <= 1e30 for x in sigma_t):
            raise node.error(f"{node.label}: sigma_t * scale must be at most 1e30")
        if not node.bool("sample_emitters", True):
            self.drpt_ignores(node, "sample_emitters", "drpt always samples emitters in media")
        phase, g, g2, blend = "isotropic", 0.0, 0.0, 0.0
        for c in node.children():
            if c.kind != "phasefunction":
                self.unsupported(c, f"{c.label} inside {node.label}")
            elif c.plugin == "blendphase":
                kids = [k for k in c.children() if k.kind == "phasefunction"]
                if len(kids) != 2:
                    raise c.error(f"{c.label} needs 2 nested phase functions, got {len(kids)}")
                if c.is_ref("weight"):
                    self.unsupported(c.ref("weight"), f"{c.ref('weight').label} as the weight of {c.label}",
                                     fallback="0.5")
                    blend = 0.5
                else:
                    blend = c.float("weight", 0.5)
                if not 0.0 <= blend <= 1.0:
                    raise c.error(f"{c.label}: weight must be in [0, 1], got {blend}")
                g, g2 = self._phase_lobe(kids[0]), self._phase_lobe(kids[1])
                phase = "blend"
                self.check_unread(c)
            else:
                g = self._phase_lobe(c)
                phase = "hg" if c.plugin == "hg" else "isotropic"
        self.check_unread(node)
        self.medium_index[node.index] = len(self.media)
        medium = Medium(node.id or f"{node.plugin}@{node.line}", tuple(sigma_t), tuple(albedo),
                        scale, phase, g, node.loc, g2=g2, blend=blend)
        if "sigma_t" in grids:  # (a constant extinction: a homogeneous medium, any albedo grid aside)
            medium.sigma_t_grid, medium.albedo_grid = grids["sigma_t"], grids.get("albedo")
            majorant = medium.sigma_t_grid.max * scale
            corners = np.array([[x, y, z, 1.0] for x in (0, 1) for y in (0, 1) for z in (0, 1)]) @ \
                np.linalg.inv(medium.sigma_t_grid.to_local).T
            depth = majorant * float(np.linalg.norm(corners[:, :3].max(0) - corners[:, :3].min(0)))
            if not depth <= MAX_MAJORANT_DEPTH:
                raise node.error(f"{node.label}: the grid's maximum sigma_t * scale times its box's "
                                 f"diagonal is {depth:.3g}; drpt's delta tracking takes about that many "
                                 f"steps across it and refuses more than {MAX_MAJORANT_DEPTH:g}")
        elif "albedo" in grids:
            self.unsupported(node, f"{node.label} with an albedo grid and a constant sigma_t",
                             fallback="the constant albedo")
        self.media.append(medium)
        return self.medium_index[node.index]

    def _phase_lobe(self, c: Node) -> float:
        """The ``g`` of an ``isotropic`` (0) or ``hg`` phase function."""
        if c.plugin == "hg":
            g = c.float("g", 0.8)
            if not -1.0 < g < 1.0:
                raise c.error(f"{c.label}: g must be in (-1, 1), got {g}")
            self.check_unread(c)
            return g
        if c.plugin != "isotropic":
            self.unsupported(c, f"phase function '{c.plugin}' (drpt has isotropic, hg and blendphase "
                             "of those)", fallback="isotropic")
        else:
            self.check_unread(c)
        return 0.0

    def grid_volume(self, node: Node) -> GridVolume:
        """Mitsuba's ``gridvolume`` from a ``.vol`` file (binary, version 3, float32)."""
        path = node.resolve_file(node.str("filename") or "")
        try:
            raw = Path(path).read_bytes()
        except OSError as e:
            raise node.error(f"{node.label}: {path}: {e.strerror}") from None
        if len(raw) < 48 or raw[:3] != b"VOL" or raw[3] != 3:
            raise node.error(f"{node.label}: {path} is not a version 3 .vol file")
        enc, nx, ny, nz, nc = np.frombuffer(raw[4:24], "<i4")
        if enc != 1:
            raise node.error(f"{node.label}: {path}: only float32 grids (encoding 1) are read, got {enc}")
        if min(nx, ny, nz) < 1 or nc not in (1, 3) or len(raw) != 48 + 4 * int(nx) * ny * nz * nc:
            raise node.error(f"{node.label}: {path}: bad size ({nx} x {ny} x {nz}, {nc} channels, "
                             f"{len(raw)} bytes)")
        bbox = np.frombuffer(raw[24:48], "<f4").astype(np.float64)
        data = np.frombuffer(raw[48:], "<f4").reshape(int(nz), int(ny), int(nx), int(nc)).copy()
        if not np.isfinite(data).all():
            raise node.error(f"{node.label}: {path}: values are not finite")
        to_world = node.transform("to_world")
        _check_matrix(node, to_world)
        to_local = np.linalg.inv(to_world)
        if node.bool("use_grid_bbox", False):
            lo, hi = bbox[:3], bbox[3:]
            if not np.all(hi > lo):
                raise node.error(f"{node.label}: {path}: its bounding box is empty")
            m = np.diag([*(1.0 / (hi - lo)), 1.0])
            m[:3, 3] = -lo / (hi - lo)
            to_local = m @ to_local
        filt = node.str("filter_type", "trilinear")
        wrap = node.str("wrap_mode", "clamp")
        if filt not in ("trilinear", "nearest"):
            raise node.error(f"{node.label}: filter_type must be trilinear or nearest, got {filt!r}")
        if wrap not in ("clamp", "repeat", "mirror"):
            raise node.error(f"{node.label}: wrap_mode must be clamp, repeat or mirror, got {wrap!r}")
        node.get("accel")
        node.bool("raw", False)  # (RGB variants read the values as given either way)
        self.check_unread(node)
        return GridVolume(data, to_local, filt, wrap)

    def _material_index(self, spec: BSDFSpec, bsdf_node: Node | None, parts, shape: Node) -> int:
        emission, (interior, exterior) = parts
        key = (bsdf_node.index if bsdf_node is not None else None, emission, interior, exterior)
        if key not in self.mat_index:
            if bsdf_node is not None:
                name = bsdf_node.id or f"{bsdf_node.plugin}@{bsdf_node.line}"
                loc = bsdf_node.loc
            else:
                name, loc = "default", shape.loc
            if isinstance(emission, Texture) or max(emission) > 0:
                name += "+area"
            self.mat_index[key] = len(self.mat_list)
            mat = _material(name, loc, spec, emission)
            mat.interior, mat.exterior = interior, exterior
            self.mat_list.append(mat)
        return self.mat_index[key]

    def shape(self, node: Node, parent: np.ndarray) -> None:
        plugin = node.plugin
        if plugin == "instance":
            groups = [c for c in node.children() if c.kind == "shape" and c.plugin == "shapegroup"]
            if len(groups) != 1:
                raise node.error(f"{node.label} needs one shapegroup, got {len(groups)}")
            m = parent @ node.transform("to_world")
            self.check_unread(node)
            group = groups[0]
            for c in group.children():
                if c.kind != "shape":
                    self.unsupported(c, f"{c.label} inside {group.label}")
                elif c.plugin in ("shapegroup", "instance"):
                    raise c.error(f"{c.label}: shapegroups cannot nest (as in Mitsuba)")
                else:
                    self.shape(c, m)
            self.check_unread(group)
            return
        if plugin not in geo.MESH_PLUGINS + geo.ANALYTIC_PLUGINS:
            self.unsupported(node, f"shape '{plugin}'")
            return
        spec, bsdf_node, parts = self._shape_parts(node)
        emission = parts[0]
        k = self._material_index(spec, bsdf_node, parts, node)
        first = len(self.meshes)
        m = parent @ node.transform("to_world")
        _check_matrix(node, m)
        attrs = sorted({t.name for t in spec.textures() if isinstance(t, MeshAttribute)})
        if attrs and plugin not in geo.MESH_PLUGINS:
            raise node.error(f"{node.label} has no mesh attributes (its BSDF reads '{attrs[0]}')")
        if plugin in geo.MESH_PLUGINS:
            mesh = geo.load_mesh(node, m, attrs)
            if len(mesh):
                self.meshes.append((mesh, k))
                self.mesh_shapes.append((self.shape_count, True))
            else:
                self.warn(node.loc, f"{node.label} has no faces")
        elif plugin == "sphere":
            center = node.vector("center", (0.0, 0.0, 0.0))
            radius = node.float("radius", 1.0)
            if not radius > 0:
                raise node.error(f"{node.label}: radius must be positive, got {radius}")
            flip = bool(node.bool("flip_normals", False))
            local = geo.sphere_local(center, radius, m)
            similar, scale = geo.is_similarity(local)
            mirrored = np.linalg.det(local[:3, :3]) < 0
            textured = bool(spec.textures()) or isinstance(emission, Texture)
            if not np.abs(local[:3, 3]).max() + abs(scale) <= MAX_COORDINATE:
                raise node.error(f"{node.label}: extends beyond {MAX_COORDINATE:g} (center "
                                 f"{tuple(float(x) for x in local[:3, 3])}, radius {scale:g})")
            if similar and not (flip ^ mirrored) and not textured:
                self.spheres.append((local[:3, 3].copy(), scale, k, local[:3, :3] / scale))
                self.sphere_shapes.append(self.shape_count)
            else:
                why = ("flip_normals" if (flip ^ mirrored) else "a to_world that is not a similarity"
                       if not similar else "a texture (drpt's analytic spheres have no uvs)")
                self.warn(node.loc, f"{node.label} with {why} is tessellated "
                          f"({geo.SPHERE_STACKS}x{geo.SPHERE_SLICES} quads)")
                self.meshes.append((geo.tessellate_sphere(local, flip ^ mirrored), k))
                self.mesh_shapes.append((self.shape_count, False))
        elif plugin == "disk":
            flip = bool(node.bool("flip_normals", False))
            self.meshes.append((geo.tessellate_disk(m, flip), k))
            self.mesh_shapes.append((self.shape_count, False))
        elif plugin == "cylinder":
            p0 = node.vector("p0", (0.0, 0.0, 0.0))
            p1 = node.vector("p1", (0.0, 0.0, 1.0))
            radius = node.float("radius", 1.0)
            if not radius > 0 or np.allclose(p0, p1):
                raise node.error(f"{node.label}: needs radius > 0 and p0 != p1")
            flip = bool(node.bool("flip_normals", False))
            local = m @ geo.cylinder_frame(p0, p1, radius)
            self.meshes.append((geo.tessellate_cylinder(local, flip), k))
            self.mesh_shapes.append((self.shape_count, False))
        for mesh, _ in self.meshes[first:]:
            _check_coordinates(node, mesh)
        self.check_unread(node)

    # ------------------------------------------------------------ emitters
    def area(self, node: Node):
        """An area emitter's radiance: an RGB triple, or a bitmap :class:`Texture`."""
        if node.is_ref("radiance"):
            tex = self._emitter_texture(node, "radiance")
            self.check_unread(node)
            return tex if tex is not None else (1.0, 1.0, 1.0)
        le = node.color("radiance", (1.0, 1.0, 1.0), emission=True)
        _nonnegative(node, "radiance", le)
        self.check_unread(node)
        return le

    def emitter(self, node: Node) -> None:
        p = node.plugin
        m = node.transform("to_world") if node.has("to_world") else None
        if p == "area":
            raise node.error(f"{node.label} must be attached to a shape")
        if p == "point":
            if node.has("position") and m is not None:
                raise node.error(f"{node.label}: give 'position' or 'to_world', not both")
            pos = node.vector("position") or (tuple(m[:3, 3]) if m is not None else (0.0, 0.0, 0.0))
            if not max(abs(x) for x in pos) <= MAX_COORDINATE:
                raise node.error(f"{node.label}: position {pos} is beyond {MAX_COORDINATE:g} or not finite")
            color = self._intensity(node, "intensity")
            self.lights.append(PointLight(tuple(float(x) for x in pos), color, loc=node.loc))
        elif p == "spot":
            m = np.eye(4) if m is None else m
            similar, _ = geo.is_similarity(m)
            if not np.isfinite(m).all() or not np.abs(m[:3, 3]).max() <= MAX_COORDINATE:
                raise node.error(f"{node.label}: position beyond {MAX_COORDINATE:g} or not finite")
            if not similar:
                raise node.error(f"{node.label}: to_world must be a rotation and translation")
            color = self._intensity(node, "intensity")
            texture = self._emitter_texture(node, "texture") if node.is_ref("texture") else None
            cutoff = node.float("cutoff_angle", 20.0)
            beam = node.float("beam_width", cutoff * 0.75)
            if not 0 < beam <= cutoff < 180:
                raise node.error(f"{node.label}: needs 0 < beam_width <= cutoff_angle < 180, "
                                 f"got {beam:g} and {cutoff:g}")
            axis = m[:3, 2] / np.linalg.norm(m[:3, 2])
            frame = m[:3, :3] / np.linalg.norm(m[:3, :3], axis=0)
            self.lights.append(SpotLight(tuple(float(x) for x in m[:3, 3]), tuple(float(x) for x in axis),
                                         color, cutoff, beam, texture=texture,
                                         frame=tuple(float(x) for x in frame.ravel()), loc=node.loc))
        elif p == "projector":
            self.projector(node, np.eye(4) if m is None else m)
        elif p == "directional":
            if node.has("direction") and m is not None:
                raise node.error(f"{node.label}: give 'direction' or 'to_world', not both")
            d = node.vector("direction")
            if d is None:
                d = tuple(m[:3, 2]) if m is not None else (0.0, 0.0, 1.0)
            if not np.linalg.norm(d) > 0 or not np.isfinite(d).all():
                raise node.error(f"{node.label}: direction has zero length or is not finite")
            e = node.color("irradiance", (1.0, 1.0, 1.0), emission=True) if not node.is_ref("irradiance") else None
            if e is None:
                self.unsupported(node.ref("irradiance"), "textured irradiance", fallback="1")
                e = (1.0, 1.0, 1.0)
            _nonnegative(node, "irradiance", e)
            self.lights.append(DirectionalLight(tuple(float(x) for x in d), e, loc=node.loc))
        elif p == "constant":
            if node.is_ref("radiance"):
                self.unsupported(node.ref("radiance"), "textured constant emitter", fallback="1")
                le = (1.0, 1.0, 1.0)
            else:
                le = node.color("radiance", (1.0, 1.0, 1.0), emission=True)
            _nonnegative(node, "radiance", le)
            self._environment(node)
            self.background = tuple(a + b for a, b in zip(self.background, le))
        elif p == "envmap":
            self._environment(node)
            filename = node.str("filename")
            if filename is None:
                self.unsupported(node, "envmap without 'filename'")
                return
            path = node.resolve_file(filename)
            scale = node.float("scale", 1.0)
            if not (scale >= 0 and math.isfinite(scale)):
                raise node.error(f"{node.label}: scale must be >= 0, got {scale}")
            rot = None
            if m is not None:
                similar, s = geo.is_similarity(m)
                r = m[:3, :3] / s if s else m[:3, :3]
                if not similar or np.linalg.det(r) < 0:
                    raise node.error(f"{node.label}: to_world must be a rotation (no scale or mirror)")
                if not np.allclose(r, np.eye(3), atol=1e-12):
                    rot = r
            # Mitsuba's envmap is infinitely far; drpt's Skybox radius only feeds a warning
            self.lights.append(Skybox(path, radius=1e30, scale=scale, rotation=rot,
                                      mis_compensation=node.bool("mis_compensation"), loc=node.loc))
        else:
            self.unsupported(node, f"emitter '{p}'")
            return
        self.check_unread(node)

    def _emitter_texture(self, node: Node, name: str):
        """The bitmap of an emitter's texture parameter (a :class:`drpt.materials.spec.Texture`)."""
        tex = node.ref(name)
        spec = self.materials.texture(tex, fallback=(1.0, 1.0, 1.0)) if tex.kind == "texture" else None
        if type(spec) is not Texture:
            self.unsupported(tex, f"{tex.label} as '{name}' of {node.label} (drpt reads a bitmap there)",
                             fallback="1")
            return None
        return spec

    def projector(self, node: Node, m: np.ndarray) -> None:
        """Mitsuba's ``projector`` (:class:`~drpt.scene.model.ProjectorLight`)."""
        similar, s = geo.is_similarity(m)
        if not similar or not math.isclose(s, 1.0, rel_tol=1e-5) or np.linalg.det(m[:3, :3]) < 0:
            raise node.error(f"{node.label}: to_world must be a rotation and translation")
        aspect = 1.0
        if node.is_ref("irradiance"):
            irr = self._emitter_texture(node, "irradiance")
            if irr is None:
                irr = (1.0, 1.0, 1.0)
            else:
                h, w = read_image(irr.path, linear=False).shape[:2]
                aspect = w / h
        else:
            irr = node.color("irradiance", (1.0, 1.0, 1.0), emission=True)
            _nonnegative(node, "irradiance", irr)
        scale = node.float("scale", 1.0)
        if not (math.isfinite(scale) and scale >= 0):
            raise node.error(f"{node.label}: scale must be >= 0, got {scale}")
        fov, axis = field_of_view(node)
        fov_y = vertical_fov(fov, axis, aspect)
        if not 0.0 < fov_y < 180.0:
            raise node.error(f"{node.label}: field of view {fov:g} ({axis}) is not in (0, 180) degrees")
        fov_x = 2.0 * math.degrees(math.atan(math.tan(math.radians(fov_y) / 2.0) * aspect))
        self.lights.append(ProjectorLight(tuple(float(x) for x in m[:3, 3]),
                                          tuple(float(x) for x in m[:3, :3].ravel()), fov_x, irr,
                                          aspect, scale, loc=node.loc))

    def _environment(self, node: Node) -> None:
        seen = getattr(self, "_env_node", None)
        if seen is not None:
            raise node.error(f"only one environment emitter per scene (as in Mitsuba; the first is "
                             f"at {seen.loc})")
        self._env_node = node

    def _intensity(self, node: Node, name: str) -> tuple:
        if node.is_ref(name):
            self.unsupported(node.ref(name), f"textured {name}", fallback="1")
            return (1.0, 1.0, 1.0)
        c = node.color(name, (1.0, 1.0, 1.0), emission=True)
        _nonnegative(node, name, c)
        return c


def _nonnegative(node: Node, name: str, c) -> None:
    if not all(math.isfinite(x) and x >= 0 for x in c):
        raise node.error(f"{node.label}: {name} must be finite and >= 0, got {tuple(c)}")


def _check_coordinates(node: Node, mesh) -> None:
    """A mesh in world space within drpt's coordinate limit (float32 rendering),
    with finite normals and uvs (a degenerate transform makes them NaN)."""
    bad = ~np.isfinite(mesh.positions) | (np.abs(mesh.positions) > MAX_COORDINATE)
    if bad.any():
        raise node.error(f"{node.label}: {int(bad.any(axis=(1, 2)).sum())} triangles have coordinates "
                         f"beyond {MAX_COORDINATE:g} or not finite")
    for name in ("normals", "uvs"):
        a = getattr(mesh, name)
        if a is not None and not np.isfinite(a).all():
            raise node.error(f"{node.label}: its {name} are not finite (a degenerate to_world or radius?)")


def _check_matrix(node: Node, m: np.ndarray) -> None:
    if not np.all(np.isfinite(m)):
        raise node.error(f"{node.label}: to_world is not finite")
    if abs(np.linalg.det(m[:3, :3])) < 1e-300:
        raise node.error(f"{node.label}: to_world is singular")


def _face_normals(p: np.ndarray) -> np.ndarray:
    g = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    n = np.linalg.norm(g, axis=1, keepdims=True)
    g = g / np.where(n > 0, n, 1.0)
    return np.repeat(g[:, None, :], 3, axis=1)


def orthographic_from_matrix(node: Node, m: np.ndarray, aspect: float,
                             near_clip: float) -> OrthographicCamera:
    """drpt's camera for Mitsuba's ``orthographic`` sensor: camera-space ``x`` in [-1, 1]
    (the image's left at +1) and ``y`` in [-1/aspect, 1/aspect] of the film, mapped by
    ``to_world`` (a rotation times a scale ``(sx, sy, sz)``: the view is ``2 sx`` wide and
    ``2 sy / aspect`` high), rays along its ``+z`` starting on the near plane ``z =
    near_clip`` (Mitsuba's ``orthographic_projection``)."""
    if not np.all(np.isfinite(m)):
        raise node.error(f"{node.label}: to_world is not finite")
    a = m[:3, :3]
    scale = np.linalg.norm(a, axis=0)
    if not np.all(scale > 0) or not np.allclose((a / scale).T @ (a / scale), np.eye(3), atol=1e-4):
        raise node.error(f"{node.label}: the orthographic sensor's to_world must be a rotation "
                         "times a scale along the camera's axes")
    if np.linalg.det(a) < 0:
        raise node.error(f"{node.label}: the camera's to_world mirrors the image (a negative scale); "
                         "drpt's camera cannot")
    if not (math.isfinite(near_clip) and near_clip >= 0):
        raise node.error(f"{node.label}: near_clip must be >= 0, got {near_clip}")
    center = m[:3, 3] + near_clip * a[:, 2]
    if max(abs(float(x)) for x in center) > MAX_COORDINATE:
        raise node.error(f"{node.label}: camera position beyond {MAX_COORDINATE:g}")
    sx, sy = float(scale[0]), float(scale[1])
    return OrthographicCamera(center=tuple(float(x) for x in center),
                              direction=tuple(float(x) for x in a[:, 2] / scale[2]),
                              up=tuple(float(x) for x in a[:, 1] / scale[1]),
                              size=2.0 * sy / aspect,
                              width=None if math.isclose(sx, sy, rel_tol=1e-6) else 2.0 * sx)


def camera_from_matrix(node: Node, m: np.ndarray, fov_y: float, **lens) -> PerspectiveCamera:
    """drpt's camera for Mitsuba's camera-to-world matrix: Mitsuba looks along local
    +z with +y up and +x to the image's *left* (``lookat`` builds columns ``(left, up,
    forward)``), drpt along ``direction`` with ``right = direction x up``; the two agree
    when the matrix is a rotation. A mirroring matrix (the image flipped left to
    right) has no drpt counterpart."""
    if not np.all(np.isfinite(m)):
        raise node.error(f"{node.label}: to_world is not finite")
    a = m[:3, :3]
    lengths = np.linalg.norm(a, axis=0)
    if not np.allclose(lengths, 1.0, atol=1e-4) or not np.allclose(a.T @ a, np.eye(3), atol=1e-4):
        raise node.error(f"{node.label}: scale factors in the camera's to_world are not allowed "
                         "(as in Mitsuba)")
    if np.linalg.det(a) < 0:
        raise node.error(f"{node.label}: the camera's to_world mirrors the image (a negative scale); "
                         "drpt's camera cannot")
    center = tuple(float(x) for x in m[:3, 3])
    if max(abs(x) for x in center) > MAX_COORDINATE:
        raise node.error(f"{node.label}: camera position beyond {MAX_COORDINATE:g}")
    return PerspectiveCamera(center=center, direction=tuple(float(x) for x in a[:, 2]),
                             up=tuple(float(x) for x in a[:, 1]), fov=float(fov_y), **lens)


def field_of_view(node: Node) -> tuple[float, str]:
    """``(fov, axis)`` of a perspective sensor or a projector: its ``fov`` and
    ``fov_axis``, or Mitsuba's conversion of ``focal_length`` (a 35 mm film's
    diagonal); a bad value is a located error."""
    if node.has("fov") and node.has("focal_length"):
        raise node.error(f"{node.label}: give 'fov' or 'focal_length', not both")
    if node.has("fov"):
        fov = node.float("fov")
        axis = (node.str("fov_axis", "x") or "x").lower()
        if not 0.0 < fov < 180.0:
            raise node.error(f"{node.label}: fov must be in (0, 180) degrees, got {fov:g}")
    else:
        f = node.str("focal_length", "50mm") or "50mm"
        try:
            value = float(f[:-2] if f.endswith("mm") else f)
        except ValueError:
            raise node.error(f"{node.label}: focal_length must be like '50mm', got {f!r}") from None
        if not (value > 0 and math.isfinite(value)):
            raise node.error(f"{node.label}: focal_length must be positive, got {f!r}")
        fov = 2.0 * math.degrees(math.atan(math.hypot(36.0, 24.0) / (2.0 * value)))
        axis = "diagonal"
    if axis not in FOV_AXES:
        raise node.error(f"{node.label}: fov_axis must be one of {', '.join(FOV_AXES)}, got {axis!r}")
    return fov, axis
