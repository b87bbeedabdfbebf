"""Mitsuba 3's own render-test scenes (``../shared/corpus/mitsuba-data``) rendered by drpt and
z-tested against the shipped references the way Mitsuba's ``src/render/tests/test_renders.py``
tests its own renders.

The statistic (Mitsuba's): per pixel and channel, in XYZ,
``z = |mean - ref| * sqrt(spp / max(ref_var, 1e-4))`` where ``ref_var`` is the reference's
per-*sample* variance image (``refs/<name>_ref_rgb_var.exr``, written by Mitsuba's ``moment``
integrator); two-sided p-values against the Sidak-corrected level
``alpha = 1 - 0.99 ** (1 / pixels)``; the scene passes when at least 99.75% of the pixel
channels have ``p > alpha``. The test assumes drpt's per-sample variance is close to Mitsuba's;
at the low sample counts used here (a few hundred spp instead of Mitsuba's 2e6 / pixels) the
test is weaker than Mitsuba's but still catches a wrong reading of the file (the negative
controls in the corpus tests check that it does).

Scenes are rendered *as authored*: no edits, the file's own film, filter, integrator and
depths; only ``spp`` is passed (as the ``$spp`` define the corpus scenes declare, and as the
sample count).
"""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from drpt.testing import SRGB_TO_XYZ, ZTest, to_xyz, z_test  # noqa: F401

from . import SHARED

CORPUS = SHARED / "corpus" / "mitsuba-data" / "tests" / "scenes"

#: participating_media scene -> spp drpt renders it with (all pass Mitsuba's z-test); rendered
#: by ``tests/render/integrators/test_media.py``, counted by the coverage test of
#: ``tests/validation/test_mitsuba_corpus.py``, which renders the other folders
MEDIA_SCENES = {
    "participating_media/test_homo_area_light_volpath.xml": 512,
    "participating_media/test_homo_dielectric_envmap_volpath.xml": 512,
    "participating_media/test_homo_emitter_inside_medium_volpath.xml": 512,
    "participating_media/test_homo_null_envmap_volpath.xml": 512,
    "participating_media/test_homo_obj_inside_medium_volpath.xml": 512,
    "participating_media/test_homo_roughdielectric_spot_volpath.xml": 512,
    "participating_media/test_surf_area_light_volpath.xml": 512,
    "participating_media/test_hetero_sigmat_albedo_volpath.xml": 512,
    "participating_media/test_hetero_sigmat_volpath.xml": 512,
}

#: participating_media scene -> what drpt lacks to render it (strict xfail; none)
MEDIA_NOT_YET: dict[str, str] = {}


def corpus_scene(rel: str) -> Path:
    """The corpus scene ``rel`` (relative to ``tests/scenes``); skips when absent."""
    p = CORPUS / rel
    if not p.is_file():
        pytest.skip(f"../shared/corpus/mitsuba-data is not present ({rel})")
    return p


def reference_files(scene: Path) -> tuple[Path, Path]:
    """``(ref, ref_var)`` for a ``test_<name>_<integrator>.xml`` (Mitsuba's naming rule)."""
    stem = scene.stem.rsplit("_", 1)[0]
    ref = scene.parent / "refs" / f"{stem}_ref_rgb.exr"
    return ref, ref.with_name(f"{stem}_ref_rgb_var.exr")


def _read(path: Path) -> np.ndarray:
    from drpt.imageio import read_image

    img = np.asarray(read_image(path), np.float64)
    if img.ndim == 2:
        img = img[..., None]
    return img[..., :3]


def cases(scenes: dict[str, int], not_yet: dict[str, str], not_yet_spp: int) -> list:
    """pytest params ``(rel, spp)``: every scene of ``scenes`` at its spp, then every scene of
    ``not_yet`` as a strict xfail whose reason is what drpt lacks."""
    out = [pytest.param(rel, spp, id=rel) for rel, spp in scenes.items()]
    out += [pytest.param(rel, not_yet_spp, id=rel, marks=pytest.mark.xfail(strict=True, reason=why))
            for rel, why in not_yet.items()]
    return out


def render_as_authored(scene_path: Path, spp: int, seed: int = 0, *, sampler: str | None = None,
                       **defines):
    """drpt's render of the corpus file at ``spp`` (RenderResult), the file's own settings
    (``sampler``: another sampler than the file's)."""
    from drpt.options import RenderOptions, with_scene_settings
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene

    scene = load_scene(scene_path, defines={"spp": str(spp), **defines})
    opts = replace(with_scene_settings(RenderOptions(progress=False, seed=seed), scene)[0], spp=spp,
                   variance=True)  # (light tracing's too: the tests read it)
    if sampler is not None:
        opts = replace(opts, sampler=sampler)
    return Renderer(scene, opts).render()


def check_scene(rel: str, spp: int, seed: int = 0, *, sampler: str | None = None, **defines) -> ZTest:
    """Render corpus scene ``rel`` as authored (with ``sampler`` if given) and z-test it
    against its reference."""
    path = corpus_scene(rel)
    ref, var = reference_files(path)
    result = render_as_authored(path, spp, seed, sampler=sampler, **defines)
    return z_test(result.image, spp, _read(ref), _read(var))


def perturbed(tmp_path: Path, rel: str, old: str, new: str) -> Path:
    """A copy of corpus scene ``rel`` in ``tmp_path`` with ``old`` replaced by ``new`` (once),
    its ``<path>`` and ``<include>`` made absolute so that it reads the same files (for the
    negative controls: the copy with ``new = old`` must pass, the perturbed one fail)."""
    src = corpus_scene(rel)
    text = src.read_text()
    assert text.count(old) == 1, old
    text = text.replace(old, new)
    text = re.sub(r'<path value="([^"]+)"', lambda m: f'<path value="{(src.parent / m.group(1)).resolve()}"', text)
    text = re.sub(r'<include filename="([^"]+)"',
                  lambda m: f'<include filename="{(src.parent / m.group(1)).resolve()}"', text)
    tmp_path.mkdir(parents=True, exist_ok=True)
    out = tmp_path / src.name
    out.write_text(text)
    return out
