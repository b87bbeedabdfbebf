"""Images in and out, chosen by file extension.

Writing (:func:`write_image`)
-----------------------------
``rgb`` is an ``(H, W, 3)`` array of *linear* radiance values, row 0 at the
top of the image.

* ``.exr`` -- linear float32, channels ``R``, ``G``, ``B`` (ZIP compressed,
  lossless), written with the ``OpenEXR`` package. Reading it back gives the
  exact same float32 values.
* ``.hdr`` -- Radiance RGBE (``-Y H +X W``, negative values clamped to 0)
  and ``.pfm`` -- Portable Float Map (``PF``, little endian, scale ``-1``,
  rows stored bottom to top as the format requires), both written by
  Mitsuba 3's ``Bitmap``.
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
* ``.hdr`` -- Radiance RGBE (``FORMAT=32-bit_rle_rgbe``), read by Mitsuba
  3's ``Bitmap``: flat and ("adaptive") run-length encoded scanlines, rows
  from the top (``-Y H +X W``; other orientations are refused). A pixel
  ``(r, g, b, e)`` becomes ``(r, g, b) * 2**(e - 136)`` (``0`` when
  ``e == 0``), so a texel read here is the one Mitsuba's emitters and
  textures read. The ``EXPOSURE`` header is ignored, as Mitsuba does.
  Old-style RLE (repeat pixels ``(1, 1, 1, k)``), which Mitsuba does not
  decode, is decoded by :func:`_read_rgbe_old_rle`.
* ``.pfm`` -- ``PF`` (RGB) or ``Pf`` (gray), either endianness, read by
  Mitsuba's ``Bitmap``, which multiplies the values by the magnitude of
  the header's scale (``1`` in files drpt writes).
* ``.png``, ``.jpg``, ``.jpeg``, ``.tga``, ``.bmp`` -- with Pillow. 8-bit (16-bit)
  channels become floats in ``[0, 1]`` by dividing by 255 (65535). With
  ``linear=True`` (the default) color channels are then decoded from sRGB
  to linear with the exact sRGB transfer curve (what Mitsuba's ``bitmap``
  texture does for 8-bit images when ``raw`` is false); alpha is never
  decoded. ``gamma=G`` decodes them with the power curve ``x ** G`` instead,
  the inverse of what :func:`write_image` writes (``compare A.png B.exr``).
  ``linear=False`` returns the encoded values. Palette images are
  expanded; gray+alpha becomes RGBA.

A missing, unreadable, truncated, malformed or empty (0 pixel) file, or one that is not a
regular file (a directory, FIFO, device or symbolic link loop), raises
``SceneError(Loc(path), message)``, a one-line message naming the file;
for a texture or sky named by a scene or MTL file
(:class:`drpt.scene.files.NamedPath`) the error names that file and line
instead, followed by the image's name.

Mitsuba is imported on the first ``.hdr`` or ``.pfm``, not before (the import takes
a noticeable fraction of a second); its
``Bitmap`` needs no variant, so none is set.
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import sys
from os import PathLike
from pathlib import Path

import numpy as np

from drpt.errors import DrptError, Loc, SceneError
from drpt.scene.files import check_input

WRITE_EXTENSIONS = (".exr", ".png", ".tga", ".hdr", ".pfm")
READ_EXTENSIONS = (".exr", ".hdr", ".pfm", ".png", ".jpg", ".jpeg", ".tga", ".bmp")

__all__ = [
    "write_image",
    "read_image",
    "read_codes",
    "decoding_table",
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
def write_image(path: str | PathLike, rgb: np.ndarray, gamma: float = 2.2,
                extra: dict[str, np.ndarray] | None = None) -> None:
    """Write a linear ``(H, W, 3)`` image; the format follows the extension.

    ``gamma`` only affects the 8-bit formats (``.png``, ``.tga``). ``extra``:
    more ``(H, W)`` float channels by name, written to ``.exr`` only (other
    formats have no room for them).
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
        # encoded in a private folder, then written by Python, which reports a
        # failed write (a full disk; Mitsuba's and OpenEXR's writers may not)
        import tempfile

        with tempfile.TemporaryDirectory(prefix="drpt-image-") as tmp:
            encoded = Path(tmp) / ("image" + ext)
            if ext == ".exr":
                _write_exr(encoded, img, extra or {})
            elif ext in (".hdr", ".pfm"):
                _write_bitmap(encoded, img)
            else:
                _write_ldr(encoded, img, gamma, "PNG" if ext == ".png" else "TGA")
            data = encoded.read_bytes()
        if not data:
            raise OSError(0, "the encoder wrote nothing")
        with open(path, "wb") as f:
            f.write(data)
    except OSError as e:
        raise DrptError(f"{path}: cannot write image: {e.strerror or e}") from e
    except RuntimeError as e:  # OpenEXR reports I/O failures this way
        raise DrptError(f"{path}: cannot write image: {_mitsuba_message(e)}") from e


