"""``drpt compare``: two images, and a scene against a cached Mitsuba reference."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pytest

from drpt import metrics
from drpt.errors import DrptError
from drpt.imageio import read_image, write_image
from drpt.tools.compare import add_parser, main

CORNELL = Path(__file__).resolve().parents[1] / "scenes" / "cornellbox" / "cornellbox.txt"


def run(*argv: str) -> int:
    parser = argparse.ArgumentParser(prog="drpt")
    sub = parser.add_subparsers(dest="command", required=True)
    add_parser(sub)
    args = parser.parse_args(["compare", *map(str, argv)])
    assert args.func is main
    return args.func(args)


def _images(tmp_path, shape=(6, 5, 3)):
    rng = np.random.default_rng(7)
    a = rng.random(shape).astype(np.float32)
    b = (a + 0.1 * rng.random(shape)).astype(np.float32)
    pa, pb = tmp_path / "a.exr", tmp_path / "b.exr"
    write_image(pa, a)
    write_image(pb, b)
    return a, b, pa, pb


def test_two_images_writes_json_and_png(tmp_path, capsys):
    a, b, pa, pb = _images(tmp_path)
    out = tmp_path / "cmp"
    assert run(pa, pb, "--out", out) == 0
    data = json.loads((out / "metrics.json").read_text())
    m = data["metrics"]
    assert data["mode"] == "images" and (data["width"], data["height"]) == (5, 6)
    assert m["rel_mse"] == pytest.approx(metrics.rel_mse(a, b), rel=1e-9)
    assert m["mae"] == pytest.approx(metrics.mae(a, b), rel=1e-9)
    assert m["smape"] == pytest.approx(metrics.smape(a, b), rel=1e-9)
    assert m["outside_ci"] is None and "no confidence" in data["outside_ci_note"]
    assert (out / "side_by_side.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    from PIL import Image

    with Image.open(out / "side_by_side.png") as im:
        assert im.width > im.height > 0
    text = capsys.readouterr().out
    assert "relMSE" in text and "n/a" in text


def test_identical_images_give_zero_metrics(tmp_path):
    a, _, pa, _ = _images(tmp_path)
    pc = tmp_path / "c.pfm"
    write_image(pc, a)
    out = tmp_path / "same"
    assert run(pa, pc, "--out", out) == 0
    m = json.loads((out / "metrics.json").read_text())["metrics"]
    assert m["rel_mse"] == m["mae"] == m["smape"] == m["max_rel_error"] == 0.0


def test_bad_inputs_raise(tmp_path):
    _, _, pa, pb = _images(tmp_path)
    small = tmp_path / "small.exr"
    write_image(small, np.zeros((3, 3, 3), np.float32))
    with pytest.raises(DrptError, match="not found"):
        run(pa, tmp_path / "missing.exr", "--out", tmp_path / "o")
    with pytest.raises(DrptError, match="sizes differ"):
        run(pa, small, "--out", tmp_path / "o")
    with pytest.raises(DrptError, match="not an image"):
        run(pa, tmp_path / "b.xyz", "--out", tmp_path / "o")
    with pytest.raises(DrptError, match="scene file, or two images"):
        run(pa, "--out", tmp_path / "o")
    with pytest.raises(DrptError, match="3 arguments"):
        run(pa, pb, pb, "--out", tmp_path / "o")
    with pytest.raises(DrptError, match="not found|no such|cannot"):
        run(tmp_path / "nope.txt", "--out", tmp_path / "o", "--cache", tmp_path / "c")
    with pytest.raises(DrptError, match="--ref-spp"):
        run(CORNELL, "--ref-spp", "4", "--out", tmp_path / "o", "--cache", tmp_path / "c")
    with pytest.raises(DrptError, match="--spp"):
        run(CORNELL, "--spp", "0", "--out", tmp_path / "o", "--cache", tmp_path / "c")
    with pytest.raises(DrptError, match="max-depth"):
        run(CORNELL, "--max-depth", "0", "--out", tmp_path / "o", "--cache", tmp_path / "c")
    (tmp_path / "file").write_text("x")
    with pytest.raises(DrptError, match="not a folder"):
        run(pa, pb, "--out", tmp_path / "file")


@pytest.mark.slow
@pytest.mark.mitsuba
def test_scene_against_cached_mitsuba_reference(tmp_path, capsys):
    cache, out = tmp_path / "cache", tmp_path / "out"
    args = [CORNELL, "--size", "24", "24", "--spp", "16", "--ref-spp", "64",
            "--cache", cache, "--out", out, "-q"]
    assert run(*args) == 0
    files = list(cache.glob("*.npz"))
    assert len(files) == 1
    for name in ("drpt.exr", "reference.exr", "side_by_side.png", "metrics.json"):
        assert (out / name).is_file(), name
    first = json.loads((out / "metrics.json").read_text())
    assert first["reference"]["cached"] is False
    assert first["reference"]["spp"] == 64 and first["drpt"]["spp"] == 16
    m = first["metrics"]
    img, ref = read_image(out / "drpt.exr"), read_image(out / "reference.exr")
    assert img.shape == ref.shape == (24, 24, 3)
    assert m["rel_mse"] == pytest.approx(metrics.rel_mse(img, ref), rel=1e-6)
    # drpt agrees with Mitsuba: few values outside the 99.7% interval
    # (above 0.27% mainly because 16-spp variance estimates are heavy tailed)
    assert 0.0 <= m["outside_ci"] < 0.05
    assert m["rel_mse"] < 0.2
    assert "outside 99.7% CI" in capsys.readouterr().out

    stamp = files[0].stat().st_mtime_ns
    # Same reference settings, other drpt spp: the cached reference is reused.
    assert run(*args[:4], "--spp", "8", *args[6:]) == 0
    second = json.loads((out / "metrics.json").read_text())
    assert second["reference"]["cached"] is True
    assert second["reference"]["key"] == first["reference"]["key"]
    assert files[0].stat().st_mtime_ns == stamp
    assert list(cache.glob("*.npz")) == files
    np.testing.assert_array_equal(read_image(out / "reference.exr"), ref)

    # A changed reference setting gives a new key and a new cache entry.
    assert run(*args, "--ref-batches", "4") == 0
    assert len(list(cache.glob("*.npz"))) == 2
