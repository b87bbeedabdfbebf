"""An env-lit test scene: a gradient sky with a one-texel sun 2e4x brighter
than the sky (``Skybox``), a glossy sphere (material ``glossy``: Phong, or
``ct_metal``: Cook-Torrance metal), a matte sphere and a matte ground; with
``point`` also a point light. The scene of tests/validation/test_env_render.py, which
benchmarks/env_sampling.py renders with both sky samplers.
"""

from pathlib import Path

import numpy as np

from ...imageio import write_image


def sky_with_sun(path, w=64, h=32, sun=(10, 40), sun_value=2e4):
    """A blue-to-white gradient sky with a one-texel sun 1e4-1e5x brighter."""
    v = (np.arange(h) + 0.5)[:, None, None] / h
    img = np.broadcast_to(np.array([0.3, 0.5, 1.0]) * (1 - v) + 0.8 * v, (h, w, 3)).copy()
    img[h // 2:] *= 0.2  # darker ground half
    img[sun] = sun_value
    write_image(path, img.astype(np.float32))
    return path


SCENE = """
PerspectiveCamera {{ center 0 1.2 5  direction 0 -0.15 -1  up 0 1 0  angle 40 }}
Lights {{ numLights {n}
    Skybox {{ sky.exr  R 1000 }}
    {point}
}}
Group {{
    numObjects 3
    TriangleMesh {{ obj_file ground.obj }}
    Sphere {{ center -0.8 0.8 0 radius 0.8  mtl {mtl} }}
    Sphere {{ center 1.0 0.6 0.5 radius 0.6  mtl matte }}
}}
"""
OBJ = """mtllib m.mtl
v -4 0 -4
v 4 0 -4
v 4 0 4
v -4 0 4
usemtl matte
f 1 4 3 2
"""
MTL = """newmtl matte
Kd 0.6 0.6 0.6
newmtl glossy
Kd 0.2 0.3 0.5
Ks 0.6 0.6 0.6
Ns 200
newmtl ct_metal
Kd 0.9 0.8 0.6
Roughness 0.15
Mentalness 1
"""


def main(out: Path, mtl: str = "glossy", point: bool = False) -> Path:
    """Write the scene into folder ``out``; return its scene file."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    sky_with_sun(out / "sky.exr")
    (out / "ground.obj").write_text(OBJ)
    (out / "m.mtl").write_text(MTL)
    p = out / "scene.txt"
    light = "PointLight { position 2 3 2  color 15 15 15 }" if point else ""
    p.write_text(SCENE.format(n=2 if point else 1, point=light, mtl=mtl))
    return p