def _write_exr(path: Path, img: np.ndarray, extra: dict[str, np.ndarray]) -> None:
    import OpenEXR

    channels = {c: np.ascontiguousarray(img[..., i]) for i, c in enumerate("RGB")}
    for name, values in extra.items():
        channels[name] = np.ascontiguousarray(np.asarray(values, np.float32).reshape(img.shape[:2]))
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    if not path.parent.is_dir():
        raise OSError(2, f"no such directory: {path.parent}")
    OpenEXR.File(header, channels).write(str(path))


def _write_ldr(path: Path, img: np.ndarray, gamma: float, fmt: str) -> None:
    from PIL import Image

    enc = np.clip(img, 0.0, 1.0) ** (1.0 / gamma)
    u8 = np.round(enc * 255.0).astype(np.uint8)
    Image.fromarray(u8, "RGB").save(path, format=fmt)


def _write_bitmap(path: Path, img: np.ndarray) -> None:
    """``.hdr`` (negative values clamped to 0 first) or ``.pfm``, by Mitsuba."""
    if path.suffix.lower() == ".hdr":
        img = np.maximum(img, 0.0)
    _bitmap_class()(np.ascontiguousarray(img, dtype=np.float32)).write(str(path))


def _bitmap_class():
    """``mitsuba.Bitmap``, imported on first use.

    ``Bitmap`` belongs to Mitsuba's core library, so no variant is set: the
    global variant stays what the rest of the program chose."""
    import mitsuba

    return mitsuba.Bitmap


def _mitsuba_message(e: Exception) -> str:
    """Mitsuba's exception text on one line, without its ``[Class]`` tags
    and the quoted file name (the caller's message starts with it), nor the
    ``: Success`` (errno 0) it appends when a file ends early."""
    text = " ".join(str(e).split())
    return re.sub(r'\[[A-Za-z:]+\]\s*|"[^"]*":\s*|:\s*Success$', "", text).strip()


# ------------------------------------------------------------------ reading
# the 8/16-bit formats Pillow reads (the others hold floats)
_LDR = tuple(e for e in READ_EXTENSIONS if e not in (".exr", ".hdr", ".pfm"))


def read_image(path: str | PathLike, linear: bool = True, gamma: float | None = None) -> np.ndarray:
    """Read an image as an ``(H, W, C)`` float32 array (see module docs).

    ``linear`` only matters for 8/16-bit formats: decode their sRGB-encoded
    color channels to linear values (textures: Mitsuba's convention), or with
    ``gamma``, by the plain power curve ``x ** gamma`` that :func:`write_image`
    encodes them with (renders). Raises :class:`SceneError` when the
    file is missing, not a regular file, unreadable, malformed or of an
    unsupported type: at the file itself, or, for a
    :class:`~drpt.scene.files.NamedPath` (a texture or sky named by a scene
    or MTL file), at the line that named it, e.g. ``scene.txt:12: sky.hdr:
    cannot read .hdr image (truncated or corrupt): ...``.
    """
    named_at = getattr(path, "named_at", None)
    path = Path(path)
    try:
        img = _read_image(path, linear and gamma is None)
        if gamma is not None and linear and _ext(path) in _LDR:
            nc = 3 if img.shape[2] >= 3 else 1
            img[..., :nc] = np.clip(img[..., :nc], 0.0, 1.0) ** gamma
        return img
    except SceneError as e:
        if named_at is None:
            raise
        raise SceneError(named_at, f"{path.name}: {e.message}") from e


def _read_image(path: Path, linear: bool) -> np.ndarray:
    ext = _ext(path)
    if ext not in READ_EXTENSIONS:
        raise SceneError(
            Loc(path),
            f"cannot read images with extension {ext or '(none)'!r}; "
            f"supported: {', '.join(READ_EXTENSIONS)}",
        )
    check_input(path, what="image file")
    try:
        with np.errstate(all="ignore"):
            if ext == ".exr":
                img = _read_exr(path)
            elif ext in (".hdr", ".pfm"):
                img = _read_bitmap(path, ext)
            else:
                img = _read_ldr(path, linear)
    except SceneError:
        raise
    except OSError as e:
        raise SceneError(Loc(path), f"cannot read image: {e.strerror or e}") from e
    except Exception as e:  # malformed data: Pillow/OpenEXR/our decoders
        raise SceneError(Loc(path), f"cannot read image: {e}") from e
    if img.ndim == 2:
        img = img[..., None]
    if img.size == 0:
        raise SceneError(Loc(path), f"empty image ({img.shape[1]}x{img.shape[0]} pixels)")
    return np.ascontiguousarray(img, dtype=np.float32)


