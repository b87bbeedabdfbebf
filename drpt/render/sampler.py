"""Sample generators: what a path's random numbers are drawn from.

``independent`` (the default) gives every lane its own PCG32 stream
(:class:`drjit.auto.PCG32`, :meth:`Renderer._trace_pass
<drpt.render.renderer.Renderer._trace_pass>`). ``ldsampler`` is a padded,
Owen-scrambled (0,2)-sequence (:class:`LDSampler`): every 2-D draw of a path
(the pixel position, the lens, a light point, a BSDF direction) takes the
first two dimensions of Sobol's sequence at the pixel's sample index, which
for ``2^m`` samples puts exactly one sample of the pixel in each of the
``2^m`` cells of every elementary grid (``2^a x 2^b`` cells, ``a + b = m``)
of that 2-D projection; 1-D draws take its first dimension (one sample per
``1 / 2^m`` interval). Each dimension (a 2-D draw counts two) has its own
random shuffle of the sample indices and its own random Owen scrambling of
the values, both hashed from ``(seed, pixel, dimension)`` (Burley, "Practical
Hash-based Owen Scrambling", JCGT 2020), so different dimensions, pixels and
seeds are decorrelated and every draw is uniform in its own right; the
shuffle is a nested uniform scramble of the index's bits (each bit flipped by
a hash of the bits above it), which maps every aligned block of ``2^m``
indices onto an aligned block, so any ``2^m`` consecutive sample indices of
a pixel (from a multiple of ``2^m``) keep the stratification. Mitsuba's ``ldsampler`` and pbrt-v4's
``PaddedSobolSampler`` are built the same way. ``zsobol``
(:class:`ZSobolSampler`, pbrt-v4's ``ZSobolSampler``) draws from one such
sequence over the whole image in Morton order instead, which spreads the
remaining error as blue noise.

A path draws its dimensions in a fixed order (camera: pixel position, then the
lens; each bounce: light selection, light point, BSDF lobe, BSDF direction,
Russian roulette), so each decision of each bounce has a dimension of its own.
Next-event estimation picks its emitter from the light point's pair
(:func:`light_sample`), so the points stay stratified over all the emitters.
A sampler has PCG32's ``next_float32()`` plus ``next_2d()``; :func:`next_2d` draws a pair from either (for PCG32 two
``next_float32()`` calls, so the independent sampler's kernels are unchanged).
"""

from __future__ import annotations

import drjit as dr
from drjit.auto import Array2f, Float, UInt32

from ..options import SAMPLERS  # noqa: F401  (the --sampler names)

#: mixed into the seed of the low-discrepancy sampler's hashes
LD_STREAM = 0x5A3B1E


def uses_ld(name: str) -> bool:  # (zsobol too: ZSobolSampler is an LDSampler)
    """Whether the ``--sampler`` ``name`` draws from :class:`LDSampler`."""
    return name != "independent"


def mix32(x: UInt32) -> UInt32:
    """A 32-bit integer hash (Wellons' lowbias32): every input bit changes
    about half of the output bits."""
    x = x ^ (x >> 16)
    x = x * 0x7FEB352D
    x = x ^ (x >> 15)
    x = x * 0x846CA68B
    return x ^ (x >> 16)


def laine_karras(x: UInt32, seed: UInt32) -> UInt32:
    """Burley's hash-based Laine-Karras permutation: each bit is flipped by a
    hash of the bits *below* it (and ``seed``), an Owen scramble of the
    bit-reversed value."""
    x = x + seed
    x = x ^ (x * 0x6C50B47C)
    x = x ^ (x * 0xB82F1E52)
    x = x ^ (x * 0xC7AFE638)
    return x ^ (x * 0x8D22F6E6)


def owen_reversed(x: UInt32, seed: UInt32) -> UInt32:
    """The Owen scramble of the fraction whose digits are ``x``'s bits from the
    least significant up (a value in reversed-bit form), as a fraction with its
    first digit in the top bit."""
    return dr.brev(laine_karras(x, seed))


def shuffle(index: UInt32, seed: UInt32) -> UInt32:
    """A random permutation of the sample indices (nested uniform scramble of
    the index bits): it maps each aligned block of ``2^m`` indices onto an
    aligned block of ``2^m``."""
    return dr.brev(laine_karras(dr.brev(index), seed))


