"""Mitsuba shapes as drpt geometry (world-space, unwelded triangles; spheres).

* ``obj``, ``ply``, ``serialized``, ``rectangle``, ``cube``: Mitsuba's own
  loaders build the mesh (``mi.load_dict`` with the node's ``filename``,
  ``to_world``, ``face_normals``, ``flip_normals``, ``flip_tex_coords``,
  ``shape_index``), so drpt gets exactly Mitsuba's vertices, faces, vertex
  normals (the file's, or the ones Mitsuba computes for a mesh without
  them unless ``face_normals``) and texture coordinates, in world space.
  ``flip_normals``: Mitsuba keeps the buffers as loaded and reports the flip
  (``has_flipped_normals``), applying it when it intersects; drpt applies it
  here, reversing the winding and negating the vertex normals as Mitsuba's
  ``Mesh::pack`` does.
* ``sphere``: an analytic :class:`~drpt.scene.model.Spheres` entry when
  ``to_world`` is a similarity and the normals point out (``flip_normals``
  false, ``to_world`` not mirroring -- Mitsuba flips the normals of a
  mirrored sphere) and its BSDF has no texture (drpt's spheres have no
  uvs); otherwise tessellated (:data:`SPHERE_STACKS` x
  :data:`SPHERE_SLICES` quads, analytic vertex normals, Mitsuba's uvs
  ``(phi / 2 pi, theta / pi)``) with a warning.
* ``disk``: tessellated, a fan of :data:`DISK_SEGMENTS` triangles of the
  unit disk in the local ``z = 0`` plane, normal ``+z`` (area smaller than
  the circle's by a relative ``(2 pi / N)^2 / 6``, 1e-4), uv ``(r, phi /
  2 pi)`` as Mitsuba's.
* ``cylinder``: tessellated, :data:`CYLINDER_SEGMENTS` flat quads around the
  open tube from ``p0`` to ``p1`` with ``radius`` (no caps, as Mitsuba's),
  radial vertex normals (outward unless flipped), uv ``(phi / 2 pi, t)``.

Texture coordinates are returned in drpt's (OBJ) convention, ``v`` up:
``(u, 1 - v)`` of Mitsuba's ``si.uv`` (see :mod:`drpt.render.texture`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .nodes import Node, _one_line
from .precheck import check_indices, check_mesh

SPHERE_STACKS = 64
SPHERE_SLICES = 128
DISK_SEGMENTS = 256
CYLINDER_SEGMENTS = 256

MESH_PLUGINS = ("obj", "ply", "serialized", "rectangle", "cube")
ANALYTIC_PLUGINS = ("sphere", "disk", "cylinder")


@dataclass
class Mesh:
    positions: np.ndarray  # (F, 3, 3)
    normals: np.ndarray | None  # (F, 3, 3) unit, or None (geometric normals)
    uvs: np.ndarray | None  # (F, 3, 2), drpt convention
    attributes: dict | None = None  # name -> (F, 3, C) corner values (mesh_attribute)

    def __len__(self) -> int:
        return int(self.positions.shape[0])


def _normalize(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 0, n, 1.0)


def transform_points(m: np.ndarray, p: np.ndarray) -> np.ndarray:
    return p @ m[:3, :3].T + m[:3, 3]


def transform_normals(m: np.ndarray, n: np.ndarray) -> np.ndarray:
    inv_t = np.linalg.inv(m[:3, :3]).T
    return _normalize(n @ inv_t.T)


def _indexed(p: np.ndarray, faces: np.ndarray, n: np.ndarray | None, uv: np.ndarray | None,
             flip: bool) -> Mesh:
    f = faces.reshape(-1, 3).astype(np.int64)
    if flip:
        f = f[:, ::-1]
    normals = None
    if n is not None and len(n):
        normals = _normalize(n[f])
        if flip:
            normals = -normals
    uvs = None
    if uv is not None and len(uv):
        uvs = uv[f].copy()
        uvs[..., 1] = 1.0 - uvs[..., 1]
    return Mesh(p[f], normals, uvs)


def load_mesh(node: Node, to_world: np.ndarray, attributes=()) -> Mesh:
    """A mesh plugin through Mitsuba's loader, in world space (``to_world`` is the
    node's own, times an instance's), with the named mesh attributes (Mitsuba's
    ``vertex_*`` / ``face_*`` buffers, per corner)."""
    mi = node.state.mi
    d = {"type": node.plugin, "to_world": mi.ScalarTransform4f(to_world.tolist())}
    if node.plugin in ("obj", "ply", "serialized"):
        filename = node.str("filename")
        if filename is None:
            raise node.error(f"{node.label}: needs a 'filename'")
        d["filename"] = str(node.resolve_file(filename))
        check_mesh(node.plugin, Path(d["filename"]), node, node.int("shape_index", 0) or 0)
    for name, get in (("face_normals", node.bool), ("flip_tex_coords", node.bool),
                      ("shape_index", node.int)):
        if node.plugin == "serialized" and name == "flip_tex_coords":
            continue
        if node.plugin in ("rectangle", "cube") and name != "face_normals":
            continue
        if node.plugin != "serialized" and name == "shape_index":
            continue
        value = get(name)
        if value is not None:
            d[name] = value
    if node.bool("flip_normals", False):
        d["flip_normals"] = True
    try:
        mesh = mi.load_dict(d)
    except RuntimeError as e:
        raise node.error(f"{node.label}: {_one_line(str(e))}") from None
    except UnicodeDecodeError:  # Mitsuba's message quotes the file's bytes
        raise node.error(f"{node.label}: Mitsuba cannot read {d.get('filename', 'the mesh')} "
                         "(not a valid mesh file)") from None
    p = np.array(mesh.vertex_positions_buffer(), dtype=np.float64).reshape(-1, 3)
    faces = np.array(mesh.faces_buffer(), dtype=np.int64).reshape(-1, 3)
    check_indices(faces, len(p), node)
    n = None
    if mesh.has_vertex_normals() and not mesh.has_face_normals():
        n = np.array(mesh.vertex_normals_buffer(), dtype=np.float64).reshape(-1, 3)
    uv = None
    if mesh.has_vertex_texcoords():
        uv = np.array(mesh.vertex_texcoords_buffer(), dtype=np.float64).reshape(-1, 2)
    # the buffers are as loaded; Mitsuba flips when it intersects (has_flipped_normals)
    flipped = bool(mesh.has_flipped_normals())
    out = _indexed(p, faces, n, uv, flipped)
    if attributes:
        out.attributes = {}
        f = faces[:, ::-1] if flipped else faces
        for name in attributes:
            if not mesh.has_attribute(name):
                raise node.error(f"{node.label} has no mesh attribute '{name}' (a mesh_attribute "
                                 "texture of its BSDF reads it)")
            buf = np.array(mesh.attribute_buffer(name), dtype=np.float64)
            if name.startswith("vertex_"):
                a = buf.reshape(len(p), -1)[f]
            else:
                a = np.repeat(buf.reshape(len(faces), -1)[:, None, :], 3, axis=1)
            if a.shape[2] not in (1, 3):
                raise node.error(f"{node.label}: mesh attribute '{name}' has {a.shape[2]} channels "
                                 "(drpt reads 1 or 3)")
            out.attributes[name] = a
    return out


# ------------------------------------------------------------ analytic shapes
def is_similarity(m: np.ndarray, rtol: float = 1e-6) -> tuple[bool, float]:
    """Whether the linear part of ``m`` is a rotation (or mirror) times a uniform
    scale, and that scale."""
    a = m[:3, :3]
    g = a.T @ a
    s2 = float(np.trace(g) / 3.0)
    if not (s2 > 0 and math.isfinite(s2)):
        return False, 0.0
    ok = np.allclose(g, s2 * np.eye(3), rtol=0, atol=rtol * s2) and np.allclose(m[3], (0, 0, 0, 1))
    return bool(ok), math.sqrt(s2)


def sphere_local(center, radius, to_world: np.ndarray) -> np.ndarray:
    """Mitsuba's sphere frame: ``to_world * translate(center) * scale(radius)``."""
    local = np.eye(4)
    local[:3, :3] *= radius
    local[:3, 3] = center
    return to_world @ local


