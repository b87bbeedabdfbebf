"""Writes many_lights: a floor lit by many small lights of very different power.

The scene the light selection is measured on (``--light-sampler``): a diffuse
floor (20 x 20) and a few diffuse boxes, lit by ``N`` (default 50) small square
lights (side 0.3) hanging 0.4 to 1.6 above the floor, each facing down (tilted by
up to 30 degrees), their radiances spread over two decades (5 to 500, log-uniform,
tinted) and their positions scattered over the floor, all drawn from a fixed seed.
Each light is its own material (its own emitter for ``--light-sampler uniform``).
A shading point sees mostly the few lights near it; a selection by power sends
most samples to the brightest lights wherever they are. The camera looks down at
the floor from (0, 9, 14). Files: ``many_lights.obj``, ``many_lights.mtl``,
``many_lights.txt``.

    python -m drpt.tools.scenegen.many_lights OUT_DIR [N]
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from . import meshes

SEED = 27
SIDE = 0.3
FLOOR_HALF = 10.0
CAMERA = ((0.0, 9.0, 14.0), (0.0, 0.0, 0.0))

SCENE = """\
# many_lights (drpt.tools.scenegen.many_lights): {n} small lights over a diffuse floor.
PerspectiveCamera {{
    center {c[0]:g} {c[1]:g} {c[2]:g}
    direction {d[0]:g} {d[1]:g} {d[2]:g}
    up 0 1 0
    angle 45
}}

Group {{
    numObjects 1
    TriangleMesh {{ obj_file many_lights.obj }}
}}
"""

FILES = ("many_lights.obj", "many_lights.mtl", "many_lights.txt")


def lights(n: int, seed: int = SEED):
    """The ``n`` lights: ``(centers (n, 3), normals (n, 3), radiances (n, 3))``."""
    rng = np.random.default_rng(seed)
    xz = rng.uniform(-0.85 * FLOOR_HALF, 0.85 * FLOOR_HALF, (n, 2))
    y = rng.uniform(0.4, 1.6, n)
    tilt = np.radians(rng.uniform(0.0, 30.0, n))
    az = rng.uniform(0.0, 2 * math.pi, n)
    normal = np.stack([np.sin(tilt) * np.cos(az), -np.cos(tilt), np.sin(tilt) * np.sin(az)], axis=1)
    level = np.exp(rng.uniform(math.log(5.0), math.log(500.0), n))
    tint = rng.uniform(0.6, 1.0, (n, 3))
    return np.column_stack([xz[:, 0], y, xz[:, 1]]), normal, level[:, None] * tint


def quad(center, normal, side: float):
    """A square of ``side`` at ``center`` whose front faces ``normal``."""
    n = np.asarray(normal, float)
    a = np.cross(n, (0.0, 0.0, 1.0) if abs(n[2]) < 0.9 else (1.0, 0.0, 0.0))
    a /= np.linalg.norm(a)
    b = np.cross(n, a)
    h = 0.5 * side
    c = np.asarray(center, float)
    V = np.array([c - h * a - h * b, c + h * a - h * b, c + h * a + h * b, c - h * a + h * b])
    F = [(0, 1, 2, 3)]
    if np.dot(meshes.face_normal(V, F[0]), n) < 0:
        F = [(3, 2, 1, 0)]
    return V, F, None


def main(out: Path, n: int = 50) -> list[Path]:
    """Write the scene with ``n`` lights into folder ``out``; return the files' paths."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    w = meshes.ObjWriter(f"many_lights, {n} lights (drpt.tools.scenegen.many_lights)", "many_lights.mtl")
    f = FLOOR_HALF
    floor = np.array([(-f, 0.0, -f), (-f, 0.0, f), (f, 0.0, f), (f, 0.0, -f)])
    w.add("floor", "floor", (floor, [(0, 1, 2, 3)], None))
    for k, (x, z, s, yaw) in enumerate([(-3.0, -2.0, 1.2, 20.0), (2.5, 1.0, 0.8, -35.0), (0.5, -5.0, 1.6, 5.0)]):
        w.add(f"box{k}", "box", meshes.box((x, 0.5 * s, z), (s, s, s), yaw, bottom=False))
    mtl = ["# many_lights (drpt.tools.scenegen.many_lights)",
           "newmtl floor", "Kd 0.6 0.6 0.6", "illum 1",
           "newmtl box", "Kd 0.5 0.45 0.4", "illum 1"]
    centers, normals, radiance = lights(n)
    for k in range(n):
        w.add(f"light{k}", f"light{k}", quad(centers[k], normals[k], SIDE))
        mtl += [f"newmtl light{k}", "Kd 0 0 0", "Ke " + " ".join(f"{v:.6g}" for v in radiance[k]), "illum 1"]
    (out / "many_lights.obj").write_text(w.text())
    (out / "many_lights.mtl").write_text("\n".join(mtl) + "\n")
    c, t = CAMERA
    (out / "many_lights.txt").write_text(SCENE.format(n=n, c=c, d=tuple(b - a for a, b in zip(c, t))))
    return [out / name for name in FILES]


def cli(argv=None) -> None:
    """``python -m drpt.tools.scenegen.many_lights OUT_DIR [N]``."""
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("n", type=int, nargs="?", default=50)
    a = ap.parse_args(argv)
    for p in main(a.out, a.n):
        print(p)


if __name__ == "__main__":
    cli()
