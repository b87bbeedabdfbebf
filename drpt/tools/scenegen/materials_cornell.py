"""Writes materials_cornell: a Cornell box of mixed PBR materials, as OBJ + MTL + scene.

The room is the bundled Cornell box's (:mod:`.cornellbox`: the published
dimensions in mm scaled by 1/100, white/red/green diffuse walls, the
ceiling light with ``Ke 17 12 4``); the two blocks are replaced by four
objects, each a material kind that the MTL statements select (see
:mod:`drpt.materials.interpret`, auto mode):

=============== ============================ ============================================
object          MTL statements               read as (auto mode)
=============== ============================ ============================================
gold sphere     ``Kd 1 0.766 0.336``,        ``principled``, metallic 1, roughness 0.4
(back, right)   ``Pm 1``, ``Pr 0.4``         (GGX alpha 0.16)
plastic box     ``Kd 0.1 0.3 0.8``,          ``principled``, metallic 0, roughness 0.3,
(front, left)   ``Pm 0``, ``Pr 0.3``         eta = ``Ni`` 1.5
frosted glass   ``Ni 1.5``, ``Tf 0.7 0.85    ``roughdielectric`` GGX alpha 0.09,
block (back,    1``, ``Pr 0.3``, illum 4     ``specular_transmittance`` = Tf
left)
water slab      ``Ni 1.33``, ``Tf 1 1 1``,   smooth ``dielectric``, IOR 1.33
(front, right)  ``Pr 0``, illum 7
walls, light    ``Kd``, ``Ks 0``, illum 1    ``diffuse`` (no PBR statements)
=============== ============================ ============================================

The MTL is written the way PBR-aware exporters (Blender's with its PBR
extensions on) write materials: ``Ns Ka Kd Ks Ke Ni d illum``, then ``Pr Pm
Ps Pc Pcr aniso anisor``; the transmissive ones add the MTL standard's
transmission filter ``Tf``. ``Ni`` (1.45, 1.5) is also principled's ``eta``.
The walls and the light are written without the PBR statements (a material
with no specular, exported without the extensions), so that they stay
Lambertian and the room stays a Cornell box.

Conductor variant (``materials_cornell_conductor.txt``): the sphere is
``gold_conductor``, ``illum 3`` with ``Ks 1 0.766 0.336``, ``Kd 0`` and
``Pr 0.2``: a ``roughconductor`` (GGX alpha 0.04, ``specular_reflectance`` =
Ks, Mitsuba's ``material = "none"``: no Fresnel falloff).

Left and right are the image's: the camera looks along +z, so +x is the
image's left (the red wall is at x = 5.5). Geometry, in scene units of
10 cm: the sphere (radius 0.85, 32 x 16 segments, smooth normals) touches
the floor; the plastic box (1.4 cube, rotated -17 degrees, open bottom)
stands on it; the glass block (1.3 x 2.4 x 1.3, rotated 20 degrees) and the
water, a closed slab 0.35 deep whose top carries waves of amplitude 0.04
(12 x 12 quads, smooth normals), float 0.01 above it, so that their closed
bottoms do not coincide with the floor. The glass, the water and the sphere
are watertight (every edge shared by two faces, wound outward). Files:
``room.obj`` (walls, light, box, glass, water), ``sphere_gold.obj``,
``sphere_conductor.obj``, ``materials_cornell.mtl``,
``materials_cornell.txt``, ``materials_cornell_conductor.txt`` (~120 kB in
all).

    python scenes/make_materials_cornell.py OUT_DIR
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from . import meshes
from .cornellbox import LIGHT, WALLS, oriented

S = 0.01  # mm -> scene units
MTL_NAME = "materials_cornell.mtl"

SPHERE_CENTER, SPHERE_RADIUS = (1.5, 0.85, 3.9), 0.85
PLASTIC = ((3.8, 0.7, 1.6), (1.4, 1.4, 1.4), -17.0)
GLASS = ((3.9, 1.21, 3.8), (1.3, 2.4, 1.3), 20.0)  # bottom at y = 0.01
WATER = dict(x0=0.5, x1=2.6, z0=0.6, z1=2.6, y0=0.01, depth=0.35, amplitude=0.04, waves=1.5, n=12)


def _mtl(name, Kd, Ks=(0.0, 0.0, 0.0), Ns=0.0, Ke=(0.0, 0.0, 0.0), Ni=1.5, d=1.0, illum=2, pbr=None,
         Tf=None) -> str:
    def v3(c):
        return " ".join(f"{x:.6f}" for x in c)

    lines = [f"newmtl {name}", f"Ns {Ns:.6f}", "Ka 1.000000 1.000000 1.000000", f"Kd {v3(Kd)}",
             f"Ks {v3(Ks)}", f"Ke {v3(Ke)}", f"Ni {Ni:.6f}", f"d {d:.6f}"]
    if Tf is not None:
        lines.append(f"Tf {v3(Tf)}")
    lines.append(f"illum {illum}")
    if pbr is not None:
        pr, pm = pbr
        lines += [f"Pr {pr:.6f}", f"Pm {pm:.6f}", "Ps 0.000000", "Pc 0.000000", "Pcr 0.030000",
                  "aniso 0.000000", "anisor 0.000000"]
    return "\n".join(lines) + "\n"


def _ns(roughness: float) -> float:
    """Blender's exporter writes ``Ns = (1 - roughness)^2 * 1000``."""
    return (1.0 - roughness) ** 2 * 1000.0


