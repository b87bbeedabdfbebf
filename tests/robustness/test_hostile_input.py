"""Hostile and extreme input files: every one gives one located error line (or
a located warning), never a traceback, a hang or a silently wrong scene.

Deep nesting, overflowing transforms, non-finite numbers, files that are not
regular files (symlink loops, FIFOs, devices, directories), negative colours,
and image files that fail when read long after parsing (the error names the
line that referenced them)."""

from __future__ import annotations

import os
import signal
import warnings
from pathlib import Path

import numpy as np
import pytest

from drpt.errors import Loc, SceneError
from drpt.scene import load_scene
from drpt.scene.files import NamedPath, check_input, read_bytes
from drpt.scene.mtl import load_mtl
from drpt.scene.obj import load_obj

CAM = "PerspectiveCamera { center 0 0 5 direction 0 0 -1 up 0 1 0 angle 45 }\n"
SPHERE = "Sphere { center 0 0 0 radius 1 }"
TRI = "Triangle { vertex0 1 0 0 vertex1 0 1 0 vertex2 0 0 1 }"


@pytest.fixture(autouse=True)
def no_hang_no_stray_warnings():
    """Every test here must finish within 10 s (a FIFO read would block) and
    emit no warning other than the ones it asks for (numpy RuntimeWarnings
    in particular become errors)."""
    def timeout(signum, frame):
        raise TimeoutError("input reading hung")

    old = signal.signal(signal.SIGALRM, timeout)
    signal.alarm(10)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", RuntimeWarning)
            yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


def scene(tmp_path: Path, body: str, name: str = "scene.txt") -> Path:
    return write(tmp_path / name, CAM + body)


def group(*objects: str) -> str:
    return f"Group {{ numObjects {len(objects)}\n" + "\n".join(objects) + "\n}\n"


def error_of(fn, *args) -> SceneError:
    with pytest.raises(SceneError) as ei:
        fn(*args)
    assert "\n" not in str(ei.value)
    return ei.value


# ------------------------------------------------------------------ nesting
@pytest.mark.parametrize("depth", [600, 10_000])
@pytest.mark.parametrize("kind", ["Group", "Transform"])
def test_deep_nesting_loads(tmp_path, depth, kind):
    opening = "Group { numObjects 1\n" if kind == "Group" else "Transform { Translate 0 0 1e-9\n"
    body = "Group { numObjects 1\n" + opening * depth + SPHERE + "\n" + "}\n" * (depth + 1)
    s = load_scene(scene(tmp_path, body))
    assert len(s.spheres) == 1
    expected_z = 0.0 if kind == "Group" else depth * 1e-9
    np.testing.assert_allclose(s.spheres.center[0], [0, 0, expected_z], atol=1e-12)
    lo, hi = s.bounds()
    assert np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))


def test_deep_nesting_exports(tmp_path):
    from drpt.export.mitsuba import write_xml

    depth = 10_000
    body = "Group { numObjects 1\n" + "Transform { Translate 0 0 0\n" * depth + TRI + "\n" + "}\n" * (depth + 1)
    s = load_scene(scene(tmp_path, body))
    assert write_xml(s, tmp_path / "out.xml", width=8, height=8, spp=1).is_file()


def test_deep_nesting_errors_are_located(tmp_path):
    depth = 700
    body = "Group { numObjects 1\n" + "Group { numObjects 1\n" * depth + "Spehre { }\n" + "}\n" * (depth + 1)
    e = error_of(load_scene, scene(tmp_path, body))
    assert e.line == depth + 3 and "Sphere" in e.message  # did you mean
    body = "Group { numObjects 1\n" + "Transform { Translate 0 0 0\n" * depth + "}\n" * (depth + 1)
    e = error_of(load_scene, scene(tmp_path, body))
    assert e.line == depth + 2 and "Transform has no object" in e.message  # the innermost one


