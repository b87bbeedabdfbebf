"""Light tracing and bdpt on every bundled scene (scenes/*/*.txt).

Each bundled scene either renders with ``--integrator bdpt`` and ``ptracer`` in agreement
with the path tracer, or is refused before rendering with one line that names what the
integrator cannot render (a :class:`~drpt.errors.DrptError`): no bundled scene renders a
wrong image with them.

Agreement: 8x8-block z-tests (``drpt.testing.block_z``) of bdpt (96 spp) and ptracer (256 spp)
against the path tracer (512 spp), 24x24, ``max_depth`` 5, independent samples, each with
drpt's per-pixel variance estimate; thresholds |z| < 4.5 over every block and channel and the
z of the image means < 4 (as test_bdpt.py's). The Cornell box has its own tests at higher spp
(test_bdpt.py, test_ptracer.py); the scenes with media render them as ``path`` does (without:
a warning says so), which this compares. Light tracing cannot sample paths whose camera vertex
sees a smooth specular surface (as Mitsuba's ``ptracer``), nor in practice one of roughness
0.001: a scene whose camera sees one is compared with bdpt only (``NO_PTRACER``). Negative
controls: bdpt without the cosine at its light vertices, or with a wrong density in next-event
estimation's MIS weight, fails the same test (|z| > 6).
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from drpt.errors import DrptError
from drpt.options import PathOptions, RenderOptions
from drpt.render.renderer import Renderer
from drpt.scene import load_scene
from drpt.testing import agreement
from support import bdpt_bugs

REPO = Path(__file__).resolve().parents[3]
BUNDLED = sorted(p.relative_to(REPO / "scenes").as_posix() for p in (REPO / "scenes").glob("*/*.txt"))
#: scenes whose camera sees a smooth dielectric (the glass sphere of the media box) or glass of
#: roughness 0.001 (the dining room's table and glasses, the showcase car's windows: a lobe so
#: narrow that light tracing reaches the camera through it only by its peak, a tail no
#: affordable spp resolves; ptracer's image lacks 28% of showcase_dusk's light at 2048 spp,
#: as Mitsuba's ptracer would): bdpt only
NO_PTRACER = {"cornellbox_media/cornellbox_media.txt", "diningroom/diningroom.txt",
              "showcase/showcase_day.txt", "showcase/showcase_dusk.txt"}
DEPTH, SIZE = 5, 24


def _load(name):
    with warnings.catch_warnings():  # media ignored by path, ptracer and bdpt (a warning)
        warnings.simplefilter("ignore")
        return load_scene(REPO / "scenes" / name)


def _render(scene, integrator, spp, seed=1):
    opts = RenderOptions(width=SIZE, height=SIZE, spp=spp, seed=seed, integrator=integrator, progress=False,
                         path=PathOptions(max_depth=DEPTH), variance=True, sampler="independent")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return Renderer(scene, opts).render()


def _agree(a, b):
    return agreement(a, b, floor=1e-5)  # (constant background pixels: float rounding alone)


def _refusal(scene, integrator):
    """The error bdpt/ptracer raise for the scene before rendering, or None."""
    try:
        _render(scene, integrator, 1)
    except DrptError as e:
        return str(e)
    return None


@pytest.fixture(scope="module")
def path_images():
    return {}


def _path_image(path_images, name, scene):
    if name not in path_images:
        path_images[name] = _render(scene, "path", 512, seed=7)
    return path_images[name]


@pytest.mark.slow
@pytest.mark.parametrize("integrator", ["bdpt", "ptracer"])
@pytest.mark.parametrize("name", [n for n in BUNDLED if n != "cornellbox/cornellbox.txt"])
def test_bundled_scene_agrees_with_path_tracing_or_is_refused(path_images, name, integrator):
    if not (REPO / "scenes" / name).exists():
        pytest.skip(f"{name} is built by its make script")
    scene = _load(name)
    refused = _refusal(scene, integrator)
    if refused is not None:
        assert "\n" not in refused and "does not support" in refused, refused
        return
    if integrator == "ptracer" and name in NO_PTRACER:
        return
    r = _render(scene, integrator, 96 if integrator == "bdpt" else 256)
    assert r.nonfinite == 0 and np.all(np.isfinite(r.image)) and r.image.mean() > 1e-3
    zb, zm = _agree(r, _path_image(path_images, name, scene))
    assert zb < 4.5 and zm < 4.0, (zb, zm)


def test_every_bundled_scene_is_checked():
    """The list above is every bundled scene in the seed's format (a new one joins it)."""
    assert "newscene/newscene.txt" in BUNDLED and "showcase/showcase_day.txt" in BUNDLED
    assert len(BUNDLED) >= 6, BUNDLED


@pytest.mark.slow
@pytest.mark.parametrize("what", bdpt_bugs.BUGS[:2])
def test_negative_controls_fail(path_images, monkeypatch, what):
    """bdpt with a bug (test_bdpt.py's controls) fails the same test."""
    bdpt_bugs.put(monkeypatch, what)
    name = "newscene/newscene.txt"
    scene = _load(name)
    zb, _ = _agree(_render(scene, "bdpt", 96), _path_image(path_images, name, scene))
    assert zb > 6.0, zb
