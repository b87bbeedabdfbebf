"""How drpt's Mitsuba XML reader finds what a file refers to, as Mitsuba's parser does:
``<path>`` folders and the file resolver's order, ``<include>`` fragments, named children
(``<ref name=...>``, ``<bsdf name=...>``), spectra given by wavelength, the ``moment``
integrator. Loading only (no renders); the renders are in test_mitsuba_xml.py and
test_mitsuba_corpus.py."""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest

from drpt.errors import SceneError
from drpt.scene import load_scene

XML = Path(__file__).resolve().parent / "data" / "xml"
SENSOR = '<sensor type="perspective"><film type="hdrfilm"><integer name="width" value="8"/>' \
         '<integer name="height" value="8"/></film></sensor>'


def _write(path: Path, body: str, version: str = "3.0.0") -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(f'<scene version="{version}">\n{body}\n</scene>\n')
    return path


def _load(path: Path, **kw):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        scene = load_scene(path, **kw)
    return scene, [str(w.message) for w in caught]


def _obj(path: Path, y: float = 0.0) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(f"v 0 {y} 0\nv 1 {y} 0\nv 0 {y} 1\nf 1 2 3\n")


# ------------------------------------------------------------ files
def test_path_folders_are_searched_last_declared_first(tmp_path):
    _obj(tmp_path / "a" / "m.obj", 1.0)
    _obj(tmp_path / "b" / "m.obj", 2.0)
    _obj(tmp_path / "scene" / "m.obj", 3.0)
    shape = '<shape type="obj"><string name="filename" value="m.obj"/></shape>'
    p = _write(tmp_path / "scene" / "s.xml", f'<path value="../a"/>\n<path value="../b"/>\n{SENSOR}\n{shape}')
    s, _ = _load(p)
    assert s.triangles.positions[0, 0, 1] == 2.0  # the last <path> comes first
    p = _write(tmp_path / "scene" / "t.xml", f"{SENSOR}\n{shape}")
    s, _ = _load(p)
    assert s.triangles.positions[0, 0, 1] == 3.0  # the scene's folder
    p = _write(tmp_path / "scene" / "u.xml", f'<path value="{tmp_path / "a"}"/>\n{SENSOR}\n{shape}')
    s, _ = _load(p)
    assert s.triangles.positions[0, 0, 1] == 1.0  # an absolute <path>


def test_an_included_fragment_resolves_files_as_mitsuba_does(tmp_path):
    # the fragment's own folder is searched while Mitsuba parses it (for nested includes and
    # spectrum files), its shapes' files after that on the scene's search path
    _obj(tmp_path / "common" / "meshes" / "m.obj", 5.0)
    _write(tmp_path / "s" / "frag" / "f.xml",
           '<shape type="obj"><string name="filename" value="meshes/m.obj"/></shape>')
    p = _write(tmp_path / "s" / "main.xml",
               f'<path value="../common"/>\n{SENSOR}\n<include filename="frag/f.xml"/>')
    s, _ = _load(p)
    assert s.triangles.positions[0, 0, 1] == 5.0


def test_a_missing_file_names_the_line_and_the_folders(tmp_path):
    (tmp_path / "c").mkdir()
    p = _write(tmp_path / "s.xml", f'<path value="c"/>\n{SENSOR}\n'
               '<shape type="obj">\n<string name="filename" value="gone.obj"/></shape>')
    with pytest.raises(SceneError) as e:
        _load(p)
    msg = str(e.value)
    assert f"{p}:4:" in msg and "gone.obj: no such file" in msg and str(tmp_path / "c") in msg


def test_a_missing_path_folder_is_a_located_error(tmp_path):
    p = _write(tmp_path / "s.xml", f'<path value="nowhere"/>\n{SENSOR}')
    with pytest.raises(SceneError) as e:
        _load(p)
    assert f"{p}:2:" in str(e.value) and "nowhere" in str(e.value)


def test_loading_leaves_mitsubas_file_resolver_as_it_was(tmp_path):
    import mitsuba as mi

    (tmp_path / "c").mkdir()
    p = _write(tmp_path / "s.xml", f'<path value="c"/>\n{SENSOR}')
    before = [str(x) for x in mi.file_resolver()]
    _load(p)
    assert [str(x) for x in mi.file_resolver()] == before