@contextlib.contextmanager
def _quiet_library_output():
    """Discard stdout and stderr (file descriptors 1 and 2 and Python's
    ``sys.stdout``/``sys.stderr``) for the duration: the OpenEXR library
    and its binding print their own lines about a corrupt file, and drpt
    reports the problem in one line of its own."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = {}
    try:
        for fd in (1, 2):
            try:
                saved[fd] = os.dup(fd)
            except OSError:  # not open: nothing to protect
                continue
            with open(os.devnull, "wb") as null:
                os.dup2(null.fileno(), fd)
        sink = io.StringIO()  # the Python binding prints through sys.stdout
        with contextlib.redirect_stdout(sink), contextlib.redirect_stderr(sink):
            yield
    finally:
        for fd, copy in saved.items():
            os.dup2(copy, fd)
            os.close(copy)


def _read_exr(path: Path) -> np.ndarray:
    import OpenEXR

    try:
        with _quiet_library_output():
            f = OpenEXR.File(str(path), separate_channels=True)
            ch = f.channels()
    except Exception as e:
        raise SceneError(Loc(path), f"cannot read .exr image (truncated or corrupt): {e}") from e
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
            a = _ldr_codes(im).astype(np.float64) / 255.0
            alpha = 1 if a.shape[2] == 4 else 0
    a = a.astype(np.float32)
    if linear:
        nc = a.shape[2] - alpha
        a[..., :nc] = srgb_to_linear(a[..., :nc])
    return a


def _ldr_codes(im) -> np.ndarray:
    """The ``(H, W, C)`` 8-bit codes of a loaded Pillow image of 8-bit channels (``C``: 1
    gray, 3 RGB or 4 RGBA; a palette or other mode converted to RGB or RGBA)."""
    mode = im.mode
    if mode == "P":
        im = im.convert("RGBA" if "transparency" in im.info else "RGB")
    elif mode == "LA" or mode == "PA" or mode == "RGBa":
        im = im.convert("RGBA")
    elif mode not in ("L", "RGB", "RGBA"):
        im = im.convert("RGB")
    a = np.asarray(im, dtype=np.uint8)
    return a[..., None] if a.ndim == 2 else a


def decoding_table(linear: bool = True) -> np.ndarray:
    """The 256 float32 values :func:`read_image` decodes an 8-bit color code to (with
    ``linear``, sRGB-decoded, else the code over 255): ``table[code]`` is bit for bit the
    value it returns for a color channel holding ``code``."""
    t = (np.arange(256, dtype=np.float64) / 255.0).astype(np.float32)
    return srgb_to_linear(t) if linear else t


def read_codes(path: str | PathLike) -> np.ndarray | None:
    """The ``(H, W, C)`` uint8 codes of an 8-bit image file (PNG, JPEG, TGA, BMP of 8-bit
    channels; ``C`` as :func:`read_image` returns them), which :func:`decoding_table`
    turns into :func:`read_image`'s values; None for any other file (float formats,
    16-bit and float PNG or TIFF modes). Raises :class:`SceneError` as :func:`read_image`
    does."""
    named_at = getattr(path, "named_at", None)
    path = Path(path)
    if _ext(path) not in _LDR:
        return None
    try:
        check_input(path, what="image file")
        from PIL import Image

        try:
            with Image.open(path) as im:
                im.load()
                if im.mode in ("I;16", "I;16B", "I;16L", "I", "F"):
                    return None
                a = _ldr_codes(im)
        except OSError as e:
            raise SceneError(Loc(path), f"cannot read image: {e.strerror or e}") from e
        except Exception as e:  # malformed data
            raise SceneError(Loc(path), f"cannot read image: {e}") from e
        if a.size == 0:
            raise SceneError(Loc(path), f"empty image ({a.shape[1]}x{a.shape[0]} pixels)")
        return np.ascontiguousarray(a)
    except SceneError as e:
        if named_at is None:
            raise
        raise SceneError(named_at, f"{path.name}: {e.message}") from e


# The first bytes of each float format Mitsuba reads for us: checked first,
# so that a PNG named ``x.hdr`` is refused rather than decoded as a PNG.
_MAGIC = {".hdr": (b"#?RADIANCE", b"#?RGBE"), ".pfm": (b"PF", b"Pf")}
_KIND = {".hdr": "a Radiance .hdr file (missing '#?RADIANCE')",
         ".pfm": "a .pfm file (expected 'PF' or 'Pf')"}


def _read_bitmap(path: Path, ext: str) -> np.ndarray:
    """``.hdr`` or ``.pfm`` with ``mitsuba.Bitmap``; old-style RLE ``.hdr``
    (which it does not decode) with :func:`_read_rgbe_old_rle`."""
    with open(path, "rb") as f:
        head = f.read(16)
    if not head.startswith(_MAGIC[ext]):
        raise SceneError(Loc(path), f"not {_KIND[ext]}")
    try:
        bmp = _bitmap_class()(str(path))
    except MemoryError as e:  # std::bad_alloc: a corrupt size in the header
        raise SceneError(Loc(path), f"cannot read {ext} image: its size does not fit "
                         "in memory (corrupt header?)") from e
    except RuntimeError as e:
        img = _read_rgbe_old_rle(path) if ext == ".hdr" else None
        if img is None:
            raise SceneError(Loc(path), f"cannot read {ext} image (truncated or corrupt): "
                             f"{_mitsuba_message(e)}") from e
        return img
    fmt, formats = bmp.pixel_format(), _bitmap_class().PixelFormat
    if fmt not in (formats.RGB, formats.Y):  # e.g. FORMAT=32-bit_rle_xyze
        raise SceneError(Loc(path), f"unsupported {ext} pixel format {fmt.name} "
                         "(only RGB or gray; .hdr: only FORMAT=32-bit_rle_rgbe)")
    return np.array(bmp, dtype=np.float32)


_RES_RE = re.compile(rb"-Y\s+(\d+)\s+\+X\s+(\d+)\s*")


def _read_rgbe_old_rle(path: Path) -> np.ndarray | None:
    """Decode an RGBE file whose scanlines are flat pixels with old-style
    run-length records, or return ``None`` when the file is not one.

    In the old encoding (Radiance before 1991) a pixel ``(1, 1, 1, k)``
    repeats the previous pixel ``k << s`` times, where ``s`` grows by 8 for
    each repeat record directly before it. Readers built on Walter's
    ``rgbe.c`` (Mitsuba's among them) decode such files as flat pixels and
    so run out of data; this decoder is only called after Mitsuba failed.
    A scanline in the new RLE encoding (``2, 2, w >> 8, w & 255``) means
    the file is not old-style: ``None``, and Mitsuba's error is reported.
    """
    data = path.read_bytes()
    header, sep, rest = data.partition(b"\n\n")
    res, nl, body = rest.partition(b"\n")
    if not (sep and nl):
        return None
    m = _RES_RE.fullmatch(res)
    if not m:
        line = res.decode("ascii", "replace")
        raise SceneError(Loc(path), f"unsupported .hdr resolution line {line!r} "
                         "(only '-Y H +X W', rows from the top)")
    h, w = int(m.group(1)), int(m.group(2))
    px = np.frombuffer(body, np.uint8, count=len(body) // 4 * 4).reshape(-1, 4)
    if len(px) < h:  # fewer records than scanlines: truncated
        return None
    repeat = (px[:, 0] == 1) & (px[:, 1] == 1) & (px[:, 2] == 1)
    new_rle = (px[:, 0] == 2) & (px[:, 1] == 2) & ((px[:, 2].astype(np.int32) << 8 | px[:, 3]) == w)
    out = np.empty((h, w, 4), np.uint8)
    i = 0
    for y in range(h):
        if i < len(px) and new_rle[i] and 8 <= w <= 0x7FFF:
            return None
        x, shift = 0, 0
        while x < w:
            if i >= len(px):
                return None  # truncated
            if repeat[i]:
                count = int(px[i, 3]) << shift
                if x == 0 or count > w - x:
                    return None
                out[y, x:x + count] = out[y, x - 1]
                x += count
                shift += 8
            else:
                out[y, x] = px[i]
                x += 1
                shift = 0
            i += 1
    e = out[..., 3].astype(np.int32)
    scale = np.where(e > 0, np.ldexp(np.float32(1.0), e - 136), np.float32(0.0))
    return out[..., :3].astype(np.float32) * scale[..., None].astype(np.float32)
