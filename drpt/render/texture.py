"""Diffuse textures (``map_Kd``) on the device.

Each image is read with :func:`drpt.imageio.read_image` (``linear=True``:
8-bit sRGB is decoded to linear, float formats are taken as stored; alpha
is dropped, a gray image is repeated to three channels) and uploaded as a
``drjit.auto.Texture2f`` with bilinear filtering (``FilterMode.Linear``)
and repeat wrapping (``WrapMode.Repeat``), on which ``eval`` interpolates
*after* the sRGB decoding, as Mitsuba's ``bitmap`` does.

A Mitsuba ``bitmap`` with other options (:class:`drpt.materials.spec.Texture`'s
``filter_type``, ``wrap_mode``, ``raw``, ``to_uv``) is a :class:`Bitmap`: the
same Dr.Jit texture with that filter and wrap mode, looked up at ``to_uv``
times Mitsuba's uv. A ``mesh_attribute`` (:class:`drpt.materials.spec.MeshAttribute`)
reads the hit triangle's corner values instead (``lookup``'s ``si``), and a
``checkerboard`` is procedural; a scene without them traces none of this.

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
``tests/render/test_texture.py``.

Dispatch and cost
-----------------
Dr.Jit textures cannot be selected per lane, so :meth:`lookup` evaluates
each texture a call site can meet (``among``: the materials pass the ids the
field, weight or map references; by default every texture of the set) under
its own mask (``tex_id == k``) and merges the results with ``select``: the
traced kernel contains one bilinear lookup per such texture (code size and a
few masked instructions grow linearly with their number; memory traffic only
occurs on active lanes). One texture needs no mask beyond ``active``. An
empty set traces nothing and returns 0.

A ``bitmap`` with ``raw`` (a normal map) of 8-bit channels is kept as its codes
(:class:`Packed8`, a quarter of the float texture's bytes), looked up bit for bit as the
float texture would be.

Bump maps read only the luminance of the four texels around a point
(:meth:`TextureSet.gradient`); the ids given as ``gradients`` (the bump maps'
textures) are also kept as one-channel textures of their texels' luminances,
computed on the device by the kernel's own float32 expression, so the gradients
are the same to the bit while each fetch reads a quarter of the bytes (Dr.Jit
keeps an RGB texture as four channels), which matters where the map is
minified and nearly every fetch misses the caches. A gray 8-bit bump map with repeat
wrapping is kept instead as its footprints' codes (:class:`GrayFootprints`): one 32-bit
gather per lookup, the same luminances to the bit.
"""

from __future__ import annotations

from os import PathLike

import drjit as dr
import numpy as np
from drjit.auto import Array2f, Array3f, Bool, Float, Int32, TensorXf, Texture2f, UInt32

from ..errors import DrptError
from ..imageio import decoding_table, read_codes, read_image
from ..materials.spec import Checkerboard, MeshAttribute, Texture

__all__ = ["Bitmap", "GrayFootprints", "Packed8", "TextureSet", "load_rgb"]


