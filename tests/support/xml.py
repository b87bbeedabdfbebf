"""The Mitsuba XML corpus of ``tests/data/xml`` (assets from ``make_assets.py``), read by drpt
and rendered by drpt and by Mitsuba *from the same file*.

* :data:`XML`: the corpus folder;
* :func:`load`: a corpus scene read by drpt, with the warnings it gave;
* :func:`render_xml_both`: drpt's render of a scene and Mitsuba's of its XML file, with the
  variance of Mitsuba's mean, for :func:`drpt.testing.assert_agree` / :func:`drpt.testing.block_z`;
* :func:`mean_z`: the z of the difference of the two images' means, per channel.

``tests/scene/mitsuba/test_mitsuba_xml.py`` tests the corpus itself; the render tests of
single features (samplers, films, lights, textures) use these helpers on their own files.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from drpt.scene import load_scene
from drpt.testing import mean_z  # noqa: F401 (the z of two image means: the tests import it from here)

from . import DATA

XML = DATA / "xml"
"""The Mitsuba XML corpus written for the tests."""


def load(name: str, **kw):
    """``(scene, warnings)``: corpus scene ``XML/<name>.xml`` read by drpt (``kw`` go to
    :func:`drpt.scene.load_scene`), and the messages of the warnings it gave."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        scene = load_scene(XML / f"{name}.xml", **kw)
    return scene, [str(w.message) for w in caught]


def render_xml_both(scene, path: Path, spp: int, defines: dict | None = None, seed: int = 3,
                    ref_spp: int | None = None, **options):
    """drpt's render of ``scene`` (the file's settings, ``spp``, RenderOptions ``options``) and
    Mitsuba's of ``path`` (at ``ref_spp``, default ``spp``) as the mean of 8 batches:
    ``(result, mean, variance of the mean)``."""
    from dataclasses import replace

    import mitsuba as mi

    from drpt.backend import mitsuba_variant
    from drpt.options import RenderOptions, with_scene_settings
    from drpt.render.renderer import Renderer

    opts = replace(with_scene_settings(RenderOptions(progress=False, seed=seed), scene)[0], spp=spp,
                   **{"variance": True, **options})  # (light tracing's too: the tests read it)
    r = Renderer(scene, opts).render()
    mi.set_variant(mitsuba_variant())
    batches = 8
    ms = mi.load_file(str(path), optimize=False,
                      **{**(defines or {}), "spp": str((ref_spp or spp) // batches)})
    runs = np.stack([np.asarray(mi.render(ms, seed=seed + 100 + 7919 * k), np.float64)[..., :3]
                     for k in range(batches)])
    ref = runs.mean(0)
    # blocks that see only a constant background have no variance in either image: allow
    # float32 rounding (1e-5 relative) there instead of dividing by zero
    return r, ref, runs.var(0, ddof=1) / batches + (1e-5 * ref) ** 2


SAMPLER_SCENE = """<scene version="3.0.0">
    <sensor type="perspective"><float name="fov" value="40"/>
        <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="6"/>
            <rfilter type="box"/></film>
        SAMPLER</sensor>
    <shape type="sphere"><bsdf type="diffuse"/></shape>
    <emitter type="constant"/>
</scene>"""


def sampler_scene(sampler: str) -> str:
    """An 8x6 XML scene (a diffuse sphere under a constant sky) whose sensor holds ``sampler``
    (the ``<sampler>`` element's text), for the tests that read a sampler from XML."""
    return SAMPLER_SCENE.replace("SAMPLER", sampler)
