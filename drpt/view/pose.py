"""drpt's camera and viser's camera pose, both ways.

viser poses a camera as ``T_world_camera`` in OpenCV's convention: the
rotation ``R`` (quaternion ``wxyz``) has columns right ``+x``, down ``+y``
and forward ``+z``, the position is the eye, and ``fov`` is the *vertical*
field of view in radians. drpt's :class:`~drpt.scene.model.PerspectiveCamera`
has a center, a direction, an up vector (not necessarily orthogonal to the
direction) and ``fov``, the full vertical field of view in degrees, and
:func:`drpt.render.camera.camera_basis` makes the orthonormal forward ``f``,
right ``r`` and up ``u`` from them. So ``R = [r, -u, f]``, ``position =
center`` and ``fov = radians(angle)``; back, ``direction = R[:, 2]``, ``up =
-R[:, 1]``, ``angle = degrees(fov)``. Both describe the same rays: a
camera converted to a pose and back has the same basis, center and angle.

An orthographic camera keeps its ``size``: the pose sets its center and
basis (viser's raster preview of it is a perspective view).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..render.camera import camera_basis
from ..scene.model import Camera, OrthographicCamera, PerspectiveCamera


def matrix_to_wxyz(R: np.ndarray) -> np.ndarray:
    """The unit quaternion (w, x, y, z), w >= 0, of a rotation matrix."""
    R = np.asarray(R, float)
    t = np.trace(R)
    if t > 0.0:
        s = 2.0 * math.sqrt(1.0 + t)
        q = [0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s]
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = 2.0 * math.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        q = [(R[2, 1] - R[1, 2]) / s, 0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s]
    elif R[1, 1] > R[2, 2]:
        s = 2.0 * math.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2])
        q = [(R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1])
        q = [(R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s]
    q = np.asarray(q)
    q /= np.linalg.norm(q)
    return -q if q[0] < 0.0 else q


def wxyz_to_matrix(wxyz) -> np.ndarray:
    """The rotation matrix of a quaternion (w, x, y, z), normalized first."""
    w, x, y, z = np.asarray(wxyz, float) / np.linalg.norm(wxyz)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def camera_to_pose(cam: Camera) -> tuple[np.ndarray, np.ndarray, float]:
    """viser's ``(position, wxyz, fov)`` of a drpt camera (``fov`` in radians;
    an orthographic camera gets a 45-degree raster view)."""
    f, r, u = camera_basis(cam)
    R = np.stack([r, -u, f], axis=1)
    fov = math.radians(cam.fov) if isinstance(cam, PerspectiveCamera) else math.radians(45.0)
    return np.asarray(cam.center, float), matrix_to_wxyz(R), fov


def pose_to_camera(position, wxyz, fov: float, like: Camera) -> Camera:
    """The drpt camera of viser's pose: a :class:`PerspectiveCamera` with the
    pose's vertical ``fov`` (radians) and ``like``'s lens (aperture and focus
    distance, when ``like`` is a thin lens), or, when ``like`` is
    orthographic, ``like``'s size at the pose."""
    R = wxyz_to_matrix(wxyz)
    center = tuple(float(c) for c in position)
    direction = tuple(float(c) for c in R[:, 2])
    up = tuple(float(c) for c in -R[:, 1])
    if isinstance(like, OrthographicCamera):
        return replace(like, center=center, direction=direction, up=up)
    if isinstance(like, PerspectiveCamera):
        return replace(like, center=center, direction=direction, up=up,
                       fov=math.degrees(float(fov)))
    return PerspectiveCamera(center, direction, up, math.degrees(float(fov)))


def look_at_point(cam: Camera, distance: float) -> np.ndarray:
    """The point ``distance`` ahead of the camera (viser orbits around it)."""
    f, _r, _u = camera_basis(cam)
    return np.asarray(cam.center, float) + distance * f


def camera_block(cam: Camera) -> str:
    """The camera as a block of the seed's scene format."""
    def v3(v) -> str:
        return " ".join(repr(float(c)) for c in v)

    if isinstance(cam, OrthographicCamera):
        head, last = "OrthographicCamera", f"    size {float(cam.size)!r}"
    else:
        head, last = "PerspectiveCamera", f"    angle {float(cam.fov)!r}"
        if cam.aperture_radius > 0.0:
            last += (f"\n    apertureRadius {float(cam.aperture_radius)!r}"
                     f"\n    focusDistance {float(cam.focus_distance)!r}")
    return (f"{head} {{\n    center {v3(cam.center)}\n    direction {v3(cam.direction)}\n"
            f"    up {v3(cam.up)}\n{last}\n}}\n")
