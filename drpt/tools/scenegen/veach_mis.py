"""Writes veach_mis: Veach's multiple-importance-sampling test scene, as OBJ + MTL + scene.

Built from the scene's published description (Veach's thesis, 1997, figure
9.2; the same setup as the common "veach-mis" test scenes): four glossy
plates of increasing roughness, each tilted so that it reflects a row of
four spherical lights toward the camera; the lights have equal power, so
their radiance falls as their size grows; a diffuse floor and back wall.
Nothing is copied from any file: geometry below is computed here.

Plates: metal, read as ``roughconductor`` (GGX) from MTL statements
``illum 3``, ``Kd 0 0 0``, ``Ks 0.7 0.7 0.7`` and ``Pr = sqrt(alpha)`` (auto
mode reads ``alpha = Pr^2``), alpha 0.005, 0.02, 0.05, 0.1 from the farthest
(highest) plate to the nearest. Mitsuba's ``material = "none"``: reflectance
``Ks`` at every angle (no Fresnel).

Lights: spheres at ``x = -3.75, -1.25, 1.25, 3.75`` (y 0.2, z -0.5), radii
0.0333, 0.1, 0.3, 0.9, radiance ``900 (0.0333 / r)^2`` = 900, 100, 11.1,
1.23 (white), tessellated (16 x 8 segments, radial normals), each its own
material. ``tests/data/xml/veach_mis.xml`` is the same scene as Mitsuba XML with
analytic spheres, roughness up to 0.2 and a large ceiling light.

Plates are 8 x 1 quads (single-sided geometry; the conductor is two-sided)
whose normal bisects the directions to the camera and to the middle of the
light row. The camera at (0, 2, 15) looks at (0, -1.5, 2.5), vertical field
of view 28 degrees; the scene is meant for 4:3 or square images at
128 pixels. Files: ``veach_mis.obj``, ``veach_mis.mtl``, ``veach_mis.txt``
(~50 kB).

    python scenes/make_veach_mis.py OUT_DIR
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from . import meshes

CAMERA = ((0.0, 2.0, 15.0), (0.0, -1.5, 2.5))
LIGHT_X = (-3.75, -1.25, 1.25, 3.75)
LIGHT_Y, LIGHT_Z = 0.2, -0.5
LIGHT_RADII = (0.0333, 0.1, 0.3, 0.9)
LIGHT_RADIANCE = tuple(900.0 * (LIGHT_RADII[0] / r) ** 2 for r in LIGHT_RADII)
#: plate centers (y, z), farthest first, and their GGX alphas
PLATES = (((-1.1, 0.9), 0.005), ((-1.75, 1.85), 0.02), ((-2.3, 2.9), 0.05), ((-2.8, 4.0), 0.1))
PLATE_WIDTH, PLATE_DEPTH = 8.0, 1.0
PLATE_KS = (0.7, 0.7, 0.7)
BASE_KD = (0.4, 0.4, 0.4)
FLOOR_Y, WALL_Z = -4.0, -4.0


def _unit(v) -> np.ndarray:
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def plate(center_yz) -> tuple:
    """The plate quad at ``center_yz``, tilted toward the camera and the lights."""
    c = np.array([0.0, *center_yz])
    to_cam = _unit(np.asarray(CAMERA[0]) - c)
    to_lights = _unit(np.array([0.0, LIGHT_Y, LIGHT_Z]) - c)
    n = _unit(to_cam + to_lights)
    along = _unit(np.cross(n, (1.0, 0.0, 0.0)))  # in the plate, perpendicular to x
    hx, hd = 0.5 * PLATE_WIDTH * np.array([1.0, 0, 0]), 0.5 * PLATE_DEPTH * along
    V = np.array([c - hx - hd, c + hx - hd, c + hx + hd, c - hx + hd])
    F = [(0, 1, 2, 3)]
    if np.dot(meshes.face_normal(V, F[0]), n) < 0:
        F = [(3, 2, 1, 0)]
    return V, F, None


def _mtl() -> str:
    out = ["# Veach's MIS scene (drpt.tools.scenegen.veach_mis), in the style of a PBR-aware exporter."]

    def v3(c):
        return " ".join(f"{x:.6f}" for x in c)

    out += ["newmtl base", "Ns 0.000000", "Ka 1.000000 1.000000 1.000000", f"Kd {v3(BASE_KD)}",
            "Ks 0.000000 0.000000 0.000000", "Ke 0.000000 0.000000 0.000000", "Ni 1.500000",
            "d 1.000000", "illum 1"]
    for k, (_, alpha) in enumerate(PLATES):
        pr = math.sqrt(alpha)
        out += [f"newmtl plate{k}", f"Ns {(1 - pr) ** 2 * 1000:.6f}", "Ka 1.000000 1.000000 1.000000",
                "Kd 0.000000 0.000000 0.000000", f"Ks {v3(PLATE_KS)}", "Ke 0.000000 0.000000 0.000000",
                "Ni 1.500000", "d 1.000000", "illum 3", f"Pr {pr:.6f}", "Pm 1.000000"]
    for k, radiance in enumerate(LIGHT_RADIANCE):
        out += [f"newmtl light{k}", "Ns 0.000000", "Ka 1.000000 1.000000 1.000000",
                "Kd 0.000000 0.000000 0.000000", "Ks 0.000000 0.000000 0.000000",
                f"Ke {v3((radiance,) * 3)}", "Ni 1.500000", "d 1.000000", "illum 1"]
    return "\n".join(out) + "\n"


SCENE = """\
# Veach's MIS scene (drpt.tools.scenegen.veach_mis): four rough metal plates
# (GGX alpha 0.005 .. 0.1) reflecting four spherical lights (radiance 900 .. 1.23).
PerspectiveCamera {{
    center {c[0]:g} {c[1]:g} {c[2]:g}
    direction {d[0]:g} {d[1]:g} {d[2]:g}
    up 0 1 0
    angle 28
}}

