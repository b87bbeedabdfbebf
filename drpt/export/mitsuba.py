"""The drpt :class:`~drpt.scene.model.Scene` as a Mitsuba 3 scene.

Two outputs of one description, built by the same code so they cannot drift:

* :func:`to_mitsuba_dict` -- a dict for ``mi.load_dict``; triangle meshes are
  ``mi.Mesh`` objects filled in memory from numpy (needs a Mitsuba variant
  set, e.g. ``mi.set_variant("llvm_ad_rgb")``).
* :func:`write_xml` -- a Mitsuba XML file (``version="3.0.0"``) plus one binary
  little-endian PLY per material in a folder ``<xml stem>_meshes`` beside it
  (referenced by relative path, which ``mi.load_file`` resolves against the
  XML's folder). Writing needs numpy only, not Mitsuba.

Both give the same scene, and both list emitters in one fixed order
(top-level lights, then the area emitters of shapes in document order), so
with the same ``seed`` the dict and ``mi.load_file(xml, optimize=False)``
render the same image sample for sample. The default ``optimize=True`` of
``mi.load_file`` merges meshes whose BSDFs are identical (in Mitsuba 3.9 the
plane ``rectangle`` counts as a mesh and becomes float32 triangles) and
orders the area emitters of meshes nondeterministically: same expectation,
other random numbers. Every transform is written as an explicit 4x4 matrix.

Equivalences (each one checked by ``tests/export/test_export.py``)
-----------------------------------------------------------
Camera
    drpt maps pixel ``(x, y)`` (continuous, from the top-left, pixel centers
    at +0.5) to ``d = normalize(f + sx*r + sy*u)`` with ``f = normalize(dir)``,
    ``r = normalize(cross(f, up))``, ``u = cross(r, f)``, ``t = tan(fov/2)``,
    ``sx = (2x/W - 1) t W/H``, ``sy = (1 - 2y/H) t``. Mitsuba's ``look_at``
    puts camera-space +x along ``cross(up, f)`` (= ``-r``, the image's
    *left*) and its film x grows to the image's right, so the plain
    ``look_at(center, center + f, up)`` matrix reproduces drpt exactly, no
    mirroring. ``fov_axis="y"`` makes ``fov`` the full vertical angle.
    ``orthographic``: Mitsuba's unit view spans camera x in [-1, 1] and
    y in [-H/W, H/W], so ``to_world = look_at @ scale(s, s, 1)`` with
    ``s = size * W / (2H)`` gives a full vertical extent of ``size`` (``scale(width/2,
    s, 1)`` for a camera with its own ``width``).
    ``near_clip``/``far_clip`` are derived from the scene size (tiny / beyond
    the exported planes). A perspective camera with an ``aperture_radius``
    above 0 becomes ``thinlens`` with the same ``fov``/``fov_axis`` and
    ``aperture_radius``, ``focus_distance``: Mitsuba's focal plane lies at
    camera-space z = ``focus_distance``, drpt's at that distance along ``f``,
    the same plane (:mod:`drpt.render.camera`).
Film, sampler, integrator
    ``hdrfilm`` (``rgb``, ``float32``, the default ``sample_border=false``) with the
    render's pixel filter as its ``rfilter`` (``rfilter=`` :func:`drpt.filters.parse_filter`'s
    spelling: ``box``, the default, so a pixel is the plain average of its
    samples; ``tent`` with its ``radius``, ``gaussian`` with its ``stddev``;
    :mod:`drpt.filters` derives why drpt's filter importance sampling has
    Mitsuba's splatting's expectation), ``independent`` sampler with
    ``sample_count`` and ``seed``, ``path`` integrator with ``max_depth``
    (-1 infinite, 1 emitters seen directly, 2 direct lighting), ``rr_depth``,
    ``hide_emitters`` (default false; a Mitsuba XML scene's own, through ``drpt export``).
    The scene's ``embree_use_robust_intersections`` is the triangle test drpt traces it
    with (:func:`drpt.scene.model.embree_robust`: true for drpt's own format, the file's
    for a Mitsuba XML), so that Mitsuba and drpt reading the export trace the same.
Materials
    Each material goes through :func:`drpt.materials.interpret.interpret_scene` (the
    same call the renderer makes, with the same ``bsdf`` mode), and
    :mod:`drpt.export.mitsuba_bsdf` writes its BSDF tree node for node as
    the Mitsuba plugins of the same names (``phong`` as ``drpt_phong``, a
    registered plugin, :mod:`drpt.export.mitsuba_phong`). drpt's own
    materials are wrapped in ``twosided`` by the interpretation, transmissive
    ones are not. A texture parameter becomes a ``bitmap``
    (``filter_type="bilinear"``, ``wrap_mode="repeat"``, sRGB-decoded for
    8-bit files as Mitsuba does by default). In a scene
    with texture coordinates, faces without them get explicit uv (0, 0)
    (drpt's lookup; Mitsuba would otherwise use barycentrics); in a scene
    without any, ``interpret_scene`` replaces each texture by its constant
    value (both drpt and the export use it) and the export warns, naming
    each material whose texture it dropped. Textures on spheres/planes use Mitsuba's
    own parameterization, not yet matched to drpt's.
Texture coordinates
    drpt stores uvs as written in the OBJ file: ``v = 0`` is the *bottom* row
    of the image. Mitsuba's bitmap lookup has ``v = 0`` at the *top* row
    (first row in memory); its OBJ loader flips ``v -> 1 - v`` on load, but
    in-memory meshes and PLY files are used as given. The exporter therefore
    writes ``(u, 1 - v)`` both in memory and in the PLY files.
Emission
    A material with emission > 0 gives its mesh (and each sphere/plane using
    it) an ``area`` emitter with ``radiance = emission``. Mitsuba's area
    emitter is ONE-sided: ``eval`` returns radiance only when
    ``cos_theta(si.wi) > 0`` with ``wi`` in the *shading* frame, and light
    sampling (``sample_direction``/``pdf_direction``) accepts only
    ``dot(d, n) < 0`` with ``n`` from ``Mesh::sample_position``: the
    barycentric interpolation of the *vertex normals* when the mesh has them,
    else the geometric normal ``cross(p1 - p0, p2 - p0)``. So a triangle
    emits toward the side its interpolated shading normal points to (its
    counter-clockwise front when it has no normals). drpt must emit only
    from that same side. Spheres emit outward; planes toward ``normal``.
Planes
    Mitsuba has no infinite plane: each becomes a ``rectangle`` with
    half-size ``1e3 * L`` (``L`` = diagonal of the box of all bounded
    geometry and the camera, at least 1), centered at the projection of that
    box's center onto the plane, with ``+z`` (the rectangle's normal) along
    the plane's ``normal``.
Lights
    ``PointLight`` -> ``point``. drpt's irradiance is
    ``color / (c + l d + q d^2)`` (6.837); Mitsuba's point light falls off
    with the inverse square only, so ``(0, 0, q)`` is exported exactly as
    ``intensity = color / q`` and any other attenuation as the nearest
    inverse-square light ``color / (c + l + q)`` (equal at distance 1) with a
    warning. ``DirectionalLight`` -> ``directional`` (``direction`` = the
    direction light travels, ``irradiance = color``). ``Skybox`` ->
    ``envmap`` through :mod:`drpt.export.mitsuba_envmap` (identity
    ``to_world``: drpt's direction/uv mapping is Mitsuba's, verified there).
    ``Background.color`` non-zero -> ``constant`` emitter, only when there is no ``Skybox``. ``Background.ambient`` (a
    Whitted term) has no Mitsuba equivalent and is ignored.
"""

