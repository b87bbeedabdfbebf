"""The scene description: plain Python and numpy data, no rendering backend.

The parser (:mod:`drpt.scene.parser`) turns a scene file into a :class:`Scene`;
the renderer and the Mitsuba exporter only read it. Everything is flattened
into world space at load time: ``Transform`` and nested ``Group`` blocks are
applied, OBJ faces are triangulated and *unwelded* (every triangle carries its
own three corners), and materials are referenced by index into
:attr:`Scene.materials`.

Conventions
-----------
* Right-handed world space, no preferred up axis (the camera's ``up`` decides).
* ``PerspectiveCamera.fov`` is the *full* field of view in degrees measured
  across the image's **vertical** axis (height); the horizontal extent follows
  from the aspect ratio. The exporter sets Mitsuba's ``fov_axis="y"`` to match.
* ``OrthographicCamera.size`` is the full world-space height of the view.
* Colors are linear RGB floats.
* World-space coordinates (vertices, sphere centers plus radii, plane
  offsets, the camera's center and point lights) are at most
  :data:`MAX_COORDINATE` in magnitude; the loader refuses larger ones.
  A direction vector's largest component is in [1e-12, 1e12] (others are
  stored normalized).
* Materials, media, lights and skies carry ``loc``, the
  :class:`~drpt.errors.Loc` (file and line) that defined them, for messages;
  it takes no part in comparisons (two materials alike in all but their
  place compare equal).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import Loc

if TYPE_CHECKING:
    from ..materials.spec import BSDFSpec  # an annotation only: drpt.materials imports this module

Vec3 = tuple[float, float, float]

#: Largest world-space coordinate magnitude a scene may have. The renderer
#: works in float32, and the watertight triangle test multiplies three
#: coordinate differences: (2e12)^3 = 8e36 still fits below float32's 3.4e38.
MAX_COORDINATE = 1e12

# Limits of the render settings a scene file may give (and of drpt.options.RenderOptions):
MAX_SIZE = 1 << 16  # pixels per side: pixel coordinates and their jitter are float32
MAX_SPP = (1 << 32) - 1  # samples per pixel: Mitsuba's sample_count is 32-bit
MAX_SAMPLES = 1 << 60  # width * height * spp: sample indices (pass * lanes + lane) stay < 2^63


def mitsuba_sample_count(plugin: str, spp: int) -> int:
    """The samples per pixel Mitsuba's sampler ``plugin`` takes for ``sample_count`` ``spp``
    (its ``set_sample_count``): ``ldsampler`` a square power of two (at least 4),
    ``stratified`` a square, ``multijitter`` ``r (ceil(spp / r))`` with ``r = floor(sqrt(spp))``,
    ``orthogonal`` the square of a prime; ``independent`` (and any other) ``spp``."""
    if plugin == "ldsampler":
        res = 2
        while res * res < spp:
            res = 1 << res.bit_length()  # Mitsuba's round_to_power_of_two(res + 1)
        return res * res
    if plugin == "stratified":
        res = math.isqrt(spp)
        return spp if res * res == spp else (res + 1) ** 2
    if plugin == "multijitter":
        r1 = math.isqrt(spp)
        return r1 * -(-spp // r1)
    if plugin == "orthogonal":
        res = max(2, math.isqrt(spp - 1) + 1)  # the smallest res with res^2 >= spp

        def prime(x: int) -> bool:
            return all(x % d for d in range(2, math.isqrt(x) + 1))

        while not prime(res):
            res += 1
        return res * res
    return spp
MAX_DEPTH = (1 << 32) - 1  # --max-depth, --rr-depth: path depths are UInt32


# --------------------------------------------------------------------- camera
@dataclass(frozen=True)
class FilmWindow:
    """The part of the film an image shows, as Mitsuba's ``hdrfilm`` crop window
    and ``perspective`` ``principal_point_offset`` define it.

    The camera's ``fov`` belongs to the whole film of ``film_width x film_height``
    pixels (its aspect); the image is the crop window of ``width x height`` pixels
    at ``(offset_x, offset_y)``, shifted by ``(shift_x, shift_y)`` film widths and
    heights (the principal point offset): image pixel position ``(x, y)`` of a
    ``width x height`` image is the film position ``((offset_x + x) / film_width +
    shift_x, (offset_y + y) / film_height + shift_y)`` in [0, 1]^2 coordinates
    (:class:`drpt.render.camera.RayCamera`; another image size samples the same
    window at that resolution)."""

    film_width: int
    film_height: int
    offset_x: int = 0
    offset_y: int = 0
    width: int | None = None  # None: the film's
    height: int | None = None
    shift_x: float = 0.0
    shift_y: float = 0.0

    @property
    def crop_size(self) -> tuple[int, int]:
        return (self.width or self.film_width, self.height or self.film_height)

    def bounds(self) -> tuple[float, float, float, float]:
        """``(u0, v0, u1, v1)``: the window on the film, in [0, 1]^2 film coordinates."""
        w, h = self.crop_size
        u0 = self.offset_x / self.film_width + self.shift_x
        v0 = self.offset_y / self.film_height + self.shift_y
        return (u0, v0, u0 + w / self.film_width, v0 + h / self.film_height)


@dataclass
class PerspectiveCamera:
    """A pinhole camera, or with ``aperture_radius > 0`` a thin lens (depth of
    field, Mitsuba's ``thinlens``): rays leave a disk of that radius around
    ``center``, perpendicular to ``direction``, and those of one image point
    meet on the plane ``focus_distance`` ahead of ``center`` (measured along
    ``direction``), where the image is sharp."""

    center: Vec3
    direction: Vec3  # need not be normalized
    up: Vec3  # need not be orthogonal to direction
    fov: float  # full vertical field of view, degrees, in (0, 180)
    aperture_radius: float = 0.0  # lens radius, world units; 0: a pinhole
    focus_distance: float | None = None  # distance of the sharp plane; required with an aperture
    #: an off-center window of the film (Mitsuba's crop window, principal point offset); None:
    #: the whole film, centered, of the image's aspect
    window: FilmWindow | None = None
    #: Mitsuba XML's ``near_clip``: Mitsuba's camera rays start on that plane, so its ``depth``
    #: AOV is the distance from there; drpt's rays start at ``center`` (only the depth AOV
    #: reads it)
    near_clip: float = 0.0


def vertical_fov(fov: float, axis: str, aspect: float) -> float:
    """drpt's vertical field of view (degrees) for Mitsuba's ``fov`` along ``fov_axis``
    on a film of ``aspect = width / height`` (Mitsuba's ``parse_fov``, then x to y)."""
    if axis == "smaller":
        axis = "y" if aspect > 1 else "x"
    elif axis == "larger":
        axis = "x" if aspect > 1 else "y"
    t = math.tan(math.radians(fov) / 2.0)
    if axis == "y":
        ty = t
    elif axis == "x":
        ty = t / aspect
    else:  # diagonal: the half diagonal is t, the half height t / sqrt(1 + aspect^2)
        ty = t / math.sqrt(1.0 + aspect * aspect)
    return math.degrees(2.0 * math.atan(ty))



@dataclass
class OrthographicCamera:
    center: Vec3
    direction: Vec3
    up: Vec3
    size: float  # full vertical extent of the view, world units
    #: full horizontal extent, world units; None: ``size`` times the image's width / height
    width: float | None = None


Camera = PerspectiveCamera | OrthographicCamera


# ------------------------------------------------------------------ materials
@dataclass
class Material:
    """One material, from an MTL ``newmtl`` or a ``Materials{}`` entry.

    Fields keep the file's own meaning; the renderer decides how to use them.
    ``None`` means "not given in the file".
    """

    name: str
    kd: Vec3 = (0.8, 0.8, 0.8)  # diffuse albedo (MTL Kd / diffuseColor)
    ks: Vec3 = (0.0, 0.0, 0.0)  # specular color (MTL Ks / specularColor)
    ns: float = 1.0  # Phong exponent (MTL Ns / exponent)
    emission: Vec3 = (0.0, 0.0, 0.0)  # radiance (MTL Ke, Le or ke)
    roughness: float | None = None  # seed's Roughness, PBR Pr
    metalness: float | None = None  # seed's Mentalness, PBR Pm
    ior: float | None = None  # MTL Ni / indexOfRefraction
    dissolve: float = 1.0  # MTL d, or 1 - Tr
    illum: int | None = None  # MTL illum model
    reflective: Vec3 = (0.0, 0.0, 0.0)  # 6.837 reflectiveColor
    transparent: Vec3 = (0.0, 0.0, 0.0)  # 6.837 transparentColor
    map_kd: Path | None = None  # diffuse texture, absolute path
    loc: Loc | None = field(default=None, compare=False)  # where it was defined (None: built in)
    # the MTL transmission filter and the PBR extension (None: not given)
    tf: Vec3 | None = None  # MTL Tf / Kt
    sheen: float | None = None  # PBR Ps
    clearcoat: float | None = None  # PBR Pc
    clearcoat_roughness: float | None = None  # PBR Pcr
    anisotropy: float | None = None  # PBR aniso
    anisotropy_rotation: float | None = None  # PBR anisor
    maps: dict[str, Path] = field(default_factory=dict)  # other map_* by lower-case key, e.g. "pr", "d"
    given: tuple[str, ...] = ()  # lower-case keys of the statements the file gave, sorted
    bsdf: BSDFSpec | None = None  # an explicit BSDF (Mitsuba XML), used as given
    #: emitted radiance as a texture (Mitsuba's area ``radiance`` bitmap), looked up at the
    #: surface's uv; ``emission`` then holds its mean (light selection by power)
    emission_texture: Any = None
    #: the participating media on either side of the surfaces of this material (Mitsuba's
    #: shape ``interior``/``exterior``): indices into :attr:`Scene.media`, ``None`` for
    #: vacuum. Shapes with a medium on either side are *medium transitions*: a ray crossing
    #: one enters the interior when it goes against the geometric normal, else the exterior
    interior: int | None = None
    exterior: int | None = None

    @property
    def is_medium_transition(self) -> bool:
        return self.interior is not None or self.exterior is not None

    @property
    def is_emissive(self) -> bool:
        return max(self.emission) > 0.0


# ------------------------------------------------------------------- geometry
@dataclass
class Triangles:
    """All triangles of the scene, world space, unwelded.

    ``positions[f, k]`` is corner ``k`` of face ``f``. The geometric normal is
    ``cross(p1 - p0, p2 - p0)`` (counter-clockwise winding is the front).
    ``normals`` holds unit per-corner shading normals; it is ``None`` when no
    face of the scene had any, and faces without their own normals get their
    geometric normal. ``uvs`` is ``None`` when no face had texture
    coordinates; faces without get (0, 0).
    """

    positions: np.ndarray  # (F, 3, 3) float64
    material: np.ndarray  # (F,) int32, index into Scene.materials
    normals: np.ndarray | None = None  # (F, 3, 3) float64
    uvs: np.ndarray | None = None  # (F, 3, 2) float64
    #: mesh attributes by Mitsuba's name (``vertex_color``, ``face_weight``): ``(F, 3, C)``
    #: float values at each corner (a face attribute repeats its value), C = 1 or 3
    attributes: dict[str, np.ndarray] = field(default_factory=dict)
    #: the emitter (shape) each face belongs to, for ``--light-sampler uniform``: faces with
    #: one id and an emissive material form one emitter (a Mitsuba XML shape); ``None``: the
    #: faces of one material form one emitter (drpt's own format, as the exporter writes
    #: one mesh per material)
    shape: np.ndarray | None = None  # (F,) int
    #: Mitsuba XML: each face's shape (1-based, in the order of Mitsuba's ``scene.shapes()``)
    #: and its index in that shape (0 on Mitsuba's analytic shapes drpt tessellates), for
    #: the ``shape_index`` and ``prim_index`` AOVs; None for other scenes
    shape_index: np.ndarray | None = None  # (F,) int32
    prim_index: np.ndarray | None = None  # (F,) int32

    def __len__(self) -> int:
        return int(self.positions.shape[0])

    def emitter_ids(self) -> np.ndarray:
        """Each face's emitter id (:attr:`shape`, else its material)."""
        return np.asarray(self.material if self.shape is None else self.shape, np.int64)

    @staticmethod
    def empty() -> "Triangles":
        return Triangles(np.zeros((0, 3, 3)), np.zeros(0, np.int32))


@dataclass
class Spheres:
    center: np.ndarray  # (S, 3) float64
    radius: np.ndarray  # (S,) float64
    material: np.ndarray  # (S,) int32
    #: (S, 3, 3) float64: each sphere's orientation (a rotation; Mitsuba's ``to_world``
    #: without its scale and translation), which orients its parameterisation
    #: (uv, dp/du) and nothing else; ``None``: the identity for every sphere
    rotation: np.ndarray | None = None
    shape_index: np.ndarray | None = None  # (S,) int32, Mitsuba XML (as Triangles.shape_index)

    def __len__(self) -> int:
        return int(self.radius.shape[0])

    @staticmethod
    def empty() -> "Spheres":
        return Spheres(np.zeros((0, 3)), np.zeros(0), np.zeros(0, np.int32))


@dataclass
class Planes:
    """Infinite planes ``dot(normal, x) == offset`` (two-sided)."""

    normal: np.ndarray  # (P, 3) float64, unit
    offset: np.ndarray  # (P,) float64
    material: np.ndarray  # (P,) int32

    def __len__(self) -> int:
        return int(self.offset.shape[0])

    @staticmethod
    def empty() -> "Planes":
        return Planes(np.zeros((0, 3)), np.zeros(0), np.zeros(0, np.int32))


# --------------------------------------------------------------------- lights
@dataclass
class PointLight:
    """Isotropic point light: irradiance ``color / (c + l*d + q*d^2)`` at distance
    ``d`` on a surface facing it (the 6.837 formula). The default (0, 0, 1)
    is the physical inverse-square law, ``color`` then being the intensity."""

    position: Vec3
    color: Vec3
    attenuation: Vec3 = (0.0, 0.0, 1.0)  # constant, linear, quadratic
    #: where the file defines it (None: not from a file)
    loc: Loc | None = field(default=None, compare=False)


@dataclass
class DirectionalLight:
    direction: Vec3  # direction the light travels
    color: Vec3  # irradiance on a surface facing the light
    #: where the file defines it (None: not from a file)
    loc: Loc | None = field(default=None, compare=False)


@dataclass
class SpotLight:
    """Mitsuba's ``spot``: a point light at ``position`` shining along
    ``direction`` with intensity ``color`` inside a cone: full within
    ``beam_width`` degrees of the axis, falling linearly in angle to 0 at
    ``cutoff_angle`` degrees. Irradiance ``color * falloff / d^2``."""

    position: Vec3
    direction: Vec3  # the cone's axis, need not be normalized
    color: Vec3
    cutoff_angle: float = 20.0  # degrees
    beam_width: float = 15.0  # degrees, at most cutoff_angle
    #: Mitsuba's ``texture`` (a :class:`drpt.materials.spec.Texture`) multiplying the intensity,
    #: looked up at ``uv = 0.5 + 0.5 (x, y) / (z tan(cutoff_angle))`` of the direction in the
    #: light's ``frame``; None: none
    texture: Any = None
    #: the light's orientation: a row-major 3x3 rotation whose columns are its local x, y, z
    #: (z = ``direction``) in world space; None: some frame around ``direction``
    frame: tuple | None = None
    #: where the file defines it (None: not from a file)
    loc: Loc | None = field(default=None, compare=False)


@dataclass
class ProjectorLight:
    """Mitsuba's ``projector``: a perspective projection of ``irradiance`` (an RGB
    triple or a :class:`drpt.materials.spec.Texture`) from ``position``, looking along the
    ``frame``'s local ``+z``: a point at local ``(x, y, z)`` (``z > 0``) sees the value
    at Mitsuba's uv ``(0.5 - 0.5 x / (z t), 0.5 - 0.5 aspect y / (z t))`` (``t =
    tan(fov_x / 2)``, ``aspect`` the texture's width / height), zero outside [0, 1]^2,
    and receives ``pi * scale * value * dist / z^3`` on a surface facing the light
    (the value is the irradiance at ``z = 1`` on the plane facing the projector)."""

    position: Vec3
    frame: tuple  # row-major 3x3 rotation, columns the local x, y, z in world space
    fov_x: float  # full horizontal field of view, degrees
    irradiance: Any = (1.0, 1.0, 1.0)
    aspect: float = 1.0  # the texture's width / height (1 for a constant)
    scale: float = 1.0
    #: where the file defines it (None: not from a file)
    loc: Loc | None = field(default=None, compare=False)


@dataclass
class Skybox:
    path: Path  # lat-long .hdr or .exr, absolute path
    radius: float = 1000.0  # the seed's R
    scale: float = 1.0  # radiance multiplier (Mitsuba envmap's scale)
    #: 3x3 rotation from the map's frame to world (Mitsuba envmap's to_world); None: identity
    rotation: np.ndarray | None = None
    #: MIS compensation of its next-event density (Mitsuba envmap's ``mis_compensation``);
    #: None: the file does not say (``RenderOptions.env_compensation`` decides)
    mis_compensation: bool | None = None
    #: where the file defines it (None: not from a file)
    loc: Loc | None = field(default=None, compare=False)


Light = PointLight | DirectionalLight | SpotLight | ProjectorLight | Skybox


@dataclass
class Background:
    color: Vec3 = (0.0, 0.0, 0.0)  # radiance of rays that escape
    ambient: Vec3 = (0.0, 0.0, 0.0)  # Whitted ambient term


@dataclass
class RenderSettings:
    """How the scene file says to render it (a Mitsuba XML's film, sampler,
    integrator and filter); ``None``: the file does not say. Command-line
    flags win over these (:func:`drpt.options.with_scene_settings`)."""

    width: int | None = None
    height: int | None = None
    spp: int | None = None
    integrator: str | None = None  # a drpt integrator name ("path")
    max_depth: int | None = None
    rr_depth: int | None = None
    hide_emitters: bool | None = None
    sampler: str | None = None  # the sampler plugin's name (drpt.render.sampler)
    seed: int | None = None  # the sampler's seed
    jitter: bool | None = None  # stratified, multijitter, orthogonal: jitter inside strata
    strength: int | None = None  # orthogonal: the orthogonal array's strength
    rfilter: str | None = None  # reconstruction filter name: "box", "tent", "gaussian"
    rfilter_params: dict = field(default_factory=dict)  # Mitsuba's names: radius, stddev
    #: Mitsuba's ``(fov, fov_axis)`` as the file gives them: an image size of another
    #: aspect than the film's keeps the fov along that axis, as Mitsuba does
    fov: tuple | None = None
    #: Mitsuba's ``moment`` integrator around the one rendered: the nested integrator's
    #: name in the file (``_arg_0`` when unnamed), which names the EXR's moment channels
    moment: str | None = None
    #: Mitsuba's ``aov`` integrator: its AOVs, ``(name, type)`` pairs (:mod:`drpt.aovs`), and
    #: the nested integrator's name (its image is also written as ``<name>.R/G/B``)
    aovs: tuple = ()
    aov_image: str | None = None
    #: Embree's robust triangle test (``RTC_SCENE_FLAG_ROBUST``, :mod:`drpt.accel.embree`): a
    #: Mitsuba XML's ``embree_use_robust_intersections`` (False when the file does not set it,
    #: as Mitsuba reads it); None: drpt's own format, traced robust (:func:`embree_robust`)
    embree_robust: bool | None = None
    #: the ``-D`` values the file was read with (``compare`` gives Mitsuba the same)
    defines: dict = field(default_factory=dict)
    #: the :class:`~drpt.errors.Loc` of the element that gave a setting, by setting name (for errors)
    origin: dict = field(default_factory=dict)
    #: what of the file drpt did not read as written, one located line each: parameters
    #: their plugins do not read (older exporters' files; Mitsuba 3 refuses them) and,
    #: with ``--ignore-unsupported``, the plugins left out or replaced. ``compare`` stops
    #: on such a file, or with ``--ignore-unsupported`` says it is not like for like
    not_read: tuple = ()


# ---------------------------------------------------------------------- media
@dataclass
class GridVolume:
    """A voxel grid (Mitsuba's ``gridvolume``): ``data`` ``(Z, Y, X, C)`` float32 values
    (C 1 or 3), looked up at ``to_local @ (p, 1)`` in the unit cube (voxel centers at
    ``(i + 0.5) / res``), ``filter`` ``"trilinear"`` or ``"nearest"``, ``wrap`` ``"clamp"``,
    ``"repeat"`` or ``"mirror"`` outside it."""

    data: np.ndarray
    to_local: np.ndarray  # (4, 4) world -> unit cube
    filter: str = "trilinear"
    wrap: str = "clamp"

    @property
    def max(self) -> float:
        return float(self.data.max()) if self.data.size else 0.0


@dataclass
class Medium:
    """A participating medium: extinction ``sigma_t * scale`` (per unit length, RGB),
    single-scattering ``albedo`` (RGB, in [0, 1]) and a phase function: ``"isotropic"``,
    ``"hg"`` (Henyey-Greenstein) with mean cosine ``g`` in (-1, 1) (positive: forward
    scattering), or ``"blend"`` (Mitsuba's ``blendphase``): ``(1 - blend)`` times HG(``g``)
    plus ``blend`` times HG(``g2``) (an isotropic lobe has g 0). Homogeneous (Mitsuba's
    ``homogeneous``) unless ``sigma_t_grid`` is set (Mitsuba's ``heterogeneous`` with a
    one-channel ``gridvolume`` extinction, which is zero outside the grid's box);
    ``albedo_grid`` replaces the constant albedo there."""

    name: str
    sigma_t: Vec3 = (1.0, 1.0, 1.0)
    albedo: Vec3 = (0.75, 0.75, 0.75)
    scale: float = 1.0
    phase: str = "isotropic"
    g: float = 0.0
    loc: Loc | None = field(default=None, compare=False)
    sigma_t_grid: GridVolume | None = None
    albedo_grid: GridVolume | None = None
    g2: float = 0.0
    blend: float = 0.0

    @property
    def is_homogeneous(self) -> bool:
        return self.sigma_t_grid is None

    @property
    def extinction(self) -> Vec3:
        return tuple(float(s) * self.scale for s in self.sigma_t)


# ---------------------------------------------------------------------- scene
@dataclass
class Scene:
    path: Path  # the scene file
    camera: Camera
    materials: list[Material]
    triangles: Triangles = field(default_factory=Triangles.empty)
    spheres: Spheres = field(default_factory=Spheres.empty)
    planes: Planes = field(default_factory=Planes.empty)
    lights: list[Light] = field(default_factory=list)
    background: Background = field(default_factory=Background)
    settings: RenderSettings | None = None  # render settings the file gives (Mitsuba XML)
    media: list[Medium] = field(default_factory=list)  # participating media (Material.interior/exterior)
    camera_medium: int | None = None  # the medium camera rays start in (index into media; None: vacuum)

    @property
    def emissive_materials(self) -> list[int]:
        return [i for i, m in enumerate(self.materials) if m.is_emissive]

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """World-space bounding box of all bounded geometry (planes excluded)."""
        lo = np.full(3, np.inf)
        hi = np.full(3, -np.inf)
        if len(self.triangles):
            p = self.triangles.positions.reshape(-1, 3)
            lo, hi = np.minimum(lo, p.min(0)), np.maximum(hi, p.max(0))
        if len(self.spheres):
            c, r = self.spheres.center, self.spheres.radius[:, None]
            lo, hi = np.minimum(lo, (c - r).min(0)), np.maximum(hi, (c + r).max(0))
        return lo, hi


def embree_robust(scene) -> bool:
    """Whether ``scene`` is traced with Embree's robust triangle test (:mod:`drpt.accel.embree`),
    as its file says: a Mitsuba XML's ``embree_use_robust_intersections`` (off unless set, as in
    Mitsuba 3), on for drpt's own format, whose scenes were measured with it. The Mitsuba export
    writes it, so that Mitsuba and drpt reading the export trace the same test."""
    said = getattr(getattr(scene, "settings", None), "embree_robust", None)
    return True if said is None else bool(said)
