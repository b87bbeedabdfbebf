"""The far floor scene against the same scene at the origin: the bias of hits far from the origin.

    PYTHONPATH=.:tests .venv/bin/python benchmarks/far_light_paths.py [--seeds N] [--integrators a,b]
        [--spawned-hits] [--spawned-camera] [--no-visibility]

Renders :func:`support.mis.floor_scene` (a floor lit by a small light 1/64 above it) at
``z = 0`` and at :data:`support.mis.FAR` (4096) with the same seeds (32x32, 16 spp,
``max_depth`` 2, independent sampler; default 8 seeds, ``ptracer,bdpt,path``) and prints, per
integrator, the mean of the paired relative differences far / origin - 1 and its t (mean over
standard error). ``--spawned-hits``: light subpaths take the hits of their rays from the
spawned origins (``DeviceScene.intersect`` in ``intersect_from``'s place);
``--spawned-camera``: connections to the camera traced from the vertex moved off its surface
to the camera (:func:`support.mis.spawned_segment` in ``camera_segment``'s place);
``--no-visibility``: no shadow ray is blocked (a diagnostic: what remains without the
visibility tests). Load-free: the numbers depend on the seeds only.
"""

from __future__ import annotations

import argparse

import drjit as dr
import numpy as np
from drjit.auto import Bool

import drpt.render.integrators.bdpt as bdpt
import drpt.render.integrators.ptracer as ptracer
from drpt.render.scene import DeviceScene
from support.mis import FAR, floor_means, spawned_segment


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--integrators", default="ptracer,bdpt,path")
    ap.add_argument("--spawned-hits", action="store_true")
    ap.add_argument("--spawned-camera", action="store_true")
    ap.add_argument("--no-visibility", action="store_true")
    args = ap.parse_args()
    if args.spawned_hits:
        DeviceScene.intersect_from = lambda self, o, p, d, active: self.intersect(o, d, active)
    if args.spawned_camera:
        ptracer.camera_segment = bdpt.camera_segment = spawned_segment
    if args.no_visibility:
        DeviceScene.occluded = lambda self, o, d, tmax, active, coherent=False: dr.zeros(Bool, dr.width(active))
    for integrator in args.integrators.split(","):
        d = floor_means(FAR, integrator, args.seeds) / floor_means(0.0, integrator, args.seeds) - 1
        t = d.mean() / (d.std(ddof=1) / np.sqrt(len(d)))
        print(f"{integrator:8s} far / origin - 1: {100 * d.mean():+.3f}%  t {t:+.1f}  ({args.seeds} seeds)", flush=True)


if __name__ == "__main__":
    main()