from __future__ import annotations

import math
import re
import warnings
from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path
from typing import Any
from xml.sax.saxutils import quoteattr

import numpy as np

from drpt.errors import DrptError, SceneWarning
from drpt.filters import parse_filter
from drpt.materials.interpret import interpret_scene
from drpt.materials.spec import BSDFSpec
from drpt.scene.model import (
    DirectionalLight,
    Material,
    OrthographicCamera,
    PerspectiveCamera,
    PointLight,
    ProjectorLight,
    Scene,
    Skybox,
    SpotLight,
    embree_robust,
)

from .mitsuba_bsdf import _error as bsdf_error
from .mitsuba_bsdf import _value as bsdf_value
from .mitsuba_bsdf import to_mitsuba as bsdf_to_mitsuba
from .mitsuba_envmap import to_mitsuba as envmap_to_mitsuba
from .mitsuba_phong import register
from .values import _RGB, _Matrix, _Point, _Vector

__all__ = ["to_mitsuba_dict", "write_xml", "look_at_matrix", "PLANE_SCALE"]

#: Half-size of an exported plane rectangle, in units of the scene diagonal.
PLANE_SCALE = 1e3


@dataclass
class _MeshData:
    """One triangle mesh (all faces of one material), unwelded."""

    name: str
    positions: np.ndarray  # (F, 3, 3)
    normals: np.ndarray | None  # (F, 3, 3)
    uvs: np.ndarray | None  # (F, 3, 2), already in Mitsuba's convention
    bsdf: dict
    emitter: dict | None
    #: mesh attributes (Mitsuba's ``vertex_*`` / ``face_*``): ``(F, 3, C)`` corner values
    attributes: dict = field(default_factory=dict)
    #: the media inside and outside the mesh (Mitsuba ``homogeneous`` dicts; None: vacuum)
    interior: dict | None = None
    exterior: dict | None = None

    def arrays(self):
        f = self.positions.shape[0]
        pos = self.positions.reshape(-1, 3).astype(np.float32)
        faces = np.arange(3 * f, dtype=np.uint32).reshape(f, 3)
        nrm = None if self.normals is None else self.normals.reshape(-1, 3).astype(np.float32)
        uv = None if self.uvs is None else self.uvs.reshape(-1, 2).astype(np.float32)
        return pos, faces, nrm, uv


