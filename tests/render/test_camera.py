"""Camera ray generation (drpt/render/camera.py) against the documented mapping."""

import math

import numpy as np
import pytest
from drjit.auto import Float

from drpt.errors import DrptError
from drpt.render.camera import RayCamera, camera_basis
from drpt.scene.model import OrthographicCamera, PerspectiveCamera


def _ray(cam, w, h, x, y):
    rc = RayCamera(cam, w, h)
    o, d = rc.ray(Float(x), Float(y))
    return np.array(o).ravel(), np.array(d).ravel()


def test_center_ray_is_forward():
    cam = PerspectiveCamera((1, 2, 3), (0, 0, -2.5), (0, 1, 0), 60)
    o, d = _ray(cam, 64, 48, 32, 24)
    assert np.allclose(o, [1, 2, 3]) and np.allclose(d, [0, 0, -1], atol=1e-6)


def test_vertical_fov_and_orientation():
    # Top edge center is fov/2 above the axis; right edge center is at the
    # horizontal half-angle atan(tan(fov/2) * W/H); +x image is camera right.
    cam = PerspectiveCamera((0, 0, 0), (0, 0, -1), (0, 1, 0), 60)
    W, H = 80, 40
    _, top = _ray(cam, W, H, 40, 0)
    assert math.isclose(math.degrees(math.atan2(top[1], -top[2])), 30, abs_tol=1e-4)
    _, right = _ray(cam, W, H, 80, 20)
    expect = math.degrees(math.atan(math.tan(math.radians(30)) * W / H))
    assert right[0] > 0 and math.isclose(math.degrees(math.atan2(right[0], -right[2])), expect, abs_tol=1e-4)


def test_orthographic_extent():
    cam = OrthographicCamera((0, 0, 5), (0, 0, -1), (0, 1, 0), 4.0)
    o, d = _ray(cam, 20, 10, 0, 0)  # top-left corner
    assert np.allclose(d, [0, 0, -1]) and np.allclose(o, [-4, 2, 5], atol=1e-6)


def test_up_is_orthogonalized():
    f, r, u = camera_basis(PerspectiveCamera((0, 0, 0), (0, 0, -1), (0, 1, -1), 45))
    assert np.allclose(u, [0, 1, 0]) and np.allclose(r, [1, 0, 0])


@pytest.mark.parametrize("direction, up", [((0, 0, 0), (0, 1, 0)), ((0, 1, 0), (0, 2, 0))])
def test_degenerate_basis_is_a_user_error(direction, up):
    with pytest.raises(DrptError):
        camera_basis(PerspectiveCamera((0, 0, 0), direction, up, 45))
