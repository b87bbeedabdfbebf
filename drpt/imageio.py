"""Images in and out, chosen by file extension.

Writing (:func:`write_image`)
-----------------------------
``rgb`` is an ``(H, W, 3)`` array of *linear* radiance values, row 0 at the
top of the image.

* ``.exr`` -- linear float32, channels ``R``, ``G``, ``B`` (ZIP compressed,
  lossless), written with the ``OpenEXR`` package. Reading it back gives the
  exact same float32 values.
* ``.hdr`` -- Radiance RGBE, flat (uncompressed) scanlines, ``-Y H +X W``.
* ``.pfm`` -- Portable Float Map (``PF``, little endian, rows stored bottom to
  top as the format requires).
* ``.png`` / ``.tga`` -- 8-bit tonemapped: ``round(255 * clamp(x, 0, 1) **
  (1 / gamma))`` per channel (a plain power curve, *not* the sRGB curve),
  written with Pillow.

An unknown extension raises :class:`drpt.errors.DrptError` naming the
supported ones. NaN or infinite values are never written: they raise
:class:`ValueError` (a renderer bug, not a user error); nothing is replaced
silently. A file that cannot be written (missing directory, no permission)
raises :class:`DrptError`.

Reading (:func:`read_image`)
----------------------------
Returns an ``(H, W, C)`` float32 array, row 0 at the top, ``C`` in
``{1, 3, 4}`` (gray, RGB, RGBA).

* ``.exr`` -- float values as stored (half or float channels; ``R,G,B[,A]``
  or a single ``Y`` channel).
* ``.hdr`` -- Radiance RGBE (``32-bit_rle_rgbe``): flat scanlines, new-style
  ("adaptive") run-length encoded scanlines and old-style RLE repeat pixels
  are all decoded. A pixel ``(r, g, b, e)`` becomes ``(r, g, b) * 2**(e -
  136)`` (``0`` when ``e == 0``), the same convention as Mitsuba 3's
  ``Bitmap`` (no half-step mantissa offset), so a texel read here equals the
  one Mitsuba reads. The ``EXPOSURE`` header is ignored, as Mitsuba does.
  Orientations ``-Y H +X W`` (standard) and ``+Y H +X W`` are supported.
* ``.pfm`` -- ``PF`` (RGB) or ``Pf`` (gray), either endianness.
* ``.png``, ``.jpg``, ``.jpeg``, ``.tga`` -- with Pillow. 8-bit (16-bit)
  channels become floats in ``[0, 1]`` by dividing by 255 (65535). With
  ``linear=True`` (the default) color channels are then decoded from sRGB
  to linear with the exact sRGB transfer curve (what Mitsuba's ``bitmap``
  texture does for 8-bit images when ``raw`` is false); alpha is never
  decoded. ``linear=False`` returns the encoded values. Palette images are
  expanded; gray+alpha becomes RGBA.

A missing, unreadable or malformed file raises
``SceneError(path, None, message)``.
"""

from __future__ import annotations

import re
from os import PathLike
from pathlib import Path

import numpy as np

from drpt.errors import DrptError, SceneError

WRITE_EXTENSIONS = (".exr", ".png", ".tga", ".hdr", ".pfm")
READ_EXTENSIONS = (".exr", ".hdr", ".pfm", ".png", ".jpg", ".jpeg", ".tga")

__all__ = [
    "write_image",
    "read_image",
    "srgb_to_linear",
    "linear_to_srgb",
    "WRITE_EXTENSIONS",
    "READ_EXTENSIONS",
]


# ------------------------------------------------------------------ helpers
def srgb_to_linear(x: np.ndarray) -> np.ndarray:
    """The exact sRGB decoding curve (IEC 61966-2-1), elementwise."""
    x = np.asarray(x, dtype=np.float32)
    return np.where(
        x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4
    ).astype(np.float32)


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    """The exact sRGB encoding curve, elementwise (input clamped at 0)."""
    x = np.maximum(np.asarray(x, dtype=np.float32), 0.0)
    return np.where(
        x <= 0.0031308, 12.92 * x, 1.055 * x ** (1.0 / 2.4) - 0.055
    ).astype(np.float32)


def _ext(path: Path) -> str:
    return path.suffix.lower()


