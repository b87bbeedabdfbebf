"""Scenes far from the unit scale: geometry up to drpt's coordinate limit
(``MAX_COORDINATE``, 1e12) renders like the same scene at scale 1.

The Cornell box (its OBJ and a sphere, lit by its area light) is scaled
uniformly about the origin with its camera; area lights are scale-free, so
the image is the same. The same seed draws the same samples, so the images
agree far better than the noise; the threshold is 1% of the mean. Negative
control: the scene at scale 1 with its light 2% brighter is told apart by
the same threshold.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from drpt.options import RenderOptions
from drpt.render.renderer import Renderer
from drpt.scene import load_scene
from support import SCENES

BOX = SCENES / "cornellbox"
THRESHOLD = 0.01


def _scene(root: Path, s: float, mtl: str | None = None) -> Path:
    for f in ("cornellbox.obj", "cornellbox.mtl"):
        shutil.copy(BOX / f, root / f)
    if mtl is not None:
        (root / "cornellbox.mtl").write_text(mtl)
    p = root / f"box_{s:g}.txt"
    p.write_text(f"PerspectiveCamera {{ center {2.78 * s!r} {2.73 * s!r} {-8.0 * s!r} direction 0 0 1 "
                 "up 0 1 0 angle 39.3 }\n"
                 "Group { numObjects 2\n"
                 f"  Transform {{ UniformScale {s!r} TriangleMesh {{ obj_file cornellbox.obj }} }}\n"
                 f"  Transform {{ UniformScale {s!r} Sphere {{ center 1.8 0.8 2.5 radius 0.8 }} }}\n}}\n")
    return p


def _mean(path: Path) -> float:
    opts = RenderOptions(width=16, height=16, spp=4, progress=False)
    return float(Renderer(load_scene(path), opts).render().image.mean())


@pytest.mark.parametrize("scale", [1e6, 1e9, 1e11, 1.2e11])  # 1.2e11: the camera at 9.6e11, near the limit
def test_far_scales_render_like_scale_one(tmp_path, scale):
    ref = _mean(_scene(tmp_path, 1.0))
    far = _mean(_scene(tmp_path, scale))
    assert ref > 0.05
    assert abs(far - ref) < THRESHOLD * ref, (scale, far, ref)


def test_negative_control_a_brighter_light_is_told_apart(tmp_path):
    ref = _mean(_scene(tmp_path, 1.0))
    mtl = (BOX / "cornellbox.mtl").read_text()
    lines = mtl.splitlines()
    # the light's emission (Ke) 2% brighter
    brighter = "\n".join(" ".join(["Ke"] + [f"{float(x) * 1.02!r}" for x in ln.split()[1:]])
                         if ln.strip().startswith("Ke") else ln for ln in lines)
    assert brighter != mtl
    other = tmp_path / "bright"
    other.mkdir()
    assert abs(_mean(_scene(other, 1.0, brighter)) - ref) > THRESHOLD * ref