def tessellate_sphere(m: np.ndarray, flip: bool) -> Mesh:
    """The unit sphere under ``m``: quads between latitude rings, analytic normals."""
    th = np.linspace(0.0, math.pi, SPHERE_STACKS + 1)
    ph = np.linspace(0.0, 2.0 * math.pi, SPHERE_SLICES + 1)
    T, P = np.meshgrid(th, ph, indexing="ij")
    v = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1)
    uv = np.stack([P / (2 * math.pi), T / math.pi], -1)
    i, j = np.meshgrid(np.arange(SPHERE_STACKS), np.arange(SPHERE_SLICES), indexing="ij")
    a, b, c, d = (i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1)
    quads = [(a, b, c), (a, c, d)]
    tris = []
    for q in quads:
        tris.append(np.stack([np.stack(k, -1) for k in q], -2).reshape(-1, 3, 2))
    idx = np.concatenate(tris)
    # drop the degenerate triangles at the poles
    pos = v[idx[..., 0], idx[..., 1]]
    area = np.linalg.norm(np.cross(pos[:, 1] - pos[:, 0], pos[:, 2] - pos[:, 0]), axis=1)
    keep = area > 1e-12
    idx = idx[keep]
    return _analytic(m, v[idx[..., 0], idx[..., 1]], v[idx[..., 0], idx[..., 1]],
                     uv[idx[..., 0], idx[..., 1]], flip)


