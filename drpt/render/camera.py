"""Camera ray generation.

A pixel position ``(x, y)`` is continuous, measured from the image's top-left
corner (pixel ``(i, j)`` covers ``[i, i+1) x [j, j+1)``). With
``f = normalize(direction)``, ``r = normalize(cross(f, up))`` and
``u = cross(r, f)``:

* perspective: ``d = normalize(f + sx*r + sy*u)`` where
  ``sx = (2x/W - 1) * tan(fov/2) * W/H`` and ``sy = (1 - 2y/H) * tan(fov/2)``;
  ``fov`` is the full *vertical* field of view;
* orthographic: origin ``center + sx*r + sy*u`` with ``sx = (2x/W - 1) *
  size/2 * W/H`` (or ``* width/2`` where the camera gives its ``width``),
  ``sy = (1 - 2y/H) * size/2``, direction ``f``;
* thin lens (a perspective camera with ``aperture_radius = A > 0`` and
  ``focus_distance = F``), Mitsuba's ``thinlens``: the pinhole ray's point
  on the focal plane, ``P = center + F * (f + sx*r + sy*u)`` (its distance
  along ``f`` is ``F``), is seen from the lens point ``O = center + A * (-px
  * r + py * u)``, ``(px, py) = square_to_uniform_disk_concentric(v)`` for
  two more uniform numbers ``v``: origin ``O``, direction ``normalize(P -
  O)``. ``-r`` is Mitsuba's camera-space x (its ``look_at`` x axis is
  ``cross(up, f)``), so the lens point of a ``v`` is Mitsuba's too. Every ray
  has weight 1, as in Mitsuba (its ``sample_ray`` returns the wavelength
  weight only).

A perspective camera's :class:`~drpt.scene.model.FilmWindow` (Mitsuba's
crop window and principal point offset) replaces ``2x/W - 1`` by ``2u - 1``
with ``u = u0 + (u1 - u0) x / W`` (and ``1 - 2y/H`` by ``1 - 2v``), ``(u0, v0,
u1, v1)`` the window on the film (``FilmWindow.bounds``), and ``W/H`` in ``sx``
by the film's aspect: the rays of Mitsuba's ``perspective_projection`` for a
crop (its ``sample_ray`` adds the offset times ``film size / crop size`` to the
crop's sample position, i.e. ``shift`` film widths). Without a window the
kernel is the one it always was.

The Mitsuba exporter reproduces exactly this mapping.
"""

from __future__ import annotations

import math

import drjit as dr
import numpy as np
from drjit.auto import Array2f, Array3f, Bool, Float

from ..errors import DrptError
from ..scene.model import Camera, OrthographicCamera, PerspectiveCamera
from .warp import square_to_uniform_disk_concentric


