"""``drpt export SCENE out.xml`` then ``drpt render out.xml`` renders what ``drpt render SCENE``
does, for every bundled scene (``scenes/*/*.txt``): the exported file carries the size,
sample count, depths and filter, and drpt's XML reader reads back the geometry, materials,
lights and camera the exporter wrote.

The two renders (same size, spp and seed) are not bit-identical (the PLY meshes and the
material table come back in another order, so the samples differ), so they are compared by
the 8x8 block z-test of drpt/testing.py (each render's own per-pixel variance): every
block within 4.5 standard errors, and the image mean within 4. Negative control: the
exported Cornell box with its white walls' reflectance 0.725 -> 0.65 fails it.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from drpt.testing import block_z

SCENES = sorted((Path(__file__).resolve().parents[2] / "scenes").glob("*/*.txt"))
SIZE, SPP = 32, 128


def _render(path: Path, opts=None):
    from drpt.options import RenderOptions, with_scene_settings
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = load_scene(path)
        base = opts or RenderOptions(progress=False, seed=7)
        o, scene = with_scene_settings(base, scene)
        return scene, o, Renderer(scene, o).render()


def _export(scene, opts, out: Path) -> Path:
    from drpt.export.mitsuba import write_xml

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return write_xml(scene, out, width=opts.width, height=opts.height, spp=opts.spp,
                         max_depth=opts.path.max_depth, rr_depth=opts.path.rr_depth, bsdf=opts.bsdf,
                         rfilter=opts.filter, hide_emitters=opts.path.hide_emitters)


def _z(a, b):
    z = block_z(a.image.astype(np.float64), a.variance, b.image.astype(np.float64), b.variance)
    n = a.image.shape[0] * a.image.shape[1]
    mean = (a.image.mean((0, 1)) - b.image.mean((0, 1))) / np.sqrt(
        (a.variance.sum((0, 1)) + b.variance.sum((0, 1))) / n ** 2)
    return np.abs(z).max(), np.abs(mean).max()


@pytest.mark.slow
@pytest.mark.parametrize("path", SCENES, ids=[p.stem for p in SCENES])
def test_export_then_render_equals_render(tmp_path, path):
    from drpt.options import RenderOptions

    opts = RenderOptions(width=SIZE, height=SIZE, spp=SPP, seed=7, progress=False)
    scene, o, direct = _render(path, opts)
    xml = _export(scene, o, tmp_path / f"{path.stem}.xml")
    back_scene, o2, back = _render(xml)
    assert (o2.width, o2.height, o2.spp, o2.filter) == (o.width, o.height, o.spp, o.filter)
    assert (o2.path.max_depth, o2.path.rr_depth) == (o.path.max_depth, o.path.rr_depth)
    zmax, zmean = _z(back, direct)
    assert zmax < 4.5 and zmean < 4.0, (zmax, zmean)


@pytest.mark.slow
def test_negative_control_a_changed_export_fails(tmp_path):
    from drpt.options import RenderOptions

    path = [p for p in SCENES if p.stem == "cornellbox"][0]
    opts = RenderOptions(width=SIZE, height=SIZE, spp=SPP, seed=7, progress=False)
    scene, o, direct = _render(path, opts)
    xml = _export(scene, o, tmp_path / "cb.xml")
    text = xml.read_text()
    assert text.count('value="0.725, 0.71, 0.68"') >= 1
    xml.write_text(text.replace('value="0.725, 0.71, 0.68"', 'value="0.65, 0.71, 0.68"'))
    _, _, back = _render(xml)
    zmax, zmean = _z(back, direct)
    assert zmax > 4.5 or zmean > 4.0, (zmax, zmean)
