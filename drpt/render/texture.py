"""Diffuse textures (``map_Kd``) on the device.

Each image is read with :func:`drpt.imageio.read_image` (``linear=True``:
8-bit sRGB is decoded to linear, float formats are taken as stored; alpha
is dropped, a gray image is repeated to three channels) and uploaded as a
``drjit.auto.Texture2f`` with bilinear filtering (``FilterMode.Linear``)
and repeat wrapping (``WrapMode.Repeat``), on which ``eval`` interpolates
*after* the sRGB decoding, as Mitsuba's ``bitmap`` does.

Texture coordinates
-------------------
drpt keeps OBJ uvs: ``v = 0`` is the *bottom* row of the image. A Dr.Jit
texture built from an ``(H, W, C)`` tensor has row 0 (the first row in
memory, i.e. the image's *top* row as :func:`read_image` returns it) at
``pos.y = 0``, and ``pos.x = 0`` at the left; texel ``(i, j)`` has its
center at ``((j + 0.5) / W, (i + 0.5) / H)``. So :meth:`TextureSet.lookup`
evaluates at ``pos = (u, 1 - v)``: the same point Mitsuba's ``bitmap``
samples at ``si.uv = (u, 1 - v)`` (what the exporter writes). Checked
against Mitsuba, including wrap-around at the borders, by
``tests/test_texture.py``.

Dispatch and cost
-----------------
Dr.Jit textures cannot be selected per lane, so :meth:`lookup` evaluates
each texture of the set under its own mask (``tex_id == k``) and merges the
results with ``select``: the traced kernel contains one bilinear lookup per
texture (code size and a few masked instructions grow linearly with the
number of textures; memory traffic only occurs on active lanes). One
texture needs no mask beyond ``active``. An empty set traces nothing and
returns 0.
"""

from __future__ import annotations

from os import PathLike

import drjit as dr
import numpy as np
from drjit.auto import Array2f, Array3f, Bool, TensorXf, Texture2f, UInt32

from ..imageio import read_image

__all__ = ["TextureSet", "load_rgb"]


def load_rgb(path: str | PathLike, raw: bool = False) -> np.ndarray:
    """``(H, W, 3)`` linear float32 texels of an image file (row 0 = top);
    ``raw``: 8/16-bit values as stored, without sRGB decoding (Mitsuba's ``raw``).

    Raises :class:`drpt.errors.SceneError` naming the file when it is
    missing, unreadable or malformed."""
    img = read_image(path, linear=not raw)
    c = img.shape[2]
    if c == 1:
        img = np.repeat(img, 3, axis=2)
    elif c >= 3:
        img = img[..., :3]  # drop alpha
    else:  # pragma: no cover - read_image returns 1, 3 or 4 channels
        img = np.concatenate([img, np.zeros(img.shape[:2] + (3 - c,), np.float32)], axis=2)
    return np.ascontiguousarray(img, dtype=np.float32)