def sobol1_reversed(i: UInt32) -> UInt32:
    """Sobol's second dimension at index ``i``, in reversed-bit form (digit
    ``t`` of the fraction in bit ``t``). Its generator matrix is Pascal's
    triangle mod 2: digit ``t`` is the XOR of the index bits ``k`` with
    ``C(k, t)`` odd, i.e. (Lucas) with ``t`` a submask of ``k``: a superset
    sum over the bit positions, five shift-and-mask steps."""
    for shift, mask in ((1, 0x55555555), (2, 0x33333333), (4, 0x0F0F0F0F),
                        (8, 0x00FF00FF), (16, 0x0000FFFF)):
        i = i ^ ((i >> shift) & mask)
    return i


def to_float(bits: UInt32) -> Float:
    """A fraction's top 24 bits as a float32 in [0, 1)."""
    return Float(bits >> 8) * (1.0 / (1 << 24))


class LDSampler:
    """A padded, Owen-scrambled (0,2)-sequence per pixel (see the module).

    Per lane: ``key`` (a hash of the seed and the lane's pixel), ``index`` (the
    sample's index among its pixel's samples), ``step`` (what
    :meth:`advance` adds to it: the pixel's lanes) and ``dim`` (the next
    dimension). A Dr.Jit struct, so it is loop state as PCG32 is."""

    DRJIT_STRUCT = {"key": UInt32, "index": UInt32, "step": UInt32, "dim": UInt32}

    def __init__(self, key: UInt32 | None = None, index: UInt32 | None = None,
                 step: UInt32 | None = None):
        self.key = UInt32(0) if key is None else UInt32(key)
        self.index = UInt32(0) if index is None else UInt32(index)
        self.step = UInt32(1) if step is None else UInt32(step)
        self.dim = dr.zeros(UInt32, dr.width(self.index))

    @classmethod
    def for_pixels(cls, seed: int, pixel: UInt32, index: UInt32, step: UInt32 | int = 1) -> LDSampler:
        """A sampler of pixels ``pixel`` (their ids in the image), at sample
        ``index``; ``seed`` is the render's."""
        from .renderer import _mix_seed  # cycle: the renderer imports this module

        s = _mix_seed(seed, LD_STREAM)  # 64 bits: both halves go into the key
        key = mix32(mix32(UInt32(pixel) ^ dr.opaque(UInt32, s & 0xFFFFFFFF)) + dr.opaque(UInt32, s >> 32))
        return cls(key, index, UInt32(step))

    def _seed(self) -> UInt32:
        """The hash of ``(key, dim)`` that scrambles the current dimension."""
        return mix32(self.key ^ (self.dim * 0x9E3779B9))

    def next_float32(self) -> Float:
        """The next 1-D dimension: Sobol's first (van der Corput), shuffled and scrambled."""
        h = self._seed()
        i = shuffle(self.index, h)
        self.dim += 1
        return to_float(owen_reversed(i, mix32(h ^ 0x68E31DA4)))

    def next_2d(self) -> Array2f:
        """The next two dimensions: Sobol's first two, from one shuffle of the
        index (so the pair is a (0,2)-sequence), each scrambled by its own hash."""
        h = self._seed()
        i = shuffle(self.index, h)
        self.dim += 2
        x = owen_reversed(i, mix32(h ^ 0x68E31DA4))
        y = owen_reversed(sobol1_reversed(i), mix32(h ^ 0xB5297A4D))
        return Array2f(to_float(x), to_float(y))

    def advance(self) -> None:
        """On to this lane's next sample (path regeneration): ``index += step``, dimension 0."""
        self.index += self.step
        self.dim = dr.zeros(UInt32, dr.width(self.dim))


_GOLDEN64 = 0x9E3779B97F4A7C15
#: mixed into the key of the streams' increments (their states take the key itself)
_SEQ_KEY = 0xD1B54A32D192ED03


def _splitmix64(z):
    """SplitMix64's finaliser (Stafford's mix 13) of UInt64 ``z`` (on the device) or of a
    Python int (on the host): a bijection on 64 bits, every input bit changing about
    half of the output bits."""
    if isinstance(z, int):
        m = 0xFFFFFFFFFFFFFFFF
        z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & m
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & m
        return z ^ (z >> 31)
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9
    z = (z ^ (z >> 27)) * 0x94D049BB133111EB
    return z ^ (z >> 31)


