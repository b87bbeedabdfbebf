"""Scene file loader: every construct, transform math, material resolution,
located errors, and the seed's own scenes when they are available."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from drpt.errors import SceneError
from drpt.scene import (
    DirectionalLight,
    OrthographicCamera,
    PerspectiveCamera,
    PointLight,
    Skybox,
    load_scene,
)
from drpt.scene.tokens import tokenize

SEED = Path(__file__).resolve().parents[3] / "shared" / "seed"

CAM = "PerspectiveCamera { center 0 0 5 direction 0 0 -1 up 0 1 0 angle 45 }\n"
TRI = "Triangle { vertex0 1 0 0 vertex1 0 1 0 vertex2 0 0 1 }"


def write(tmp_path: Path, text: str, name: str = "scene.txt") -> Path:
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


def load(tmp_path: Path, text: str, **files: str):
    for name, body in files.items():
        write(tmp_path, body, name.replace("_", "."))
    return load_scene(write(tmp_path, text))


def group(*objects: str, n: int | None = None) -> str:
    count = n if n is not None else sum(1 for o in objects if not o.startswith("MaterialIndex"))
    return "Group {\n numObjects %d\n%s\n}\n" % (count, "\n".join(objects))


def transformed(ops: str, obj: str = TRI) -> str:
    return f"Transform {{ {ops} {obj} }}"


# ------------------------------------------------------------------ tokens
def test_tokenizer_rules():
    toks = tokenize("Group{ a}b # comment {\n// whole line\n c // tail\n dir//x.obj\n")
    assert [(t.text, t.line) for t in toks] == [
        ("Group", 1), ("{", 1), ("a", 1), ("}", 1), ("b", 1), ("c", 3), ("dir//x.obj", 4)]


# ------------------------------------------------------------- good files
def test_minimal_scene_default_material(tmp_path):
    s = load(tmp_path, CAM + group("Sphere { center 1 2 3 radius 0.5 }"))
    assert isinstance(s.camera, PerspectiveCamera) and s.camera.fov == 45.0
    assert s.path == (tmp_path / "scene.txt").resolve()
    assert len(s.spheres) == 1 and len(s.triangles) == 0 and len(s.planes) == 0
    np.testing.assert_array_equal(s.spheres.center, [[1, 2, 3]])
    assert s.spheres.radius.tolist() == [0.5]
    assert [m.name for m in s.materials] == ["default"]
    assert s.materials[0].kd == (0.8, 0.8, 0.8)
    assert s.spheres.material.dtype == np.int32


def test_all_blocks(tmp_path):
    (tmp_path / "sky.hdr").write_bytes(b"#?RADIANCE\n")
    (tmp_path / "wood.png").write_bytes(b"x")
    text = """
