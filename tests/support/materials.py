"""The material test box: a floor, a back wall and a ceiling light (OBJ + MTL), one sphere of
the material under test (MTL material ``mtl``: phong, phong_sharp, ct_gold, ct_rough,
ct_plastic, glass, mirror), a diffuse sphere beside it; drpt's scene format.

``tests/validation/test_materials_render.py`` renders each MTL material in it against Mitsuba
3 (through the exporter); the BSDF tests put their own ``BSDFSpec`` on the sphere with
:func:`with_bsdf` and do the same.
"""

from __future__ import annotations

from dataclasses import replace

from drpt.scene import load_scene

MTL = """
newmtl white
Kd 0.7 0.7 0.7
newmtl light
Kd 0 0 0
Ke 8 8 8
newmtl phong
Kd 0.3 0.4 0.6
Ks 0.5 0.5 0.5
Ns 60
newmtl phong_sharp
Kd 0.1 0.1 0.1
Ks 0.8 0.8 0.8
Ns 2000
newmtl ct_gold
Kd 0.9 0.75 0.3
Roughness 0.2
Mentalness 0.9
newmtl ct_rough
Kd 0.5 0.6 0.9
Roughness 0.9
Mentalness 0.9
newmtl ct_plastic
Kd 0.8 0.2 0.2
Roughness 0.3
Mentalness 0
newmtl glass
Ni 1.5
d 0
newmtl mirror
illum 3
Kd 0 0 0
Ks 0.9 0.9 0.9
"""

OBJ = """
mtllib box.mtl
v -3 0 -3
v 3 0 -3
v 3 0 3
v -3 0 3
v -3 4 -3
v 3 4 -3
v -1 3.99 -1
v 1 3.99 -1
v 1 3.99 1
v -1 3.99 1
usemtl white
f 1 4 3 2
f 1 2 6 5
usemtl light
f 7 8 9 10
"""

SCENE = """
PerspectiveCamera {{ center 0 1.6 6  direction 0 -0.15 -1  up 0 1 0  angle 40 }}
Group {{
    numObjects 3
    TriangleMesh {{ obj_file box.obj }}
    Sphere {{ center -0.7 0.8 0 radius 0.8  mtl {mtl} }}
    Sphere {{ center 1.2 0.6 0.6 radius 0.6  mtl white }}
}}
"""


def make(tmp_path, mtl):
    """The box with material ``mtl`` on the test sphere, written to ``tmp_path`` and read."""
    (tmp_path / "box.mtl").write_text(MTL)
    (tmp_path / "box.obj").write_text(OBJ)
    p = tmp_path / "scene.txt"
    p.write_text(SCENE.format(mtl=mtl))
    return load_scene(p)


def with_bsdf(scene, name, spec):
    """``scene`` with material ``name``'s BSDF replaced by ``spec`` (a ``BSDFSpec``), in place."""
    i = next(k for k, m in enumerate(scene.materials) if m.name == name)
    scene.materials[i] = replace(scene.materials[i], bsdf=spec)
    return scene
