"""How drpt's Mitsuba XML reader finds what a file refers to, as Mitsuba's parser does:
``<path>`` folders and the file resolver's order, ``<include>`` fragments, named children
(``<ref name=...>``, ``<bsdf name=...>``), spectra given by wavelength, the ``moment``
integrator. Loading only (no renders); the renders are in test_mitsuba_xml.py and
test_mitsuba_corpus.py."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from drpt.errors import SceneError
from drpt.scene import load_scene
from drpt.scene.mitsuba.nodes import Node

_IS_CHILD = Node._is_child

XML = Path(__file__).resolve().parents[2] / "data" / "xml"  # tests/data/xml
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


# ------------------------------------------------------------ the moment integrator
MOMENT = """<integrator type="moment"><integrator type="path" name="p"><integer name="max_depth" value="1"/>
</integrator></integrator>
<sensor type="perspective"><transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/>
</transform><film type="hdrfilm"><integer name="width" value="12"/><integer name="height" value="12"/>
<rfilter type="box"/></film><sampler type="independent"><integer name="sample_count" value="256"/></sampler>
</sensor>
<shape type="sphere"><emitter type="area"><rgb name="radiance" value="1,0.5,2"/></emitter></shape>"""


def test_moment_renders_its_nested_integrator(tmp_path):
    s, warns = _load(_write(tmp_path / "m.xml", MOMENT))
    st = s.settings
    assert st.moment == "p" and st.integrator == "path" and st.max_depth == 1
    assert not warns
    s, _ = _load(_write(tmp_path / "n.xml", MOMENT.replace(' name="p"', "")))
    assert s.settings.moment == "_arg_0"


def test_moment_without_a_nested_integrator_is_an_error(tmp_path):
    with pytest.raises(SceneError, match=r"m.xml:2: integrator 'moment' needs a nested integrator"):
        _load(_write(tmp_path / "m.xml", '<integrator type="moment"/>\n' + SENSOR))


@pytest.mark.slow
@pytest.mark.mitsuba
def test_moment_channels_are_mitsubas(tmp_path):
    """The EXR of a render of a ``moment`` scene has Mitsuba's AOV channels. The pixels on the
    sphere's outline see the emitter or nothing, so their second moment is the same for any
    estimator: the image means of drpt's and Mitsuba's channels agree within 2% (each image's
    noise is about 0.2% of it here); a second moment computed per RGB channel instead of in
    XYZ (the negative control) is off by more than 10%."""
    import subprocess
    import sys

    import mitsuba as mi
    import numpy as np
    import OpenEXR

    p = _write(tmp_path / "m.xml", MOMENT)
    out = tmp_path / "d.exr"
    r = subprocess.run([sys.executable, "-m", "drpt", "render", str(p), "-o", str(out), "-q"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    ch = OpenEXR.File(str(out), separate_channels=True).channels()
    names = ["p.X", "p.Y", "p.Z", "m2_p.X", "m2_p.Y", "m2_p.Z"]
    assert set(ch) == {"R", "G", "B", *names}
    drpt = np.stack([np.asarray(ch[k].pixels, np.float64) for k in names], -1)
    mi.set_variant("scalar_rgb")
    ref = np.asarray(mi.render(mi.load_file(str(p)), seed=5), np.float64)[..., 3:]
    n = drpt.shape[0] * drpt.shape[1]
    got, want = drpt.reshape(n, 6).mean(0), ref.reshape(n, 6).mean(0)
    assert np.abs(got / want - 1).max() < 0.02, (got, want)
    rgb = np.stack([np.asarray(ch[c].pixels, np.float64) for c in "RGB"], -1)
    per_channel = (rgb ** 2).reshape(n, 3).mean(0)  # a pixel's E[R]^2, ... instead of E[X^2]
    assert np.abs(per_channel / want[3:] - 1).max() > 0.1


# ------------------------------------------------------------ named children
def test_named_children_are_read_as_mitsuba_reads_them(tmp_path):
    body = """<bsdf type="roughplastic" id="red"><rgb name="diffuse_reflectance" value="0.5,0.1,0.1"/></bsdf>