#: drpt's samplers that Mitsuba 3 has a plugin of the same name and meaning for
MITSUBA_SAMPLERS = ("independent", "stratified", "multijitter", "orthogonal", "ldsampler")

_TAGS = {
    "perspective": "sensor", "orthographic": "sensor", "thinlens": "sensor",
    "hdrfilm": "film", "box": "rfilter", "tent": "rfilter", "gaussian": "rfilter",
    **{name: "sampler" for name in MITSUBA_SAMPLERS},
    "path": "integrator", "volpath": "integrator",
    "homogeneous": "medium", "hg": "phase", "isotropic": "phase", "blendphase": "phase",
    "twosided": "bsdf", "diffuse": "bsdf", "drpt_phong": "bsdf", "principled": "bsdf",
    "dielectric": "bsdf", "conductor": "bsdf", "roughconductor": "bsdf", "blendbsdf": "bsdf", "principledthin": "bsdf",
    "plastic": "bsdf", "roughplastic": "bsdf", "thindielectric": "bsdf", "roughdielectric": "bsdf",
    "mask": "bsdf", "null": "bsdf", "normalmap": "bsdf", "bumpmap": "bsdf",
    "area": "emitter", "point": "emitter", "directional": "emitter", "spot": "emitter", "projector": "emitter",
    "envmap": "emitter", "constant": "emitter",
    "sphere": "shape", "rectangle": "shape", "ply": "shape",
    "bitmap": "texture", "mesh_attribute": "texture", "checkerboard": "texture", "rawconstant": "texture",
}