# ---------------------------------------------------------------- overflows
@pytest.mark.parametrize("ops, message", [
    ("UniformScale 1e200 UniformScale 1e200", "overflow"),
    ("Matrix { 1e300 0 0 0 0 1e300 0 0 0 0 1e300 0 0 0 0 1 } UniformScale 1e10", "overflow"),
    ("UniformScale 1e200", "beyond drpt's limit"),
    ("Scale 1e308 1 1e-308", "singular"),
    ("UniformScale 1e-200 UniformScale 1e-200", "singular"),
    ("Matrix { 1 0 0 0 0 1 0 0 0 0 0 0 0 0 0 1 }", "singular"),
    ("Translate 1e13 1e13 1e13", "beyond drpt's limit"),
])
@pytest.mark.parametrize("obj", [SPHERE, TRI, "Plane { normal 0 1 0 offset 1e11 }"])
def test_overflowing_transforms_are_errors(tmp_path, ops, message, obj):
    lines = ["Group { numObjects 1", f"Transform {{ {ops}", obj, "}", "}"]
    e = error_of(load_scene, scene(tmp_path, "\n".join(lines) + "\n"))
    if message == "overflow":
        assert e.line == 3 and "overflow" in e.message
    else:
        assert e.line in (3, 4) and message in e.message


def test_huge_untransformed_geometry_is_an_error(tmp_path):
    e = error_of(load_scene, scene(tmp_path, group("Sphere { center 0 0 0 radius 1e200 }")))
    assert e.line == 3 and "Sphere reaches 1e+200" in e.message
    write(tmp_path / "big.obj", "v 0 0 0\nv 1e30 0 0\nv 0 1 0\nf 1 2 3\n")
    e = error_of(load_scene, scene(tmp_path, group("TriangleMesh { obj_file big.obj }")))
    assert e.line == 3 and "big.obj reaches 1e+30" in e.message
    e = error_of(load_scene, write(tmp_path / "c.txt", CAM.replace("center 0 0 5", "center 0 0 1e20") + group(TRI)))
    assert e.line == 1 and "camera center" in e.message
    e = error_of(load_scene, scene(tmp_path, "Lights { numLights 1 PointLight { position 1e300 0 0 color 1 1 1 } }\n"
                                   + group(TRI)))
    assert e.line == 2 and "PointLight position" in e.message


def test_extreme_but_valid_vectors_load(tmp_path):
    """Huge or tiny direction vectors are only directions: no overflow, no warning."""
    cam = "PerspectiveCamera { center 0 0 5 direction 0 0 -1e12 up 0 1e-300 0 angle 45 }\n"
    body = ("Lights { numLights 1 DirectionalLight { direction 1e-300 -1e-300 0 color 1 1 1 } }\n"
            + group("Plane { normal 0 1e300 0 offset 1e300 }",
                    "Transform { Rotate 1e-300 0 0 90 " + SPHERE + " }"))
    s = load_scene(write(tmp_path / "scene.txt", cam + body))
    np.testing.assert_allclose(s.planes.normal[0], [0, 1, 0])
    np.testing.assert_allclose(s.planes.offset[0], 1.0)


def test_huge_normals_in_obj(tmp_path):
    write(tmp_path / "n.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 1e300 1e300 1e300\nvn 0 0 1e-300\n"
          "f 1//1 2//2 3//1\n")
    m = load_obj(tmp_path / "n.obj")
    np.testing.assert_allclose(m.normals[0], [[3 ** -0.5] * 3, [0, 0, 1], [3 ** -0.5] * 3])


@pytest.mark.parametrize("text", ["inf", "-inf", "nan", "1e999", "-1e400", "NaN", "Infinity"])
def test_non_finite_numbers_everywhere(tmp_path, text):
    e = error_of(load_scene, scene(tmp_path, group(f"Sphere {{ center 0 {text} 0 radius 1 }}")))
    assert e.line == 3 and text in e.message
    light = f"Lights {{ numLights 1 PointLight {{ position 0 0 0 color 1 {text} 1 }} }}\n"
    e = error_of(load_scene, scene(tmp_path, light + group(TRI)))
    assert e.line == 2
    matrix = f"Matrix {{ 1 0 0 0 0 1 0 0 0 0 1 0 0 0 {text} 1 }}"
    e = error_of(load_scene, scene(tmp_path, group(f"Transform {{ {matrix} {TRI} }}")))
    assert e.line == 3
    write(tmp_path / "m.obj", f"v 0 0 0\nv 1 0 0\nv 0 1 {text}\nf 1 2 3\n")
    e = error_of(load_obj, tmp_path / "m.obj")
    assert e.line == 3 and text in e.message
    write(tmp_path / "m.mtl", f"newmtl a\nKd 1 1 1\nNs {text}\n")
    e = error_of(load_mtl, tmp_path / "m.mtl")
    assert e.line == 3 and text in e.message


