"""Where things come from: the seed parser, the OBJ and the MTL reader put a
:class:`~drpt.errors.Loc` on what they build (materials, media, lights, skies, texture
paths), and their errors and warnings name the file and line of the mistake."""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest

from drpt.errors import Loc, SceneError, SceneWarning
from drpt.imageio import read_image
from drpt.materials.interpret import interpret
from drpt.scene import load_scene

SCENE = """\
PerspectiveCamera { center 0 0 5 direction 0 0 -1 up 0 1 0 angle 45 }
Lights { numLights 2
  PointLight { position 0 1 0 color 1 1 1 }
  Skybox { sky.hdr }
}
Media { numMedia 1
  Medium { sigmaT 1 1 1 }
}
Materials { numMaterials 1
  Material { diffuseColor 0.5 0.5 0.5 texture tex.png }
}
Group { numObjects 2
  MaterialIndex 0
  TriangleMesh { obj_file m.obj }
  Sphere { center 0 0 0 radius 1 }
}
"""
OBJ = "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl red\nf 1 2 3\n"
MTL = "newmtl red\nKd 0.6 0.1 0.1\nmap_Kd tex.png\n"


def _files(tmp_path: Path, scene: str = SCENE, obj: str = OBJ, mtl: str = MTL) -> Path:
    for name, text in (("m.obj", obj), ("m.mtl", mtl)):
        (tmp_path / name).write_text(text)
    (tmp_path / "sky.hdr").write_bytes(b"not read while parsing")
    (tmp_path / "tex.png").write_bytes(b"not a png")
    p = tmp_path / "scene.txt"
    p.write_text(scene)
    return p.resolve()


def _error(tmp_path: Path, **texts) -> SceneError:
    with pytest.raises(SceneError) as e:
        load_scene(_files(tmp_path, **texts))
    return e.value


def test_what_the_readers_build_carries_its_place(tmp_path):
    p = _files(tmp_path)
    d = p.parent
    s = load_scene(p)
    block, red = s.materials[0], next(m for m in s.materials if m.name == "red")
    assert block.loc == Loc(p, 10) and red.loc == Loc(d / "m.mtl", 1)
    point, sky = s.lights
    assert point.loc == Loc(p, 3) and sky.loc == Loc(p, 4) and sky.path.named_at == Loc(p, 4)
    assert s.media[0].loc == Loc(p, 7)
    assert block.map_kd.named_at == Loc(p, 10) and red.map_kd.named_at == Loc(d / "m.mtl", 3)
    for m, at in ((block, Loc(p, 10)), (red, Loc(d / "m.mtl", 3))):
        spec = interpret(m)
        assert spec.loc == m.loc
        (tex,) = spec.textures()
        assert tex.loc == at


def test_the_default_material_has_no_place(tmp_path):
    s = load_scene(_files(tmp_path, scene=SCENE.replace("  MaterialIndex 0\n", "")))
    default = [m for m in s.materials if m.name == "default"]
    assert default and default[0].loc is None


@pytest.mark.parametrize("where, old, new, line", [
    ("scene", "radius 1", "radius -1", 15),  # the seed parser
    ("scene", "m.obj }", "gone.obj }", 14),  # a missing OBJ: at the line naming it
    ("obj", "f 1 2 3", "f 1 2 9", 6),  # the OBJ reader
    ("obj", "mtllib m.mtl", "mtllib gone.mtl", 1),  # a missing MTL: at the OBJ's mtllib line
    ("mtl", "Kd 0.6 0.1 0.1", "Kd 0.6 abc 0.1", 2),  # the MTL reader, through the OBJ
    ("mtl", "map_Kd tex.png", "map_Kd gone.png", 3),  # a missing texture: at its map_Kd
])
def test_each_reader_locates_its_errors(tmp_path, where, old, new, line):
    texts = {"scene": SCENE, "obj": OBJ, "mtl": MTL}
    assert old in texts[where]
    texts[where] = texts[where].replace(old, new)
    e = _error(tmp_path, **texts)
    file = {"scene": "scene.txt", "obj": "m.obj", "mtl": "m.mtl"}[where]
    assert e.loc == Loc((tmp_path / file).resolve(), line), str(e)
    assert str(e).startswith(f"{(tmp_path / file).resolve()}:{line}: ") and "\n" not in str(e)


def test_an_image_read_later_is_reported_where_it_was_named(tmp_path):
    s = load_scene(_files(tmp_path))
    red = next(m for m in s.materials if m.name == "red")
    with pytest.raises(SceneError) as e:
        read_image(red.map_kd)  # "not a png": read at render time
    assert e.value.loc == Loc(tmp_path.resolve() / "m.mtl", 3)
    assert e.value.message.startswith("tex.png: cannot read image")


def test_warnings_name_their_place(tmp_path):
    scene = SCENE.replace("  Sphere { center 0 0 0 radius 1 }\n",
                          "  Transform { Scale 1 2 1\n    Sphere { center 0 0 0 radius 1 } }\n")
    p = _files(tmp_path, scene=scene, mtl=MTL + "bump b.png\n")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        load_scene(p)
    located = {(w.message.loc, w.message.message.split(" ")[0]) for w in caught
               if isinstance(w.message, SceneWarning)}
    assert located == {(Loc(p.parent / "m.mtl", 4), "MTL"), (Loc(p, 16), "Sphere")}, \
        [str(w.message) for w in caught]
