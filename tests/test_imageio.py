"""drpt.imageio: writing and reading images by extension."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from drpt.errors import DrptError, SceneError
from drpt.imageio import linear_to_srgb, read_image, srgb_to_linear, write_image

SHARED = Path(__file__).resolve().parents[2] / "shared"
ENV_HDR = SHARED / "seed" / "scenes" / "environment.hdr"


def _img(h=5, w=7, scale=4.0, seed=0) -> np.ndarray:
    return (np.random.default_rng(seed).random((h, w, 3)) * scale).astype(np.float32)


def test_exr_round_trip_exact(tmp_path):
    a = _img()
    a[0, 0] = [0.0, 1e-30, 65504.0 * 4]
    write_image(tmp_path / "a.exr", a)
    b = read_image(tmp_path / "a.exr")
    assert b.dtype == np.float32 and b.shape == a.shape
    assert np.array_equal(a, b)


@pytest.mark.parametrize("ext", [".png", ".tga"])
def test_ldr_round_trip(tmp_path, ext):
    a = _img(scale=1.2)  # some values above 1 get clamped
    gamma = 2.2
    p = tmp_path / f"a{ext}"
    write_image(p, a, gamma=gamma)
    with Image.open(p) as im:
        assert im.mode == "RGB" and im.size == (a.shape[1], a.shape[0])
        u8 = np.asarray(im)
    expected = np.round(np.clip(a, 0, 1) ** (1 / gamma) * 255)
    assert np.array_equal(u8, expected.astype(np.uint8))
    enc = read_image(p, linear=False)
    assert np.abs(enc - np.clip(a, 0, 1) ** (1 / gamma)).max() <= 0.5 / 255 + 1e-6
    # gamma round trip: encoded ** gamma recovers the clamped linear value
    # within the 8-bit quantization step propagated through the curve
    lin = enc ** gamma
    assert np.abs(lin - np.clip(a, 0, 1)).max() < 0.02


def test_ldr_read_decodes_srgb(tmp_path):
    u8 = np.array([[[0, 10, 128], [200, 255, 64]]], np.uint8)
    p = tmp_path / "s.png"
    Image.fromarray(u8, "RGB").save(p)
    lin = read_image(p)  # linear=True is the default
    x = u8 / 255.0
    ref = np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)
    np.testing.assert_allclose(lin, ref, rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(read_image(p, linear=False), x, rtol=1e-6)
    np.testing.assert_allclose(linear_to_srgb(srgb_to_linear(x)), x, atol=1e-6)


def test_ldr_gray_and_alpha(tmp_path):
    g = np.arange(12, dtype=np.uint8).reshape(3, 4) * 20
    Image.fromarray(g, "L").save(tmp_path / "g.png")
    a = read_image(tmp_path / "g.png", linear=False)
    assert a.shape == (3, 4, 1)
    np.testing.assert_allclose(a[..., 0], g / 255.0, rtol=1e-6)
    rgba = np.zeros((2, 2, 4), np.uint8)
    rgba[..., 3] = 128
    rgba[..., 0] = 128
    Image.fromarray(rgba, "RGBA").save(tmp_path / "a.png")
    b = read_image(tmp_path / "a.png")
    assert b.shape == (2, 2, 4)
    np.testing.assert_allclose(b[..., 3], 128 / 255.0, rtol=1e-6)  # alpha stays linear
    np.testing.assert_allclose(b[..., 0], srgb_to_linear(np.float32(128 / 255.0)), rtol=1e-6)


def test_jpeg_read(tmp_path):
    u8 = np.full((8, 8, 3), 200, np.uint8)
    Image.fromarray(u8).save(tmp_path / "a.jpg", quality=100)
    a = read_image(tmp_path / "a.jpg", linear=False)
    assert a.shape == (8, 8, 3)
    assert np.abs(a - 200 / 255).max() < 3 / 255


def test_hdr_and_pfm_round_trip(tmp_path):
    a = _img(scale=100.0)
    a[1, 2] = 0.0
    write_image(tmp_path / "a.pfm", a)
    assert np.array_equal(read_image(tmp_path / "a.pfm"), a)
    write_image(tmp_path / "a.hdr", a)
    b = read_image(tmp_path / "a.hdr")
    assert b.shape == a.shape
    # RGBE keeps 8 mantissa bits relative to the largest channel
    assert np.all(np.abs(b - a) <= a.max(axis=2, keepdims=True) / 128)
    assert np.all(b[1, 2] == 0)


def _rle_hdr(path: Path, rgbe: np.ndarray) -> None:
    """Encode RGBE pixels with new-style (adaptive) RLE scanlines."""
    h, w = rgbe.shape[:2]
    out = bytearray(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n" + f"-Y {h} +X {w}\n".encode())
    for y in range(h):
        out += bytes([2, 2, w >> 8, w & 255])
        for c in range(4):
            row = rgbe[y, :, c]
            x = 0
            while x < w:
                run = 1
                while x + run < w and run < 127 and row[x + run] == row[x]:
                    run += 1
                if run >= 3:
                    out += bytes([128 + run, row[x]])
                    x += run
                else:
                    n = 1
                    while x + n < w and n < 128 and not (
                        x + n + 2 < w and row[x + n] == row[x + n + 1] == row[x + n + 2]
                    ):
                        n += 1
                    out += bytes([n]) + bytes(row[x:x + n])
                    x += n
    path.write_bytes(bytes(out))


def test_hdr_rle_decode(tmp_path):
    rng = np.random.default_rng(3)
    h, w = 6, 300  # > 255 wide: two-byte width in the scanline header
    rgbe = rng.integers(128, 256, (h, w, 4)).astype(np.uint8)
    rgbe[..., 3] = rng.integers(120, 140, (h, w))
    rgbe[:, 40:200] = [200, 100, 150, 130]  # long runs
    rgbe[2, :, 3] = 0  # a black scanline
    _rle_hdr(tmp_path / "r.hdr", rgbe)
    img = read_image(tmp_path / "r.hdr")
    e = rgbe[..., 3].astype(np.int32)
    ref = np.where((e > 0)[..., None], rgbe[..., :3] * np.ldexp(1.0, e - 136)[..., None], 0.0)
    np.testing.assert_array_equal(img, ref.astype(np.float32))


def test_hdr_old_style_rle(tmp_path):
    w = 5
    px = [[200, 100, 50, 130], [1, 1, 1, 3], [10, 20, 30, 128]]  # repeat 3 times
    data = (b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n" + f"-Y 1 +X {w}\n".encode()
            + bytes(sum(px, [])))
    (tmp_path / "o.hdr").write_bytes(data)
    img = read_image(tmp_path / "o.hdr")
    assert img.shape == (1, w, 3)
    np.testing.assert_array_equal(img[0, :4], np.broadcast_to(img[0, 0], (4, 3)))
    assert img[0, 0, 0] == 200 * 2.0 ** -6


@pytest.mark.mitsuba
def test_seed_environment_hdr():
    if not ENV_HDR.is_file():
        pytest.skip("shared/seed/scenes/environment.hdr is not present")
    img = read_image(ENV_HDR)
    assert img.shape == (512, 1024, 3) and img.dtype == np.float32
    assert np.isfinite(img).all() and img.min() >= 0 and img.max() > 1
    try:
        import mitsuba as mi

        from drpt.backend import mitsuba_variant
        mi.set_variant(mitsuba_variant())
    except Exception:
        return
    assert np.array_equal(img, np.array(mi.Bitmap(str(ENV_HDR))))  # same decoding as Mitsuba


def test_write_errors(tmp_path):
    with pytest.raises(DrptError, match=r"\.exr.*\.png"):
        write_image(tmp_path / "a.bmp", _img())
    bad = _img()
    bad[1, 1, 1] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        write_image(tmp_path / "a.png", bad)
    bad[1, 1, 1] = np.inf
    with pytest.raises(ValueError):
        write_image(tmp_path / "a.exr", bad)
    assert not (tmp_path / "a.png").exists() and not (tmp_path / "a.exr").exists()
    with pytest.raises(ValueError, match="shape"):
        write_image(tmp_path / "a.png", np.zeros((4, 4)))
    for ext in (".exr", ".png", ".hdr"):
        with pytest.raises(DrptError):
            write_image(tmp_path / "missing_dir" / f"a{ext}", _img())


def test_read_errors(tmp_path):
    with pytest.raises(SceneError, match="not found") as ei:
        read_image(tmp_path / "nope.png")
    assert ei.value.path == str(tmp_path / "nope.png") and ei.value.line is None
    with pytest.raises(SceneError, match="extension"):
        read_image(tmp_path / "a.gif")
    for name in ("bad.exr", "bad.png", "bad.hdr", "bad.pfm", "bad.jpg"):
        (tmp_path / name).write_bytes(b"not an image at all")
        with pytest.raises(SceneError) as ei:
            read_image(tmp_path / name)
        assert str(ei.value).startswith(str(tmp_path / name) + ": ") and "\n" not in str(ei.value)
    # truncated RLE .hdr
    _rle_hdr(tmp_path / "t.hdr", np.full((4, 20, 4), 130, np.uint8))
    data = (tmp_path / "t.hdr").read_bytes()
    (tmp_path / "t.hdr").write_bytes(data[: len(data) - 10])
    with pytest.raises(SceneError, match="hdr"):
        read_image(tmp_path / "t.hdr")


def test_hdr_pfm_refusals(tmp_path):
    rgbe = bytes([128, 0, 0, 129, 0, 128, 0, 129])
    head = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n"
    (tmp_path / "up.hdr").write_bytes(head + b"+Y 2 +X 1\n" + rgbe)
    with pytest.raises(SceneError, match=r"up\.hdr: unsupported .hdr resolution line '\+Y 2"):
        read_image(tmp_path / "up.hdr")
    (tmp_path / "ok.hdr").write_bytes(head + b"-Y 2 +X 1\n" + rgbe)
    np.testing.assert_array_equal(read_image(tmp_path / "ok.hdr")[:, 0], [[1, 0, 0], [0, 1, 0]])
    (tmp_path / "xyz.hdr").write_bytes(head.replace(b"rgbe", b"xyze") + b"-Y 2 +X 1\n" + rgbe)
    with pytest.raises(SceneError, match="XYZ"):
        read_image(tmp_path / "xyz.hdr")
    (tmp_path / "huge.hdr").write_bytes(head + b"-Y 1000000 +X 1000000\n" + rgbe)
    with pytest.raises(SceneError, match="huge.hdr: .*memory"):
        read_image(tmp_path / "huge.hdr")
    # content must match the extension: a PNG named .pfm is refused
    Image.fromarray(np.zeros((2, 2, 3), np.uint8)).save(tmp_path / "p.png")
    (tmp_path / "p.pfm").write_bytes((tmp_path / "p.png").read_bytes())
    with pytest.raises(SceneError, match="not a .pfm file"):
        read_image(tmp_path / "p.pfm")


@pytest.mark.mitsuba
def test_float_formats_leave_mitsuba_variant(tmp_path):
    import mitsuba as mi

    before = mi.variant()
    write_image(tmp_path / "a.hdr", _img())
    read_image(tmp_path / "a.hdr")
    assert mi.variant() == before