# ------------------------------------------------------------------ writing
def write_image(path: str | PathLike, rgb: np.ndarray, gamma: float = 2.2) -> None:
    """Write a linear ``(H, W, 3)`` image; the format follows the extension.

    ``gamma`` only affects the 8-bit formats (``.png``, ``.tga``).
    Raises :class:`DrptError` for an unsupported extension or an unwritable
    path, and :class:`ValueError` for a wrongly shaped array or NaN/Inf values.
    """
    path = Path(path)
    ext = _ext(path)
    if ext not in WRITE_EXTENSIONS:
        raise DrptError(
            f"{path}: cannot write images with extension {ext or '(none)'!r}; "
            f"supported: {', '.join(WRITE_EXTENSIONS)}"
        )
    img = np.asarray(rgb)
    if img.ndim != 3 or img.shape[2] != 3 or img.shape[0] == 0 or img.shape[1] == 0:
        raise ValueError(f"write_image expects an (H, W, 3) array, got shape {img.shape}")
    img = img.astype(np.float32, copy=False)
    if not np.all(np.isfinite(img)):
        bad = int(np.count_nonzero(~np.isfinite(img)))
        raise ValueError(f"write_image({path}): image has {bad} NaN/Inf values")
    if not gamma > 0:
        raise ValueError(f"gamma must be positive, got {gamma}")

    try:
        if ext == ".exr":
            _write_exr(path, img)
        elif ext == ".hdr":
            _write_hdr(path, img)
        elif ext == ".pfm":
            _write_pfm(path, img)
        else:
            _write_ldr(path, img, gamma, "PNG" if ext == ".png" else "TGA")
    except OSError as e:
        raise DrptError(f"{path}: cannot write image: {e.strerror or e}") from e
    except RuntimeError as e:  # OpenEXR reports I/O failures this way
        raise DrptError(f"{path}: cannot write image: {e}") from e


def _write_exr(path: Path, img: np.ndarray) -> None:
    import OpenEXR

    channels = {c: np.ascontiguousarray(img[..., i]) for i, c in enumerate("RGB")}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    if not path.parent.is_dir():
        raise OSError(2, f"no such directory: {path.parent}")
    OpenEXR.File(header, channels).write(str(path))


def _write_ldr(path: Path, img: np.ndarray, gamma: float, fmt: str) -> None:
    from PIL import Image

    enc = np.clip(img, 0.0, 1.0) ** (1.0 / gamma)
    u8 = np.round(enc * 255.0).astype(np.uint8)
    Image.fromarray(u8, "RGB").save(path, format=fmt)


def _float_to_rgbe(img: np.ndarray) -> np.ndarray:
    """(H, W, 3) float -> (H, W, 4) uint8 RGBE (negative values clamp to 0)."""
    img = np.maximum(img.astype(np.float64), 0.0)
    v = img.max(axis=2)
    mant, exp = np.frexp(v)  # v = mant * 2**exp, mant in [0.5, 1)
    ok = v >= 1e-32
    scale = np.where(ok, mant * 256.0 / np.where(ok, v, 1.0), 0.0)
    out = np.zeros(img.shape[:2] + (4,), np.uint8)
    out[..., :3] = np.clip(np.floor(img * scale[..., None]), 0, 255).astype(np.uint8)
    out[..., 3] = np.where(ok, np.clip(exp + 128, 0, 255), 0).astype(np.uint8)
    return out


def _write_hdr(path: Path, img: np.ndarray) -> None:
    h, w = img.shape[:2]
    header = (
        b"#?RADIANCE\n# written by drpt\nFORMAT=32-bit_rle_rgbe\n\n"
        + f"-Y {h} +X {w}\n".encode()
    )
    with open(path, "wb") as f:
        f.write(header)
        f.write(_float_to_rgbe(img).tobytes())


def _write_pfm(path: Path, img: np.ndarray) -> None:
    h, w = img.shape[:2]
    with open(path, "wb") as f:
        f.write(f"PF\n{w} {h}\n-1.0\n".encode())
        f.write(np.ascontiguousarray(img[::-1], dtype="<f4").tobytes())


# ------------------------------------------------------------------ reading
def read_image(path: str | PathLike, linear: bool = True) -> np.ndarray:
    """Read an image as an ``(H, W, C)`` float32 array (see module docs).

    ``linear`` only matters for 8/16-bit formats: decode their sRGB-encoded
    color channels to linear values. Raises :class:`SceneError` when the
    file is missing, unreadable, malformed or of an unsupported type.
    """
    path = Path(path)
    ext = _ext(path)
    if ext not in READ_EXTENSIONS:
        raise SceneError(
            path, None,
            f"cannot read images with extension {ext or '(none)'!r}; "
            f"supported: {', '.join(READ_EXTENSIONS)}",
        )
    if not path.is_file():
        raise SceneError(path, None, "image file not found")
    try:
        if ext == ".exr":
            img = _read_exr(path)
        elif ext == ".hdr":
            img = _read_hdr(path)
        elif ext == ".pfm":
            img = _read_pfm(path)
        else:
            img = _read_ldr(path, linear)
    except SceneError:
        raise
    except OSError as e:
        raise SceneError(path, None, f"cannot read image: {e.strerror or e}") from e
    except Exception as e:  # malformed data: Pillow/OpenEXR/our decoders
        raise SceneError(path, None, f"cannot read image: {e}") from e
    if img.ndim == 2:
        img = img[..., None]
    return np.ascontiguousarray(img, dtype=np.float32)


