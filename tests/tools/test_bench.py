"""``drpt bench``: drpt vs Mitsuba 3 ray and render throughput, tables, CSV and chart."""

from __future__ import annotations

import argparse
import csv
import math

import pytest

from drpt.errors import DrptError
from drpt.tools import bench

NUMBERS = ["build_s", "accel_mib", "primary_mrays", "incoherent_mrays", "shadow_mrays",
           "render_s", "msamples_s", "mi_load_s", "mi_primary_mrays", "mi_incoherent_mrays",
           "mi_shadow_mrays", "mi_render_s", "mi_msamples_s"]


def _parse(argv):
    parser = argparse.ArgumentParser(prog="drpt")
    bench.add_parser(parser.add_subparsers(dest="command", required=True))
    return parser.parse_args(["bench", *argv])


@pytest.fixture(scope="module")
def run(tmp_path_factory, cornell):
    out = tmp_path_factory.mktemp("bench")
    args = _parse([str(cornell), "--size", "16", "16", "--spp", "2", "--rays", "4096",
                   "--accel", "bvh,grid", "--out", str(out)])
    assert args.func is bench.main
    rc = args.func(args)
    with open(out / "bench.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    return rc, out, rows


def test_defaults():
    args = _parse([])
    assert args.scenes == [] and args.accel == "auto,bvh,grid" and args.out == "bench"
    assert not args.no_mitsuba and args.bsdf is None
    assert all(p.is_file() for p in bench.DEFAULT_SCENES)


@pytest.mark.slow
@pytest.mark.mitsuba
def test_writes_files(run):
    rc, out, rows = run
    assert rc == 0
    for name in ("bench.md", "bench.csv", "bench.png"):
        assert (out / name).stat().st_size > 0
    assert "| cornellbox | bvh |" in (out / "bench.md").read_text()


@pytest.mark.slow
@pytest.mark.mitsuba
def test_csv_rows_positive_and_ratios_finite(run):
    _, _, rows = run
    assert [(r["scene"], r["accel"]) for r in rows] == [("cornellbox", "bvh"),
                                                        ("cornellbox", "grid")]
    for r in rows:
        for k in NUMBERS:
            assert float(r[k]) > 0, (k, r[k])
        for k, _ in bench.RATIOS:
            v = float(r[k])
            assert math.isfinite(v) and v > 0, (k, r[k])


def test_no_mitsuba(tmp_path, cornell):
    args = _parse([str(cornell), "--size", "8", "8", "--spp", "1", "--rays", "1024",
                   "--accel", "bvh", "--repeat", "1", "--no-mitsuba", "--out", str(tmp_path)])
    assert args.func(args) == 0
    with open(tmp_path / "bench.csv", newline="") as f:
        (row,) = list(csv.DictReader(f))
    assert float(row["primary_mrays"]) > 0 and row["ratio_render"] == ""
    assert (tmp_path / "bench.png").exists()


def test_bvh_variants_as_accelerators(tmp_path, monkeypatch, cornell):
    import drpt.render.renderer as renderer

    seen = []
    real = renderer.Renderer.__init__

    def spy(self, scene, options):
        seen.append((options.accel, options.bvh_method, options.sah_threshold,
                     options.bvh_min_leaf))
        real(self, scene, options)

    monkeypatch.setattr(renderer.Renderer, "__init__", spy)
    args = _parse([str(cornell), "--size", "8", "8", "--spp", "1", "--rays", "1024",
                   "--accel", "bvh-median,bvh-threshold,bvh-sah,bvh", "--sah-threshold", "3",
                   "--min-leaf", "2", "--repeat", "1", "--no-mitsuba", "--out", str(tmp_path)])
    assert args.func(args) == 0
    with open(tmp_path / "bench.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [r["accel"] for r in rows] == ["bvh-median", "bvh-threshold", "bvh-sah", "bvh"]
    assert all(float(r["primary_mrays"]) > 0 for r in rows)
    assert seen == [("bvh", "median", None, 2), ("bvh", "threshold", 3, 2), ("bvh", "sah", None, 2),
                    ("bvh", "auto", None, 2)]
    assert "bvh-threshold K = 3" in (tmp_path / "bench.md").read_text()


def test_missing_scene(tmp_path):
    args = _parse([str(tmp_path / "nope.txt"), "--out", str(tmp_path / "o")])
    with pytest.raises(DrptError, match="not found"):
        args.func(args)
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("argv", [["--accel", "kd"], ["--accel", ","], ["--spp", "0"],
                                  ["--rays", "-1"], ["--max-depth", "0"],
                                  ["--accel", "bvh-octree"], ["--sah-threshold", "-1"],
                                  ["--min-leaf", "0"]])
def test_bad_options(tmp_path, argv, cornell):
    args = _parse([str(cornell), *argv, "--out", str(tmp_path / "o")])
    with pytest.raises(DrptError):
        args.func(args)


def test_chart_uses_a_log_axis():
    """A build ratio of ~400 next to ratios near 1 flattened every other bar on a linear
    axis: the chart's axis is logarithmic, and every bar keeps a visible height."""
    import matplotlib.pyplot as plt
    import numpy as np

    from drpt.tools.bench import RATIOS, chart

    rows = [dict({k: v for (k, _), v in zip(RATIOS, (400.0, 1.1, 1.6, 1.4, 2.0))},
                 scene="cornellbox", accel="inline")]
    fig = chart(rows, mitsuba=True)
    try:
        ax = fig.axes[0]
        assert ax.get_yscale() == "log"
        lo, hi = ax.get_ylim()
        heights = [p.get_height() for p in ax.patches]
        # on the log axis the smallest bar spans a fair part of the axis
        assert min(np.log(h / lo) for h in heights) / np.log(hi / lo) > 0.05
    finally:
        plt.close(fig)


def test_other_scenes_are_read_as_every_command_reads_them(tmp_path, monkeypatch, scenes_dir):
    """bench read any scene but newscene as Phong; render, compare and profile read `auto`.
    The bundled scenes keep the readings of the published numbers."""
    import shutil

    seen = {}

    class Stop(Exception):
        pass

    def spy(scene, options, rays, repeat):
        seen[scene.path.name] = options.bsdf
        raise Stop

    monkeypatch.setattr(bench, "bench_drpt", spy)
    for f in ("cornellbox.txt", "cornellbox.obj", "cornellbox.mtl"):
        shutil.copy(scenes_dir / "cornellbox" / f, tmp_path / f)
    (tmp_path / "cornellbox.txt").rename(tmp_path / "box.txt")
    for scene in (tmp_path / "box.txt", scenes_dir / "cornellbox" / "cornellbox.txt",
                  scenes_dir / "newscene" / "newscene.txt"):
        args = _parse([str(scene), "--no-mitsuba", "--accel", "bvh", "--rays", "64",
                       "--out", str(tmp_path / "b")])
        with pytest.raises(Stop):
            bench.main(args)
    assert seen == {"box.txt": "auto", "cornellbox.txt": "phong", "newscene.txt": "cook-torrance"}
