"""Emissive triangles as lights (drpt/render/lights/area.py)."""

import numpy as np
from drjit.auto import Array2f, Bool, Float, UInt32
from scipy import stats

from drpt.render.lights.area import AreaLights
from drpt.render.surface import SurfaceData
from drpt.scene.model import Material, PerspectiveCamera, Scene, Triangles

CAM = PerspectiveCamera((0, 0, 5), (0, 0, -1), (0, 1, 0), 40)


def lights_scene(n_split=1):
    """Three emitters of different area and radiance, plus a dark triangle."""
    tris, mats = [], []
    for k, (size, mat) in enumerate([(1.0, 0), (2.0, 1), (0.5, 2), (1.0, 3)]):
        p0 = np.array([3.0 * k, 0, 0])
        tris.append([p0, p0 + [size, 0, 0], p0 + [0, size, 0]])
        mats.append(mat)
    materials = [Material("a", emission=(1, 1, 1)), Material("b", emission=(2, 0, 0)),
                 Material("c", emission=(0, 0, 5)), Material("dark")]
    return Scene(path=None, camera=CAM, materials=materials,
                 triangles=Triangles(np.array(tris, float), np.array(mats, np.int32)))


def test_selection_is_proportional_to_power():
    scene = lights_scene()
    lights = AreaLights(scene, SurfaceData(scene))
    assert lights.count == 3
    n = 200_000
    rng = np.random.default_rng(0)
    ls = lights.sample(Float(rng.random(n).astype(np.float32)),
                       Array2f(rng.random((2, n)).astype(np.float32)), Bool(True))
    x = np.array(ls.p)[0]
    which = np.floor(x / 3.0 + 1e-6).astype(int)
    counts = np.bincount(which, minlength=4)
    assert counts[3] == 0  # the dark triangle is never chosen
    area = np.array([0.5, 2.0, 0.125])
    lum = np.array([1.0, 2 * 0.2126, 5 * 0.0722])
    p = area * lum / (area * lum).sum()
    _, pvalue = stats.chisquare(counts[:3], p * n)
    assert pvalue > 1e-3
    # the reported area density is P(k) / area_k
    np.testing.assert_allclose(np.array(ls.pdf_area), (p / area)[which], rtol=1e-5)
    assert np.allclose(np.array(lights.pdf_area(UInt32([0, 1, 2, 3]), Bool(True))),
                       list(p / area) + [0.0], rtol=1e-5)