def load_rgb(path: str | PathLike, raw: bool = False) -> np.ndarray:
    """``(H, W, 3)`` linear float32 texels of an image file (row 0 = top);
    ``raw``: 8-bit values as stored (no sRGB decoding, Mitsuba's ``raw``).

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

    def __init__(self, paths, triangles=None, gradients: tuple[int, ...] = ()):
        self.paths = list(paths)
        self.textures: list = []
        self.shapes: list[tuple[int, int]] = []
        #: per id in ``gradients`` (the bump maps' textures) that is a bilinear image: its
        #: luminance as a one-channel texture, which :meth:`gradient` reads
        self.luminance: dict[int, Texture2f] = {}
        for p in self.paths:
            if isinstance(p, MeshAttribute):  # the shapes' own values
                self.textures.append(_Attribute(p, triangles))
                self.shapes.append((0, 0))
                continue
            if isinstance(p, Checkerboard):  # a procedural texture
                self.textures.append(_Checker(p))
                self.shapes.append((0, 0))
                continue
            raw = isinstance(p, Texture) and p.raw
            codes = read_codes(p.path) if raw and len(self.textures) not in gradients else None
            if codes is not None:  # a raw 8-bit image: its codes, decoded per lookup
                self.textures.append(Packed8.of(codes, p))
                self.shapes.append(codes.shape[:2])
                continue
            if isinstance(p, Texture):  # an image with Mitsuba bitmap's options
                self.textures.append(Bitmap(p))
                self.shapes.append(self.textures[-1].shape)
                continue
            img = load_rgb(p)
            self.shapes.append(img.shape[:2])
            self.textures.append(Texture2f(TensorXf(img), filter_mode=dr.FilterMode.Linear,
                                           wrap_mode=dr.WrapMode.Repeat))
        #: per id in ``gradients`` that is a gray 8-bit image with bilinear filtering and
        #: repeat wrapping: its footprints' codes (:class:`GrayFootprints`), which
        #: :meth:`gradient` reads in place of the luminance texture
        self.footprints: dict[int, GrayFootprints] = {}
        for k in gradients:
            image = getattr(self.textures[k], "tex", self.textures[k])
            if hasattr(image, "eval_fetch") and image.filter_mode() == dr.FilterMode.Linear:
                fp = GrayFootprints.of(self.paths[k]) if image.wrap_mode() == dr.WrapMode.Repeat else None
                if fp is not None:
                    self.footprints[k] = fp
                else:
                    self.luminance[k] = _luminance_texture(image)

    def __len__(self) -> int:
        return len(self.textures)

    def lookup(self, tex_id: UInt32, uv: Array2f, active: Bool = True, scalar: bool = False,
               si=None, among: tuple[int, ...] | None = None) -> Array3f:
        """Bilinear, repeat-wrapped linear RGB of texture ``tex_id`` at OBJ ``uv``
        (a procedural texture: its value there; ``scalar``: the one a float
        parameter reads, whose luminance the caller takes; a mesh attribute: its
        value at the interaction ``si``'s point of its primitive).

        ``among``: the ids ``tex_id`` can hold on active lanes (host side, e.g. the textures
        one field references); only those are traced, so a floor's reflectance does not
        evaluate a leaf's opacity map. ``None``: every texture of the set.

        Lanes that are inactive or whose id is out of range (or not in ``among``) give 0."""
        ids = range(len(self.textures)) if among is None else among
        if not ids:
            return Array3f(0.0)
        active = Bool(active)
        pos = Array2f(uv.x, 1.0 - uv.y)
        if len(ids) == 1:
            k = ids[0]
            m = active & (tex_id == k)
            return dr.select(m, _eval(self.textures[k], pos, uv, m, scalar, si), 0.0)
        out = Array3f(0.0)
        for k in ids:
            m = active & (tex_id == k)
            out = dr.select(m, _eval(self.textures[k], pos, uv, m, scalar, si), out)
        return out


    def gradient(self, tex_id: UInt32, uv: Array2f, active: Bool = True,
                 among: tuple[int, ...] | None = None) -> Array2f:
        """The derivatives of texture ``tex_id``'s luminance along Mitsuba's ``u`` and
        ``v`` (``(u, 1 - v)`` of drpt's ``uv``) at ``uv``: Mitsuba's ``bitmap.eval_1_grad``,
        the bilinear interpolant's differences of the four texels around ``uv`` times the
        resolution. 0 for procedural textures and inactive lanes.

        ``among``: as :meth:`lookup`'s, the ids ``tex_id`` can hold on active lanes (the
        bump maps' textures); only those are traced, other lanes give 0. ``None``: every
        texture of the set."""
        active = Bool(active)
        pos = Array2f(uv.x, 1.0 - uv.y)
        out = Array2f(0.0)
        ids = range(len(self.textures)) if among is None else among
        for k in ids:
            tex, (h, w) = self.textures[k], self.shapes[k]
            image = getattr(tex, "tex", tex)  # an image texture, possibly wrapped with options
            if not hasattr(image, "eval_fetch") or image.filter_mode() != dr.FilterMode.Linear:
                continue  # procedural, or nearest (whose gradient is 0 almost everywhere)
            m = active & (tex_id == k)
            a = getattr(tex, "m", None) or (1.0, 0.0, 0.0, 0.0, 1.0, 0.0)  # a to_uv, row-major
            p = Array2f(pos.x * a[0] + pos.y * a[1] + a[2], pos.x * a[3] + pos.y * a[4] + a[5])
            if k in self.footprints:  # a gray 8-bit map: one 32-bit gather per footprint
                f00, f10, f01, f11 = self.footprints[k].fetch(p, m)
            elif k in self.luminance:  # the texels' luminances, a quarter of the RGB texture's bytes
                f00, f10, f01, f11 = (c[0] for c in self.luminance[k].eval_fetch(p, m))
            else:
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


def _luminance_texture(image: Texture2f) -> Texture2f:
    """A one-channel texture of ``image``'s texel luminances (:func:`_lum`, computed by the
    device's float32 arithmetic, so each is bit for bit what a kernel computes from the RGB
    texel), with ``image``'s filter and wrap modes."""
    t = image.tensor()
    h, w = t.shape[0], t.shape[1]
    flat = t.array
    n = h * w
    idx = dr.arange(UInt32, n) * t.shape[2]
    c = Array3f(dr.gather(Float, flat, idx), dr.gather(Float, flat, idx + 1), dr.gather(Float, flat, idx + 2))
    lum = _lum(c)
    dr.eval(lum)
    return Texture2f(TensorXf(lum, (h, w, 1)), filter_mode=image.filter_mode(), wrap_mode=image.wrap_mode())


def _eval(tex, pos: Array2f, uv: Array2f, active: Bool, scalar: bool, si=None) -> Array3f:
    if isinstance(tex, _Attribute):
        return tex.eval(si, active)
    if isinstance(tex, _Checker):
        return tex.eval(pos, scalar)  # pos = (u, 1 - v): Mitsuba's uv
    if isinstance(tex, (Bitmap, Packed8)):
        return tex.eval(pos, active)
    return Array3f(tex.eval(pos, active))


_FILTERS = {"bilinear": dr.FilterMode.Linear, "nearest": dr.FilterMode.Nearest}
_WRAPS = {"repeat": dr.WrapMode.Repeat, "mirror": dr.WrapMode.Mirror, "clamp": dr.WrapMode.Clamp}


class Bitmap:
    """Mitsuba's ``bitmap`` with its options (:class:`drpt.materials.spec.Texture`): Dr.Jit's
    texture (the one Mitsuba's uses) with the filter and wrap mode, the texels sRGB-decoded
    unless ``raw``, looked up at ``to_uv`` times Mitsuba's uv."""

    def __init__(self, spec: Texture):
        img = load_rgb(spec.path, raw=spec.raw)
        self.shape = img.shape[:2]
        self.m = None if spec.to_uv is None else [float(x) for x in spec.to_uv]
        self.tex = Texture2f(TensorXf(img), filter_mode=_FILTERS[spec.filter_type],
                             wrap_mode=_WRAPS[spec.wrap_mode])

    def eval(self, uv: Array2f, active: Bool = True) -> Array3f:
        """The texel value at Mitsuba's uv (``(u, 1 - v)`` of drpt's)."""
        m = self.m
        if m is not None:
            uv = Array2f(uv.x * m[0] + uv.y * m[1] + m[2], uv.x * m[3] + uv.y * m[4] + m[5])
        return Array3f(self.tex.eval(uv, active))


class Packed8:
    """An 8-bit image (PNG, JPEG, TGA, BMP) kept as its codes, one ``uint32`` per texel
    (``R | G << 8 | B << 16``, a gray image's code once), a quarter of the bytes of the
    float32 RGB texture :class:`Bitmap` and the plain textures keep (Dr.Jit stores three
    channels as four floats), looked up as that texture is, bit for bit.

    A lookup reads the four codes of its bilinear footprint (one 32-bit gather each) and
    decodes each channel through the image's 256-entry table
    (:func:`drpt.imageio.decoding_table`: sRGB-decoded, or ``raw`` codes over 255), whose
    values are :func:`drpt.imageio.read_image`'s for that code; the position, the wrapped
    corners, the weights and the sum are Dr.Jit's ``Texture2f.eval`` (``tex_eval`` of its
    ``texture_impl.h``: ``fma(uv, res, -0.5)``, its floor, the corners in the order
    ``(x0, y0), (x1, y0), (x0, y1), (x1, y1)`` summed by ``fma``; nearest: the texel at
    ``floor(uv res)``), so the values are the float texture's to the bit
    (``tests/render/test_texture.py``). A minified texture (a sphere showing a 2048x2048
    map at 192x192 pixels) misses the caches on nearly every fetch; the codes take 16 MB
    where the floats take 64 MB. ``to_uv`` (``m``, row-major 2x3) as :class:`Bitmap`'s.

    :class:`TextureSet` keeps the ``raw`` bitmaps (normal maps) so, whose codes a division
    decodes; an sRGB-decoded image stays a float texture: its twelve table gathers per
    lookup cost more than the bytes they save (docs/performance.md, "Textures: 8-bit
    codes, bump maps' footprints")."""

    def __init__(self, codes: np.ndarray, table: np.ndarray, filter_mode=dr.FilterMode.Linear,
                 wrap_mode=dr.WrapMode.Repeat, m=None):
        h, w, c = codes.shape
        self.shape = (h, w)
        self.m = m
        self.gray = c < 3
        self.nearest = filter_mode == dr.FilterMode.Nearest
        self._filter, self.wrap = filter_mode, wrap_mode
        c32 = codes.astype(np.uint32)
        packed = c32[..., 0] if self.gray else c32[..., 0] | (c32[..., 1] << 8) | (c32[..., 2] << 16)
        self.texels = UInt32(np.ascontiguousarray(packed).ravel())
        table = np.asarray(table, np.float32)
        #: raw codes over 255 are decoded by a division (exact, as the table's float64
        #: quotient rounded; by an opaque divisor, which Dr.Jit does not turn into a
        #: multiplication by its reciprocal), other tables by a gather
        self.divisor = dr.opaque(Float, 255.0) if np.array_equal(table, decoding_table(False)) else None
        self.table = Float(table)

    @classmethod
    def of(cls, codes: np.ndarray, p) -> Packed8:
        """The texture of a scene's image ``p`` (a path: sRGB-decoded, bilinear, repeat; a
        :class:`~drpt.materials.spec.Texture`: its options) from its codes."""
        if not isinstance(p, Texture):
            return cls(codes, decoding_table(True))
        m = None if p.to_uv is None else [float(x) for x in p.to_uv]
        return cls(codes, decoding_table(not p.raw), _FILTERS[p.filter_type], _WRAPS[p.wrap_mode], m)

    def filter_mode(self):
        """The filter, as a Dr.Jit texture's ``filter_mode()``."""
        return self._filter

    def wrap_mode(self):
        """The wrap mode, as a Dr.Jit texture's ``wrap_mode()``."""
        return self.wrap

    def _wrap(self, i: Int32, res: int) -> Int32:
        return _wrap(i, res, self.wrap)

    def _texel(self, x: Int32, y: Int32, active: Bool) -> Array3f:
        code = dr.gather(UInt32, self.texels, UInt32(y * self.shape[1] + x), active)
        chans = (code,) if self.gray else (code & 0xFF, (code >> 8) & 0xFF, code >> 16)
        if self.divisor is not None:
            vals = [Float(c) / self.divisor for c in chans]
        else:
            vals = [dr.gather(Float, self.table, c, active) for c in chans]
        return Array3f(*(vals * 3 if self.gray else vals))

    def _footprint(self, uv: Array2f):
        h, w = self.shape
        px = dr.fma(uv.x, w, -0.5)
        py = dr.fma(uv.y, h, -0.5)
        ix, iy = Int32(dr.floor(px)), Int32(dr.floor(py))
        w1x, w1y = px - Float(ix), py - Float(iy)
        xs = (self._wrap(ix, w), self._wrap(ix + 1, w))
        ys = (self._wrap(iy, h), self._wrap(iy + 1, h))
        return xs, ys, (1.0 - w1x, w1x), (1.0 - w1y, w1y)

    def _uv(self, uv: Array2f) -> Array2f:
        m = self.m
        if m is None:
            return uv
        return Array2f(uv.x * m[0] + uv.y * m[1] + m[2], uv.x * m[3] + uv.y * m[4] + m[5])

    def eval(self, uv: Array2f, active: Bool = True) -> Array3f:
        """The filtered value at Mitsuba's uv (``(u, 1 - v)`` of drpt's), ``to_uv`` applied."""
        uv = self._uv(uv)
        active = Bool(active)
        h, w = self.shape
        if self.nearest:
            x = self._wrap(Int32(dr.floor(uv.x * w)), w)
            y = self._wrap(Int32(dr.floor(uv.y * h)), h)
            return self._texel(x, y, active)
        xs, ys, wx, wy = self._footprint(uv)
        out = None
        for corner in range(4):
            bx, by = corner & 1, corner >> 1
            c = self._texel(xs[bx], ys[by], active)
            weight = wx[bx] * wy[by]
            out = c * weight if out is None else dr.fma(c, weight, out)
        return out

    def eval_fetch(self, uv: Array2f, active: Bool = True) -> list:
        """The four texels of the bilinear footprint at ``uv`` (Dr.Jit's ``eval_fetch``:
        ``(x0, y0), (x1, y0), (x0, y1), (x1, y1)``), each as three channels; ``to_uv`` is
        the caller's (as for a Dr.Jit texture)."""
        active = Bool(active)
        xs, ys, _, _ = self._footprint(uv)
        return [list(self._texel(xs[c & 1], ys[c >> 1], active)) for c in range(4)]


def _wrap(i: Int32, res: int, mode) -> Int32:
    """Dr.Jit's ``tex_wrap`` of the integer coordinate ``i`` on an axis of ``res`` texels:
    clamped, or ``i mod res`` (Euclidean), reflected in the periods ``floor(i / res)`` that
    are odd (mirror). The period comes from a float estimate corrected by one step either
    way (exact for ``|i| < 2^23``), not from an integer division, which the CPU's vector
    units lack (LLVM would divide lane by lane); beyond that the texel may differ from
    Dr.Jit's but stays inside the image."""
    if mode == dr.WrapMode.Clamp:
        return dr.clip(i, 0, res - 1)
    q = Int32(dr.floor(Float(i) * (1.0 / res)))
    mod = i - q * res
    low, high = mod < 0, mod >= res
    mod = dr.select(low, mod + res, dr.select(high, mod - res, mod))
    if mode == dr.WrapMode.Mirror:
        q = dr.select(low, q - 1, dr.select(high, q + 1, q))
        mod = dr.select((q & 1) == 0, mod, res - 1 - mod)
    return dr.clip(mod, 0, res - 1)  # (a no-op for |i| < 2^23: memory safety beyond)


class GrayFootprints:
    """A gray 8-bit bump map (every texel's channels equal) with repeat wrapping, kept as
    the codes of each texel's bilinear footprint: texel ``(x, y)`` holds in one ``uint32``
    the codes of ``(x, y), (x + 1, y), (x, y + 1), (x + 1, y + 1)`` (wrapped), so that
    :meth:`fetch` reads a footprint with one 32-bit gather, in one cache line, where the
    luminance texture's ``eval_fetch`` makes four gathers in two rows of the image. A
    code's luminance is the kernel's own expression of its decoded value: a raw code's
    value by an exact division (as :class:`Packed8`'s), an sRGB code's read from a
    256-entry table computed on the device from :func:`drpt.imageio.decoding_table`'s
    values; so the four values are the luminance texture's (and the RGB texture's
    luminances) bit for bit. Same bytes as the luminance texture (4 per texel)."""

    def __init__(self, codes: np.ndarray, table: np.ndarray):
        h, w = codes.shape
        self.shape = (h, w)
        c = codes.astype(np.uint32)
        right = np.roll(c, -1, axis=1)
        packed = c | (right << 8) | (np.roll(c, -1, axis=0) << 16) | (np.roll(right, -1, axis=0) << 24)
        self.records = UInt32(np.ascontiguousarray(packed).ravel())
        table = np.asarray(table, np.float32)
        #: raw codes: the luminance computed from the code over 255 (an exact division, as
        #: :class:`Packed8` decodes them), else read from the table
        self.divisor = dr.opaque(Float, 255.0) if np.array_equal(table, decoding_table(False)) else None
        t = Float(table)
        self.lum = _lum(Array3f(t, t, t))
        dr.eval(self.lum)

    @classmethod
    def of(cls, p) -> GrayFootprints | None:
        """The footprints of the scene's image ``p`` (a path or a
        :class:`~drpt.materials.spec.Texture`), or None where it is not a gray 8-bit image."""
        codes = read_codes(getattr(p, "path", p))
        if codes is None:
            return None
        gray = codes[..., 0]
        if codes.shape[2] >= 3 and not (np.array_equal(gray, codes[..., 1]) and np.array_equal(gray, codes[..., 2])):
            return None
        raw = bool(getattr(p, "raw", False))
        return cls(np.ascontiguousarray(gray), decoding_table(not raw))

    def fetch(self, uv: Array2f, active: Bool) -> tuple[Float, Float, Float, Float]:
        """The luminances of the footprint's corners ``(x0, y0), (x1, y0), (x0, y1),
        (x1, y1)`` at the texture position ``uv`` (``to_uv`` applied), as Dr.Jit's
        ``eval_fetch`` orders them."""
        h, w = self.shape
        x = _wrap(Int32(dr.floor(dr.fma(uv.x, w, -0.5))), w, dr.WrapMode.Repeat)
        y = _wrap(Int32(dr.floor(dr.fma(uv.y, h, -0.5))), h, dr.WrapMode.Repeat)
        code = dr.gather(UInt32, self.records, UInt32(y * w + x), active)
        corners = [(code >> s) & 0xFF for s in (0, 8, 16, 24)]
        if self.divisor is not None:
            return tuple(_lum(Array3f(t, t, t)) for t in (Float(c) / self.divisor for c in corners))
        return tuple(dr.gather(Float, self.lum, c, active) for c in corners)


def _vec3(a: np.ndarray) -> Array3f:
    a = np.ascontiguousarray(a, dtype=np.float32).reshape(-1, 3)
    return Array3f(a[:, 0].copy(), a[:, 1].copy(), a[:, 2].copy())


class _Attribute:
    """Mitsuba's ``mesh_attribute`` (:class:`drpt.materials.spec.MeshAttribute`): the attribute's
    corner values of the hit triangle blended with the barycentric coordinates of the hit
    point, computed from the point as Mitsuba's ``barycentric_coordinates`` does (a face
    attribute has equal corners), times ``scale``; 1 channel is gray. Other primitives
    (spheres, planes) read 0."""

    def __init__(self, spec, triangles):
        attrs = getattr(triangles, "attributes", None) or {}
        if spec.name not in attrs:
            raise DrptError(f"mesh_attribute '{spec.name}': no shape of the scene has it")
        a = np.asarray(attrs[spec.name], np.float64) * float(spec.scale)
        if a.shape[2] == 1:
            a = np.repeat(a, 3, axis=2)
        self.n = len(a)
        self.face = spec.name.startswith("face_")
        self.v0, self.v1, self.v2 = (_vec3(a[:, k]) for k in range(3))
        p = np.asarray(triangles.positions, np.float32).astype(np.float64)
        self.p0, self.e1, self.e2 = _vec3(p[:, 0]), _vec3(p[:, 1] - p[:, 0]), _vec3(p[:, 2] - p[:, 0])

    def eval(self, si, active: Bool) -> Array3f:
        act = Bool(active) & si.valid & (si.prim < self.n)
        i = dr.select(act, si.prim, 0)
        if self.face:  # equal corners: no blending
            return dr.select(act, dr.gather(Array3f, self.v0, i, act), 0.0)
        e1 = dr.gather(Array3f, self.e1, i, act)
        e2 = dr.gather(Array3f, self.e2, i, act)
        rel = si.p - dr.gather(Array3f, self.p0, i, act)
        d00, d01, d11 = dr.dot(e1, e1), dr.dot(e1, e2), dr.dot(e2, e2)
        d20, d21 = dr.dot(rel, e1), dr.dot(rel, e2)
        inv = dr.rcp(dr.maximum(d00 * d11 - d01 * d01, 1e-30))
        b1 = (d11 * d20 - d01 * d21) * inv
        b2 = (d00 * d21 - d01 * d20) * inv
        v = (dr.gather(Array3f, self.v0, i, act) * (1.0 - b1 - b2)
             + dr.gather(Array3f, self.v1, i, act) * b1 + dr.gather(Array3f, self.v2, i, act) * b2)
        return dr.select(act, v, 0.0)


class _Checker:
    """Mitsuba's ``checkerboard`` (:class:`drpt.materials.spec.Checkerboard`) at Mitsuba's uv,
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
