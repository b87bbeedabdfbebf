"""``compare scene.xml``: the reference is Mitsuba on the user's own XML file (drpt/tools/xmlref.py).

Checked here: compare on corpus files agrees at the file's own settings; the reference
is the file's, not drpt's reading of it (drpt given a modified copy while Mitsuba gets
the original is caught); flags that differ from the file edit Mitsuba's film and
integrator alike; the reference is cached and a change of the file renders a new one;
a file drpt does not read as written (the 0.6 file, whose unread parameters Mitsuba 3
refuses; a plugin drpt lacks) stops compare, or with --ignore-unsupported is compared and
marked not like for like.
"""

from __future__ import annotations

import json
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.mitsuba

XML = Path(__file__).resolve().parents[1] / "data" / "xml"  # tests/data/xml


def _compare(tmp_path, scene, *flags, out="out"):
    from drpt.cli import main

    o = tmp_path / out
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rc = main(["compare", str(scene), "--out", str(o), "--cache", str(tmp_path / "cache"), "-q", *flags])
    assert rc == 0
    report = json.loads((o / "metrics.json").read_text())
    from drpt.imageio import read_image

    return report, read_image(o / "drpt.exr").astype(np.float64), read_image(o / "reference.exr").astype(np.float64)


def _mean_rel(a, b):
    return np.abs(a.mean((0, 1)) / b.mean((0, 1)) - 1.0).max()


@pytest.mark.parametrize("name", ["textured", "meshes"])
def test_compare_xml_agrees_with_mitsuba_on_the_file(tmp_path, name):
    report, x, ref = _compare(tmp_path, XML / f"{name}.xml", "--spp", "256", "--ref-spp", "1024")
    r = report["reference"]
    assert r["renderer"].endswith("on the XML file")
    assert r["xml"]["file"] == str(XML / f"{name}.xml") and report["like_for_like"]
    assert r["xml"]["rfilter"] is None and r["xml"]["integrator"] is None  # the file's own
    assert (report["width"], report["height"]) == (32, 24) == (x.shape[1], x.shape[0])  # the film's
    assert report["filter"] == "box"  # the file's rfilter
    # measured: 0.8% (meshes), 1.2% (textured) outside with 8-batch reference variances
    assert report["metrics"]["outside_ci"] < 0.03, report["metrics"]
    assert _mean_rel(x, ref) < 0.01


def test_compare_xml_catches_drpt_reading_a_modified_file(tmp_path, monkeypatch):
    """drpt renders a copy with the floor's reflectance 0.7 -> 0.6, Mitsuba the original file:
    compare must fail it (were the reference drpt's export, it would agree)."""
    import drpt.scene as ds
    import drpt.tools.compare as cmp

    src = (XML / "spot.xml").read_text()
    assert '<rgb name="reflectance" value="0.7"/>' in src
    shutil.copy(XML / "common_sensor.xml", tmp_path / "common_sensor.xml")
    bad = tmp_path / "spot_bad.xml"
    bad.write_text(src.replace('<rgb name="reflectance" value="0.7"/>', '<rgb name="reflectance" value="0.6"/>'))
    real = ds.load_scene

    def load_modified(path, **kw):
        scene = real(bad, **kw)
        scene.path = Path(path).resolve()  # Mitsuba's reference reads the original
        return scene

    good, x0, ref0 = _compare(tmp_path, XML / "spot.xml", "--spp", "256", "--ref-spp", "1024", out="good")
    monkeypatch.setattr(cmp, "load_scene", load_modified)  # the loader compare calls
    report, x, ref = _compare(tmp_path, XML / "spot.xml", "--spp", "256", "--ref-spp", "1024", out="bad")
    assert report["reference"]["cached"] and np.array_equal(ref, ref0)  # the same reference
    assert good["metrics"]["outside_ci"] < 0.03 and _mean_rel(x0, ref0) < 0.01
    assert report["metrics"]["outside_ci"] > 0.15, report["metrics"]
    assert _mean_rel(x, ref) > 0.05


def test_flags_edit_mitsubas_film_and_integrator(tmp_path):
    report, x, ref = _compare(tmp_path, XML / "spot.xml", "--spp", "64", "--ref-spp", "256", "--size", "20", "10",
                              "--filter", "tent", "--max-depth", "2")
    e = report["reference"]["xml"]
    assert e["size"] == [20, 10] and ref.shape == (10, 20, 3) == x.shape
    assert e["rfilter"] == "tent"
    assert e["integrator"] == {"max_depth": 2, "rr_depth": 5, "hide_emitters": True}
    assert report["max_depth"] == 2 and report["filter"] == "tent"
    # depth 2 (direct light only) is darker than the file's depth 4 (measured: 3.8%)
    full, _, ref4 = _compare(tmp_path, XML / "spot.xml", "--spp", "16", "--ref-spp", "256", "--size", "20", "10",
                             "--filter", "tent", out="d4")
    assert full["reference"]["xml"]["integrator"] is None
    assert ref4.mean() > 1.02 * ref.mean()
    assert _mean_rel(x, ref) < 0.03


def test_reference_is_cached_and_a_changed_file_renders_a_new_one(tmp_path):
    for f in ("spot.xml", "common_sensor.xml"):
        shutil.copy(XML / f, tmp_path / f)
    scene = tmp_path / "spot.xml"
    flags = ("--spp", "4", "--ref-spp", "64")
    a, _, ra = _compare(tmp_path, scene, *flags, out="a")
    b, _, rb = _compare(tmp_path, scene, *flags, out="b")
    assert not a["reference"]["cached"] and b["reference"]["cached"] and np.array_equal(ra, rb)
    inc = tmp_path / "common_sensor.xml"  # an included file counts too
    inc.write_text(inc.read_text().replace('value="40"', 'value="45"'))
    c, _, rc = _compare(tmp_path, scene, *flags, out="c")
    assert not c["reference"]["cached"] and c["reference"]["key"] != a["reference"]["key"]