def pcg_streams(n: int, key: int):
    """``n`` PCG32 streams, one per lane, for the 64-bit ``key`` (a hash of the seed and
    the pass): lane ``i``'s initial state and increment are SplitMix64 hashes of ``key +
    (i + 1) * gamma`` (the increment's with a second key), computed on the device from
    opaque keys (one kernel for every pass).

    Not :class:`drjit.auto.PCG32`'s ``PCG32(n, initstate, initseq)``: it gives lane ``i``
    the state ``initstate + i`` and the increment ``initseq + i``, and such streams are
    correlated (the pairs of values of nearby lanes fail a chi-square test of
    independence by far: tests/render/test_sampler.py). The renderer gives a pixel's
    samples and its neighbours' adjacent or regularly spaced lanes, so a pixel filter that
    splats a sample into its neighbours summed correlated samples, and a pixel at a
    light's edge was noisier than Mitsuba's (docs/performance.md, "Per-pixel variance
    against Mitsuba's"). Mitsuba hashes its streams (``sample_tea_32``) for the same
    reason."""
    from drjit.auto import PCG32, UInt64

    lane = UInt64(dr.arange(UInt32, n)) + 1
    k_state = dr.opaque(UInt64, key & 0xFFFFFFFFFFFFFFFF)
    k_seq = dr.opaque(UInt64, _splitmix64((key ^ _SEQ_KEY) & 0xFFFFFFFFFFFFFFFF))
    step = lane * _GOLDEN64
    rng = PCG32(n)
    rng.seed(_splitmix64(k_state + step), _splitmix64(k_seq + step))
    return rng


def next_2d(rng) -> Array2f:
    """A 2-D sample from ``rng``: :meth:`LDSampler.next_2d`, or two draws of a PCG32."""
    if isinstance(rng, LDSampler):
        return rng.next_2d()
    return Array2f(rng.next_float32(), rng.next_float32())


def next_path(rng) -> None:
    """Before a lane's next path (path regeneration): an :class:`LDSampler` moves to
    the lane's next sample index; a PCG32 stream just goes on."""
    if isinstance(rng, LDSampler):
        rng.advance()


def light_sample(scene, rng, u_sel: Float, u_light: Array2f, active, ref=None) -> tuple[Float, Array2f]:
    """The light selection's and the emitter's samples for next-event estimation: with an
    :class:`LDSampler` both from the stratified pair ``u_light`` (the selection from its
    first value, which is then rescaled:
    :meth:`~drpt.render.lights.selection.LightSelection.reuse`, ``ref`` the shading
    point), else ``(u_sel, u_light)`` as drawn. A spatially varying selection (the light
    BVH, ``static`` False) rescales ``u`` along its walk, so it keeps its own dimension."""
    if isinstance(rng, LDSampler) and scene.emitter_selection.static:
        return scene.emitter_selection.reuse(u_light, ref, active)
    return u_sel, u_light


def _morton2(x: UInt32, y: UInt32) -> UInt32:
    """The Morton (Z-order) code of ``(x, y)`` (16 bits each): x in the even bits."""
    def spread(v):
        v = (v | (v << 8)) & 0x00FF00FF
        v = (v | (v << 4)) & 0x0F0F0F0F
        v = (v | (v << 2)) & 0x33333333
        return (v | (v << 1)) & 0x55555555
    return spread(UInt32(x)) | (spread(UInt32(y)) << 1)


#: the 24 permutations of (0, 1, 2, 3), each packed in 8 bits (2 bits per image)
_PERMS = [sum(p[i] << (2 * i) for i in range(4)) for p in __import__("itertools").permutations(range(4))]


