"""``python -m drpt gallery`` at tiny sizes on the Cornell box only."""

import json

import numpy as np
import pytest

from drpt.cli import main
from drpt.imageio import read_image
from drpt.tools.gallery import downsample


def test_downsample_is_block_mean():
    a = np.arange(4 * 6 * 3, dtype=np.float64).reshape(4, 6, 3)
    d = downsample(a, 2)
    assert d.shape == (2, 3, 3)
    assert np.allclose(d[1, 2], a[2:4, 4:6].mean((0, 1)))


@pytest.mark.slow
def test_gallery_cli_with_and_without_reference(tmp_path, capsys):
    out = tmp_path / "g"
    # --scale 1: rendered at the reference's 128x128, so the error column is filled
    assert main(["gallery", "--scenes", "cornellbox", "--scale", "1", "--spp", "4",
                 "--out", str(out), "--quiet"]) == 0
    for f in ("cornellbox.png", "gallery.md", "gallery.html", "gallery.json"):
        assert (out / f).is_file(), f
    assert read_image(out / "cornellbox.png").shape[:2] == (128, 128)
    (row,) = json.loads((out / "gallery.json").read_text())
    assert row["name"] == "cornellbox" and row["spp"] == 4 and row["samples_per_second"] > 0
    ref = row["reference"]
    assert ref["downsample"] == 1 and ref["spp"] == 8192
    # 4 spp: noise dominates; an unbiased render's relMSE is near its noise estimate
    assert 0 < ref["rel_mse"] < 3 * ref["noise_rel_mse"]
    md = (out / "gallery.md").read_text()
    assert "![cornellbox](cornellbox.png)" in md and f"{ref['rel_mse']:.2e}" in md
    assert "cornellbox" in capsys.readouterr().out

    # a size that is not a multiple of the reference's: no error column
    out2 = tmp_path / "g2"
    assert main(["gallery", "--scenes", "cornellbox", "--size", "40", "30", "--spp", "1",
                 "--out", str(out2), "--quiet"]) == 0
    (row,) = json.loads((out2 / "gallery.json").read_text())
    assert row["reference"] is None and (row["width"], row["height"]) == (40, 30)
    assert "no reference at this size" in (out2 / "gallery.md").read_text()


def test_gallery_unknown_scene_is_a_user_error(tmp_path, capsys):
    assert main(["gallery", "--scenes", "nosuchscene", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "nosuchscene" in err and "cornellbox" in err