OrthographicCamera { center 0 0 10 direction 0 0 -2 up 0 1 0 size 5 }
Background { color 0.1 0.2 0.3 ambientLight 0.01 0.02 0.03 }
Lights {
    numLights 4
    DirectionalLight { direction -1 -1 -1 color 0.5 0.5 0.5 }
    PointLight { position 1 2 3 color 4 4 4 }
    PointLight { position 0 0 0 color 1 1 1 attenuation 1 0.5 0.25 }
    Skybox { sky.hdr }
}
Materials {
    numMaterials 3
    Material { diffuseColor 1 0 0 }
    PhongMaterial {
        diffuseColor 0 1 0 specularColor 0.5 0.5 0.5 exponent 20
        reflectiveColor 0.1 0.1 0.1 transparentColor 0.2 0.2 0.2
        indexOfRefraction 1.5 texture wood.png
    }
    PhongMaterial {
        Kd 0.25
        Le 5 5 5
        Roughness 0.4 Mentalness 0.6
    }
}
Group {
    numObjects 5
    MaterialIndex 1
    Sphere { center 0 0 0 radius 1 }
    Plane { normal 0 2 0 offset -4 }
    MaterialIndex 0
    Triangle { vertex0 0 0 0 vertex1 1 0 0 vertex2 0 1 0 }
    Group { numObjects 1 MaterialIndex 2 Sphere { radius 2 center 5 5 5 } }
    Sphere { center 1 1 1 radius 0.5 }
}
"""
    s = load(tmp_path, text)
    assert s.camera == OrthographicCamera((0, 0, 10), (0, 0, -2), (0, 1, 0), 5.0)
    assert s.background.color == (0.1, 0.2, 0.3) and s.background.ambient == (0.01, 0.02, 0.03)
    d, p1, p2, sky = s.lights
    assert isinstance(d, DirectionalLight) and d.direction == (-1, -1, -1)
    assert isinstance(p1, PointLight) and p1.attenuation == (0.0, 0.0, 1.0)  # physical default
    assert p2.attenuation == (1.0, 0.5, 0.25)
    assert isinstance(sky, Skybox) and sky.path == (tmp_path / "sky.hdr").resolve() and sky.radius == 1000.0
    m0, m1, m2 = s.materials  # block entries, in order; no default needed
    assert (m0.name, m0.kd) == ("material_0", (1, 0, 0))
    assert m1.kd == (0, 1, 0) and m1.ks == (0.5, 0.5, 0.5) and m1.ns == 20
    assert m1.reflective == (0.1, 0.1, 0.1) and m1.transparent == (0.2, 0.2, 0.2) and m1.ior == 1.5
    assert m1.map_kd == (tmp_path / "wood.png").resolve()
    assert m2.kd == (0.25, 0.25, 0.25) and m2.emission == (5, 5, 5)
    assert m2.roughness == 0.4 and m2.metalness == 0.6
    assert s.spheres.material.tolist() == [1, 2, 0]  # nested group's MaterialIndex does not leak
    assert s.planes.material.tolist() == [1]
    np.testing.assert_allclose(s.planes.normal, [[0, 1, 0]])
    np.testing.assert_allclose(s.planes.offset, [-2])  # normalized: 2y = -4 -> y = -2
    assert s.triangles.material.tolist() == [0]
    assert s.triangles.normals is None and s.triangles.uvs is None
    assert s.emissive_materials == [2]


def test_skybox_radius_and_materialindex_before_materials_block(tmp_path):
    (tmp_path / "e.hdr").write_bytes(b"x")
    text = CAM + group("MaterialIndex 0", TRI) + "Lights { numLights 1 Skybox { e.hdr R 50 } }\n" \
        + "Materials { numMaterials 1 Material { diffuseColor 0 0 1 } }\n"
    s = load(tmp_path, text)
    assert s.lights[0].radius == 50.0
    assert s.materials[s.triangles.material[0]].kd == (0, 0, 1)


# -------------------------------------------------------------- transforms
def test_translate_rotate_triangle_order(tmp_path):
    # M = Translate @ ZRotate: rotate first, then translate.
    s = load(tmp_path, CAM + group(transformed("Translate 1 0 0 ZRotate 90")))
    np.testing.assert_allclose(s.triangles.positions[0], [[1, 1, 0], [0, 0, 0], [1, 0, 1]], atol=1e-12)
    s = load(tmp_path, CAM + group(transformed("ZRotate 90 Translate 1 0 0")))
    np.testing.assert_allclose(s.triangles.positions[0], [[0, 2, 0], [-1, 1, 0], [0, 1, 1]], atol=1e-12)


@pytest.mark.parametrize("rot", ["Rotate { axis 0 0 1 angle 90 }", "Rotate { 0 0 1 90 }",
                                 "Rotate 0 0 2 90", "Rotate { angle 90 axis 0 0 3 }"])
def test_rotate_forms_equal_zrotate(tmp_path, rot):
    ref = load(tmp_path, CAM + group(transformed("ZRotate 90"))).triangles.positions
    got = load(tmp_path, CAM + group(transformed(rot))).triangles.positions
    np.testing.assert_allclose(got, ref, atol=1e-12)


def test_xyz_rotations_right_handed(tmp_path):
    s = load(tmp_path, CAM + group(transformed("XRotate 90"), transformed("YRotate 90")))
    p = s.triangles.positions
    np.testing.assert_allclose(p[0, 1], [0, 0, 1], atol=1e-12)  # y -> z about x
    np.testing.assert_allclose(p[1, 2], [1, 0, 0], atol=1e-12)  # z -> x about y


def test_matrix_row_major_and_nesting(tmp_path):
    m = "Matrix { 1 0 0 5  0 1 0 0  0 0 1 0  0 0 0 1 }"
    s = load(tmp_path, CAM + group(transformed("UniformScale 2", transformed(m))))
    # parent scale applied after the child's translation: 2 * (p + (5,0,0))
    np.testing.assert_allclose(s.triangles.positions[0], [[12, 0, 0], [10, 2, 0], [10, 0, 2]])


def test_transformed_group_and_scale(tmp_path):
    inner = group(TRI, "Sphere { center 0 0 0 radius 1 }")
    with pytest.warns(UserWarning, match="tessellated"):
        s = load(tmp_path, CAM + group(transformed("Translate 0 0 1 Scale 2 3 4", inner)))
    np.testing.assert_allclose(s.triangles.positions[0], [[2, 0, 1], [0, 3, 1], [0, 0, 5]])
    assert len(s.spheres) == 0 and len(s.triangles) > 1000
    p = s.triangles.positions[1:].reshape(-1, 3)
    np.testing.assert_allclose((p[:, 0] / 2) ** 2 + (p[:, 1] / 3) ** 2 + ((p[:, 2] - 1) / 4) ** 2, 1.0)


def test_similarity_sphere_baked(tmp_path):
    s = load(tmp_path, CAM + group(transformed("Translate 1 2 3 YRotate 30 UniformScale 2",
                                               "Sphere { center 1 0 0 radius 0.5 }")))
    assert len(s.triangles) == 0
    c = math.cos(math.radians(30)) * 2, 0, -math.sin(math.radians(30)) * 2
    np.testing.assert_allclose(s.spheres.center, [[1 + c[0], 2, 3 + c[2]]])
    np.testing.assert_allclose(s.spheres.radius, [1.0])


def test_nonuniform_sphere_tessellated(tmp_path):
    with pytest.warns(UserWarning, match=r"scene.txt:\d+: Sphere .*tessellated"):
        s = load(tmp_path, CAM + group(transformed("Translate 1 0 0 Scale 2 1 1",
                                                   "Sphere { center 0 0 0 radius 1 }")))
    assert len(s.spheres) == 0
    assert 1000 <= len(s.triangles) <= 5000
    p = s.triangles.positions.reshape(-1, 3)
    x = (p[:, 0] - 1) / 2
    np.testing.assert_allclose(x**2 + p[:, 1] ** 2 + p[:, 2] ** 2, 1.0, atol=1e-9)  # on the ellipsoid
    n = s.triangles.normals.reshape(-1, 3)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0)
    expected = np.stack([x / 2, p[:, 1], p[:, 2]], axis=1)  # gradient of the ellipsoid
    expected /= np.linalg.norm(expected, axis=1, keepdims=True)
    np.testing.assert_allclose(n, expected, atol=1e-9)
    # counter-clockwise from outside: geometric normals point outwards
    tri = s.triangles.positions
    g = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    assert (np.einsum("ij,ij->i", g, tri.mean(1) - [1, 0, 0]) > 0).all()


def test_plane_transforms(tmp_path):
    planes = [
        transformed("Translate 0 2 0", "Plane { normal 0 1 0 offset 1 }"),
        transformed("ZRotate 90", "Plane { normal 0 1 0 offset 1 }"),
        transformed("Scale 1 2 1", "Plane { normal 0 1 0 offset 1 }"),
        transformed("Scale 2 1 1", "Plane { normal 1 1 0 offset 1 }"),
    ]
    s = load(tmp_path, CAM + group(*planes))
    np.testing.assert_allclose(s.planes.normal[:3], [[0, 1, 0], [-1, 0, 0], [0, 1, 0]], atol=1e-12)
    np.testing.assert_allclose(s.planes.offset[:3], [3, 1, 2], atol=1e-12)
    # x + y = 1 scaled by 2 in x: x/2 + y = 1 -> normal (1, 2)/sqrt(5), offset 2/sqrt(5)
    np.testing.assert_allclose(s.planes.normal[3], np.array([1, 2, 0]) / math.sqrt(5))
    np.testing.assert_allclose(s.planes.offset[3], 2 / math.sqrt(5))


def test_mirror_keeps_front_side(tmp_path):
    obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1/1 2/2/1 3/3/1\n"
    s = load(tmp_path, CAM + group(transformed("Scale -1 1 1", "TriangleMesh { obj_file m.obj }")), m_obj=obj)
    p = s.triangles.positions[0]
    g = np.cross(p[1] - p[0], p[2] - p[0])
    assert g @ s.triangles.normals[0, 0] > 0  # winding still agrees with the shading normal
    np.testing.assert_allclose(s.triangles.normals[0], [[0, 0, 1]] * 3)
    # uvs follow their corners
    for k in range(3):
        np.testing.assert_allclose(p[k], [-s.triangles.uvs[0, k, 0], s.triangles.uvs[0, k, 1], 0])


def test_mesh_normals_inverse_transpose(tmp_path):
    obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 1 1 0\nf 1//1 2//1 3//1\n"
    s = load(tmp_path, CAM + group(transformed("Scale 2 1 1", "TriangleMesh { obj_file m.obj }")), m_obj=obj)
    np.testing.assert_allclose(s.triangles.normals[0, 0], np.array([0.5, 1, 0]) / math.hypot(0.5, 1))
    np.testing.assert_allclose(s.triangles.positions[0, 1], [2, 0, 0])


# --------------------------------------------------------------- materials
MTL = "newmtl shiny\nKd 0.1 0.2 0.3\nNs 50\nnewmtl lamp\nKd 0 0 0\nLe 7 7 7\n"
OBJ = "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nusemtl lamp\nf 2 4 3\n"


def test_sphere_mtl_forward_reference_and_mesh_materials(tmp_path):
    text = CAM + "Materials { numMaterials 1 Material { diffuseColor 0 1 0 } }\n" + group(
        "Sphere { center 0 0 0 radius 1 mtl shiny }",  # before the mesh that loads m.mtl
        "MaterialIndex 0",
        "TriangleMesh { obj_file m.obj }",
        "TriangleMesh { obj_file m.obj }",
        "Sphere { center 0 0 0 radius 1 }",
    )
    s = load(tmp_path, text, m_mtl=MTL, m_obj=OBJ)
    names = [m.name for m in s.materials]
    assert names == ["material_0", "shiny", "lamp"]  # block first, each material once
    assert s.spheres.material.tolist() == [1, 0]
    # first face has no usemtl -> the current MaterialIndex; second face -> lamp
    assert s.triangles.material.tolist() == [0, 2, 0, 2]
    assert s.materials[2].emission == (7, 7, 7) and s.emissive_materials == [2]
    assert s.materials[1].loc.file.endswith("m.mtl") and s.materials[1].loc.line == 1


def test_mesh_without_usemtl_uses_default(tmp_path):
    s = load(tmp_path, CAM + group("TriangleMesh { obj_file m.obj }"), m_mtl=MTL, m_obj=OBJ)
    assert [m.name for m in s.materials] == ["default", "lamp"]
    assert s.triangles.material.tolist() == [0, 1]


def test_mixing_meshes_with_and_without_normals_and_uvs(tmp_path):
    obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nvt 0.5 0.5\nf 1/1/1 2/1/1 3/1/1\n"
    s = load(tmp_path, CAM + group("TriangleMesh { obj_file m.obj }", TRI), m_obj=obj)
    assert s.triangles.normals.shape == (2, 3, 3) and s.triangles.uvs.shape == (2, 3, 2)
    np.testing.assert_allclose(s.triangles.normals[1], [np.ones(3) / math.sqrt(3)] * 3)
    np.testing.assert_array_equal(s.triangles.uvs[1], np.zeros((3, 2)))


def test_conflicting_mtl_names_first_wins(tmp_path):
    write(tmp_path, "newmtl x\nKd 1 0 0\n", "a.mtl")
    write(tmp_path, "newmtl x\nKd 0 0 1\n", "b.mtl")
    write(tmp_path, "mtllib a.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl x\nf 1 2 3\n", "a.obj")
    write(tmp_path, "mtllib b.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl x\nf 1 2 3\n", "b.obj")
    text = CAM + group("TriangleMesh { obj_file a.obj }", "TriangleMesh { obj_file b.obj }",
                       "Sphere { center 0 0 0 radius 1 mtl x }")
    with pytest.warns(UserWarning, match="also defined"):
        s = load(tmp_path, text)
    assert [m.kd for m in s.materials] == [(1, 0, 0), (0, 0, 1)]  # each mesh keeps its own
    assert s.spheres.material.tolist() == [0]


# ------------------------------------------------------------------ errors
def G(*objs, n=None):
    return CAM + group(*objs, n=n)


ERRORS = [
    # (scene text, line, fragment)
    (CAM + "Foo { }\n", 2, "unknown block 'Foo'"),
    (CAM + "Sphere { center 0 0 0 radius 1 }\n", 2, "inside a Group"),
    (G("Sphere { center 0 0 0 radius 1 colour 1 }"), 4, "unknown field in Sphere 'colour'"),
    (G("Sphere center 0 0 0 radius 1 }"), 4, "expected '{'"),
    (G("Sphere { center 0 0 0 radius 1 center 1 1 1 }"), 4, "given twice"),
    (G("Sphere { center 0 0 0 }"), 4, "missing 'radius'"),
    ("PerspectiveCamera { center 0 0 5 direction 0 0 -1 up 0 1 0 angle 45\n"
     "Group { numObjects 0 }\n", 2, "'}' missing"),
    (CAM + "Group {\n numObjects 1\n Sphere { center 0 0 0 radius 1 }\n", 4, "unexpected end of file"),
    (CAM + "Group {\n numObjects 1\n Sphere { center 0 0", 4, "unexpected end of file"),
    (G("Sphere { center 0 1.0.0 0 radius 1 }"), 4, "'1.0.0'"),
    (G("Sphere { center 0 abc 0 radius 1 }"), 4, "'abc'"),
    (G("Sphere { center 0 0 0 radius nan }"), 4, "'nan'"),
    (G("Sphere { center 0 0 0 radius inf }"), 4, "'inf'"),
    (G("Sphere { center 0 0 0 radius 1e999 }"), 4, "'1e999'"),
    (G("Sphere { center 0 0 1_0 radius 1 }"), 4, "'1_0'"),
    (G("Sphere { center 0 0 0 radius -1 }"), 4, "radius must be positive"),
    (G("Plane { normal 0 0 0 offset 1 }"), 4, "zero length"),
    (G(TRI, TRI, n=3), 2, "numObjects 3 but contains 2"),
    (G(TRI, n=-1), 3, "must not be negative"),
    (CAM + "Group { numObjects x }\n", 2, "integer"),
    (CAM + "Group { Sphere { center 0 0 0 radius 1 } }\n", 2, "numObjects"),
    (CAM + "Lights { numLights 2\nPointLight { position 0 0 0 color 1 1 1 } }\n" + group(TRI), 2,
     "numLights 2 but contains 1"),
    (CAM + "\nMaterials { numMaterials 2 Material { } }\n" + group(TRI), 3, "numMaterials 2 but contains 1"),
    (CAM + "Materials { numMaterials 1 Checkerboard { } }\n" + group(TRI), 2, "unknown material type"),
    (CAM + "Lights { numLights 1 SpotLight { } }\n" + group(TRI), 2, "unknown light"),
    (group(TRI), 4, "no camera"),
    (CAM + CAM + group(TRI), 2, "second camera"),
    (G("MaterialIndex 0", TRI), 4, "MaterialIndex 0 is out of range (there is no Materials block)"),
    (CAM + "Materials { numMaterials 1 Material { } }\n" + group("MaterialIndex 1", TRI), 5,
     "MaterialIndex 1 is out of range (the Materials block defines 1)"),
    ("PerspectiveCamera { center 0 0 5 direction 0 0 -1 up 0 1 0 angle 180 }\n" + group(TRI), 1, "(0, 180)"),
    ("PerspectiveCamera { center 0 0 5 direction 0 0 -1 up 0 1 0 angle 0 }\n" + group(TRI), 1, "(0, 180)"),
    ("PerspectiveCamera { center 0 0 5\n direction 0 0 0 up 0 1 0 angle 30 }\n" + group(TRI), 2, "zero length"),
    ("PerspectiveCamera { center 0 0 5 direction 0 0 -1\n up 0 0 3 angle 30 }\n" + group(TRI), 2, "parallel"),
    ("OrthographicCamera { center 0 0 5 direction 0 0 -1 up 0 1 0 size 0 }\n" + group(TRI), 1, "positive"),
    ("PerspectiveCamera { center 0 0 5 direction 0 0 -1 up 0 1 0 }\n" + group(TRI), 1, "missing 'angle'"),
    (G("TriangleMesh { obj_file nothere.obj }"), 4, "nothere.obj"),
    (G("Sphere { center 0 0 0 radius 1 mtl ghost }"), 4, "unknown material 'ghost'"),
    (G(transformed("Translate 1 0 0", TRI + " " + TRI)), 4, "exactly one object"),
    (G(transformed("Translate 1 0 0", "")), 4, "no object"),
    (G("Transform { " + TRI + " Translate 1 0 0 }"), 4, "operations come first"),
    (G(transformed("Scale 1 0 1")), 4, "singular"),
    (G(transformed("UniformScale 0")), 4, "singular"),
    (G(transformed("Matrix { 1 0 0 0 0 1 0 0 0 0 1 0 0 0 1 1 }")), 4, "last row"),
    (G(transformed("Matrix { 1 0 0 0 0 1 0 0 0 0 1 0 0 0 1 }")), 4, "'}'"),
    (G(transformed("Rotate { 0 0 0 90 }")), 4, "zero length"),
    (G(transformed("Shear 1")), 4, "unknown transform operation"),
    (CAM + "Lights { numLights 1 Skybox { R 10 } }\n" + group(TRI), 2, "needs a file name"),
    (CAM + "Lights { numLights 1 Skybox { a.hdr b.hdr } }\n" + group(TRI), 2, "one file name"),
    (CAM + "Lights { numLights 1\n Skybox { gone.hdr } }\n" + group(TRI), 3, "gone.hdr"),
    (CAM + "Materials { numMaterials 1\n PhongMaterial { texture gone.png } }\n" + group(TRI), 3, "gone.png"),
    (CAM + "Materials { numMaterials 1\n PhongMaterial { Kd 1 x 1 } }\n" + group(TRI), 3, "'x'"),
    (CAM + "Lights { numLights 1 PointLight { position 0 0 0 color 1 1 1 attenuation 0 0 0 } }\n"
     + group(TRI), 2, "attenuation"),
]


@pytest.mark.parametrize("text, line, fragment", ERRORS)
def test_errors(tmp_path, text, line, fragment):
    p = write(tmp_path, text, "bad.txt")
    with pytest.raises(SceneError) as e:
        load_scene(p)
    msg = str(e.value)
    assert msg.startswith(f"{p.resolve()}:{line}: "), msg
    assert fragment in msg, msg


def test_error_in_obj_is_reported_in_obj(tmp_path):
    write(tmp_path, "v 0 0 0\nv 1 0 0\nf 1 2 3\n", "m.obj")
    with pytest.raises(SceneError) as e:
        load(tmp_path, G("TriangleMesh { obj_file m.obj }"))
    assert "m.obj:3:" in str(e.value)


def test_missing_mtl_reported_at_obj_line(tmp_path):
    write(tmp_path, "v 0 0 0\nmtllib lost.mtl\n", "m.obj")
    with pytest.raises(SceneError) as e:
        load(tmp_path, G("TriangleMesh { obj_file m.obj }"))
    assert "m.obj:2:" in str(e.value) and "lost.mtl" in str(e.value)


def test_unreadable_and_non_utf8(tmp_path):
    with pytest.raises(SceneError, match="not found"):
        load_scene(tmp_path / "nothing.txt")
    with pytest.raises(SceneError, match="directory"):
        load_scene(tmp_path)
    p = tmp_path / "latin1.txt"
    p.write_bytes((CAM + "# caf\xe9\n").encode("latin-1"))
    with pytest.raises(SceneError) as e:
        load_scene(p)
    assert "latin1.txt:2:" in str(e.value) and "UTF-8" in str(e.value)


def test_truncations_never_leak_python_errors(tmp_path):
    """Cut a scene using every construct at each token: the loader must
    either succeed or raise SceneError, never anything else."""
    write(tmp_path, OBJ, "m.obj")
    write(tmp_path, MTL, "m.mtl")
    full = (
        CAM + "Background { color 0 0 0 }\nLights { numLights 1 PointLight { position 0 0 0 color 1 1 1 } }\n"
        "Materials { numMaterials 1 PhongMaterial { diffuseColor 1 0 0 Ns 3 } }\n"
        + group("MaterialIndex 0", "Sphere { center 0 0 0 radius 1 mtl shiny }",
                transformed("Rotate { axis 0 1 0 angle 30 } Matrix { 1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1 }",
                            "TriangleMesh { obj_file m.obj }"),
                "Plane { normal 0 1 0 offset 0 }")
    )
    words = full.split(" ")
    outcomes = set()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for k in range(len(words)):
            for variant in (" ".join(words[:k]), " ".join(words[:k] + ["}"] + words[k:]),
                            " ".join(words[:k] + words[k + 1:])):
                p = write(tmp_path, variant, "cut.txt")
                try:
                    load_scene(p)
                    outcomes.add("ok")
                except SceneError:
                    outcomes.add("error")
    assert outcomes == {"ok", "error"}


# -------------------------------------------------------------------- seed
def seed_scene(name: str) -> Path:
    p = SEED / "scenes" / name
    if not p.is_file():
        pytest.skip("seed files not available")
    return p


def obj_triangle_count(path: Path) -> int:
    n = 0
    for line in path.read_text().splitlines():
        parts = line.split()
        if parts and parts[0] == "f":
            n += len(parts) - 3
    return n


def test_seed_cornellbox():
    p = seed_scene("cornellbox.txt")
    s = load_scene(p)
    assert isinstance(s.camera, PerspectiveCamera) and s.camera.fov == 60.0
    assert len(s.triangles) == obj_triangle_count(p.parent / "cornellbox.obj")
    assert len(s.spheres) == 0
    assert isinstance(s.lights[0], Skybox) and s.lights[0].path == (p.parent / "environment.hdr").resolve()
    light = [m for m in s.materials if m.name == "cornellbox_light"]
    assert len(light) == 1 and light[0].emission == (10.0, 10.0, 10.0)
    assert s.emissive_materials == [s.materials.index(light[0])]
    np.testing.assert_allclose(np.linalg.norm(s.triangles.normals, axis=2), 1.0)
    assert s.materials[0].roughness == 0.95 and s.materials[0].metalness == 0.01


def test_seed_newscene():
    p = seed_scene("newscene.txt")
    s = load_scene(p)
    assert len(s.spheres) == 5
    assert len(s.triangles) == obj_triangle_count(p.parent / "newscene.obj")
    names = [s.materials[i].name for i in s.spheres.material]
    assert names == ["cornellbox_6_material", "cornellbox_7_material", "cornellbox_8_material",
                     "cornellbox_6_material", "cornellbox_9_material"]
    np.testing.assert_allclose(s.spheres.radius, [0.15, 0.15, 0.1, 0.16, 0.18])
    assert len({id(m) for m in s.materials}) == len(s.materials)
    assert [s.materials[i].name for i in s.emissive_materials] == ["cornellbox_light"]


@pytest.mark.parametrize("name, missing, line", [("carday.txt", "car.obj", 18), ("cardusk.txt", "car.obj", 18),
                                                 ("diningroom.txt", "diningroom.obj", 18)])
def test_seed_missing_geometry(name, missing, line):
    p = seed_scene(name)
    with pytest.raises(SceneError) as e:
        load_scene(p)
    assert missing in str(e.value)
    assert str(e.value).startswith(f"{p.resolve()}:{line}:")