def _read_exr(path: Path) -> np.ndarray:
    import OpenEXR

    f = OpenEXR.File(str(path), separate_channels=True)
    ch = f.channels()
    names = list(ch)
    if all(c in ch for c in "RGB"):
        order = ["R", "G", "B"] + (["A"] if "A" in ch else [])
    elif "Y" in ch:
        order = ["Y"]
    elif len(names) == 1:
        order = names
    else:
        raise ValueError(f"no R,G,B or Y channels (has {', '.join(sorted(names))})")
    return np.stack([np.asarray(ch[c].pixels, dtype=np.float32) for c in order], -1)


def _read_ldr(path: Path, linear: bool) -> np.ndarray:
    from PIL import Image

    with Image.open(path) as im:
        im.load()
        mode = im.mode
        if mode in ("I;16", "I;16B", "I;16L", "I"):
            a = np.asarray(im, dtype=np.float64)
            a = a / (65535.0 if mode.startswith("I;16") or a.max() > 255 else 255.0)
            a = np.clip(a, 0.0, 1.0)[..., None]
            alpha = 0
        elif mode == "F":
            return np.asarray(im, dtype=np.float32)[..., None]  # already linear
        else:
            if mode == "P":
                im = im.convert("RGBA" if "transparency" in im.info else "RGB")
            elif mode == "LA" or mode == "PA" or mode == "RGBa":
                im = im.convert("RGBA")
            elif mode not in ("L", "RGB", "RGBA"):
                im = im.convert("RGB")
            a = np.asarray(im, dtype=np.float64) / 255.0
            if a.ndim == 2:
                a = a[..., None]
            alpha = 1 if a.shape[2] == 4 else 0
    a = a.astype(np.float32)
    if linear:
        nc = a.shape[2] - alpha
        a[..., :nc] = srgb_to_linear(a[..., :nc])
    return a


_RES_RE = re.compile(rb"^([-+])Y\s+(\d+)\s+\+X\s+(\d+)\s*$")


def _read_hdr(path: Path) -> np.ndarray:
    data = path.read_bytes()
    if not (data.startswith(b"#?RADIANCE") or data.startswith(b"#?RGBE")):
        raise SceneError(path, None, "not a Radiance .hdr file (missing '#?RADIANCE')")
    # Header: lines until an empty line, then the resolution line.
    pos = data.find(b"\n") + 1
    fmt = None
    while True:
        end = data.find(b"\n", pos)
        if end < 0:
            raise SceneError(path, None, "truncated .hdr header")
        line = data[pos:end].strip()
        pos = end + 1
        if not line:
            break
        if line.startswith(b"FORMAT="):
            fmt = line[7:].decode("ascii", "replace")
    if fmt is not None and fmt != "32-bit_rle_rgbe":
        raise SceneError(path, None, f"unsupported .hdr FORMAT {fmt!r} (only 32-bit_rle_rgbe)")
    end = data.find(b"\n", pos)
    m = _RES_RE.match(data[pos:end if end >= 0 else len(data)])
    if not m:
        res = data[pos:end].decode("ascii", "replace")
        raise SceneError(path, None, f"unsupported .hdr resolution line {res!r}")
    flip = m.group(1) == b"+"
    h, w = int(m.group(2)), int(m.group(3))
    if h <= 0 or w <= 0:
        raise SceneError(path, None, f"bad .hdr size {w}x{h}")
    pos = end + 1
    buf = np.frombuffer(data, np.uint8, offset=pos) if pos < len(data) else np.zeros(0, np.uint8)
    rgbe = _decode_rgbe_scanlines(buf, w, h, path)
    if flip:
        rgbe = rgbe[::-1]
    return _rgbe_to_float(rgbe)


def _rgbe_to_float(rgbe: np.ndarray) -> np.ndarray:
    e = rgbe[..., 3].astype(np.int32)
    scale = np.where(e > 0, np.ldexp(np.float32(1.0), e - 136), np.float32(0.0)).astype(np.float32)
    return rgbe[..., :3].astype(np.float32) * scale[..., None]