def _analytic(m, pos, nrm, uv, flip) -> Mesh:
    """Local triangles ``pos`` with local normals ``nrm`` (outward), in world space,
    oriented so that the geometric normal agrees with the (flipped) shading normal."""
    p = transform_points(m, pos.reshape(-1, 3)).reshape(-1, 3, 3)
    n = transform_normals(m, nrm.reshape(-1, 3)).reshape(-1, 3, 3)
    if flip:
        n = -n
    g = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    wrong = np.einsum("ij,ij->i", g, n.sum(1)) < 0
    p[wrong] = p[wrong][:, ::-1]
    n[wrong] = n[wrong][:, ::-1]
    uv = uv.copy()
    uv[wrong] = uv[wrong][:, ::-1]
    uv[..., 1] = 1.0 - uv[..., 1]
    return Mesh(p, n, uv)


def tessellate_disk(m: np.ndarray, flip: bool) -> Mesh:
    k = np.arange(DISK_SEGMENTS)
    phi0 = 2 * math.pi * k / DISK_SEGMENTS
    phi1 = 2 * math.pi * (k + 1) / DISK_SEGMENTS
    zero = np.zeros_like(phi0)
    pos = np.stack([np.stack([zero, zero, zero], -1),
                    np.stack([np.cos(phi0), np.sin(phi0), zero], -1),
                    np.stack([np.cos(phi1), np.sin(phi1), zero], -1)], 1)
    nrm = np.broadcast_to(np.array([0.0, 0.0, 1.0]), pos.shape).copy()
    uv = np.stack([np.stack([zero, phi0 / (2 * math.pi)], -1),
                   np.stack([zero + 1, phi0 / (2 * math.pi)], -1),
                   np.stack([zero + 1, phi1 / (2 * math.pi)], -1)], 1)
    return _analytic(m, pos, nrm, uv, flip)


def cylinder_frame(p0, p1, radius) -> np.ndarray:
    """Mitsuba's cylinder object-to-local frame: ``translate(p0) * to_frame(d) *
    scale(r, r, |d|)``, with the frame of ``d`` built as Mitsuba's
    ``coordinate_system``."""
    p0 = np.asarray(p0, float)
    d = np.asarray(p1, float) - p0
    length = float(np.linalg.norm(d))
    n = d / length
    sign = math.copysign(1.0, n[2])
    a = -1.0 / (sign + n[2])
    b = n[0] * n[1] * a
    s = np.array([sign * n[0] * n[0] * a + 1.0, sign * b, -sign * n[0]])
    t = np.array([b, sign + n[1] * n[1] * a, -n[1]])
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2] = s * radius, t * radius, n * length
    m[:3, 3] = p0
    return m


def tessellate_cylinder(m: np.ndarray, flip: bool) -> Mesh:
    k = np.arange(CYLINDER_SEGMENTS)
    phi0 = 2 * math.pi * k / CYLINDER_SEGMENTS
    phi1 = 2 * math.pi * (k + 1) / CYLINDER_SEGMENTS
    c0, s0, c1, s1 = np.cos(phi0), np.sin(phi0), np.cos(phi1), np.sin(phi1)
    z0, z1 = np.zeros_like(phi0), np.ones_like(phi0)
    a = np.stack([c0, s0, z0], -1)
    b = np.stack([c1, s1, z0], -1)
    c = np.stack([c1, s1, z1], -1)
    d = np.stack([c0, s0, z1], -1)
    pos = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    nrm = pos.copy()
    nrm[..., 2] = 0.0
    u0, u1 = phi0 / (2 * math.pi), phi1 / (2 * math.pi)
    uva = np.stack([u0, z0], -1)
    uvb = np.stack([u1, z0], -1)
    uvc = np.stack([u1, z1], -1)
    uvd = np.stack([u0, z1], -1)
    uv = np.concatenate([np.stack([uva, uvb, uvc], 1), np.stack([uva, uvc, uvd], 1)])
    return _analytic(m, pos, nrm, uv, flip)