def _compare_rc(tmp_path, scene, *flags, out="out"):
    import subprocess
    import sys

    r = subprocess.run([sys.executable, "-m", "drpt", "compare", str(scene), "--out", str(tmp_path / out),
                        "--cache", str(tmp_path / "cache"), "-q", *flags],
                       capture_output=True, text=True, timeout=300)
    return r.returncode, r.stderr


def test_compare_stops_where_drpt_does_not_read_the_file_as_written(tmp_path):
    """The 0.6 file has parameters its plugins do not read: the reference of the file as
    written is not the scene drpt renders (and Mitsuba 3 refuses it), so compare stops."""
    import mitsuba as mi

    from drpt.backend import mitsuba_variant

    mi.set_variant(mitsuba_variant())
    with pytest.raises(Exception, match="int_ior|strict_normals|unreferenced|unused"):
        mi.load_file(str(XML / "legacy06.xml"), optimize=False)  # Mitsuba 3 refuses the file itself
    rc, err = _compare_rc(tmp_path, XML / "legacy06.xml", "--spp", "4", "--ref-spp", "16")
    errors = [line for line in err.splitlines() if line.startswith("drpt: error:")]
    assert rc == 2 and len(errors) == 1 and err.strip().splitlines()[-1] == errors[0], err
    assert "drpt does not read all of the file" in err and "strict_normals" in err
    assert "--ignore-unsupported compares anyway" in err
    assert not (tmp_path / "out" / "metrics.json").exists()
    rc, err = _compare_rc(tmp_path, XML / "legacy06.xml", "--spp", "4", "--ref-spp", "16",
                          "--ignore-unsupported")
    assert rc == 2 and "Mitsuba refuses the file" in err, err  # as written, with no parameter dropped


def test_ignore_unsupported_compares_marked_not_like_for_like(tmp_path):
    """A plugin drpt lacks (the hair BSDF) with --ignore-unsupported: drpt renders its fallback,
    Mitsuba the file as written, and the report says the two are not the same scene."""
    src = (XML / "spot.xml").read_text()
    shutil.copy(XML / "common_sensor.xml", tmp_path / "common_sensor.xml")
    p = tmp_path / "hair.xml"
    p.write_text(src.replace('<bsdf type="diffuse"><rgb name="reflectance" value="0.7"/></bsdf>',
                             '<bsdf type="hair"/>', 1))
    rc, err = _compare_rc(tmp_path, p, "--spp", "4", "--ref-spp", "16")
    assert rc == 2 and "unsupported BSDF plugin 'hair'" in err, err
    report, _, _ = _compare(tmp_path, p, "--spp", "4", "--ref-spp", "16", "--ignore-unsupported")
    assert report["like_for_like"] is False and "hair" in report["not_read"][0]
    good, _, _ = _compare(tmp_path, XML / "spot.xml", "--spp", "4", "--ref-spp", "16", out="good")
    assert good["like_for_like"] is True and good["not_read"] == []


def test_d65_constant_is_mitsubas():
    import mitsuba as mi

    from drpt.scene.mitsuba.nodes import D65_RGB, mitsuba

    mitsuba()
    s = mi.load_string('<scene version="3.0.0"><emitter type="point"><spectrum name="intensity" value="1"/>'
                       '</emitter></scene>')
    p = mi.traverse(s)
    (k,) = [k for k in p.keys() if k.endswith("intensity.value")]
    assert np.allclose(np.array(p[k]).ravel(), D65_RGB, rtol=1e-6)


def test_compare_a_cropped_film(tmp_path):
    report, x, ref = _compare(tmp_path, XML / "crop.xml", "--spp", "128", "--ref-spp", "512")
    assert (report["width"], report["height"]) == (32, 24) and ref.shape == (24, 32, 3)
    assert report["metrics"]["outside_ci"] < 0.03, report["metrics"]
    assert _mean_rel(x, ref) < 0.01
    from drpt.cli import main

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rc = main(["compare", str(XML / "crop.xml"), "--out", str(tmp_path / "s"), "--size", "64", "48",
                   "--cache", str(tmp_path / "cache"), "-q"])
    assert rc == 2  # Mitsuba cannot render the window at another size: one-line error


def test_hide_emitters_flag_edits_mitsubas_integrator():
    """``--hide-emitters`` other than the file's own edits Mitsuba's integrator (as the
    depths do); the file's own value leaves the file's integrator as it is."""
    from drpt.cli import build_parser
    from drpt.cli.args import given_settings, options_from_args
    from drpt.options import with_scene_settings
    from drpt.scene import load_scene
    from drpt.tools.xmlref import MitsubaXML

    scene = load_scene(XML / "spot.xml")
    assert scene.settings.hide_emitters is True
    for value, edit in (("off", {"max_depth": 4, "rr_depth": 5, "hide_emitters": False}), ("on", None)):
        a = build_parser().parse_args(["compare", str(XML / "spot.xml"), "--hide-emitters", value])
        options, _ = with_scene_settings(options_from_args(a), scene, given_settings(a))
        got = MitsubaXML.for_scene(scene, options).integrator
        assert got == edit, (value, got)