def _decode_rgbe_scanlines(buf: np.ndarray, w: int, h: int, path: Path) -> np.ndarray:
    n = buf.size
    # Fast path: the whole body is flat RGBE (no RLE of any kind).
    if n == w * h * 4 and not _is_new_rle(buf, 0, w):
        flat = buf.reshape(h, w, 4)
        if not np.any((flat[..., 0] == 1) & (flat[..., 1] == 1) & (flat[..., 2] == 1)):
            return flat
    out = np.empty((h, w, 4), np.uint8)
    pos = 0
    for y in range(h):
        if _is_new_rle(buf, pos, w):
            pos += 4
            for c in range(4):
                row = out[y, :, c]
                x = 0
                while x < w:
                    if pos >= n:
                        raise SceneError(path, None, f"truncated .hdr data at scanline {y}")
                    count = int(buf[pos])
                    pos += 1
                    if count > 128:
                        count -= 128
                        if count > w - x or pos >= n:
                            raise SceneError(path, None, f"bad RLE run in .hdr scanline {y}")
                        row[x:x + count] = buf[pos]
                        pos += 1
                    else:
                        if count == 0 or count > w - x or pos + count > n:
                            raise SceneError(path, None, f"bad RLE dump in .hdr scanline {y}")
                        row[x:x + count] = buf[pos:pos + count]
                        pos += count
                    x += count
        else:
            pos = _decode_flat_scanline(buf, pos, out[y], w, path, y)
    return out


def _is_new_rle(buf: np.ndarray, pos: int, w: int) -> bool:
    if not (8 <= w <= 0x7FFF) or pos + 4 > buf.size:
        return False
    return (
        buf[pos] == 2 and buf[pos + 1] == 2 and not (buf[pos + 2] & 0x80)
        and (int(buf[pos + 2]) << 8 | int(buf[pos + 3])) == w
    )


def _decode_flat_scanline(buf, pos, row, w, path, y) -> int:
    """Flat pixels, possibly with old-style RLE repeat markers (1,1,1,n)."""
    n = buf.size
    if pos + 4 * w > n:
        chunk = None
    else:
        chunk = buf[pos:pos + 4 * w].reshape(w, 4)
        if not np.any((chunk[:, 0] == 1) & (chunk[:, 1] == 1) & (chunk[:, 2] == 1)):
            row[:] = chunk
            return pos + 4 * w
    # Old-style RLE: (1, 1, 1, k) repeats the previous pixel k << shift times.
    x, shift = 0, 0
    while x < w:
        if pos + 4 > n:
            raise SceneError(path, None, f"truncated .hdr data at scanline {y}")
        px = buf[pos:pos + 4]
        pos += 4
        if px[0] == 1 and px[1] == 1 and px[2] == 1:
            if x == 0:
                raise SceneError(path, None, f"bad old-style RLE in .hdr scanline {y}")
            count = int(px[3]) << shift
            if count > w - x:
                raise SceneError(path, None, f"bad old-style RLE in .hdr scanline {y}")
            row[x:x + count] = row[x - 1]
            x += count
            shift += 8
        else:
            row[x] = px
            x += 1
            shift = 0
    return pos


def _read_pfm(path: Path) -> np.ndarray:
    data = path.read_bytes()
    tokens: list[bytes] = []
    pos = 0
    while len(tokens) < 4:  # "PF"/"Pf", width, height, scale
        while pos < len(data) and data[pos:pos + 1].isspace():
            pos += 1
        start = pos
        while pos < len(data) and not data[pos:pos + 1].isspace():
            pos += 1
        if start == pos:
            raise SceneError(path, None, "truncated .pfm header")
        tokens.append(data[start:pos])
    pos += 1  # the single whitespace byte after the scale
    kind = tokens[0]
    if kind not in (b"PF", b"Pf"):
        raise SceneError(path, None, "not a .pfm file (expected 'PF' or 'Pf')")
    c = 3 if kind == b"PF" else 1
    try:
        w, h, scale = int(tokens[1]), int(tokens[2]), float(tokens[3])
    except ValueError:
        raise SceneError(path, None, "bad .pfm header") from None
    dtype = "<f4" if scale < 0 else ">f4"
    count = w * h * c
    if len(data) - pos < 4 * count:
        raise SceneError(path, None, "truncated .pfm data")
    a = np.frombuffer(data, dtype, count=count, offset=pos).reshape(h, w, c)
    return a[::-1].astype(np.float32)
