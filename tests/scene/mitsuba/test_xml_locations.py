"""Where things come from in a Mitsuba XML scene: every node has a
:class:`~drpt.errors.Loc` (the file that holds its element, an ``<include>``d one too, and
the element's line), the materials, textures, lights and skies built from a node carry it,
and the reader's errors and warnings name it."""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest

from drpt.errors import Loc, SceneError, SceneWarning
from drpt.scene import load_scene

XML = """\
<scene version="3.0.0">
<sensor type="perspective"><film type="hdrfilm"><integer name="width" value="8"/>
    <integer name="height" value="8"/></film></sensor>
<bsdf type="diffuse" id="tex">
    <texture type="bitmap" name="reflectance">
        <string name="filename" value="t.png"/>
    </texture>
</bsdf>
<shape type="obj">
    <string name="filename" value="m.obj"/>
    <ref id="tex"/>
</shape>
<emitter type="point"><point name="position" x="0" y="1" z="0"/></emitter>
<emitter type="envmap"><string name="filename" value="sky.exr"/></emitter>
<include filename="more.xml"/>
</scene>
"""
MORE = """\
<scene version="3.0.0">

<shape type="sphere">
    <transform name="to_world"><scale x="1" y="2" z="1"/></transform>
</shape>
</scene>
"""


def _files(tmp_path: Path, xml: str = XML, more: str = MORE) -> Path:
    (tmp_path / "m.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    (tmp_path / "t.png").write_bytes(b"read at render time")
    (tmp_path / "sky.exr").write_bytes(b"read at render time")
    (tmp_path / "more.xml").write_text(more)
    p = tmp_path / "s.xml"
    p.write_text(xml)
    return p.resolve()


def _load(p: Path):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        s = load_scene(p)
    return s, [w.message for w in caught]


def test_materials_textures_lights_and_skies_carry_their_element(tmp_path):
    p = _files(tmp_path)
    s, _ = _load(p)
    tex = next(m for m in s.materials if m.name == "tex")
    assert tex.loc == Loc(p, 4) and tex.bsdf.loc == Loc(p, 4)
    (t,) = tex.bsdf.textures()
    assert t.loc == Loc(p, 5) and t.path.named_at == Loc(p, 5)
    point, sky = s.lights
    assert point.loc == Loc(p, 13) and sky.loc == Loc(p, 14) and sky.path.named_at == Loc(p, 14)
    sphere = next(m for m in s.materials if m.name == "default")
    assert sphere.loc == Loc(p.parent / "more.xml", 3)  # the shape's own element, in its file


def test_warnings_name_the_element(tmp_path):
    p = _files(tmp_path)
    _, caught = _load(p)
    tessellated = [w for w in caught if "is tessellated" in str(w)]
    assert len(tessellated) == 1 and isinstance(tessellated[0], SceneWarning)
    assert tessellated[0].loc == Loc(p.parent / "more.xml", 3), str(tessellated[0])


@pytest.mark.parametrize("file, old, new, line", [
    ("s.xml", '<point name="position"', '<point name="position" value="1 2"', 13),  # precheck
    ("s.xml", 'value="sky.exr"', 'value="gone.exr"', 14),  # the reader, at the node
    ("s.xml", '<ref id="tex"/>', '<ref id="nothing"/>', 9),  # Mitsuba's parser
    ("more.xml", '<scale x="1"', '<scale x="0"', 3),  # the reader, in an included file
])
def test_errors_name_the_file_and_line(tmp_path, file, old, new, line):
    texts = {"s.xml": XML, "more.xml": MORE}
    assert old in texts[file]
    texts[file] = texts[file].replace(old, new)
    p = _files(tmp_path, texts["s.xml"], texts["more.xml"])
    with pytest.raises(SceneError) as e:
        _load(p)
    assert e.value.loc == Loc(p.parent / file, line), str(e.value)
    assert "\n" not in str(e.value)