GOLD = (1.0, 0.766, 0.336)

MTL = "".join([
    "# Mixed-material Cornell box (drpt.tools.scenegen.materials_cornell), written in the style\n"
    "# of a PBR-aware OBJ exporter.\n",
    _mtl("white", (0.725, 0.71, 0.68), illum=1),
    _mtl("red", (0.63, 0.065, 0.05), illum=1),
    _mtl("green", (0.14, 0.45, 0.091), illum=1),
    _mtl("light", (0.0, 0.0, 0.0), Ke=(17.0, 12.0, 4.0), illum=1),
    _mtl("gold", GOLD, Ks=(0.5, 0.5, 0.5), Ns=_ns(0.4), Ni=1.45, pbr=(0.4, 1.0)),
    _mtl("blue_plastic", (0.1, 0.3, 0.8), Ks=(0.5, 0.5, 0.5), Ns=_ns(0.3), Ni=1.5, pbr=(0.3, 0.0)),
    _mtl("frosted_glass", (1.0, 1.0, 1.0), Ks=(0.5, 0.5, 0.5), Ns=_ns(0.3), Ni=1.5, illum=4,
         Tf=(0.7, 0.85, 1.0), pbr=(0.3, 0.0)),
    _mtl("water", (1.0, 1.0, 1.0), Ks=(0.5, 0.5, 0.5), Ns=1000.0, Ni=1.33, illum=7, Tf=(1.0, 1.0, 1.0),
         pbr=(0.0, 0.0)),
    _mtl("gold_conductor", (0.0, 0.0, 0.0), Ks=GOLD, Ns=_ns(0.2), Ni=1.45, illum=3, pbr=(0.2, 1.0)),
])

SCENE = """\
# Cornell box with a gold sphere, a plastic box, a frosted glass block and water
# (drpt.tools.scenegen.materials_cornell). Materials: {mtl}, read by their statements.
PerspectiveCamera {{
    center 2.78 2.73 -8.0
    direction 0 0 1
    up 0 1 0
    angle 39.3
}}

Group {{
    numObjects 2
    TriangleMesh {{ obj_file room.obj }}
    TriangleMesh {{ obj_file {sphere} }}
}}
"""

FILES = ("room.obj", "sphere_gold.obj", "sphere_conductor.obj", MTL_NAME, "materials_cornell.txt",
         "materials_cornell_conductor.txt")


def _quads(quads):
    V = np.concatenate([np.asarray(q, float) for q in quads]) * S
    F = [tuple(range(4 * i, 4 * i + 4)) for i in range(len(quads))]
    return V, F, None


def room() -> meshes.ObjWriter:
    w = meshes.ObjWriter("Cornell box room, plastic box, frosted glass block and water slab\n"
                         "(drpt.tools.scenegen.materials_cornell)", MTL_NAME)
    inside = (278, 274, 280)
    w.add("walls_white", "white", _quads([oriented(WALLS[k], toward=inside) for k in ("floor", "ceiling", "back")]))
    w.add("wall_red", "red", _quads([oriented(WALLS["red"], toward=inside)]))
    w.add("wall_green", "green", _quads([oriented(WALLS["green"], toward=inside)]))
    w.add("light", "light", _quads([oriented(LIGHT, normal=(0, -1, 0))]))
    center, size, yaw = PLASTIC
    mesh = meshes.box(center, size, yaw, bottom=False)
    meshes.check_outward(mesh[0], mesh[1], center)
    w.add("plastic_box", "blue_plastic", mesh)
    center, size, yaw = GLASS
    mesh = meshes.box(center, size, yaw)
    meshes.check_outward(mesh[0], mesh[1], center)
    w.add("glass_block", "frosted_glass", mesh)
    top, rest = meshes.wavy_slab(**WATER)
    inside = ((WATER["x0"] + WATER["x1"]) / 2, WATER["y0"] + WATER["depth"] / 2, (WATER["z0"] + WATER["z1"]) / 2)
    meshes.check_outward(top[0], top[1], inside)
    meshes.check_outward(rest[0], rest[1], inside)
    w.add("water_surface", "water", top)
    w.add("water_sides", "water", rest)
    return w


def sphere(material: str) -> meshes.ObjWriter:
    w = meshes.ObjWriter(f"{material} sphere (drpt.tools.scenegen.materials_cornell)", MTL_NAME)
    mesh = meshes.uv_sphere(SPHERE_CENTER, SPHERE_RADIUS, 32, 16)
    meshes.check_outward(mesh[0], mesh[1], SPHERE_CENTER)
    w.add("sphere", material, mesh)
    return w


def main(out: Path) -> list[Path]:
    """Write the scene files into folder ``out`` (created if missing); return their paths."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "room.obj").write_text(room().text())
    (out / "sphere_gold.obj").write_text(sphere("gold").text())
    (out / "sphere_conductor.obj").write_text(sphere("gold_conductor").text())
    (out / MTL_NAME).write_text(MTL)
    (out / "materials_cornell.txt").write_text(SCENE.format(mtl=MTL_NAME, sphere="sphere_gold.obj"))
    (out / "materials_cornell_conductor.txt").write_text(SCENE.format(mtl=MTL_NAME, sphere="sphere_conductor.obj"))
    return [out / f for f in FILES]


def cli(argv=None) -> None:
    """``python scenes/make_materials_cornell.py OUT_DIR``."""
    meshes.folder_cli(main, __doc__.splitlines()[0], argv)


if __name__ == "__main__":
    cli()