class ZSobolSampler(LDSampler):
    """pbrt-v4's ``ZSobolSampler`` (Ahmed and Wonka, "Screen-Space Blue-Noise Diffusion of
    Monte Carlo Sampling Error via Hierarchical Ordering of Pixels", 2020): one Owen-scrambled
    Sobol (0,2)-sequence over the whole image, whose index is the pixel's Morton code
    followed by the sample's index, with each base-4 digit of it permuted by a hash of the
    digits above it and the dimension. A pixel's samples are an aligned block of the
    sequence (stratified as :class:`LDSampler`'s), and neighbouring pixels' blocks are
    stratified together, so the error is spread as blue noise. ``key`` holds the pixel's
    Morton code shifted past the sample bits; :meth:`for_image` makes the class of an image
    size and spp (its digit counts are class attributes)."""

    log2spp = 0
    digits = 0

    @classmethod
    def for_image(cls, width: int, height: int, spp: int) -> type:
        """The class for an image of ``width x height`` pixels and ``spp`` samples per
        pixel (None where the index does not fit 32 bits)."""
        log2spp = max(0, (spp - 1).bit_length())
        log2res = max(0, (max(width, height) - 1).bit_length())
        if 2 * log2res + log2spp > 32:
            return None
        return type(f"ZSobol_{log2res}_{log2spp}", (cls,),
                    {"log2spp": log2spp, "digits": log2res + (log2spp + 1) // 2})

    @classmethod
    def for_pixels_xy(cls, seed: int, x: UInt32, y: UInt32, index: UInt32, step: UInt32 | int = 1):
        """A sampler of pixels ``(x, y)`` at sample ``index`` (``step``: as
        :meth:`LDSampler.for_pixels`); ``seed`` is the render's."""
        from .renderer import _mix_seed  # cycle: the renderer imports this module

        s = _mix_seed(seed, LD_STREAM) & 0xFFFFFFFF
        out = cls(_morton2(x, y) << cls.log2spp, index, UInt32(step))
        out.seed = dr.opaque(UInt32, s) + dr.zeros(UInt32, dr.width(out.index))
        return out

    DRJIT_STRUCT = {"key": UInt32, "index": UInt32, "step": UInt32, "dim": UInt32, "seed": UInt32}

    def __init__(self, key=None, index=None, step=None):
        super().__init__(key, index, step)
        self.seed = UInt32(0)

    def _sample_index(self) -> UInt32:
        """The sequence index of the current sample and dimension (pbrt's GetSampleIndex)."""
        m = self.key | self.index
        odd = self.log2spp & 1
        dimhash = self.dim * 0x55555555
        out = dr.zeros(UInt32, dr.width(m))
        table = UInt32(_PERMS)
        for i in range(self.digits - 1, odd - 1, -1):
            shift = 2 * i - odd
            digit = (m >> shift) & 3
            higher = m >> (shift + 2) if shift + 2 < 32 else UInt32(0)
            p = (mix32(higher ^ dimhash) >> 24) % 24
            perm = dr.gather(UInt32, table, p)
            out |= ((perm >> (2 * digit)) & 3) << shift
        if odd:
            out |= (m & 1) ^ (mix32((m >> 1) ^ dimhash) & 1)
        return out

    def next_float32(self) -> Float:
        """The next dimension's value in ``[0, 1)`` for each lane."""
        i = self._sample_index()
        h = mix32(self.seed ^ (self.dim * 0x9E3779B9))
        self.dim += 1
        return to_float(owen_reversed(i, h))

    def next_2d(self) -> Array2f:
        """The next two dimensions, stratified together (a 2-D Sobol point), in ``[0, 1)^2``."""
        i = self._sample_index()
        h = mix32(self.seed ^ (self.dim * 0x9E3779B9))
        self.dim += 2
        x = owen_reversed(i, mix32(h ^ 0x68E31DA4))
        y = owen_reversed(sobol1_reversed(i), mix32(h ^ 0xB5297A4D))
        return Array2f(to_float(x), to_float(y))


def pack(rng) -> tuple:
    """A sampler's state as two UInt64 arrays (the wavefront integrator's buffers): a PCG32's
    ``(state, inc)``; an :class:`LDSampler`'s ``key | index << 32`` and ``dim | step << 32``
    (a :class:`ZSobolSampler`'s ``seed`` in place of ``step``, which one path per lane does
    not use)."""
    from drjit.auto import UInt64

    if not isinstance(rng, LDSampler):
        return rng.state, rng.inc
    other = rng.seed if isinstance(rng, ZSobolSampler) else rng.step
    return (UInt64(rng.key) | (UInt64(rng.index) << 32), UInt64(rng.dim) | (UInt64(other) << 32))


def unpack(kind: type, a, b):
    """The sampler of class ``kind`` whose state :func:`pack` gave as ``(a, b)``."""
    if not issubclass(kind, LDSampler):
        rng = kind()
        rng.state, rng.inc = a, b
        return rng
    rng = kind(UInt32(a), UInt32(a >> 32), UInt32(1))
    rng.dim = UInt32(b)
    if issubclass(kind, ZSobolSampler):
        rng.seed = UInt32(b >> 32)
    else:
        rng.step = UInt32(b >> 32)
    return rng