class TextureSet:
    """The scene's textures, indexed by position in ``paths``."""

    def __init__(self, paths):
        self.paths = list(paths)
        self.textures: list = []
        self.shapes: list[tuple[int, int]] = []
        for p in self.paths:
            raw = getattr(p, "raw", False)  # a drpt.shading.Texture read raw (no sRGB decoding)
            if raw:
                p = p.path
            elif not isinstance(p, (str, PathLike)):  # a procedural texture (drpt.shading.Checkerboard)
                self.textures.append(_Checker(p))
                self.shapes.append((0, 0))
                continue
            img = load_rgb(p, raw=raw)
            self.shapes.append(img.shape[:2])
            self.textures.append(Texture2f(TensorXf(img), filter_mode=dr.FilterMode.Linear,
                                           wrap_mode=dr.WrapMode.Repeat))

    def __len__(self) -> int:
        return len(self.textures)

    def lookup(self, tex_id: UInt32, uv: Array2f, active: Bool = True, scalar: bool = False) -> Array3f:
        """Bilinear, repeat-wrapped linear RGB of texture ``tex_id`` at OBJ ``uv``
        (a procedural texture: its value there; ``scalar``: the one a float
        parameter reads, whose luminance the caller takes).

        Lanes that are inactive or whose id is out of range give 0."""
        if not self.textures:
            return Array3f(0.0)
        active = Bool(active)
        pos = Array2f(uv.x, 1.0 - uv.y)
        if len(self.textures) == 1:
            m = active & (tex_id == 0)
            return dr.select(m, _eval(self.textures[0], pos, uv, m, scalar), 0.0)
        out = Array3f(0.0)
        for k, tex in enumerate(self.textures):
            m = active & (tex_id == k)
            out = dr.select(m, _eval(tex, pos, uv, m, scalar), out)
        return out


    def gradient(self, tex_id: UInt32, uv: Array2f, active: Bool = True) -> Array2f:
        """The derivatives of texture ``tex_id``'s luminance along Mitsuba's ``u`` and
        ``v`` (``(u, 1 - v)`` of drpt's ``uv``) at ``uv``: Mitsuba's ``bitmap.eval_1_grad``,
        the bilinear interpolant's differences of the four texels around ``uv`` times the
        resolution. 0 for procedural textures and inactive lanes."""
        active = Bool(active)
        pos = Array2f(uv.x, 1.0 - uv.y)
        out = Array2f(0.0)
        for k, (tex, (h, w)) in enumerate(zip(self.textures, self.shapes)):
            image = getattr(tex, "tex", tex)  # an image texture, possibly wrapped with options
            if not hasattr(image, "eval_fetch") or image.filter_mode() != dr.FilterMode.Linear:
                continue  # procedural, or nearest (whose gradient is 0 almost everywhere)
            m = active & (tex_id == k)
            a = getattr(tex, "m", None) or (1.0, 0.0, 0.0, 0.0, 1.0, 0.0)  # a to_uv, row-major
            p = Array2f(pos.x * a[0] + pos.y * a[1] + a[2], pos.x * a[3] + pos.y * a[4] + a[5])
            f00, f10, f01, f11 = (_lum(Array3f(*c)) for c in image.eval_fetch(p, m))
            px = dr.fma(p.x, w, -0.5)
            py = dr.fma(p.y, h, -0.5)
            w1x, w1y = px - dr.floor(px), py - dr.floor(py)
            w0x, w0y = 1.0 - w1x, 1.0 - w1y
            gx = dr.fma(w0y, f10 - f00, w1y * (f11 - f01))
            gy = dr.fma(w0x, f01 - f00, w1x * (f11 - f10))
            # Mitsuba's transposed multiply by to_uv, then times the resolution
            du = (a[0] * gx + a[3] * gy) * w
            dv = (a[1] * gx + a[4] * gy) * h
            out = dr.select(m, Array2f(du, dv), out)
        return out


def _lum(c: Array3f):
    return 0.212671 * c.x + 0.715160 * c.y + 0.072169 * c.z


def _eval(tex, pos: Array2f, uv: Array2f, active: Bool, scalar: bool) -> Array3f:
    if isinstance(tex, _Checker):
        return tex.eval(pos, scalar)  # pos = (u, 1 - v): Mitsuba's uv
    return Array3f(tex.eval(pos, active))


class _Checker:
    """Mitsuba's ``checkerboard`` (:class:`drpt.shading.Checkerboard`) at Mitsuba's uv,
    ``(u, 1 - v)`` of drpt's OBJ-convention uv."""

    def __init__(self, spec):
        self.m = [float(x) for x in spec.to_uv]
        self.c0 = tuple(float(x) for x in spec.color0)
        self.c1 = tuple(float(x) for x in spec.color1)
        # a float parameter reads a constant color's channel mean (Mitsuba's eval_1 of an
        # rgb value), returned gray so that the caller's luminance keeps it
        self.m0 = (sum(self.c0) / 3.0,) * 3
        self.m1 = (sum(self.c1) / 3.0,) * 3

    def eval(self, uv: Array2f, scalar: bool) -> Array3f:
        m = self.m
        s = uv.x * m[0] + uv.y * m[1] + m[2]
        t = uv.x * m[3] + uv.y * m[4] + m[5]
        a = (s - dr.floor(s)) > 0.5
        b = (t - dr.floor(t)) > 0.5
        if scalar:  # Mitsuba's eval_1 swaps the colors
            return dr.select(a != b, Array3f(*self.m0), Array3f(*self.m1))
        return dr.select(a == b, Array3f(*self.c0), Array3f(*self.c1))