Group {{
    numObjects 1
    TriangleMesh {{ obj_file veach_mis.obj }}
}}
"""

FILES = ("veach_mis.obj", "veach_mis.mtl", "veach_mis.txt")


def main(out: Path) -> list[Path]:
    """Write the scene files into folder ``out`` (created if missing); return their paths."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    w = meshes.ObjWriter("Veach's MIS scene (drpt.tools.scenegen.veach_mis)", "veach_mis.mtl")
    floor = np.array([(-20.0, FLOOR_Y, -4.0), (-20.0, FLOOR_Y, 20.0), (20.0, FLOOR_Y, 20.0),
                      (20.0, FLOOR_Y, -4.0)])
    wall = np.array([(-20.0, FLOOR_Y, WALL_Z), (20.0, FLOOR_Y, WALL_Z), (20.0, 16.0, WALL_Z),
                     (-20.0, 16.0, WALL_Z)])
    assert meshes.face_normal(floor, (0, 1, 2, 3))[1] > 0 and meshes.face_normal(wall, (0, 1, 2, 3))[2] > 0
    w.add("floor", "base", (floor, [(0, 1, 2, 3)], None))
    w.add("back_wall", "base", (wall, [(0, 1, 2, 3)], None))
    for k, (yz, _) in enumerate(PLATES):
        w.add(f"plate{k}", f"plate{k}", plate(yz))
    for k, (x, r) in enumerate(zip(LIGHT_X, LIGHT_RADII)):
        c = (x, LIGHT_Y, LIGHT_Z)
        mesh = meshes.uv_sphere(c, r, 16, 8)
        meshes.check_outward(mesh[0], mesh[1], c)
        w.add(f"light{k}", f"light{k}", mesh)
    (out / "veach_mis.obj").write_text(w.text())
    (out / "veach_mis.mtl").write_text(_mtl())
    c, t = CAMERA
    (out / "veach_mis.txt").write_text(SCENE.format(c=c, d=tuple(b - a for a, b in zip(c, t))))
    return [out / f for f in FILES]


def cli(argv=None) -> None:
    """``python scenes/make_veach_mis.py OUT_DIR``."""
    meshes.folder_cli(main, __doc__.splitlines()[0], argv)


if __name__ == "__main__":
    cli()
