"""Sky importance sampling vs uniform sphere sampling at equal spp.

An env-lit glossy scene (:mod:`drpt.tools.scenegen.envsun`, the one in
tests/validation/test_env_render.py: a gradient sky
with a one-texel sun 2e4x brighter than the sky, a glossy Phong sphere, a
matte sphere, a matte ground) is rendered by drpt with both sky samplers at
the same spp and compared against a 1024-spp luminance-sampled reference.

    .venv/bin/python benchmarks/env_sampling.py [spp]
"""

import sys
import tempfile
from pathlib import Path

import numpy as np

from drpt.options import PathOptions, RenderOptions
from drpt.render.renderer import Renderer
from drpt.scene import load_scene
from drpt.tools.scenegen import envsun


def render(scene, spp, sampling, seed):
    opt = RenderOptions(width=96, height=64, spp=spp, seed=seed, progress=False,
                        env_sampling=sampling, path=PathOptions(max_depth=5))
    r = Renderer(scene, opt).render()
    return r.image, r.seconds


def main(spp=16):
    scene = load_scene(envsun.main(Path(tempfile.mkdtemp())))
    ref, _ = render(scene, 1024, "luminance", 99)
    print("| sky sampling | spp | relMSE | time (s) |\n|---|---|---|---|")
    out = {}
    for sampling in ("luminance", "uniform"):
        img, secs = render(scene, spp, sampling, 1)
        rel = float(np.mean((img - ref) ** 2 / (ref**2 + 1e-2)))
        out[sampling] = rel
        print(f"| {sampling} | {spp} | {rel:.4g} | {secs:.2f} |")
    print(f"\nuniform / luminance relMSE at {spp} spp: {out['uniform'] / out['luminance']:.1f}x")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 16)
