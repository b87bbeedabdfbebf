"""4x4 affine transforms (numpy) for the scene format's ``Transform`` blocks.

Matrices act on column vectors: ``p_world = M @ [x, y, z, 1]``. A
``Transform`` block's operations compose left to right as written
(``M = Op1 @ Op2 @ ...``), so the *last* operation is applied to the object
first, as in MIT 6.837; nested transforms compose as ``M_parent @ M``.

Geometry helpers:

* points: ``M @ p``;
* normals: the inverse-transpose of the 3x3 part, then renormalized;
* triangles: positions and normals as above; when ``det(M) < 0`` corners 1
  and 2 are swapped so the geometric normal ``cross(p1 - p0, p2 - p0)`` keeps
  pointing to the same (outer) side as the transformed shading normals;
* planes ``dot(n, x) = d``: the normal by inverse-transpose, the point ``n d``
  by ``M``;
* spheres: a similarity (uniform scale times rotation, within 1e-6 relative)
  keeps a sphere a sphere; anything else needs :func:`tessellate_sphere`.

Angles are in degrees, rotations right-handed. ``Translate 1 0 0`` then ``RotateZ 90``
(written in that order) rotates a point first, then moves it:

>>> m = compose(translate(1, 0, 0), rotate_z(90))
>>> transform_points(m, np.array([1.0, 0.0, 0.0])).round(12).tolist()
[1.0, 1.0, 0.0]
"""

from __future__ import annotations

import math

import numpy as np


def identity() -> np.ndarray:
    """The 4x4 identity."""
    return np.eye(4)


def translate(x: float, y: float, z: float) -> np.ndarray:
    """Translation by ``(x, y, z)``."""
    m = np.eye(4)
    m[:3, 3] = (x, y, z)
    return m


def scale(x: float, y: float, z: float) -> np.ndarray:
    """Scale by ``x``, ``y``, ``z`` along the axes (negative factors mirror)."""
    return np.diag([x, y, z, 1.0])


def rotate_axis(axis, degrees: float) -> np.ndarray:
    """Right-handed rotation by ``degrees`` about ``axis`` (need not be unit).

    Raises ``ValueError`` for a zero-length axis."""
    a = normalize(axis)
    if not a.any():
        raise ValueError("rotation axis has zero length")
    x, y, z = a
    t = math.radians(degrees)
    c, s = math.cos(t), math.sin(t)
    C = 1.0 - c
    m = np.eye(4)
    m[:3, :3] = [
        [c + x * x * C, x * y * C - z * s, x * z * C + y * s],
        [y * x * C + z * s, c + y * y * C, y * z * C - x * s],
        [z * x * C - y * s, z * y * C + x * s, c + z * z * C],
    ]
    return m


def rotate_x(degrees: float) -> np.ndarray:
    """Right-handed rotation by ``degrees`` about the x axis."""
    return rotate_axis((1.0, 0.0, 0.0), degrees)


def rotate_y(degrees: float) -> np.ndarray:
    """Right-handed rotation by ``degrees`` about the y axis."""
    return rotate_axis((0.0, 1.0, 0.0), degrees)


def rotate_z(degrees: float) -> np.ndarray:
    """Right-handed rotation by ``degrees`` about the z axis."""
    return rotate_axis((0.0, 0.0, 1.0), degrees)


# Vectors and matrices whose largest entry lies in this range are handled
# directly; outside it they are first divided by that entry, so that squares,
# cubes and inverses stay within float64. (Inside it the results are the
# plain formulas' own, bit for bit.)
_PLAIN = (1e-90, 1e90)


def _prescale(big: float) -> float:
    """The divisor to apply first: 1 in the plain range, else ``big``."""
    return 1.0 if _PLAIN[0] < big < _PLAIN[1] else big


def compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a @ b``; an overflow gives inf entries (see :func:`is_finite`), not a warning."""
    with np.errstate(all="ignore"):
        return a @ b


def is_finite(m: np.ndarray) -> bool:
    """Whether every entry of ``m`` is finite (an overflowing :func:`compose` gives inf)."""
    return bool(np.isfinite(m).all())


def is_identity(m: np.ndarray) -> bool:
    """Whether ``m`` is exactly the identity (no tolerance)."""
    return bool(np.array_equal(m, np.eye(4)))


def normal_matrix(m: np.ndarray) -> np.ndarray:
    """Inverse-transpose of the 3x3 part (raises ``LinAlgError`` if singular)."""
    return np.linalg.inv(m[:3, :3]).T


def is_invertible(m: np.ndarray) -> bool:
    """Whether the 3x3 part is finite and not (numerically) singular:
    ``|det(A / s)| > 1e-12`` with ``s`` its largest entry, so the test does
    not depend on the matrix's scale (and cannot overflow)."""
    a = m[:3, :3]
    if not is_finite(a):
        return False
    s = float(np.abs(a).max())
    if not s > 0:
        return False
    with np.errstate(all="ignore"):
        return abs(float(np.linalg.det(a / s))) > 1e-12


