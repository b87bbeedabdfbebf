"""Distributed render benchmark (not a test): ``--workers N`` against a plain
render, and the per-chunk overhead against the chunk size.

For each chunk size (``--chunk-spp``) the same render runs in this process
(chunk after chunk) and on a local Dask cluster of ``--workers`` processes
(one thread each, started once and kept warm: its first render compiles the
kernels and is not counted). The per-chunk overhead is the worker time a
chunk costs beyond its share of the plain render:
``(workers * distributed seconds - plain seconds) / chunks``: scheduling, the
transfer of the 48-byte-per-pixel sums, the merge, and idle workers at the end.

Run: python benchmarks/cluster_render.py [--scene S] [--size W H] [--spp N] [--workers N]
     [--chunks 1,4,16,64]
"""

from __future__ import annotations

import argparse
import logging
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--scene", default=str(REPO / "scenes/cornellbox/cornellbox.txt"))
    p.add_argument("--size", nargs=2, type=int, default=(128, 128))
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--chunks", default="1,4,16,64", help="chunk sizes (samples per pixel)")
    a = p.parse_args()

    from distributed import Client, LocalCluster

    from drpt.distributed.job import run
    from drpt.options import RenderOptions
    from drpt.scene import load_scene

    scene = load_scene(a.scene)
    base = RenderOptions(width=a.size[0], height=a.size[1], spp=a.spp, progress=False)
    out = Path("/tmp/drpt-bench-distributed.exr")
    t0 = time.perf_counter()
    cluster = LocalCluster(n_workers=a.workers, threads_per_worker=1, processes=True,
                           dashboard_address=None, silence_logs=logging.ERROR)
    client = Client(cluster)
    import os

    from drpt.distributed.engine import _share_cores

    client.run(_share_cores, max(1, (os.cpu_count() or 1) // a.workers))
    print(f"local cluster of {a.workers} workers started in {time.perf_counter() - t0:.1f} s")
    warm = replace(base, chunk_spp=max(1, a.spp // 8))
    run(scene, warm, out, cluster=cluster.scheduler_address)  # workers compile the kernels
    run(scene, warm, out)  # and this process
    print(f"{Path(a.scene).name}, {a.size[0]}x{a.size[1]}, {a.spp} spp")
    print(f"{'chunk spp':>9} {'chunks':>6} {'plain s':>8} {'workers s':>9} {'speed-up':>8} "
          f"{'overhead/chunk':>14} {'same image':>10}")
    for c in (int(x) for x in a.chunks.split(",")):
        opts = replace(base, chunk_spp=c)
        t = time.perf_counter()
        plain = run(scene, opts, out).result.image
        tp = time.perf_counter() - t
        t = time.perf_counter()
        dist = run(scene, opts, out, cluster=cluster.scheduler_address)
        td = time.perf_counter() - t
        n = sum(s.chunks for s in dist.workers.values())
        over = (a.workers * td - tp) / n
        print(f"{c:>9} {n:>6} {tp:>8.2f} {td:>9.2f} {tp / td:>7.2f}x {over * 1e3:>11.1f} ms "
              f"{str(np.array_equal(plain, dist.result.image)):>10}")
    client.close()
    cluster.close()


if __name__ == "__main__":
    main()
