"""Diffuse textures (drpt/render/texture.py): texel values at texel centers,
bilinear midpoints, repeat wrapping, the OBJ v-flip (v = 0 is the image's
bottom row), PNG (sRGB-decoded) and EXR inputs, several textures in one set,
clear errors for bad files, and equality with Mitsuba's ``bitmap`` texture
(bilinear, repeat) evaluated at uv = (u, 1 - v) -- what the exporter writes."""

from __future__ import annotations

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Array2f, Float, UInt32

from drpt.errors import SceneError
from drpt.imageio import srgb_to_linear, write_image
from drpt.render.texture import TextureSet, _luminance_texture
from drpt.testing import mitsuba

H, W = 4, 5


def _float_image():
    """Asymmetric linear image: R grows to the right, G grows downward (row 0 = top)."""
    i, j = np.mgrid[0:H, 0:W].astype(np.float32)
    return np.stack([j / (W - 1), i / (H - 1), 0.1 + 0.01 * (i * W + j)], -1).astype(np.float32)


@pytest.fixture
def exr(tmp_path):
    p = tmp_path / "tex.exr"
    img = _float_image()
    write_image(p, img)
    return p, img


@pytest.fixture
def png(tmp_path):
    from PIL import Image

    rng = np.random.default_rng(0)
    u8 = rng.integers(0, 256, size=(H + 1, W + 2, 3), dtype=np.uint8)
    u8[0, 0] = (255, 0, 0)  # top-left red
    u8[-1, 0] = (0, 0, 255)  # bottom-left blue
    p = tmp_path / "tex.png"
    Image.fromarray(u8, "RGB").save(p)
    return p, srgb_to_linear(u8.astype(np.float32) / 255.0)


def _lookup(ts, uv, ids=None, active=True):
    uv = np.asarray(uv, dtype=np.float32)
    n = uv.shape[1]
    ids = np.zeros(n, np.uint32) if ids is None else np.asarray(ids, np.uint32)
    r = ts.lookup(UInt32(ids), Array2f(Float(uv[0]), Float(uv[1])), active)
    return np.broadcast_to(np.array(r), (3, n))


def _center_uv(i, j, h=H, w=W):
    """OBJ uv of the center of texel (row i from the top, column j)."""
    return (j + 0.5) / w, 1.0 - (i + 0.5) / h


def test_texel_centers(exr):
    p, img = exr
    ts = TextureSet([p])
    i, j = np.mgrid[0:H, 0:W]
    u, v = _center_uv(i.ravel(), j.ravel())
    got = _lookup(ts, [u, v])
    np.testing.assert_allclose(got.T, img.reshape(-1, 3), atol=1e-6)


