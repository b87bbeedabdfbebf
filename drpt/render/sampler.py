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
a pixel (from a multiple of ``2^m``) keep the stratification. pbrt-v4's
``PaddedSobolSampler`` is built the same way. Mitsuba's ``ldsampler`` shuffles the
indices per dimension too, but scrambles the values with one seed per pixel for every
dimension, so all of a pixel's 1-D draws take the same ``2^m`` values: where the largest is
below 0.95, its path tracer's Russian roulette (survival at most 0.95) never ends a path
that keeps its throughput, such as one trapped by total internal reflection in a glass box
(docs/performance.md, the dining room's NaN pixels). ``zsobol``
(:class:`ZSobolSampler`, pbrt-v4's ``ZSobolSampler``) draws from one such
sequence over the whole image in Morton order instead, which spreads the
remaining error as blue noise.

``stratified``, ``multijitter`` and ``orthogonal`` are Mitsuba's plugins of
those names (:class:`Stratified`, :class:`Multijitter`, :class:`Orthogonal`,
made for a sample count by :func:`strata_sampler`): a pixel's samples are a set
of strata per draw (a square grid; Kensler's correlated multi-jittered grid;
the rows of a multi-jittered orthogonal array over a prime), shuffled among the
samples by a random permutation (:func:`permute`) hashed from the seed, the
pixel and the dimension, with hashed offsets inside the strata. They keep
:class:`LDSampler`'s state, so everything that carries or packs one carries
them.

A path draws its dimensions in a fixed order (camera: pixel position, then the
lens; each bounce: light selection, light point, BSDF lobe, BSDF direction,
Russian roulette), so each decision of each bounce has a dimension of its own.
Next-event estimation picks its emitter from the light point's pair
(:func:`light_sample`), so the points stay stratified over all the emitters.
A sampler has PCG32's ``next_float32()`` plus ``next_2d()``; :func:`next_2d` draws a pair from either (for PCG32 two
``next_float32()`` calls, so the independent sampler's kernels are unchanged).
"""

from __future__ import annotations

import functools
import math

import drjit as dr
from drjit.auto import PCG32, Array2f, Float, UInt32, UInt64

from ..options import SAMPLERS  # noqa: F401  (the --sampler names)
from ..scene.model import mitsuba_sample_count

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


def ld_stream_key(seed: int) -> tuple[UInt32, UInt32]:
    """The 64-bit key of a render's low-discrepancy sequences, a hash of its ``seed``, as
    its low and high 32 bits in opaque ``UInt32``: what :meth:`LDSampler.for_pixels` and
    :meth:`ZSobolSampler.for_pixels_xy` take in place of the seed where it must be a
    device input (a frozen pass's, :mod:`drpt.render.frozen`)."""
    from .renderer import _mix_seed  # cycle: the renderer imports this module

    s = _mix_seed(seed, LD_STREAM)
    return dr.opaque(UInt32, s & 0xFFFFFFFF), dr.opaque(UInt32, s >> 32)


def _stream_key_halves(seed) -> tuple[UInt32, UInt32]:
    """The low and high 32 bits of the low-discrepancy key of ``seed``: the render's seed
    (an ``int``) or its :func:`ld_stream_key`."""
    return ld_stream_key(seed) if isinstance(seed, int) else seed


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
    dimension). A Dr.Jit struct, so it is loop state as PCG32 is. Every field is as wide
    as the widest of ``key``, ``index`` and ``step`` (a field given as one value for
    all lanes is broadcast, the same values): as the state of a symbolic loop, a field
    of another width than the loop's makes Dr.Jit record the loop's body again
    (:mod:`drpt.render.loops`)."""

    DRJIT_STRUCT = {"key": UInt32, "index": UInt32, "step": UInt32, "dim": UInt32}

    def __init__(self, key: UInt32 | None = None, index: UInt32 | None = None,
                 step: UInt32 | None = None):
        key = UInt32(0) if key is None else UInt32(key)
        index = UInt32(0) if index is None else UInt32(index)
        step = UInt32(1) if step is None else UInt32(step)
        n = max(dr.width(key), dr.width(index), dr.width(step))
        self.key, self.index, self.step = (v + dr.zeros(UInt32, n) if dr.width(v) != n else v
                                           for v in (key, index, step))
        self.dim = dr.zeros(UInt32, n)

    @classmethod
    def for_pixels(cls, seed, pixel: UInt32, index: UInt32, step: UInt32 | int = 1) -> LDSampler:
        """A sampler of pixels ``pixel`` (their ids in the image), at sample
        ``index``; ``seed`` is the render's (or its :func:`ld_stream_key`)."""
        lo, hi = _stream_key_halves(seed)  # 64 bits: both halves go into the key
        key = mix32(mix32(UInt32(pixel) ^ lo) + hi)
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


def pcg_keys(key: int) -> tuple:
    """The two opaque ``UInt64`` keys of :func:`pcg_streams` for ``key`` (made outside a
    frozen pass, whose inputs they are: :mod:`drpt.render.frozen`)."""
    from drjit.auto import UInt64

    return (dr.opaque(UInt64, key & 0xFFFFFFFFFFFFFFFF),
            dr.opaque(UInt64, _splitmix64((key ^ _SEQ_KEY) & 0xFFFFFFFFFFFFFFFF)))


def pcg_streams(n: int, key):
    """``n`` PCG32 streams, one per lane, for the 64-bit ``key`` (a hash of the seed and
    the pass; an ``int``, or its :func:`pcg_keys`): lane ``i``'s initial
    state and increment are SplitMix64 hashes of ``key + (i + 1) * gamma`` (the
    increment's with a second key), computed on the device from opaque keys (one kernel
    for every pass).

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
    k_state, k_seq = pcg_keys(key) if isinstance(key, int) else key
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


#: PCG32's multiplier (its state steps ``state * PCG32_MULT + inc`` mod 2^64, as Dr.Jit's)
PCG32_MULT = 0x5851F42D4C957F2D


def skip_draws(rng, count: int):
    """Where ``rng`` is a PCG32: a copy of it as it is, and ``rng`` itself moved past ``count``
    draws in one step (``state * M^count + inc * (1 + M + ... + M^(count - 1))`` mod 2^64: two
    multiplications instead of ``count`` dependent ones); the copy then draws what ``rng``
    would have drawn. For draws that only some lanes use, made in a symbolic ``if`` on them
    (:meth:`~drpt.render.integrators.path.PathIntegrator.bounce`): a packet that skips the
    branch pays for neither the values nor the chain of steps. Any other sampler: None,
    ``rng`` unchanged (an :class:`LDSampler`'s draws are a dimension counter)."""
    if not isinstance(rng, PCG32):
        return None
    start = PCG32(rng)
    mult = pow(PCG32_MULT, count, 1 << 64)
    add = sum(pow(PCG32_MULT, i, 1 << 64) for i in range(count)) % (1 << 64)
    rng.state = rng.state * UInt64(mult) + rng.inc * UInt64(add)
    return start


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
                    {"log2spp": log2spp, "digits": log2res + (log2spp + 1) // 2,
                     "perms": UInt32(_PERMS)})

    #: the 24 permutations of a base-4 digit, 2 bits per entry (a device array of the
    #: class :meth:`for_image` makes, created with it: a frozen pass's input,
    #: :mod:`drpt.render.frozen`, that its recording cannot upload itself)
    perms = None

    @classmethod
    def for_pixels_xy(cls, seed, x: UInt32, y: UInt32, index: UInt32, step: UInt32 | int = 1):
        """A sampler of pixels ``(x, y)`` at sample ``index`` (``step``: as
        :meth:`LDSampler.for_pixels`); ``seed`` is the render's (or its
        :func:`ld_stream_key`)."""
        lo, _ = _stream_key_halves(seed)
        out = cls(_morton2(x, y) << cls.log2spp, index, UInt32(step))
        out.seed = lo + dr.zeros(UInt32, dr.width(out.index))
        return out

    DRJIT_STRUCT = {"key": UInt32, "index": UInt32, "step": UInt32, "dim": UInt32, "seed": UInt32}

    def __init__(self, key=None, index=None, step=None):
        super().__init__(key, index, step)
        self.seed = dr.zeros(UInt32, dr.width(self.index))

    def _sample_index(self) -> UInt32:
        """The sequence index of the current sample and dimension (pbrt's GetSampleIndex)."""
        m = self.key | self.index
        odd = self.log2spp & 1
        dimhash = self.dim * 0x55555555
        out = dr.zeros(UInt32, dr.width(m))
        table = self.perms if self.perms is not None else UInt32(_PERMS)
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



#: rounds of :func:`permute`'s hash
PERMUTE_ROUNDS = 5


def permute(x: UInt32, n: int, seed: UInt32) -> UInt32:
    """A random permutation of ``0 .. n - 1`` (``n`` a Python int, at most 2^31), chosen by
    ``seed``, applied to ``x < n``: the role of Kensler's hash-based permutation ("Correlated
    Multi-Jittered Sampling", 2013; Mitsuba's ``permute_kensler``) in Mitsuba's samplers, by
    the same method, cycle walking: a bijective hash of the ``k``-bit integers (``2^k >= n``)
    keyed by ``seed`` is applied to ``x``, and again while the value is ``n`` or more; on the
    cycle through ``x`` the first value below ``n`` is ``x``'s image, so the whole is a
    bijection of ``0 .. n - 1`` (about ``2^k / n < 2`` applications on average). The hash is
    :data:`PERMUTE_ROUNDS` rounds of a key XOR, a multiplication by an odd number of the
    key, a multiplication by a constant and two xorshifts of the ``k`` bits (each a
    bijection); the round keys are steps of an LCG from a hash of ``seed``."""
    if n <= 1:
        return dr.zeros(UInt32, dr.width(x))
    k = (n - 1).bit_length()
    mask = (1 << k) - 1
    sh, sh2 = max(1, k // 2), max(1, (k + 1) // 3)
    s = mix32(seed ^ 0x2F6B3C1D)
    keys = []
    for _ in range(PERMUTE_ROUNDS):
        s = s * 0x2C1B3C6D + 0x297A2D39
        keys.append(s ^ (s >> 16))

    def bijection(v, keys):
        for key in keys:
            v = ((v ^ key) * (key >> 15 | 1)) & mask
            v = v ^ (v >> sh)
            v = ((v + (key >> 7)) * 0x2C1B3C6D) & mask
            v = v ^ (v >> sh2)
        return v

    x = bijection(UInt32(x), keys)
    if n == mask + 1:  # a power of two: every value is in range
        return x
    out = dr.while_loop((x, *keys), lambda v, *_: v >= n,
                        lambda v, *ks: (bijection(v, ks), *ks))
    return out[0]


#: the largest float32 below 1
ONE_MINUS = float.fromhex("0x1.fffffep-1")


def _jitter(h: UInt32, r: UInt32, jitter: bool, salt: int = 0x1B873593) -> Float:
    """A sample's offset inside its stratum: uniform from a hash of the dimension's seed
    ``h``, the sample ``r`` and ``salt`` (Mitsuba draws it from the lane's PCG32), or the
    stratum's middle without ``jitter``."""
    if not jitter:
        return dr.full(Float, 0.5, dr.width(r))
    return to_float(mix32(mix32(h ^ salt) + r * 0x85EBCA6B))


class StrataSampler(LDSampler):
    """The base of Mitsuba's stratified, multijitter and orthogonal samplers (see
    :func:`strata_sampler`): a pixel's samples are ``count`` strata per dimension, each
    dimension's strata shuffled among the samples by :func:`permute` with a seed hashed from
    ``(key, block, dimension)``, a sample's offset inside its stratum hashed from the same
    and its index. Sample ``index`` of a pixel is sample ``index mod count`` of its block
    ``index // count``: every ``count`` consecutive samples from a multiple of ``count`` are
    stratified, and a render beyond ``count`` samples (a live view's frames) draws fresh
    blocks. As :class:`LDSampler`'s, a value depends on the seed, pixel, sample index and
    dimension only, so chunked and resumed renders are the plain one bit for bit.
    Subclasses set the class attributes (:func:`strata_sampler`)."""

    count = 1  # samples per block (Mitsuba's sample_count, rounded as it rounds it)
    jitter = True

    DRJIT_STRUCT = {**LDSampler.DRJIT_STRUCT, "block": UInt32, "r": UInt32}

    def __init__(self, key=None, index=None, step=None):
        super().__init__(key, index, step)
        self._enter_block()

    def _enter_block(self) -> None:
        """``block``: the hash of the lane's pixel key and block; ``r``: the sample's place in
        its block (computed once per sample: every draw reads them)."""
        if self.count == 1:
            self.block, self.r = mix32(self.key + self.index * 0x632BE5AB), dr.zeros(UInt32, dr.width(self.index))
            return
        block = self.index // self.count
        self.block, self.r = mix32(self.key + block * 0x632BE5AB), self.index - block * self.count

    def _block(self) -> tuple[UInt32, UInt32]:
        return self.block, self.r

    def advance(self) -> None:
        super().advance()
        self._enter_block()

    def _dim_seed(self, seed: UInt32, dim: UInt32) -> UInt32:
        return mix32(seed ^ (dim * 0x9E3779B9))

    def next_float32(self) -> Float:
        """A 1-D draw: the pixel's samples one in each interval ``1 / count``."""
        seed, r = self._block()
        h = self._dim_seed(seed, self.dim)
        self.dim += 1
        p = permute(r, self.count, h)
        return dr.minimum((Float(p) + _jitter(h, r, self.jitter)) * (1.0 / self.count), ONE_MINUS)


class Stratified(StrataSampler):
    """Mitsuba's ``stratified``: ``count = res^2``; a 1-D draw puts a pixel's samples one in
    each of ``count`` intervals, a 2-D draw one in each cell of the ``res x res`` grid (the
    cells shuffled among the samples, each dimension by its own permutation)."""

    res = 1

    def next_2d(self) -> Array2f:
        seed, r = self._block()
        h = self._dim_seed(seed, self.dim)
        self.dim += 2
        p = permute(r, self.count, h)
        y = p // self.res if self.res > 1 else dr.zeros(UInt32, dr.width(p))
        x = p - y * self.res
        jx, jy = _jitter(h, r, self.jitter), _jitter(h, r, self.jitter, 0xCC9E2D51)
        return Array2f(dr.minimum((Float(x) + jx) * (1.0 / self.res), ONE_MINUS),
                       dr.minimum((Float(y) + jy) * (1.0 / self.res), ONE_MINUS))


class Multijitter(StrataSampler):
    """Mitsuba's ``multijitter`` (Kensler's correlated multi-jittered sampling): ``count =
    nx ny`` with ``ny = floor(sqrt(spp))``, ``nx = ceil(spp / ny)``; a 2-D draw puts one
    sample in each cell of the ``nx x ny`` grid and, inside its cell, in the sub-column and
    sub-row that makes the ``x`` values one per ``1 / count`` interval and the ``y`` values
    too (the sub-cells shuffled by one permutation per axis for the whole pixel); a 1-D draw
    is :class:`Stratified`'s."""

    nx = ny = 1

    def next_2d(self) -> Array2f:
        seed, r = self._block()
        h = self._dim_seed(seed, self.dim)
        self.dim += 2
        s = permute(r, self.count, h)
        y = s // self.nx if self.nx > 1 else s
        x = s - y * self.nx
        sx = permute(x, self.nx, mix32(h ^ 0x68BC21EB))  # x's sub-row inside its cell
        sy = permute(y, self.ny, mix32(h ^ 0x02E5BE93))  # y's sub-column
        jx, jy = _jitter(h, r, self.jitter), _jitter(h, r, self.jitter, 0xCC9E2D51)
        u = (Float(x) + (Float(sy) + jx) * (1.0 / self.ny)) * (1.0 / self.nx)
        v = (Float(y) + (Float(sx) + jy) * (1.0 / self.nx)) * (1.0 / self.ny)
        return Array2f(dr.minimum(u, ONE_MINUS), dr.minimum(v, ONE_MINUS))


class Orthogonal(StrataSampler):
    """Mitsuba's ``orthogonal``: an orthogonal array of strength ``strength`` over a prime
    ``res`` (``count = res^2``), with multi-jittered offsets. Every dimension of a sample
    reads the same row of the array (the pixel's rows shuffled once per block). Strength 2
    is Bose's construction: row ``(a0, a1)`` has ``a0`` in dimension 0, ``a1`` in 1 and ``a0
    + (j - 1) a1 mod res`` in dimension ``j >= 2``, so any two dimensions among ``0 ..
    res`` put one sample in each of the ``res x res`` cells of their square (dimension ``j``
    and ``j + res`` hold the same column, as in Mitsuba); inside its stratum a value's
    sub-stratum is its partner dimension's (``j xor 1``) column, so a 2-D draw from an even
    dimension is also multi-jittered. Strength ``t > 2`` is Bush's construction: row ``i``'s
    base-``res`` digits are a polynomial's coefficients, dimension ``j`` holds its value at
    ``j``, and ``res^2`` of its ``res^t`` rows are drawn, as Mitsuba draws them (a pixel's
    samples then are not the whole array). A 2-D draw is two 1-D draws."""

    res = 2
    strength = 2
    DRJIT_STRUCT = {**StrataSampler.DRJIT_STRUCT, "row": UInt32}

    def _enter_block(self) -> None:
        """Also ``row``: the sample's row of the array (the same for all its dimensions)."""
        super()._enter_block()
        rows = self.count if self.strength == 2 else self.res ** self.strength
        self.row = permute(self.r, rows, self.block)

    def next_float32(self) -> Float:
        seed, r = self._block()
        j = UInt32(self.dim)
        self.dim += 1
        p, q = self.res, j % self.res
        h = self._dim_seed(seed, j)
        i = self.row
        if self.strength == 2:
            a0 = i // p
            a1 = i - a0 * p
            partner = j ^ 1

            def column(c):
                m = (c + (p - 1)) % p  # (c - 1) mod p
                v = (a0 + m * a1) % p
                return dr.select(c == 0, a0, dr.select(c == 1, a1, v))

            stratum = permute(column(j), p, mix32(h ^ 0x51633E2D))
            sub = permute(column(partner), p, mix32(h ^ 0x68BC21EB))
            m = p
        else:
            rows = p ** self.strength
            phi = dr.zeros(UInt32, dr.width(i))
            digits = []
            rest = UInt32(i)
            for _ in range(self.strength):
                nxt = rest // p
                digits.append(rest - nxt * p)
                rest = nxt
            for d in reversed(digits):  # Horner, mod p at each step
                phi = (phi * q + d) % p
            m = rows // p
            stratum = permute(phi, p, mix32(h ^ 0x51633E2D))
            sub = permute((i // p) % m, m, mix32(h ^ 0x68BC21EB))
        u = (Float(stratum) + (Float(sub) + _jitter(h, r, self.jitter)) * (1.0 / m)) * (1.0 / p)
        return dr.minimum(u, ONE_MINUS)

    def next_2d(self) -> Array2f:
        u = self.next_float32()
        return Array2f(u, self.next_float32())

#: the samplers of :func:`strata_sampler`, by ``--sampler`` name
STRATA = {"stratified": Stratified, "multijitter": Multijitter, "orthogonal": Orthogonal}


@functools.lru_cache(maxsize=None)
def strata_sampler(name: str, spp: int, jitter: bool = True, strength: int = 2) -> type:
    """The class of Mitsuba's sampler ``name`` (``stratified``, ``multijitter`` or
    ``orthogonal``) for ``spp`` samples per pixel: its strata laid out for the sample count
    Mitsuba rounds ``spp`` to (:func:`drpt.scene.model.mitsuba_sample_count`;
    with fewer samples, a pixel's are the first ``spp`` of its shuffled strata)."""
    count = mitsuba_sample_count(name, spp)
    attrs = {"count": count, "jitter": bool(jitter)}
    if name == "stratified":
        attrs["res"] = math.isqrt(count)
    elif name == "multijitter":
        attrs["ny"] = math.isqrt(spp)
        attrs["nx"] = count // attrs["ny"]
    else:
        attrs["res"], attrs["strength"] = math.isqrt(count), int(strength)
    return type(f"{STRATA[name].__name__}_{count}", (STRATA[name],), attrs)


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