def transform_points(m: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Apply ``m`` to points of shape (..., 3); an overflow gives inf, not a warning."""
    with np.errstate(all="ignore"):
        return p @ m[:3, :3].T + m[:3, 3]


def transform_normals(m: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Apply the inverse-transpose of ``m`` to normals (..., 3) and renormalize.

    Normals that end up with zero length stay zero. The inverse is taken of
    the matrix divided by its largest entry (the normals' directions do not
    change), so huge or tiny scales neither overflow nor underflow."""
    a = m[:3, :3] / _prescale(float(np.abs(m[:3, :3]).max()))
    with np.errstate(all="ignore"):
        out = n @ np.linalg.inv(a)  # rows times (A^-T)^T
        length = np.linalg.norm(out, axis=-1, keepdims=True)
    if np.isfinite(length).all() and (length[length > 0] > _PLAIN[0]).all():
        return np.divide(out, length, out=np.zeros_like(out), where=length > 0)
    return normalize(out)


def length(v) -> float:
    """Euclidean length of the vector ``v``, without overflow or underflow in between."""
    v = np.asarray(v, dtype=np.float64)
    big = float(np.abs(v).max()) if v.size else 0.0
    if not (big > 0 and math.isfinite(big)):
        return big
    k = _prescale(big)
    return k * float(np.linalg.norm(v / k))


def normalize(v: np.ndarray) -> np.ndarray:
    """Unit vectors along the last axis of ``v``; zero (or non-finite) ones become zero.

    Each vector is divided by its largest component first, so lengths far
    beyond sqrt(float64 max) neither overflow nor warn."""
    v = np.asarray(v, dtype=np.float64)
    with np.errstate(all="ignore"):
        big = np.abs(v).max(axis=-1, keepdims=True)
        ok = (big > 0) & np.isfinite(big)
        k = np.where((big > _PLAIN[0]) & (big < _PLAIN[1]), 1.0, big)
        w = np.divide(v, k, out=np.zeros_like(v), where=ok)
        length = np.linalg.norm(w, axis=-1, keepdims=True)
        return np.divide(w, length, out=np.zeros_like(w), where=ok & (length > 0))


def transform_triangles(m: np.ndarray, positions: np.ndarray, normals: np.ndarray | None):
    """Transform per-corner arrays (F, 3, 3); see the module docstring.

    Returns ``(positions, normals, flipped)``; when ``flipped`` is true the
    caller must swap corners 1 and 2 of any other per-corner array (uvs)."""
    p = transform_points(m, positions)
    n = None if normals is None else transform_normals(m, normals)
    flipped = bool(np.linalg.det(m[:3, :3] / _prescale(float(np.abs(m[:3, :3]).max()))) < 0)
    if flipped:
        p = p[:, [0, 2, 1]]
        if n is not None:
            n = n[:, [0, 2, 1]]
    return p, n, flipped


def transform_plane(m: np.ndarray, normal, offset: float) -> tuple[np.ndarray, float]:
    """Transform the plane ``dot(normal, x) = offset`` (normal unit)."""
    n = np.asarray(normal, dtype=np.float64)
    point = transform_points(m, n * offset)
    n2 = transform_normals(m, n)
    with np.errstate(all="ignore"):
        return n2, float(n2 @ point)


def similarity_scale(m: np.ndarray, rtol: float = 1e-6) -> float | None:
    """The uniform scale factor if the 3x3 part of ``m`` is a similarity
    (``A^T A = s^2 I`` within ``rtol`` relative), else ``None``."""
    a = m[:3, :3]
    big = float(np.abs(a).max())
    if not (big > 0 and math.isfinite(big)):
        return None
    k = _prescale(big)  # the test is scale-free; this keeps A^T A finite
    a = a / k
    g = a.T @ a
    s2 = float(np.trace(g)) / 3.0
    if not s2 > 0:
        return None
    if np.abs(g - s2 * np.eye(3)).max() > rtol * s2:
        return None
    return k * math.sqrt(s2)


def tessellate_sphere(center, radius: float, rings: int = 32, segments: int = 32):
    """A UV sphere: ``(positions (F,3,3), normals (F,3,3))``, outward normals,
    counter-clockwise seen from outside. 32 x 32 gives 1984 triangles."""
    c = np.asarray(center, dtype=np.float64)
    theta = np.linspace(0.0, math.pi, rings + 1)  # from +z pole to -z pole
    phi = np.linspace(0.0, 2.0 * math.pi, segments + 1)
    st, ct = np.sin(theta)[:, None], np.cos(theta)[:, None]
    dirs = np.stack([st * np.cos(phi)[None, :], st * np.sin(phi)[None, :],
                     np.broadcast_to(ct, (rings + 1, segments + 1))], axis=-1)
    dirs[0] = (0.0, 0.0, 1.0)
    dirs[-1] = (0.0, 0.0, -1.0)
    i, j = np.meshgrid(np.arange(rings), np.arange(segments), indexing="ij")
    a = dirs[i, j]
    b = dirs[i + 1, j]
    cc = dirs[i + 1, j + 1]
    d = dirs[i, j + 1]
    # Quads (a, b, c, d) are counter-clockwise from outside; drop the
    # degenerate triangle at each pole.
    upper = np.stack([a, b, cc], axis=-2)[:-1].reshape(-1, 3, 3)  # b, c at the south pole on the last ring
    lower = np.stack([a, cc, d], axis=-2)[1:].reshape(-1, 3, 3)  # a, d at the north pole on ring 0
    tris = np.concatenate([upper, lower], axis=0)
    return c + radius * tris, tris.copy()