def test_v_flip_orientation(exr, png):
    p, img = exr
    ts = TextureSet([p])
    # v near 1 = top row (G = 0), v near 0 = bottom row (G = 1); u near 0 = left (R = 0)
    got = _lookup(ts, [[0.5 / W, 0.5 / W], [1.0 - 0.5 / H, 0.5 / H]])
    np.testing.assert_allclose(got[:, 0], img[0, 0], atol=1e-6)
    np.testing.assert_allclose(got[:, 1], img[H - 1, 0], atol=1e-6)
    assert got[1, 0] == pytest.approx(0.0, abs=1e-6) and got[1, 1] == pytest.approx(1.0)
    # the PNG's top-left texel is red, its bottom-left texel blue
    pp, lin = png
    ts2 = TextureSet([pp])
    h, w = lin.shape[:2]
    got = _lookup(ts2, [[0.5 / w, 0.5 / w], [1.0 - 0.5 / h, 0.5 / h]])
    np.testing.assert_allclose(got[:, 0], [1.0, 0.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(got[:, 1], [0.0, 0.0, 1.0], atol=1e-6)


def test_bilinear_midpoints(exr):
    p, img = exr
    ts = TextureSet([p])
    # halfway between texel centers (1, 2) and (1, 3): u = 3 / W
    u, v = 3.0 / W, 1.0 - 1.5 / H
    np.testing.assert_allclose(_lookup(ts, [[u], [v]])[:, 0], 0.5 * (img[1, 2] + img[1, 3]),
                               atol=1e-6)
    # halfway between rows 1 and 2 (v = 1 - 2 / H), column 0
    np.testing.assert_allclose(_lookup(ts, [[0.5 / W], [1.0 - 2.0 / H]])[:, 0],
                               0.5 * (img[1, 0] + img[2, 0]), atol=1e-6)
    # the center of four texels: their mean
    np.testing.assert_allclose(_lookup(ts, [[2.0 / W], [1.0 - 2.0 / H]])[:, 0],
                               img[1:3, 1:3].reshape(-1, 3).mean(0), atol=1e-6)
    # a quarter of the way: 3/4 of the nearer texel
    np.testing.assert_allclose(_lookup(ts, [[(2.75) / W], [1.0 - 1.5 / H]])[:, 0],
                               0.75 * img[1, 2] + 0.25 * img[1, 3], atol=1e-6)


def test_repeat_wrap(exr):
    p, img = exr
    ts = TextureSet([p])
    # at u = 0 (the left border) the left and right columns blend 50/50
    v = 1.0 - 0.5 / H
    np.testing.assert_allclose(_lookup(ts, [[0.0], [v]])[:, 0], 0.5 * (img[0, 0] + img[0, -1]),
                               atol=1e-6)
    # at v = 1 (top border) the top and bottom rows blend
    np.testing.assert_allclose(_lookup(ts, [[0.5 / W], [1.0]])[:, 0],
                               0.5 * (img[0, 0] + img[-1, 0]), atol=1e-6)
    # integer shifts of uv change nothing
    rng = np.random.default_rng(1)
    uv = rng.random((2, 500)).astype(np.float32)
    base = _lookup(ts, uv)
    for du, dv in ((1, 0), (-1, 2), (3, -3)):
        np.testing.assert_allclose(_lookup(ts, uv + np.array([[du], [dv]], np.float32)), base,
                                   atol=2e-5)


def test_png_is_srgb_decoded(png):
    p, lin = png
    ts = TextureSet([p])
    h, w = lin.shape[:2]
    i, j = np.mgrid[0:h, 0:w]
    u, v = _center_uv(i.ravel(), j.ravel(), h, w)
    np.testing.assert_allclose(_lookup(ts, [u, v]).T, lin.reshape(-1, 3), atol=2e-6)


def test_alpha_and_gray(tmp_path):
    from PIL import Image

    rgba = np.zeros((2, 2, 4), np.uint8)
    rgba[..., 0] = 255
    rgba[..., 3] = 7
    Image.fromarray(rgba, "RGBA").save(tmp_path / "a.png")
    gray = np.full((2, 2), 128, np.uint8)
    Image.fromarray(gray, "L").save(tmp_path / "g.png")
    ts = TextureSet([tmp_path / "a.png", tmp_path / "g.png"])
    got = _lookup(ts, [[0.3, 0.3], [0.6, 0.6]], ids=[0, 1])
    np.testing.assert_allclose(got[:, 0], [1.0, 0.0, 0.0], atol=1e-6)
    g = float(srgb_to_linear(np.float32(128 / 255)))
    np.testing.assert_allclose(got[:, 1], [g, g, g], atol=1e-6)


def test_several_textures_and_masks(exr, png):
    (pe, img), (pp, lin) = exr, png
    ts = TextureSet([pe, pp])
    assert len(ts) == 2
    u, v = _center_uv(1, 2)
    h, w = lin.shape[:2]
    u2, v2 = _center_uv(2, 3, h, w)
    uv = [[u, u2, u, u], [v, v2, v, v]]
    ids = [0, 1, 7, 0]  # 7: out of range -> 0
    active = dr.llvm.Bool([True, True, True, False])
    got = _lookup(ts, uv, ids, active)
    np.testing.assert_allclose(got[:, 0], img[1, 2], atol=1e-6)
    np.testing.assert_allclose(got[:, 1], lin[2, 3], atol=2e-6)
    np.testing.assert_array_equal(got[:, 2], 0.0)
    np.testing.assert_array_equal(got[:, 3], 0.0)


def test_among_gives_the_full_lookups_values_on_its_ids_and_traces_only_them(exr, png):
    """``lookup(..., among=ids)`` (a material field's textures) gives every lane whose id is
    in ``ids`` what the full lookup gives, to the float, with one id, several and none; a
    lane whose id is not in ``ids`` reads 0 (negative control: it is not 0 in full). It
    traces only those textures' lookups: fewer operations than the full lookup (negative
    control: ``among`` naming every texture traces as many as the full lookup)."""
    (pe, img), (pp, _) = exr, png
    ts = TextureSet([pe, pp, pe])
    uv = [[0.1, 0.3, 0.55, 0.8], [0.2, 0.9, 0.45, 0.6]]
    ids = [1, 1, 0, 2]

    def lookup(among):
        return np.array(ts.lookup(UInt32(ids), Array2f(Float(uv[0]), Float(uv[1])), True, among=among))

    full = _lookup(ts, uv, ids, True)
    assert np.all(full != 0.0)
    u, v = _center_uv(1, 2)
    np.testing.assert_allclose(_lookup(ts, [[u], [v]], [0], True)[:, 0], img[1, 2], atol=1e-6)
    one = lookup((1,))
    np.testing.assert_array_equal(one[:, :2], full[:, :2])
    np.testing.assert_array_equal(one[:, 2:], 0.0)
    two = lookup((0, 1))
    np.testing.assert_array_equal(two[:, :3], full[:, :3])
    np.testing.assert_array_equal(two[:, 3], 0.0)
    np.testing.assert_array_equal(lookup(()), 0.0)
    np.testing.assert_array_equal(lookup((0, 1, 2)), full)

    def ops(among):
        flag = dr.flag(dr.JitFlag.KernelHistory)
        dr.set_flag(dr.JitFlag.KernelHistory, True)
        try:
            dr.kernel_history_clear()
            traced = Array2f(Float(uv[0]), Float(uv[1])) + 0 * dr.arange(Float, 4)  # (not literals)
            dr.eval(ts.lookup(UInt32(ids), traced, True, among=among))
            return sum(k.get("operation_count", 0) for k in dr.kernel_history()
                       if k.get("type") == dr.KernelType.JIT)
        finally:
            dr.set_flag(dr.JitFlag.KernelHistory, flag)

    assert ops((1,)) < ops((0, 1)) < ops(None)
    assert ops((0, 1, 2)) == ops(None)


def test_gradient_among_gives_the_full_gradients_on_its_ids_and_traces_only_them(exr, png):
    """``gradient(..., among=ids)`` (the bump maps' textures) gives every lane whose id is in
    ``ids`` the full gradient, to the float, and 0 elsewhere (negative control: not 0 in
    full), tracing fewer operations than the full gradient (negative control: ``among``
    naming every texture traces as many)."""
    (pe, _), (pp, _) = exr, png
    ts = TextureSet([pe, pp, pe])
    uv = [[0.1, 0.3, 0.55, 0.8], [0.2, 0.9, 0.45, 0.6]]
    ids = [1, 1, 0, 2]

    def grad(among, traced=False):
        st = Array2f(Float(uv[0]), Float(uv[1]))
        if traced:
            st = st + 0 * dr.arange(Float, 4)  # (not literals)
        return ts.gradient(UInt32(ids), st, True, among=among)

    full = np.array(grad(None))
    assert np.all(np.abs(full).sum(axis=0) != 0.0)
    one = np.array(grad((1,)))
    np.testing.assert_array_equal(one[:, :2], full[:, :2])
    np.testing.assert_array_equal(one[:, 2:], 0.0)
    np.testing.assert_array_equal(np.array(grad((0, 1, 2))), full)

    def ops(among):
        flag = dr.flag(dr.JitFlag.KernelHistory)
        dr.set_flag(dr.JitFlag.KernelHistory, True)
        try:
            dr.kernel_history_clear()
            dr.eval(grad(among, traced=True))
            return sum(k.get("operation_count", 0) for k in dr.kernel_history()
                       if k.get("type") == dr.KernelType.JIT)
        finally:
            dr.set_flag(dr.JitFlag.KernelHistory, flag)

    assert ops((1,)) < ops(None)
    assert ops((0, 1, 2)) == ops(None)


@pytest.mark.parametrize("wrap", ["repeat", "mirror", "clamp"])
def test_gradient_from_the_luminance_texture_is_the_rgb_ones_to_the_bit(exr, png, wrap):
    """A bump map's texture kept as its texels' luminances (``gradients``: one channel, a
    quarter of the RGB texture's bytes) gives the gradients of the RGB texture bit for bit,
    plain and with Mitsuba's ``bitmap`` options (wrap modes, ``to_uv``), inside and across the
    borders (negative control: the luminance texture of other weights, the channels' mean,
    differs)."""
    (pe, _), (pp, _) = exr, png
    from drpt.materials.spec import Texture

    paths = [pe, Texture(pp, 0.5, wrap_mode=wrap, raw=True, to_uv=(1.5, 0.2, 0.1, -0.3, 2.0, 0.4, 0, 0, 1))]
    rng = np.random.default_rng(1)
    n = 4096
    uv = Array2f(Float(rng.uniform(-1.2, 2.2, n).astype(np.float32)),
                 Float(rng.uniform(-1.2, 2.2, n).astype(np.float32)))
    ids = UInt32(rng.integers(0, 2, n).astype(np.uint32))
    rgb = TextureSet(paths)
    lum = TextureSet(paths, gradients=(0, 1))
    assert set(lum.luminance) == {0, 1} and not rgb.luminance
    assert lum.luminance[1].wrap_mode() == rgb.textures[1].wrap_mode()  # a Packed8 (8-bit codes)
    want = np.array(rgb.gradient(ids, uv, True))
    got = np.array(lum.gradient(ids, uv, True))
    assert np.abs(want).sum() > 0.0
    np.testing.assert_array_equal(got, want)

    import drpt.render.texture as texture

    mean = texture._lum
    try:
        texture._lum = lambda c: (c.x + c.y + c.z) * (1.0 / 3.0)
        control = TextureSet(paths, gradients=(0, 1))
    finally:
        texture._lum = mean
    assert not np.array_equal(np.array(control.gradient(ids, uv, True)), want)


@pytest.mark.parametrize("mode", ["L", "RGB"])
def test_gray_bump_map_footprints_give_the_luminance_gradients_to_the_bit(tmp_path, mode):
    """A gray 8-bit bump map with repeat wrapping is read through its footprints' codes
    (:class:`GrayFootprints`: one 32-bit gather per lookup) and gives the gradients of the
    luminance texture and of the RGB texture bit for bit: a one-channel PNG and an RGB one
    with equal channels, plain (sRGB) and as a raw ``bitmap`` with ``to_uv``, at 4096 points
    inside and across the borders. Not for a mirror-wrapped map (it keeps the luminance
    texture). Negative control: footprints whose right and lower neighbours are swapped
    differ."""
    from PIL import Image

    from drpt.materials.spec import Texture
    from drpt.render.texture import GrayFootprints

    rng = np.random.default_rng(5)
    g = rng.integers(0, 256, (9, 13), dtype=np.uint8)
    path = tmp_path / f"bump_{mode}.png"
    Image.fromarray(g if mode == "L" else np.repeat(g[..., None], 3, axis=2), mode).save(path)
    to_uv = (1.5, 0.2, 0.1, -0.3, 2.0, 0.4, 0, 0, 1)
    paths = [path, Texture(path, 0.5, raw=True, to_uv=to_uv), Texture(path, 0.5, wrap_mode="mirror")]
    n = 4096
    uv = Array2f(Float(rng.uniform(-1.2, 2.2, n).astype(np.float32)),
                 Float(rng.uniform(-1.2, 2.2, n).astype(np.float32)))
    ids = UInt32(rng.integers(0, 3, n).astype(np.uint32))
    rgb = TextureSet(paths)
    fp = TextureSet(paths, gradients=(0, 1, 2))
    assert set(fp.footprints) == {0, 1} and set(fp.luminance) == {2}
    want = np.array(rgb.gradient(ids, uv, True))
    assert np.abs(want).sum() > 0.0
    np.testing.assert_array_equal(np.array(fp.gradient(ids, uv, True)), want)
    lum = TextureSet(paths, gradients=(0, 1, 2))
    lum.luminance.update({k: _luminance_texture(getattr(lum.textures[k], "tex", lum.textures[k]))
                          for k in (0, 1)})
    lum.footprints.clear()
    np.testing.assert_array_equal(np.array(lum.gradient(ids, uv, True)), want)
    # negative control: the right and lower neighbours swapped in every record
    r = np.array(fp.footprints[0].records)
    swapped = (r & 0xFF0000FF) | ((r >> 8) & 0xFF) << 16 | ((r >> 16) & 0xFF) << 8
    fp.footprints[0].records = UInt32(swapped.astype(np.uint32))
    assert not np.array_equal(np.array(fp.gradient(ids, uv, True)), want)
    assert isinstance(fp.footprints[1], GrayFootprints)


_MODES = [pytest.param("RGB", (13, 17, 3), marks=pytest.mark.slow), ("L", (9, 6)), ("RGBA", (7, 11, 4)),
          ("P", (8, 5))]


@pytest.mark.parametrize("mode,shape", _MODES)
def test_packed_8_bit_texture_is_the_float_texture_to_the_bit(tmp_path, mode, shape):
    """An 8-bit image kept as its codes (:class:`Packed8`: a uint32 per texel, decoded by the
    sRGB table or, raw, by a division) looks up what the float32 texture of
    :func:`load_rgb`'s texels does, bit for bit: bilinear and nearest, the three wrap modes,
    ``raw`` or sRGB-decoded, gray, RGBA and palette files, at 20,000 points of
    ``[-3, 3]^2`` (inside the image and across its borders), and its ``eval_fetch`` gives the
    four corners Dr.Jit's does (every filter and wrap mode on RGB, two of the six on the
    other layouts). Negative control: the codes decoded as Dr.Jit's own 8-bit
    textures decode them (``code * (1 / 255)``), 1 ulp off for some codes, differ."""
    from PIL import Image

    from drpt.imageio import decoding_table, read_codes
    from drpt.render.texture import Packed8, load_rgb

    rng = np.random.default_rng(7)
    a = rng.integers(0, 256, shape, dtype=np.uint8)
    im = Image.fromarray(a, "L").convert("P") if mode == "P" else Image.fromarray(a, mode)
    path = tmp_path / f"t_{mode}.png"
    im.save(path)
    codes = read_codes(path)
    assert codes.dtype == np.uint8 and codes.shape[:2] == a.shape[:2]
    n = 20000
    uv = Array2f(Float(rng.uniform(-3, 3, n).astype(np.float32)), Float(rng.uniform(-3, 3, n).astype(np.float32)))
    for raw in (False, True):
        img = load_rgb(path, raw=raw)
        combos = [(f, w) for f in (dr.FilterMode.Linear, dr.FilterMode.Nearest)
                  for w in (dr.WrapMode.Repeat, dr.WrapMode.Mirror, dr.WrapMode.Clamp)]
        for filt, wrap in combos if mode == "RGB" else [combos[0], combos[4]]:
            ref = dr.auto.Texture2f(dr.auto.TensorXf(img), filter_mode=filt, wrap_mode=wrap)
            packed = Packed8(codes, decoding_table(not raw), filt, wrap)
            assert (packed.divisor is not None) == raw
            want = np.array(ref.eval(uv))
            np.testing.assert_array_equal(np.array(packed.eval(uv)), want)
            if filt == dr.FilterMode.Linear:
                for c_ref, c_got in zip(ref.eval_fetch(uv), packed.eval_fetch(uv)):
                    np.testing.assert_array_equal(np.array(c_got), np.array(c_ref))
    # negative control: Dr.Jit's 8-bit decoding of the raw codes
    img = load_rgb(path, raw=True)
    ref = dr.auto.Texture2f(dr.auto.TensorXf(img), filter_mode=dr.FilterMode.Nearest)
    drjit_u8 = np.arange(256, dtype=np.float32) * np.float32(1.0 / 255.0)
    assert not np.array_equal(drjit_u8, decoding_table(False))
    control = Packed8(codes, drjit_u8, dr.FilterMode.Nearest, dr.WrapMode.Clamp)
    assert control.divisor is None
    assert not np.array_equal(np.array(control.eval(uv)), np.array(ref.eval(uv)))


def test_which_textures_are_packed(tmp_path, exr, png):
    """Raw 8-bit images (a ``bitmap`` with ``raw``) become :class:`Packed8`; sRGB-decoded 8-bit
    images (whose table gathers cost more than the bytes they save), float images and a bump
    map's texture (``gradients``: its luminance or footprints) stay float textures;
    :func:`drpt.imageio.read_codes` reads no codes from float or 16-bit files."""
    from PIL import Image

    from drpt.imageio import read_codes
    from drpt.materials.spec import Texture
    from drpt.render.texture import Packed8

    (pe, _), (pp, _) = exr, png
    deep = tmp_path / "deep.png"
    Image.fromarray(np.full((3, 4), 40000, np.uint16)).save(deep)
    assert read_codes(pe) is None and read_codes(deep) is None
    ts = TextureSet([pe, pp, Texture(pp, 0.5, raw=True), Texture(pp, 0.5), Texture(pp, 0.7, raw=True), deep],
                    gradients=(4,))
    kinds = [type(t).__name__ for t in ts.textures]
    assert kinds == ["Texture2f", "Texture2f", "Packed8", "Bitmap", "Bitmap", "Texture2f"]
    assert isinstance(ts.textures[2], Packed8) and ts.textures[2].divisor is not None
    assert ts.shapes[1] == ts.shapes[2] == ts.shapes[4]
    with pytest.raises(SceneError, match="nope.jpg"):
        read_codes(tmp_path / "nope.jpg")


def test_empty_set_traces_nothing():
    ts = TextureSet([])
    assert len(ts) == 0
    r = ts.lookup(UInt32(0, 1), Array2f(Float(0.1, 0.2), Float(0.3, 0.4)), True)
    assert np.all(np.array(r) == 0.0)


def test_bad_files_name_the_file(tmp_path):
    missing = tmp_path / "nope.png"
    with pytest.raises(SceneError, match="nope.png"):
        TextureSet([missing])
    bad = tmp_path / "corrupt.png"
    bad.write_bytes(b"\x89PNG\r\n\x1a\n this is not a png")
    with pytest.raises(SceneError, match="corrupt.png"):
        TextureSet([bad])
    bad_exr = tmp_path / "corrupt.exr"
    bad_exr.write_bytes(b"garbage")
    with pytest.raises(SceneError, match="corrupt.exr"):
        TextureSet([bad_exr])


@pytest.mark.mitsuba
@pytest.mark.parametrize("kind", ["png", "exr", "gray", "rgba"])
def test_equals_mitsuba_bitmap(kind, exr, png, tmp_path):
    from PIL import Image

    mi = mitsuba()
    if kind in ("png", "exr"):
        p, _ = exr if kind == "exr" else png
    else:
        rng = np.random.default_rng(9)
        shape, mode = ((6, 3), "L") if kind == "gray" else ((3, 7, 4), "RGBA")
        p = tmp_path / f"{kind}.png"
        Image.fromarray(rng.integers(0, 256, size=shape, dtype=np.uint8), mode).save(p)
    ts = TextureSet([p])
    rng = np.random.default_rng(4)
    n = 20_000
    uv = rng.uniform(-2.0, 3.0, size=(2, n)).astype(np.float32)
    # include exact borders, texel centers and edges
    uv[:, :6] = [[0.0, 1.0, 0.0, 0.5, -1.0, 0.999999], [0.0, 1.0, 1.0, 0.5, 2.0, 1e-6]]
    ours = _lookup(ts, uv)
    tex = mi.load_dict({"type": "bitmap", "filename": str(p), "filter_type": "bilinear",
                        "wrap_mode": "repeat"})
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.uv = mi.Point2f(uv[0], 1.0 - uv[1])
    theirs = np.array(tex.eval(si))
    np.testing.assert_allclose(ours, theirs, atol=2e-6, rtol=0)
    assert np.abs(ours - theirs).mean() < 2e-7


# ------------------------------------------------------------ end to end
_TEX_MTL = """
newmtl floor
Kd 0.5 0.5 0.5
map_Kd floor.png
newmtl wall
Kd 0.5 0.5 0.5
map_Kd wall.exr
newmtl light
Kd 0 0 0
Ke 8 8 8
"""

_TEX_OBJ = """
mtllib tex.mtl
v -3 0 -3
v 3 0 -3
v 3 0 3
v -3 0 3
v -3 4 -3
v 3 4 -3
v -1 3.99 -1
v 1 3.99 -1
v 1 3.99 1
v -1 3.99 1
vt -0.5 -0.5
vt 1.5 -0.5
vt 1.5 1.5
vt -0.5 1.5
vt 0 0
vt 1 0
vt 1 1
vt 0 1
usemtl floor
f 1/4 4/1 3/2 2/3
usemtl wall
f 1/5 2/6 6/7 5/8
usemtl light
f 7 8 9 10
"""

_TEX_SCENE = """
PerspectiveCamera { center 0 2.2 6  direction 0 -0.3 -1  up 0 1 0  angle 45 }
Group {
    numObjects 1
    TriangleMesh { obj_file tex.obj }
}
"""


@pytest.mark.mitsuba
def test_textured_render_matches_mitsuba(tmp_path):
    """Two textures (PNG on the floor with uvs beyond [0, 1], EXR on the back
    wall) rendered by drpt and by Mitsuba through the exporter."""
    from PIL import Image

    from drpt.options import PathOptions, RenderOptions
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene
    from drpt.testing import assert_agree, render_both

    rng = np.random.default_rng(12)
    floor = rng.integers(20, 256, size=(4, 6, 3), dtype=np.uint8)
    wall = _float_image() * 0.8 + 0.1

    def scene_with(floor, wall, folder):
        folder.mkdir()
        Image.fromarray(floor, "RGB").save(folder / "floor.png")
        write_image(folder / "wall.exr", wall)
        (folder / "tex.mtl").write_text(_TEX_MTL)
        (folder / "tex.obj").write_text(_TEX_OBJ)
        (folder / "scene.txt").write_text(_TEX_SCENE)
        return load_scene(folder / "scene.txt")

    r, ref, ref_var = render_both(scene_with(floor, wall, tmp_path / "a"), 48, 32, 128,
                                  max_depth=4)
    assert r.image.mean() > 0.02
    assert_agree(r, ref, ref_var)
    # Negative control: drpt with both textures flipped upside down must disagree
    # (the statistic sees a v-flip bug).
    flipped = scene_with(floor[::-1].copy(), wall[::-1].copy(), tmp_path / "b")
    rf = Renderer(flipped, RenderOptions(width=48, height=32, spp=128, seed=1, progress=False,
                                         path=PathOptions(max_depth=4))).render()
    with pytest.raises(AssertionError):
        assert_agree(rf, ref, ref_var)