# ------------------------------------------------------------ geometry
def _normalize(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    n = np.linalg.norm(v)
    if not n > 0:
        raise DrptError(f"cannot export: zero-length vector {tuple(v)}")
    return v / n


def look_at_matrix(origin, target, up) -> np.ndarray:
    """Mitsuba's ``ScalarTransform4f().look_at(origin, target, up)`` as numpy.

    Columns: camera +x = ``normalize(cross(up, dir))`` (the image's left),
    +y = ``cross(dir, x)``, +z = ``dir``, translation = ``origin``.
    """
    origin = np.asarray(origin, dtype=np.float64)
    d = _normalize(np.asarray(target, dtype=np.float64) - origin)
    left = np.cross(_normalize(up), d)
    if not np.linalg.norm(left) > 1e-12:
        raise DrptError("cannot export camera: 'up' is parallel to the view direction")
    left = left / np.linalg.norm(left)
    new_up = np.cross(d, left)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, new_up, d, origin
    return m


def _any_perpendicular(d) -> tuple[float, float, float]:
    """An up vector for ``look_at_matrix`` that is not parallel to ``d``."""
    d = _normalize(d)
    a = np.array([0.0, 1.0, 0.0]) if abs(d[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    return tuple(float(x) for x in a)


def _frame_matrix(center, normal, half_size) -> np.ndarray:
    """Rectangle to_world: [-1,1]^2 x {0} -> plane, +z -> normal."""
    n = _normalize(normal)
    a = np.array([1.0, 0, 0]) if abs(n[0]) < 0.9 else np.array([0, 1.0, 0])
    t = _normalize(np.cross(a, n))
    b = np.cross(n, t)  # (t, b, n) right-handed: cross(t, b) = n
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = t * half_size, b * half_size, n, center
    return m


def _extent(scene: Scene) -> tuple[np.ndarray, float]:
    """Center and diagonal (>= 1) of bounded geometry plus the camera."""
    lo, hi = scene.bounds()
    cam = np.asarray(scene.camera.center, dtype=np.float64)
    lo, hi = np.minimum(lo, cam), np.maximum(hi, cam)
    return 0.5 * (lo + hi), max(float(np.linalg.norm(hi - lo)), 1.0)


def _f3(v) -> tuple[float, float, float]:
    a = [float(x) for x in v]
    if len(a) != 3 or not all(math.isfinite(x) for x in a):
        raise DrptError(f"cannot export: bad 3-vector {v!r}")
    return (a[0], a[1], a[2])


# ------------------------------------------------------ the description
def mitsuba_sampler(name: str) -> str:
    """The Mitsuba sampler plugin an export names for drpt's resolved sampler ``name``
    (``RenderOptions.sampler`` after :func:`drpt.options.resolve_sampler`): the plugin of
    the same name, ``independent`` for one Mitsuba lacks (``zsobol``)."""
    return name if name in MITSUBA_SAMPLERS else "independent"


def _describe(scene: Scene, width: int, height: int, spp: int, max_depth: int,
              rr_depth: int, seed: int, bsdf: str = "auto", rfilter: str = "box",
              hide_emitters: bool = False, sampler: str = "independent") -> dict:
    pixel_filter = parse_filter(rfilter)
    media = [_medium(m) for m in (getattr(scene, "media", None) or [])]
    if int(width) <= 0 or int(height) <= 0:
        raise DrptError(f"image size must be positive, got {width}x{height}")
    if int(spp) <= 0:
        raise DrptError(f"samples per pixel must be positive, got {spp}")
    width, height = int(width), int(height)
    center, diag = _extent(scene)
    plane_half = PLANE_SCALE * diag
    cam_dist = float(np.linalg.norm(np.asarray(scene.camera.center) - center))
    far_clip = 10.0 * (plane_half + cam_dist + diag)
    near_clip = 1e-6 * diag

    out: dict[str, Any] = {"type": "scene"}
    out["integrator"] = {
        "type": "volpath" if media else "path",
        "max_depth": int(max_depth),
        "rr_depth": int(rr_depth),
        "hide_emitters": bool(hide_emitters),
    }
    # the triangle test drpt traces the scene with (Mitsuba's default is the other for drpt's format)
    out["embree_use_robust_intersections"] = embree_robust(scene)

    cam = scene.camera
    origin = np.asarray(_f3(cam.center))
    fwd = _normalize(_f3(cam.direction))
    to_world = look_at_matrix(origin, origin + fwd, _f3(cam.up))
    sensor: dict[str, Any]
    if isinstance(cam, PerspectiveCamera):
        if not 0.0 < float(cam.fov) < 180.0:
            raise DrptError(f"cannot export camera: fov {cam.fov} not in (0, 180)")
        sensor = {"type": "perspective", "fov_axis": "y", "fov": float(cam.fov)}
        if cam.aperture_radius > 0.0:
            if cam.focus_distance is None or not float(cam.focus_distance) > 0.0:
                raise DrptError(f"cannot export camera: a thin lens needs a positive focus "
                                f"distance, got {cam.focus_distance}")
            sensor = {"type": "thinlens", "fov_axis": "y", "fov": float(cam.fov),
                      "aperture_radius": float(cam.aperture_radius),
                      "focus_distance": float(cam.focus_distance)}
    elif isinstance(cam, OrthographicCamera):
        if not float(cam.size) > 0.0:
            raise DrptError(f"cannot export camera: size {cam.size} must be positive")
        s = float(cam.size) * width / (2.0 * height)
        sx = s if getattr(cam, "width", None) is None else float(cam.width) / 2.0
        to_world = to_world @ np.diag([sx, s, 1.0, 1.0])
        sensor = {"type": "orthographic"}
    else:  # pragma: no cover - model has only these two
        raise DrptError(f"cannot export camera of type {type(cam).__name__}")
    film_size = {"width": width, "height": height}
    window = getattr(cam, "window", None)
    if window is not None:
        # the film's fov and aspect, the crop window as the image, the shift on the sensor
        if tuple(window.crop_size) != (width, height):
            raise DrptError(f"cannot export camera: its film window is {window.crop_size[0]}x"
                            f"{window.crop_size[1]}, the image {width}x{height}")
        film_size = {"width": window.film_width, "height": window.film_height}
        if (window.offset_x, window.offset_y, *window.crop_size) != (0, 0, window.film_width,
                                                                     window.film_height):
            film_size.update(crop_offset_x=window.offset_x, crop_offset_y=window.offset_y,
                             crop_width=width, crop_height=height)
        if (window.shift_x, window.shift_y) != (0.0, 0.0):
            if sensor["type"] != "perspective":
                raise DrptError("cannot export camera: Mitsuba's thinlens has no principal point offset")
            sensor["principal_point_offset_x"] = float(window.shift_x)
            sensor["principal_point_offset_y"] = float(window.shift_y)
    sensor["near_clip"] = near_clip
    sensor["far_clip"] = far_clip
    sensor["to_world"] = _Matrix(to_world)
    sensor["film"] = {
        "type": "hdrfilm",
        **film_size,
        "pixel_format": "rgb",
        "component_format": "float32",
        "rfilter": pixel_filter.to_mitsuba(),  # sample_border: Mitsuba's default, false
    }
    sensor["sampler"] = {"type": mitsuba_sampler(sampler), "sample_count": int(spp), "seed": int(seed)}
    if media and getattr(scene, "camera_medium", None) is not None:
        sensor["medium"] = media[scene.camera_medium]
    out["sensor"] = sensor

    # -- materials
    specs = interpret_scene(scene, bsdf)
    used = np.unique(np.concatenate([np.asarray(p.material, np.int64) for p in
                                     (scene.triangles, scene.spheres, scene.planes)]))
    for i in used:
        if 0 <= i < len(specs):
            for n in specs[i].notes:
                warnings.warn(SceneWarning(specs[i].loc, n), stacklevel=3)
    bsdfs = [_bsdf(spec) for spec in specs]
    emitters = [
        ({"type": "area", "radiance": bsdf_value(m.emission_texture, m.loc or f"material '{m.name}'")}
         if getattr(m, "emission_texture", None) is not None else
         {"type": "area", "radiance": _RGB(_f3(m.emission))}) if m.is_emissive else None
        for m in scene.materials
    ]
    nmat = len(scene.materials)

    def with_media(shape: dict, m: Material) -> dict:
        """``shape`` with the material's interior and exterior media (a medium transition)."""
        for side in ("interior", "exterior"):
            k = getattr(m, side, None)
            if k is not None:
                shape[side] = media[k]
        return shape

    def check_mat(idx: np.ndarray, what: str) -> None:
        if idx.size and (idx.min() < 0 or idx.max() >= nmat):
            raise DrptError(f"cannot export: {what} references a material index out of range")

    # -- triangle meshes, one per material
    tri = scene.triangles
    if len(tri):
        check_mat(tri.material, "a triangle")
        for mi_ in np.unique(tri.material):
            sel = tri.material == mi_
            uvs = None
            if tri.uvs is not None:  # faces without uvs in the file hold zeros
                uvs = tri.uvs[sel].copy()
                uvs[..., 1] = 1.0 - uvs[..., 1]  # OBJ v=0 bottom -> Mitsuba v=0 top
            name = _mesh_name(int(mi_), scene.materials[mi_])
            out[f"mesh_{name}"] = _MeshData(
                name=name,
                positions=tri.positions[sel],
                normals=None if tri.normals is None else tri.normals[sel],
                uvs=uvs,
                bsdf=bsdfs[mi_],
                emitter=emitters[mi_],
                attributes={k: a[sel] for k, a in getattr(tri, "attributes", {}).items()},
                interior=with_media({}, scene.materials[mi_]).get("interior"),
                exterior=with_media({}, scene.materials[mi_]).get("exterior"),
            )

    # -- spheres
    sph = scene.spheres
    check_mat(sph.material, "a sphere")
    for i in range(len(sph)):
        r = float(sph.radius[i])
        if not r > 0:
            raise DrptError(f"cannot export sphere {i}: radius {r} must be positive")
        shape = {"type": "sphere", "center": _Point(_f3(sph.center[i])), "radius": r,
                 "bsdf": bsdfs[sph.material[i]]}
        if sph.rotation is not None:  # the sphere's orientation: its uv and dp/du
            m = np.eye(4)
            m[:3, :3] = sph.rotation[i] * r
            m[:3, 3] = sph.center[i]
            del shape["center"], shape["radius"]
            shape["to_world"] = _Matrix(m)
        if emitters[sph.material[i]] is not None:
            shape["emitter"] = emitters[sph.material[i]]
        out[f"sphere_{i}"] = with_media(shape, scene.materials[sph.material[i]])

    # -- planes
    pl = scene.planes
    check_mat(pl.material, "a plane")
    for i in range(len(pl)):
        n = _normalize(pl.normal[i])
        d = float(pl.offset[i]) / float(np.linalg.norm(pl.normal[i]))
        p0 = center - (float(n @ center) - d) * n
        shape = {"type": "rectangle", "to_world": _Matrix(_frame_matrix(p0, n, plane_half)),
                 "bsdf": bsdfs[pl.material[i]]}
        if emitters[pl.material[i]] is not None:
            shape["emitter"] = emitters[pl.material[i]]
        out[f"plane_{i}"] = with_media(shape, scene.materials[pl.material[i]])

    # -- lights
    has_sky = any(isinstance(light, Skybox) for light in scene.lights)
    for i, light in enumerate(scene.lights):
        if isinstance(light, PointLight):
            c, l, q = (float(a) for a in light.attenuation)
            if c == 0.0 and l == 0.0:
                scale = 1.0 / q
            else:
                scale = 1.0 / (c + l + q)
                warnings.warn(SceneWarning(
                    light.loc, f"point light {i}: attenuation {(c, l, q)} has no Mitsuba equivalent "
                    "(Mitsuba's point light falls off with the inverse square only); "
                    f"exported as intensity color/{c + l + q:g}, equal at distance 1"),
                    stacklevel=3,
                )
            out[f"light_{i}"] = {"type": "point", "position": _Point(_f3(light.position)),
                                 "intensity": _RGB(tuple(scale * x for x in _f3(light.color)))}
        elif isinstance(light, DirectionalLight):
            out[f"light_{i}"] = {"type": "directional",
                                 "direction": _Vector(tuple(_normalize(_f3(light.direction)))),
                                 "irradiance": _RGB(_f3(light.color))}
        elif isinstance(light, SpotLight):
            if getattr(light, "frame", None) is not None:  # the light's own orientation
                m = _light_matrix(light.position, light.frame)
            else:
                m = look_at_matrix(_f3(light.position),
                                   tuple(a + b for a, b in zip(_f3(light.position), _f3(light.direction))),
                                   _any_perpendicular(_f3(light.direction)))
            out[f"light_{i}"] = {"type": "spot", "to_world": _Matrix(m),
                                 "intensity": _RGB(_f3(light.color)),
                                 "cutoff_angle": float(light.cutoff_angle),
                                 "beam_width": float(light.beam_width)}
            if getattr(light, "texture", None) is not None:
                out[f"light_{i}"]["texture"] = bsdf_value(light.texture, light.loc or f"light {i}")
        elif isinstance(light, ProjectorLight):
            irr = light.irradiance
            out[f"light_{i}"] = {"type": "projector", "fov": float(light.fov_x), "fov_axis": "x",
                                 "to_world": _Matrix(_light_matrix(light.position, light.frame)),
                                 "scale": float(light.scale),
                                 "irradiance": _RGB(_f3(irr)) if isinstance(irr, tuple)
                                 else bsdf_value(irr, light.loc or f"light {i}")}
        elif isinstance(light, Skybox):
            node = envmap_to_mitsuba(light, scale=getattr(light, "scale", 1.0))
            rotation = getattr(light, "rotation", None)
            if rotation is not None:
                m = np.eye(4)
                m[:3, :3] = rotation
                node["to_world"] = m @ node["to_world"]
            node["to_world"] = _Matrix(node["to_world"])
            out[f"light_{i}"] = node
        else:  # pragma: no cover
            raise DrptError(f"cannot export light of type {type(light).__name__}")
    bg = _f3(scene.background.color)
    if max(bg) > 0.0 and not has_sky:
        out["background"] = {"type": "constant", "radiance": _RGB(bg)}
    # Top-level emitters first, then shapes (whose area emitters Mitsuba
    # lists after all top-level ones anyway): one fixed order for both outputs.
    head = {k: v for k, v in out.items() if not _is_shape(v)}
    shapes = {k: v for k, v in out.items() if _is_shape(v)}
    return {**head, **shapes}


def _medium(m) -> dict:
    """Mitsuba's ``homogeneous`` medium for a drpt :class:`~drpt.scene.model.Medium`
    (a heterogeneous one is refused)."""
    if not m.is_homogeneous:
        raise bsdf_error(m.loc or f"medium '{m.name}'", "cannot export a heterogeneous medium "
                         "(drpt's Mitsuba export writes homogeneous ones)")
    if m.phase == "blend":
        lobes = [{"type": "hg", "g": float(g)} if g != 0.0 else {"type": "isotropic"} for g in (m.g, m.g2)]
        phase = {"type": "blendphase", "weight": float(m.blend), "phase_0": lobes[0], "phase_1": lobes[1]}
    elif m.phase == "hg" and m.g != 0.0:
        phase = {"type": "hg", "g": float(m.g)}
    else:
        phase = {"type": "isotropic"}
    # (sigma_t as a color in [0, 1] times the scale: Mitsuba reads an RGB value of a
    # dict as a reflectance, which must not exceed 1)
    st = _f3(m.sigma_t)
    peak = max(max(st), 0.0) or 1.0
    return {"type": "homogeneous", "sigma_t": _RGB(tuple(x / peak for x in st)),
            "albedo": _RGB(_f3(m.albedo)), "scale": float(m.scale) * peak, "phase": phase}


def _light_matrix(position, frame) -> np.ndarray:
    """A light's to_world: its frame's columns (local x, y, z in world space) and position."""
    m = np.eye(4)
    m[:3, :3] = np.asarray(frame, float).reshape(3, 3)
    m[:3, 3] = _f3(position)
    return m


def _is_shape(node: Any) -> bool:
    return isinstance(node, _MeshData) or (isinstance(node, dict) and _TAGS.get(node.get("type")) == "shape")


def _mesh_name(index: int, m: Material) -> str:
    safe = re.sub(r"[^A-Za-z0-9_.-]+", "_", m.name or "")[:40].strip("_.")
    return f"{index:03d}_{safe}" if safe else f"{index:03d}"


def _plain(node: Any) -> Any:
    """Lobe exporters speak plain Mitsuba dicts; turn their rgb values into _RGB."""
    if isinstance(node, dict):
        if node.get("type") == "rgb":
            return _RGB(_f3(node["value"]))
        return {k: _plain(v) for k, v in node.items()}
    return node


def _bsdf(spec: BSDFSpec) -> dict:
    """The Mitsuba BSDF for what drpt renders of a material (``spec``, see drpt.materials.interpret).

    A missing texture file is an error, also where the texture is dropped."""
    for path in spec.dropped:
        if not Path(path).is_file():
            raise bsdf_error(spec.loc or "material", f"texture {path} not found")
    return _plain(bsdf_to_mitsuba(spec))


# ---------------------------------------------------------------- dict
def to_mitsuba_dict(scene: Scene, width: int, height: int, spp: int,
                    max_depth: int = -1, rr_depth: int = 5, seed: int = 0,
                    bsdf: str = "auto", rfilter: str = "box", hide_emitters: bool = False,
                    sampler: str = "independent") -> dict:
    """The scene as a dict for ``mi.load_dict`` (a Mitsuba variant must be set).

    Triangle meshes are in-memory ``mi.Mesh`` objects (one per material),
    the rest are plain plugin dicts. See the module docs for the mapping.
    """
    import mitsuba as mi

    if mi.variant() is None:
        raise DrptError("Mitsuba has no variant set; call mi.set_variant('llvm_ad_rgb') first")
    desc = _describe(scene, width, height, spp, max_depth, rr_depth, seed, bsdf, rfilter, hide_emitters,
                     sampler)
    register()  # drpt_phong, in case a material needs it
    # Shapes and top-level emitters are instantiated here, in document order.
    # load_dict would otherwise put the ready-made mi.Mesh objects before
    # everything else, while mi.load_file(..., optimize=False) keeps the XML's
    # document order. Emitter order decides which light a sample picks, so
    # this keeps dict and XML renders sample for sample.
    out: dict[str, Any] = {}
    for key, node in desc.items():
        if key in ("type", "integrator", "sensor") or isinstance(node, bool):
            out[key] = _to_dict(node, mi)
        elif isinstance(node, _MeshData):
            out[key] = _build_mesh(node, mi)
        else:
            out[key] = mi.load_dict(_to_dict(node, mi))
    return out


def _to_dict(node: Any, mi) -> Any:
    if isinstance(node, dict):
        return {k: _to_dict(v, mi) for k, v in node.items()}
    if isinstance(node, _RGB):
        return {"type": "rgb", "value": list(node.value)}
    if isinstance(node, _Point):
        return mi.ScalarPoint3f(*node.value)
    if isinstance(node, _Vector):
        return mi.ScalarVector3f(*node.value)
    if isinstance(node, _Matrix):
        return mi.ScalarTransform4f(np.asarray(node.value, dtype=np.float64))
    if isinstance(node, _MeshData):
        return _build_mesh(node, mi)
    return node


def _build_mesh(md: _MeshData, mi):
    pos, faces, nrm, uv = md.arrays()
    props = mi.Properties()
    props["bsdf"] = mi.load_dict(_to_dict(md.bsdf, mi))
    if md.emitter is not None:
        props["emitter"] = mi.load_dict(_to_dict(md.emitter, mi))
    for side in ("interior", "exterior"):
        if getattr(md, side) is not None:
            props[side] = mi.load_dict(_to_dict(getattr(md, side), mi))
    mesh = mi.Mesh(md.name, pos.shape[0], faces.shape[0], props,
                   has_vertex_normals=nrm is not None,
                   has_vertex_texcoords=uv is not None)
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(pos.ravel())
    params["faces"] = mi.UInt32(faces.ravel())
    if nrm is not None:
        params["vertex_normals"] = mi.Float(nrm.ravel())
    if uv is not None:
        params["vertex_texcoords"] = mi.Float(uv.ravel())
    params.update()
    for name, a in md.attributes.items():  # per corner: unwelded vertices; a face's first corner
        v = a.reshape(-1, a.shape[2]) if name.startswith("vertex_") else a[:, 0, :]
        mesh.add_attribute(name, a.shape[2], mi.Float(np.ascontiguousarray(v, np.float32).ravel()))
    return mesh


# ----------------------------------------------------------------- XML
def write_xml(scene: Scene, out_xml_path: str | PathLike, width: int, height: int,
              spp: int, max_depth: int = -1, rr_depth: int = 5, seed: int = 0,
              bsdf: str = "auto", rfilter: str = "box", hide_emitters: bool = False,
              sampler: str = "independent") -> Path:
    """Write the scene as Mitsuba 3 XML plus PLY meshes; return the XML path.

    Phong materials use the ``drpt_phong`` plugin, which Mitsuba knows only
    after ``drpt.export.mitsuba_phong.register()`` (call it before
    ``mi.load_file``).

    Meshes go to ``<stem>_meshes/<index>_<material>.ply`` beside the XML
    (binary little endian, unwelded per-corner vertices, ``nx ny nz`` and
    ``u v`` when the scene has them). The file loads with ``mi.load_file``.
    """
    xml_path = Path(out_xml_path)
    desc = _describe(scene, width, height, spp, max_depth, rr_depth, seed, bsdf, rfilter, hide_emitters,
                     sampler)
    mesh_dir = xml_path.parent / f"{xml_path.stem}_meshes"
    try:
        xml_path.parent.mkdir(parents=True, exist_ok=True)
        lines = ['<?xml version="1.0" encoding="utf-8"?>',
                 "<!-- written by drpt.export.mitsuba -->",
                 '<scene version="3.0.0">']
        for key, node in desc.items():
            if key == "type":
                continue
            if isinstance(node, _MeshData):
                mesh_dir.mkdir(parents=True, exist_ok=True)
                ply = mesh_dir / f"{node.name}.ply"
                _write_ply(ply, *node.arrays(), attributes=node.attributes)
                lines += _xml_mesh(node, f"{mesh_dir.name}/{ply.name}", key, 1)
            elif isinstance(node, bool):  # a property of the scene itself
                lines += _xml_value(key, node, 1)
            else:
                lines += _xml_plugin(node, None, key, 1)
        lines.append("</scene>")
        xml_path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    except OSError as e:
        raise DrptError(f"{xml_path}: cannot write Mitsuba scene: {e.strerror or e}") from e
    return xml_path


def _fmt(x: float) -> str:
    return repr(float(x))


def _xml_plugin(node: dict, name: str | None, ident: str | None, depth: int) -> list[str]:
    pad = "    " * depth
    ptype = node["type"]
    tag = _TAGS[ptype]
    attrs = f"type={quoteattr(ptype)}"
    if name is not None:
        attrs += f" name={quoteattr(name)}"
    if ident is not None and tag in ("shape", "emitter", "sensor", "integrator"):
        attrs += f" id={quoteattr(ident)}"
    lines = [f"{pad}<{tag} {attrs}>"]
    for k, v in node.items():
        if k != "type":
            lines += _xml_value(k, v, depth + 1)
    lines.append(f"{pad}</{tag}>")
    return lines


def _xml_value(k: str, v: Any, depth: int) -> list[str]:
    pad = "    " * depth
    n = quoteattr(k)
    if isinstance(v, dict):
        # Nested plugins that are property values (textures) carry a name;
        # children such as bsdf/emitter/film/sampler/rfilter need none.
        tag = _TAGS[v["type"]]
        named = tag == "texture" or k not in ("bsdf", "emitter", "film", "sampler", "rfilter", "phase")
        return _xml_plugin(v, k if named else None, None, depth)
    if isinstance(v, bool):
        return [f'{pad}<boolean name={n} value="{str(v).lower()}"/>']
    if isinstance(v, (int, np.integer)):
        return [f'{pad}<integer name={n} value="{int(v)}"/>']
    if isinstance(v, (float, np.floating)):
        return [f'{pad}<float name={n} value="{_fmt(v)}"/>']
    if isinstance(v, str):
        return [f"{pad}<string name={n} value={quoteattr(v)}/>"]
    if isinstance(v, _RGB):
        return [f'{pad}<rgb name={n} value="{", ".join(_fmt(c) for c in v.value)}"/>']
    if isinstance(v, (_Point, _Vector)):
        tag = "point" if isinstance(v, _Point) else "vector"
        x, y, z = (_fmt(c) for c in v.value)
        return [f'{pad}<{tag} name={n} x="{x}" y="{y}" z="{z}"/>']
    if isinstance(v, _Matrix):
        vals = " ".join(_fmt(c) for c in np.asarray(v.value).ravel())
        return [f"{pad}<transform name={n}>", f'{pad}    <matrix value="{vals}"/>',
                f"{pad}</transform>"]
    raise TypeError(f"cannot write {k}={v!r} to Mitsuba XML")  # pragma: no cover


def _xml_mesh(md: _MeshData, rel_path: str, ident: str, depth: int) -> list[str]:
    node: dict[str, Any] = {"type": "ply", "filename": rel_path}
    if md.normals is None:
        node["face_normals"] = True  # don't let the loader invent smooth normals
    node["bsdf"] = md.bsdf
    if md.emitter is not None:
        node["emitter"] = md.emitter
    for side in ("interior", "exterior"):
        if getattr(md, side) is not None:
            node[side] = getattr(md, side)
    return _xml_plugin(node, None, ident, depth)


def _write_ply(path: Path, pos: np.ndarray, faces: np.ndarray,
               nrm: np.ndarray | None, uv: np.ndarray | None, attributes=None) -> None:
    """Binary little-endian PLY: float32 vertex props, uchar/uint32 face list; mesh
    attributes as ``<name>_<channel>`` vertex or face properties (``vertex_color`` ->
    vertex ``color_0..2``, Mitsuba's PLY loader's naming)."""
    attributes = attributes or {}
    vattr = {k[len("vertex_"):]: a for k, a in attributes.items() if k.startswith("vertex_")}
    fattr = {k[len("face_"):]: a for k, a in attributes.items() if k.startswith("face_")}
    nv, nf = pos.shape[0], faces.shape[0]
    props = ["x", "y", "z"]
    cols = [pos]
    if nrm is not None:
        props += ["nx", "ny", "nz"]
        cols.append(nrm)
    if uv is not None:
        props += ["u", "v"]
        cols.append(uv)
    for base, a in vattr.items():
        props += [f"{base}_{c}" for c in range(a.shape[2])]
        cols.append(a.reshape(-1, a.shape[2]))
    vert = np.ascontiguousarray(np.concatenate(cols, axis=1), dtype="<f4")
    header = ["ply", "format binary_little_endian 1.0", "comment written by drpt",
              f"element vertex {nv}"]
    header += [f"property float {p}" for p in props]
    header += [f"element face {nf}", "property list uchar uint vertex_indices"]
    fields = [("n", "u1"), ("idx", "<u4", (3,))]
    for base, a in fattr.items():
        header += [f"property float {base}_{c}" for c in range(a.shape[2])]
        fields += [(f"{base}_{c}", "<f4") for c in range(a.shape[2])]
    header.append("end_header")
    face_rec = np.zeros(nf, dtype=fields)
    face_rec["n"] = 3
    face_rec["idx"] = faces
    for base, a in fattr.items():
        for c in range(a.shape[2]):
            face_rec[f"{base}_{c}"] = a[:, 0, c]
    with open(path, "wb") as f:
        f.write(("\n".join(header) + "\n").encode("ascii"))
        f.write(vert.tobytes())
        f.write(face_rec.tobytes())