<sensor type="perspective" name="sensor"><film type="hdrfilm" name="film"><integer name="width" value="8"/>
<integer name="height" value="8"/><rfilter type="tent" name="rfilter"/></film>
<sampler type="independent" name="sampler"><integer name="sample_count" value="3"/></sampler></sensor>
<shape type="sphere"><ref name="bsdf" id="red"/></shape>
<shape type="sphere"><float name="radius" value="0.5"/>
<bsdf type="twosided" name="bsdf"><bsdf type="diffuse" name="bsdf_0"/></bsdf>
<emitter type="area" name="emitter"><rgb name="radiance" value="2,2,2"/></emitter></shape>"""
    s, warns = _load(_write(tmp_path / "s.xml", body))
    assert not warns, warns
    assert s.settings.rfilter == "tent" and s.settings.spp == 3
    kinds = {m.name: (m.bsdf.kind, m.emission) for m in s.materials}
    assert kinds["red"][0] == "roughplastic"
    (twosided,) = [m for m in s.materials if m.bsdf.kind == "twosided"]
    assert twosided.bsdf.children[0].kind == "diffuse" and twosided.emission == (2.0, 2.0, 2.0)


def test_drpt_reads_its_own_export(tmp_path):
    from drpt.export.mitsuba import write_xml

    src = load_scene(Path(__file__).resolve().parents[3] / "scenes" / "cornellbox" / "cornellbox.txt")
    out = tmp_path / "cb.xml"
    write_xml(src, out, 16, 16, 4)
    s, warns = _load(out)
    assert not warns, warns
    kd = {m.bsdf.children[0].params["kd"] for m in s.materials if m.bsdf.kind == "twosided"}
    assert len(kd) >= 3 and kd <= {m.kd for m in src.materials}
    assert sum(max(m.emission) > 0 for m in s.materials) == 1


# ------------------------------------------------------------ spectra given by wavelength
SPECTRA = """<sensor type="perspective"><film type="hdrfilm"><integer name="width" value="8"/>
<integer name="height" value="8"/></film></sensor>
<shape type="sphere" id="a"><bsdf type="diffuse" id="dif">
<spectrum name="reflectance" value="400:0.1, 500:0.5, 600:0.3, 700:0.2"/></bsdf>
<emitter type="area"><spectrum name="radiance" value="400:0, 500:8, 600:15.6, 700:18.4"/></emitter></shape>
<shape type="sphere" id="b"><bsdf type="roughconductor" id="cond">
<spectrum name="eta" filename="eta.spd"/><spectrum name="k" value="400:3, 550:2.5, 700:4"/>
<spectrum name="specular_reflectance" value="400:0.1, 500:0.5, 600:3"/></bsdf></shape>
<emitter type="point"><spectrum name="intensity" value="380:1, 780:2"/></emitter>"""


@pytest.mark.mitsuba
def test_wavelength_spectra_are_mitsubas_rgb(tmp_path):
    """Reflectance (D65-weighted, clamped to [0, 1]), emission (not weighted, clamped at 0)
    and unbounded parameters (conductors' eta and k: weighted, not clamped above 1), from
    values and from an .spd file, equal what Mitsuba's scalar_rgb variant loads from the
    same file (its plugins' parameters, mi.traverse)."""
    import mitsuba as mi
    import numpy as np

    (tmp_path / "eta.spd").write_text("# eta\n400 1.2\n500 0.9\n600 0.4\n700 0.3\n")
    p = _write(tmp_path / "s.xml", SPECTRA)
    s, warns = _load(p)
    assert len(warns) == 1 and "specular_reflectance" in warns[0] and "s.xml:7" in warns[0], warns
    mi.set_variant("scalar_rgb")
    params = mi.traverse(mi.load_file(str(p)))

    def mitsuba(key):
        return np.array(params[key], np.float64).ravel()

    mat = {m.name: m for m in s.materials}
    assert np.allclose(mat["dif+area"].bsdf.params["kd"], mitsuba("a.bsdf.reflectance.value"), atol=1e-6)
    assert np.allclose(mat["dif+area"].emission, mitsuba("a.emitter.radiance.value"), atol=1e-5)
    cond = mat["cond"].bsdf.params
    for name in ("eta", "k", "specular_reflectance"):
        assert np.allclose(cond[name], mitsuba(f"b.bsdf.{name}.value"), atol=1e-6), name
    assert max(cond["k"]) > 1  # unbounded
    (light,) = s.lights
    key = [k for k in params.keys() if k.endswith("intensity.value")][0]
    assert np.allclose(light.color, mitsuba(key), atol=1e-5)


def test_a_missing_spd_file_is_a_located_error(tmp_path):
    p = _write(tmp_path / "s.xml", f'{SENSOR}\n<bsdf type="diffuse">\n'
               '<spectrum name="reflectance" filename="gone.spd"/></bsdf>')
    with pytest.raises(SceneError) as e:
        _load(p)
    assert f"{p}:4:" in str(e.value) and "gone.spd" in str(e.value)


# ------------------------------------------------------------ messages
@pytest.mark.parametrize("ref, message", [
    ('<ref id="nope"/>', '<ref id="nope"/>: no object has id "nope"'),
    ('<ref name="bsdf" id="nope"/>', '<ref name="bsdf" id="nope"/>: no object has id "nope"'),
])
def test_a_ref_to_a_missing_id_names_the_ref(tmp_path, ref, message):
    p = _write(tmp_path / "s.xml", f'{SENSOR}\n<shape type="sphere">{ref}</shape>')
    with pytest.raises(SceneError) as e:
        _load(p)
    assert str(e.value) == f"{p}:3: {message}"
    assert "_arg_" not in str(e.value)


def test_unread_parameters_are_listed_once_and_children_are_not(tmp_path):
    body = (f'{SENSOR}\n<shape type="sphere"><bsdf type="roughconductor" name="bsdf">'
            '<float name="int_ior" value="1.5"/></bsdf></shape>')
    s, warns = _load(_write(tmp_path / "s.xml", body))
    assert len(warns) == 1 and "'int_ior' of bsdf 'roughconductor' at" in warns[0], warns
    assert "'bsdf'" not in warns[0] and "Mitsuba 3 refuses them" in warns[0]
    assert s.settings.not_read and "int_ior" in s.settings.not_read[0]


# ------------------------------------------------------------ files as other tools write them
STYLES = XML / "styles"


def _old_children(self, key):  # the reader before named children, for shapes: only unnamed ones
    if self.kind != "shape":
        return _IS_CHILD(self, key)
    return self._type(key) == "ResolvedReference" and key.startswith("_arg_")


def _spectrum_without_d65(self, name, s, emission):
    mi = self.state.mi
    rgb = mi.spectrum_list_to_srgb(list(s.wavelengths), list(s.values), bounded=False, d65=False)
    return (float(rgb[0]), float(rgb[1]), float(rgb[2]))


@pytest.mark.slow
@pytest.mark.mitsuba
@pytest.mark.parametrize("name, control", [
    ("blender", None), ("legacy05", None),
    ("blender", ("_is_child", _old_children)),
    ("legacy05", ("_spectrum_rgb", _spectrum_without_d65)),
], ids=["blender", "legacy05", "blender, named children dropped", "legacy05, reflectances without D65"])
def test_files_written_by_other_tools_render_like_mitsuba(monkeypatch, name, control):
    """tests/data/xml/styles: ``blender`` (as Mitsuba's Blender add-on writes a scene: every
    nested plugin named, ``<ref id=.. name="bsdf">``, a ``<path>`` folder, matrices, defaults)
    and ``legacy05`` (a 0.5 file: camelCase, spectra given by wavelength and an ``.spd`` file,
    ``<ref name="bsdf">``, a named rfilter) read without a warning and render like Mitsuba
    rendering the same file (8x8 block z-test below 4.5, image mean z below 4, as
    test_mitsuba_xml's corpus). Negative controls: the reader's old ways (named children
    dropped; reflectance spectra integrated without the D65 weighting) fail it."""
    from drpt.testing import block_z
    from support.xml import mean_z, render_xml_both

    path = STYLES / f"{name}.xml"
    if control is not None:
        monkeypatch.setattr(Node, *control)
    s, warns = _load(path, ignore_unsupported=control is not None)  # (a dropped child is unsupported)
    assert control is not None or not warns, warns
    r, ref, var = render_xml_both(s, path, 256)
    assert r.image.shape == (24, 32, 3) and ref.mean() > 0.05 and ref.std() > 0.03  # not just the sky
    z = np.abs(block_z(r.image.astype(np.float64), r.variance, ref, var)).max()
    zmean = np.abs(mean_z(r, ref, var)).max()
    if control is None:
        assert z < 4.5 and zmean < 4.0, (z, zmean)
    else:
        assert z > 4.5 or zmean > 4.0, (z, zmean)


def test_a_parameter_mitsuba_reads_and_drpt_does_not_is_unsupported(tmp_path, monkeypatch):
    """The unread-parameter warning names only parameters Mitsuba's plugin refuses too (drpt
    asks Mitsuba, loading the plugin with the node's parameters); one Mitsuba reads is an
    unsupported parameter instead. Simulated with the film's pixel_format, which drpt
    reads without using it."""
    from drpt.scene.mitsuba import reader

    monkeypatch.setitem(reader._SILENT, "film", ())
    body = SENSOR.replace("</film>", '<string name="pixel_format" value="rgb"/></film>')
    p = _write(tmp_path / "s.xml", body)
    with pytest.raises(SceneError) as e:
        _load(p)
    assert "unsupported parameter 'pixel_format' of film 'hdrfilm' (Mitsuba reads it, drpt does not)" in str(e.value)
    s, warns = _load(p, ignore_unsupported=True)
    assert len(warns) == 1 and "pixel_format" in warns[0] and "do not read" not in warns[0], warns
    assert "pixel_format" in s.settings.not_read[0]