# ---------------------------------------------------- files that are no files
def _obj_scene(tmp_path: Path) -> Path:
    return scene(tmp_path, group("TriangleMesh { obj_file mesh.obj }"))


def _make(tmp_path: Path, name: str, kind: str) -> None:
    p = tmp_path / name
    if kind == "fifo":
        os.mkfifo(p)
    elif kind == "loop":
        os.symlink(tmp_path / (name + ".other"), p)
        os.symlink(p, tmp_path / (name + ".other"))
    elif kind == "directory":
        p.mkdir()
    elif kind == "device":
        os.symlink("/dev/zero", p)


KINDS = {"fifo": "named pipe (FIFO)", "loop": "symbolic link loop", "directory": "is a directory",
         "device": "is a device"}


@pytest.mark.parametrize("kind", sorted(KINDS))
def test_special_files_as_scene_obj_mtl(tmp_path, kind):
    _make(tmp_path, "scene.txt", kind)
    e = error_of(load_scene, tmp_path / "scene.txt")
    named = "/dev/zero" if kind == "device" else "scene.txt"  # a symlink is reported by its target
    assert KINDS[kind] in e.message and e.path.endswith(named) and e.line is None

    d = tmp_path / "obj"
    d.mkdir()
    _make(d, "mesh.obj", kind)
    e = error_of(load_scene, _obj_scene(d))
    assert KINDS[kind] in e.message and e.path.endswith("scene.txt") and e.line == 3

    d = tmp_path / "mtl"
    d.mkdir()
    write(d / "mesh.obj", "mtllib lib.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    _make(d, "lib.mtl", kind)
    e = error_of(load_scene, _obj_scene(d))
    assert KINDS[kind] in e.message and e.path.endswith("mesh.obj") and e.line == 1


@pytest.mark.parametrize("kind", sorted(KINDS))
def test_special_files_as_texture_and_sky(tmp_path, kind):
    _make(tmp_path, "wood.png", kind)
    write(tmp_path / "lib.mtl", "newmtl a\nKd 1 1 1\nmap_Kd wood.png\n")
    write(tmp_path / "mesh.obj", "mtllib lib.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nusemtl a\nf 1/1 2/1 3/1\n")
    e = error_of(load_scene, _obj_scene(tmp_path))
    assert KINDS[kind] in e.message and e.path.endswith("lib.mtl") and e.line == 3

    _make(tmp_path, "sky.hdr", kind)
    e = error_of(load_scene, scene(tmp_path, "Lights { numLights 1\nSkybox { sky.hdr } }\n" + group(TRI)))
    assert KINDS[kind] in e.message and e.line == 3 and e.path.endswith("scene.txt")


def test_dev_null_reads_as_empty(tmp_path):
    assert read_bytes("/dev/null") == b""
    check_input("/dev/null")
    assert len(load_obj("/dev/null")) == 0
    assert load_mtl("/dev/null") == {}
    os.symlink("/dev/null", tmp_path / "empty.obj")
    with pytest.warns(UserWarning, match="has no faces"):
        s = load_scene(scene(tmp_path, group("TriangleMesh { obj_file empty.obj }")))
    assert len(s.triangles) == 0
    # the scene itself: an empty scene, seen by a default camera
    with pytest.warns(UserWarning, match="no blocks"):
        s = load_scene("/dev/null")
    assert len(s.triangles) == len(s.spheres) == len(s.planes) == 0 and s.camera is not None


def test_a_scene_without_group_has_no_geometry(tmp_path):
    s = load_scene(scene(tmp_path, "Background { color 1 1 1 }\n"))
    assert len(s.triangles) == len(s.spheres) == len(s.planes) == 0
    assert s.background.color == (1.0, 1.0, 1.0)
    e = error_of(load_scene, write(tmp_path / "nocam.txt", "Background { color 1 1 1 }\n"))
    assert "no camera" in e.message


def test_nul_byte_in_a_file_name(tmp_path):
    e = error_of(load_scene, scene(tmp_path, group("TriangleMesh { obj_file me\0sh.obj }")))
    assert e.line == 3 and "NUL" in e.message
    write(tmp_path / "mesh.obj", "mtllib a\0b.mtl\n")
    e = error_of(load_obj, tmp_path / "mesh.obj")
    assert e.line == 1 and "NUL" in e.message


# ------------------------------------------------------------ negative colours
def test_negative_reflectance_is_clamped_with_a_warning(tmp_path):
    write(tmp_path / "lib.mtl", "newmtl a\nKd 0.5 -0.25 0.5\nKs -1\n")
    with pytest.warns(UserWarning) as rec:
        mats = load_mtl(tmp_path / "lib.mtl")
    assert mats["a"].kd == (0.5, 0.0, 0.5) and mats["a"].ks == (0.0, 0.0, 0.0)
    texts = [str(w.message) for w in rec]
    assert any(t.startswith(f"{tmp_path / 'lib.mtl'}:2: Kd") and "negative" in t for t in texts)
    assert any(t.startswith(f"{tmp_path / 'lib.mtl'}:3: Ks") for t in texts)

    body = ("Materials { numMaterials 1\nMaterial { diffuseColor 1 -1 1\n Kd 0.5 0.5 0.5 }\n}\n"
            "Group { numObjects 1 MaterialIndex 0 " + TRI + " }\n")
    p = write(tmp_path / "scene.txt", CAM + body)
    body2 = body.replace("\n Kd 0.5 0.5 0.5", "")
    p2 = write(tmp_path / "scene2.txt", CAM + body2)
    with pytest.warns(UserWarning, match=r"scene2\.txt:3: diffuseColor 1 -1 1 has a negative channel"):
        s = load_scene(p2)
    assert s.materials[0].kd == (1.0, 0.0, 1.0)
    with pytest.warns(UserWarning, match="negative"):
        load_scene(p)


@pytest.mark.parametrize("light, line", [
    ("Lights { numLights 1\nPointLight { position 0 0 0 color 1 -1 1 } }", 3),
    ("Lights { numLights 1\nDirectionalLight { direction 0 -1 0\ncolor -1 1 1 } }", 4),
    ("Background { color 0 0 -0.1 }", 2),
    ("Background { ambientLight -1 0 0 }", 2),
    ("Materials { numMaterials 1\nMaterial { Ke 1 -2 1 } }", 3),
])
def test_negative_light_colours_are_errors(tmp_path, light, line):
    e = error_of(load_scene, scene(tmp_path, light + "\n" + group(TRI)))
    assert e.line == line and "negative" in e.message


def test_negative_emission_in_mtl_is_an_error(tmp_path):
    write(tmp_path / "lib.mtl", "newmtl lamp\nKd 0 0 0\nKe 10 -1 10\n")
    e = error_of(load_mtl, tmp_path / "lib.mtl")
    assert e.line == 3 and "Ke" in e.message and "negative" in e.message


# --------------------------------------------- errors name the referencing line
def _corrupt_png(path: Path) -> None:
    from drpt.imageio import write_image

    write_image(path, np.full((4, 4, 3), 0.5, np.float32))
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def test_corrupt_sky_error_names_the_skybox_line(tmp_path):
    from drpt.render.lights.envmap import EnvironmentLight

    _corrupt_png(tmp_path / "sky.png")
    s = load_scene(scene(tmp_path, "Lights { numLights 1\n\nSkybox { sky.png } }\n" + group(TRI)))
    sky = s.lights[0].path
    assert isinstance(sky, NamedPath) and sky.named_at == Loc(tmp_path / "scene.txt", 4)
    e = error_of(EnvironmentLight.from_file, sky)
    assert str(e).startswith(f"{tmp_path / 'scene.txt'}:4: sky.png: cannot read image")


def test_corrupt_texture_error_names_the_map_kd_line(tmp_path):
    from drpt.render.texture import load_rgb

    _corrupt_png(tmp_path / "wood.png")
    write(tmp_path / "lib.mtl", "newmtl a\nKd 1 1 1\n\nmap_Kd wood.png\n")
    write(tmp_path / "mesh.obj", "mtllib lib.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nusemtl a\nf 1/1 2/1 3/1\n")
    s = load_scene(_obj_scene(tmp_path))
    e = error_of(load_rgb, s.materials[0].map_kd)
    assert str(e).startswith(f"{tmp_path / 'lib.mtl'}:4: wood.png: cannot read image")
    # the scene format's own 'texture' field
    body = ("Materials { numMaterials 1\nMaterial { texture wood.png } }\n"
            "Group { numObjects 1 MaterialIndex 0 TriangleMesh { obj_file mesh.obj } }\n")
    s = load_scene(scene(tmp_path, body, "scene2.txt"))
    e = error_of(load_rgb, s.materials[0].map_kd)
    assert str(e).startswith(f"{tmp_path / 'scene2.txt'}:3: wood.png: ")


def test_empty_image_is_an_error(tmp_path):
    from drpt.imageio import read_image

    (tmp_path / "e.hdr").write_bytes(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 0 +X 0\n")
    e = error_of(read_image, tmp_path / "e.hdr")
    assert e.path == str(tmp_path / "e.hdr")


def test_cli_corrupt_sky_is_one_line_at_the_skybox(tmp_path, capsys):
    from drpt.cli import main

    _corrupt_png(tmp_path / "sky.png")
    p = scene(tmp_path, "Lights { numLights 1\nSkybox { sky.png } }\n" + group(TRI))
    assert main(["export", str(p), str(tmp_path / "out.xml")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"drpt: error: {p}:3: sky.png: cannot read image")


def test_huge_and_tiny_direction_vectors_are_stored_normalized(tmp_path):
    cam = "PerspectiveCamera { center 0 0 5 direction 0 0 -1e308 up 0 1e308 0 angle 40 }\n"
    light = "Lights { numLights 1 DirectionalLight { direction 1e-300 -1e-300 0 color 1 1 1 } }\n"
    s = load_scene(write(tmp_path / "scene.txt", cam + light + group(TRI)))
    assert s.camera.direction == (0.0, 0.0, -1.0) and s.camera.up == (0.0, 1.0, 0.0)
    np.testing.assert_allclose(s.lights[0].direction, [2 ** -0.5, -(2 ** -0.5), 0])
    s = load_scene(write(tmp_path / "plain.txt", CAM + group(TRI)))
    assert s.camera.direction == (0.0, 0.0, -1.0) and s.camera.up == (0.0, 1.0, 0.0)


def test_corrupt_exr_prints_nothing_but_the_error(tmp_path, capfd):
    from drpt.imageio import read_image, write_image

    rng = np.random.default_rng(1)
    write_image(tmp_path / "t.exr", rng.random((256, 64, 3)).astype(np.float32))
    data = (tmp_path / "t.exr").read_bytes()
    (tmp_path / "t.exr").write_bytes(data[: len(data) * 2 // 3])
    e = error_of(read_image, tmp_path / "t.exr")
    assert "truncated or corrupt" in e.message
    out, err = capfd.readouterr()
    assert out == "" and err == ""


@pytest.mark.parametrize("sep", ["\v", "\f", "\x1c", "\x1d", "\x1e", "\x85", "\u2028", "\u2029"])
def test_only_newlines_end_lines(tmp_path, sep):
    from drpt.scene.tokens import tokenize

    assert [t.line for t in tokenize(f"a{sep}{{\nb")] == [1, 1, 2]
    write(tmp_path / "m.obj", f"v 0 0 0{sep}v x\n")
    e = error_of(load_obj, tmp_path / "m.obj")
    assert e.line == 1
    write(tmp_path / "m.mtl", f"# c{sep}f 1 2 0\nKd 1\n")
    e = error_of(load_mtl, tmp_path / "m.mtl")
    assert e.line == 2 and "before any 'newmtl'" in e.message
    write(tmp_path / "r.obj", "v 0 0 0\rv 1 0 0\r\nv 0 1 0\rf 1 2 4\r")
    e = error_of(load_obj, tmp_path / "r.obj")
    assert e.line == 4


@pytest.mark.parametrize("light, line", [
    ("Lights { numLights 1\nPointLight { position 0 0 0 color 1 1e39 1 } }", 3),
    ("Materials { numMaterials 1\nMaterial { diffuseColor 1e300 1 1 } }", 3),
    ("Materials { numMaterials 1\nMaterial { Ke 1e39 } }", 3),
    ("Materials { numMaterials 1\nMaterial { exponent 1e300 } }", 3),
    ("Materials { numMaterials 1\nMaterial { Ni -1e300 } }", 3),
])
def test_values_beyond_float32_are_errors(tmp_path, light, line):
    e = error_of(load_scene, scene(tmp_path, light + "\n" + group(TRI)))
    assert e.line == line and ("float32" in e.message)