def camera_basis(cam: Camera) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit forward, right and up vectors of a camera (numpy, float64)."""
    f = np.asarray(cam.direction, float)
    up = np.asarray(cam.up, float)
    if np.linalg.norm(f) == 0.0:
        raise DrptError("camera direction has zero length")
    f = f / np.linalg.norm(f)
    r = np.cross(f, up)
    if np.linalg.norm(r) < 1e-9 * max(np.linalg.norm(up), 1e-30):
        raise DrptError("camera up vector is parallel to its direction")
    r = r / np.linalg.norm(r)
    return f, r, np.cross(r, f)


class RayCamera:
    """Rays of a camera at an image size.

    The camera's position and basis are opaque Dr.Jit values, kernel inputs:
    a kernel traced with another camera of the same kind (perspective or
    orthographic, pinhole or thin lens) and image size is the same kernel,
    found in Dr.Jit's kernel cache, so moving the camera (or changing its
    aperture or focus) compiles nothing (:mod:`drpt.render.progressive`
    relies on it). The image size is a literal of the kernel (pixel indices
    divide by the width). :attr:`thin_lens` says whether :meth:`ray` needs
    its ``lens`` sample.
    """

    def __init__(self, cam: Camera, width: int, height: int):
        self.width, self.height = width, height
        f, r, u = camera_basis(cam)
        self.orthographic = isinstance(cam, OrthographicCamera)
        if isinstance(cam, PerspectiveCamera):
            half_h = math.tan(math.radians(cam.fov) / 2.0)
        else:
            half_h = cam.size / 2.0
        window = getattr(cam, "window", None) if isinstance(cam, PerspectiveCamera) else None
        self.window = window
        if window is None:
            half_w = half_h * width / height
            if getattr(cam, "width", None) is not None:  # an orthographic view of its own aspect
                half_w = cam.width / 2.0
        else:
            # the fov is the whole film's; image position x of W maps to film position
            # u = u0 + (u1 - u0) x / W, sx = 2 u - 1 (and sy = 1 - 2 v)
            half_w = half_h * window.film_width / window.film_height
            u0, v0, u1, v1 = window.bounds()
            self.kx, self.bx = 2.0 * (u1 - u0) / width, 2.0 * u0 - 1.0
            self.ky, self.by = -2.0 * (v1 - v0) / height, 1.0 - 2.0 * v0
        # Opaque, not literals: in Dr.Jit 1.5, ``Float(0.0) * wide_array``
        # resizes the literal 0 operand in place, so a camera basis with a
        # zero component would keep the first pass's width and break the next
        # pass of another size (tests/cli/test_cli.py covers it).
        self.center = dr.opaque(Array3f, tuple(map(float, cam.center)))
        self.f = dr.opaque(Array3f, tuple(map(float, f)))
        self.r = dr.opaque(Array3f, tuple(map(float, r * half_w)))  # scaled by half extents
        self.u = dr.opaque(Array3f, tuple(map(float, u * half_h)))
        aperture = getattr(cam, "aperture_radius", 0.0)
        self.thin_lens = isinstance(cam, PerspectiveCamera) and aperture > 0.0
        if self.thin_lens:
            if cam.focus_distance is None or not cam.focus_distance > 0.0:
                raise DrptError(f"a thin-lens camera needs a positive focus distance, got "
                                f"{cam.focus_distance}")
            self.lens_x = dr.opaque(Array3f, tuple(map(float, -r * aperture)))
            self.lens_y = dr.opaque(Array3f, tuple(map(float, u * aperture)))
            self.focus = dr.opaque(Float, float(cam.focus_distance))

    def ray(self, x: Float, y: Float, lens: Array2f | None = None) -> tuple[Array3f, Array3f]:
        """World-space ray (origin, unit direction) through pixel position (x, y);
        a thin lens also takes ``lens``, two uniform numbers that pick the point
        on the lens (without them: the lens center, the pinhole ray)."""
        if self.window is None:
            sx = 2.0 * x / self.width - 1.0
            sy = 1.0 - 2.0 * y / self.height
        else:
            sx = x * self.kx + self.bx
            sy = y * self.ky + self.by
        if self.orthographic:
            return self.center + self.r * sx + self.u * sy, Array3f(self.f)
        if self.thin_lens and lens is not None:
            p = square_to_uniform_disk_concentric(lens)
            offset = self.lens_x * p.x + self.lens_y * p.y
            target = (self.f + self.r * sx + self.u * sy) * self.focus
            return self.center + offset, dr.normalize(target - offset)
        return Array3f(self.center), dr.normalize(self.f + self.r * sx + self.u * sy)

    def connect(self, p: Array3f) -> tuple[Float, Float, Array3f, Float, Float, Bool]:
        """The camera seen from world points ``p`` (light tracing's connection to the sensor,
        Mitsuba's perspective ``sample_direction``): ``(x, y, wc, dist, importance, valid)``
        with ``(x, y)`` the pixel position ``p`` projects to, ``wc`` the unit direction from
        ``p`` toward the camera's center, ``dist`` the distance, and ``importance`` the
        sensor's importance per unit area at ``p``, ``W_e / dist^2``, where
        ``W_e = 1 / (A cos^3 theta)`` for a film of area ``A`` on the plane at distance 1
        (``theta``: the angle between ``-wc`` and the view direction). ``valid`` is False
        where ``p`` is behind the camera or outside the image. Pinhole cameras only (no crop
        window)."""
        v = p - self.center
        dist = dr.norm(v)
        z = dr.dot(v, self.f)
        inv_z = dr.rcp(z)
        half_w2 = dr.squared_norm(self.r)
        half_h2 = dr.squared_norm(self.u)
        sx = dr.dot(v, self.r) / half_w2 * inv_z
        sy = dr.dot(v, self.u) / half_h2 * inv_z
        x = (sx + 1.0) * (0.5 * self.width)
        y = (1.0 - sy) * (0.5 * self.height)
        valid = (z > 0.0) & (x >= 0.0) & (x < self.width) & (y >= 0.0) & (y < self.height)
        cos_t = z / dist
        area = 4.0 * dr.sqrt(half_w2 * half_h2)
        importance = dr.rcp(area * cos_t * cos_t * cos_t * dist * dist)
        wc = -v / dist
        return x, y, wc, dist, dr.select(valid, importance, 0.0), valid
