"""Environment light: an HDR latitude-longitude map infinitely far away.

Direction <-> image mapping (Mitsuba 3's ``envmap`` with identity ``to_world``)
------------------------------------------------------------------------------
World +Y is up. A unit world direction ``d`` (pointing from the scene toward
the sky, i.e. the direction a ray escapes in) maps to

* ``u = atan2(d.x, -d.z) / (2 pi)``, wrapped into ``[0, 1)`` -- ``u = 0`` is
  toward -Z, ``u = 1/4`` toward +X, ``u = 1/2`` toward +Z, ``u = 3/4``
  toward -X (``u`` grows left to right in the image);
* ``v = acos(d.y) / pi`` -- ``v = 0`` straight up (+Y), ``v = 1`` straight
  down; image row 0 is the top (``v = 0``).

Inverse: ``d = (sin(2 pi u) sin(pi v), cos(pi v), -cos(2 pi u) sin(pi v))``.

Where the texels sit (the bilinear lookup, exactly Mitsuba 3.9's
``EnvironmentMapEmitter::eval_spectrum``) for a ``W x H`` image:

* columns are *texel centered* and periodic: column ``i`` is at
  ``u = (i + 0.5) / W``; between column ``W-1`` and column ``0`` (across
  ``u = 0``) the lookup interpolates through the wrap (Mitsuba stores an
  extra column equal to column 0);
* rows are *vertex centered*: row ``j`` is at ``v = j / (H - 1)``, so row 0
  *is* the north pole and row ``H-1`` the south pole (the whole first row
  collapses onto the +Y direction; which of its texels is seen straight up
  follows ``atan2`` of the two tiny components, as in Mitsuba).

So with ``x = frac(u - 0.5/W) * W`` and ``y = v * (H - 1)``, the radiance is
the bilinear blend of texels ``(floor(x), floor(y))`` .. ``(floor(x)+1,
floor(y)+1)`` (column ``W`` = column 0, indices clamped to ``W-1`` /
``H-2``), times ``scale``. Maps Mitsuba refuses (narrower than 2 or shorter
than 3 texels) work here too: ``H = 1`` is constant in ``v``, ``W = 1``
constant in ``u``. One deliberate difference: Mitsuba wraps ``v`` with
``v - floor(v)`` as well, so the exact direction ``(0, -1, 0)`` (when
``acos`` returns exactly pi) reads the *north* pole row; drpt clamps and
reads the south pole row (a set of measure zero).

``d`` must be unit length; like Mitsuba, the lookup does not renormalise
it. This was verified against Mitsuba 3.9.1 by evaluating its ``envmap``
emitter at 50 000 random directions (agreement to ~2e-6 relative, float32
``atan2``/``acos`` rounding) and by rendering maps with one marked texel
through a ``perspective`` camera (``tests/render/lights/test_envmap.py``);
the matching Mitsuba emitter is ``envmap`` with ``to_world`` = identity
(:func:`drpt.export.mitsuba_envmap.to_mitsuba`).

Sampling
--------
The sampling grid is the grid of *bilinear patches*: cell ``(j, i)``
(``j < max(H-1, 1)`` latitude bands, ``i < W`` columns) covers ``x`` in
``[i, i+1)`` and ``y`` in ``[j, j+1)``, where ``eval`` blends the four texels
at its corners. A cell is picked with probability proportional to
``mean luminance of its 4 corners * Omega_j`` (``Omega_j = (2 pi / W)
(cos theta_j - cos theta_{j+1})``, the cell's solid angle; the row from a
marginal alias table, the column from that row's conditional alias table:
:func:`alias_tables`, Walker's method: one uniform cell pick and one threshold
test each, two independent lookups, no search).
Inside the cell the position ``(fx, ft)`` is drawn
from the *bilinear* density of the corner luminances ``c00, c10, c01, c11``::

    q(fx, ft) = bilerp(c, fx, ft) / mean(c)        (integrates to 1 on [0,1]^2)

exactly (``ft`` from the linear marginal ``lerp(c00+c10, c01+c11, ft)``,
then ``fx`` from the linear conditional), where ``fx`` is the fraction
across the columns and ``ft`` the fraction of the band's ``cos theta``
range (``cos theta`` rather than ``theta``, an equal-area split, computed
as ``1 -/+ cos theta`` so it stays accurate near the poles). The density in
*solid angle* is::

    pdf(d) = P(row) P(col | row) / Omega_cell * q(fx, ft)

so ``pdf`` follows the radiance's luminance inside each cell, not only from
cell to cell: the luminance of ``eval(d) / pdf(d)`` is constant up to the
difference between ``ft`` and ``eval``'s ``fy`` (linear in ``theta``), a
second-order effect in thin bands (on the showcase skies its relative
variance is ~1e-4 of that of a piecewise-constant density, which was 0.3).
Because ``cos theta`` rather than ``theta`` is parameterised, there is no
``1 / sin theta`` factor: the pdf is bounded (at most ``4 / min Omega``) at
and near the poles and needs no clamp. The weight is positive wherever
``eval`` can be, except on cell edges (measure zero).

``P(row)`` and ``P(col | row)`` are the probabilities the *stored float32*
alias thresholds realise (computed exactly from them), so ``pdf`` is the
density the sampler realises, whatever the rounding of the weights, to the
resolution of the float32 fraction ``f`` below: each cell's probability to
about ``2^-23`` (absolute). A uniform
number picks a cell ``i = floor(u N)`` and its fraction ``f = u N - i`` is
tested against the threshold; ``f`` rescaled to the kept or the alias part of
``[0, 1)`` is the uniform number used inside the cell. So that every positive
cell's threshold stays well above the resolution of ``f``, a positive cell
weight is raised to at least ``1e-6`` of its row total (and a positive row to
``1e-6`` of the total) -- this only moves a negligible amount of probability
toward nearly black cells. Cell luminances are summed in float64 and
normalised by the brightest cell before they are stored in float32, so texels
up to the float32 maximum keep their weight; texels more than ~1e-40 times dimmer
than the brightest may underflow to a zero weight (irrelevant for real
maps). The kernels scale corner luminances before adding them, for the
same reason.

:meth:`EnvironmentLight.sample` returns ``(d, eval(d), pdf(d))`` computed
from the cell it picked and the point ``(fx, ft)`` it drew there: the cell's
four texels, gathered once for the draw, give the radiance (at ``fx`` and
``eval``'s row fraction ``fy``, from ``d.y``) and the density, with no
second lookup of ``d`` (its ``atan2``, texel gathers and band tables).
They equal :meth:`eval` and :meth:`pdf` of ``d`` up to float rounding: ``d``
maps back to where it was drawn up to the rounding of ``atan2``, ``acos`` and
the band fraction (relative differences of about 1e-6), and of ``cos theta``
itself within a few texels of a pole, where ``1 - cos theta`` is small (up to
about 1e-2 there: the density is that of the point drawn, the lookup's that of
the rounded ``d``). Next-event estimation and a BSDF sample that reaches the
same direction weigh it alike (MIS) to that precision. The density is that of the cell
drawn, positive also for a sample that lands by round-off on the edge of a
zero-weight neighbour (where :meth:`pdf` of ``d`` may read 0). Callers skip
pdf-0 samples (inactive lanes, a black map).

MIS compensation
----------------
:meth:`EnvironmentLight.compensated` (Mitsuba's ``envmap`` ``mis_compensation``; Karlik et
al. 2019, "MIS compensation: optimizing sampling techniques in multiple importance
sampling") is the same map with the sampling scheme above run on the corner weights
``max(luminance - offset, 0)`` instead of the luminance, ``offset`` the mean luminance of the
texels (each texel alike, as Mitsuba), or no compensation where the map is nearly constant
(minimum within 1% of the mean, Mitsuba's rule). Next-event estimation then draws where the
map is brighter than its mean, and the BSDF or phase sample, combined by MIS, covers the
rest: the compensated density is 0 in every cell whose four corners are at or below the
mean, so it is unbiased only beside such a complement (``DeviceScene`` gives it to the
next-event estimation of ``path`` and ``volpath`` alone, :func:`drpt.render.scene.env_compensated`).
Its radiance, power (``luminance_integral``) and texel data are the map's.

Input sanitising: NaN, +-Inf and negative channel values are set to 0 and
the affected texels counted in :attr:`EnvironmentLight.warnings`. A gray
image is replicated to RGB, an alpha channel is dropped. ``scale`` multiplies
the radiance (like Mitsuba's ``scale``), not the sampling density.
"""

from __future__ import annotations

import copy
import math
from os import PathLike
from pathlib import Path

import drjit as dr
import numpy as np
from drjit.auto import Array2f, Array3f, Array4f, Bool, Float, UInt32

from ...errors import DrptError
from ...imageio import read_image
from . import EmitterSample

__all__ = ["EnvironmentLight", "SkyEmitter", "sanitize_image", "check_radius", "compensation_offset",
           "LUMINANCE"]

#: Luminance weights of linear sRGB / Rec. 709 (Mitsuba's ``luminance()``).
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])

#: Minimum weight of a positive cell relative to its row (and of a positive
#: row relative to the total), so that its alias threshold is never below what a
#: float32 uniform number resolves.
WEIGHT_FLOOR = 1e-6

_ONE_MINUS_EPS = float(np.nextafter(np.float32(1.0), np.float32(0.0)))


def sanitize_image(image) -> tuple[np.ndarray, int]:
    """``(H, W, 3)`` float32 C-contiguous ``image`` with NaN/Inf/negative
    values set to 0 (a copy when anything is changed; the input is never
    modified), and the number of texels that had such a value.

    Accepts ``(H, W)``, ``(H, W, 1)`` (gray), ``(H, W, 2)`` (gray + alpha),
    ``(H, W, 3)`` and ``(H, W, 4)`` (alpha dropped).
    """
    img = np.asarray(image, dtype=np.float32)
    if img.ndim == 2:
        img = img[:, :, None]
    if img.ndim != 3 or img.shape[0] < 1 or img.shape[1] < 1 or img.shape[2] not in (1, 2, 3, 4):
        raise DrptError(f"environment map must be an (H, W, 1|3|4) image, got shape {img.shape}")
    if img.shape[2] <= 2:
        img = np.repeat(img[:, :, :1], 3, axis=2)
    else:
        img = img[:, :, :3]
    img = np.ascontiguousarray(img, dtype=np.float32)
    lo, hi = img.min(), img.max()  # NaN propagates into both
    if lo >= 0.0 and np.isfinite(hi):
        return img, 0  # may share memory with the input (never written)
    img = img.copy()
    with np.errstate(invalid="ignore"):
        bad = ~(img >= 0.0) | ~np.isfinite(img)  # NaN fails >= 0
    count = int(np.count_nonzero(bad.any(axis=2)))
    img[bad] = 0.0
    return img, count


def check_radius(scene_bounds_lo, scene_bounds_hi, radius) -> str | None:
    """A warning message if geometry reaches beyond the skybox radius, else None.

    drpt puts the environment map infinitely far away; the seed renderer
    used a sky sphere of radius ``R`` centered at the world origin, which
    would hide (or cut) geometry farther than ``R`` from the origin. Bounds
    are the axis-aligned box of the *bounded* geometry; non-finite
    coordinates (infinite planes) and empty boxes (lo > hi) are ignored.
    """
    lo = np.asarray(scene_bounds_lo, dtype=np.float64).reshape(3)
    hi = np.asarray(scene_bounds_hi, dtype=np.float64).reshape(3)
    R = float(radius)
    if not np.all(lo <= hi):
        return None
    ext = np.maximum(np.abs(lo), np.abs(hi))
    ext = np.where(np.isfinite(ext), ext, 0.0)
    reach = float(np.linalg.norm(ext))  # farthest box corner from the origin
    if not (math.isfinite(R) and R > 0.0):
        return (f"skybox radius {R:g} is not a positive number; the environment map is "
                "treated as infinitely far away")
    if reach > R:
        return (f"skybox radius {R:g}: geometry reaches up to {reach:g} from the origin; "
                "drpt treats the environment map as infinitely far away, so geometry "
                "beyond the sky sphere stays visible (the seed renderer would hide it)")
    return None


class EnvironmentLight:
    """Infinitely distant light from a lat-long RGB radiance map (see module docs)."""

    def __init__(self, image, scale: float = 1.0, name: str = "environment map",
                 compensation: bool = False):
        scale = float(scale)
        if not (math.isfinite(scale) and scale >= 0.0):
            raise DrptError(f"{name}: scale must be a finite number >= 0, got {scale}")
        img, bad = sanitize_image(image)
        self.name = name
        self.scale = scale
        self.warnings: list[str] = []
        if bad:
            self.warnings.append(f"{name}: {bad} NaN/Inf/negative texel{'s' if bad != 1 else ''} "
                                 "set to 0")
        H, W = img.shape[:2]
        self.height, self.width = H, W
        ny = max(H - 1, 1)  # latitude bands (bilinear patch rows)
        self._ny = ny

        # Texel data, each texel (r, g, b, luminance): one packet gather reads a corner's
        # radiance and its sampling weight. The lookup wraps column W to column 0 (Mitsuba
        # stores that extra column) and a single row serves as its own neighbor.
        self._data = _texels(img)
        self._half_texel = 0.5 / W

        theta = np.arange(ny + 1) * (math.pi / ny)
        # 1 - cos(theta) and 1 + cos(theta), accurate near either pole
        one_minus_cos = 2.0 * np.sin(0.5 * theta) ** 2
        one_plus_cos = 2.0 * np.cos(0.5 * theta) ** 2
        north = 0.5 * (theta[:-1] + theta[1:]) <= 0.5 * math.pi
        t0 = np.where(north, one_minus_cos[:-1], one_plus_cos[:-1])
        dt = np.where(north, one_minus_cos[1:] - one_minus_cos[:-1],
                      one_plus_cos[1:] - one_plus_cos[:-1])
        self._t0 = Float(t0.astype(np.float32))
        self._dt = Float(dt.astype(np.float32))
        self._north = Bool(north)

        lum = img @ LUMINANCE  # float64
        #: the luminance that next-event estimation's density ignores (see
        #: :meth:`compensated`); 0: the density follows the luminance itself
        self.offset = 0.0
        self._tables(lum)
        if compensation:
            self._compensate(lum)

    def _tables(self, lum: np.ndarray) -> None:
        """The sampling tables of the corner weights ``max(lum - offset, 0)`` (host side:
        cell weights summed in float64, stored float32 relative to the brightest cell, so
        texels up to the float32 maximum neither overflow nor vanish)."""
        H, W, ny = self.height, self.width, self._ny
        if self.offset > 0.0:
            lum = np.maximum(lum - self.offset, 0.0)
        # mean luminance of each bilinear patch's 4 corners = its mean luminance
        cell = lum + np.roll(lum, -1, axis=1)  # columns i, i+1
        cell = cell[:-1] + cell[1:] if H > 1 else cell * 2.0  # rows j, j+1
        peak = float(cell.max())
        cell = (cell / peak if peak > 0.0 else cell).astype(np.float32)
        theta = np.arange(ny + 1) * (math.pi / ny)
        dcos = 2.0 * np.sin(0.5 * (theta[:-1] + theta[1:])) * math.sin(0.5 * math.pi / ny)
        omega = (2.0 * math.pi / W) * dcos  # solid angle of a cell in band j
        w = cell
        w *= omega[:, None].astype(np.float32)
        if self.offset == 0.0:
            self.is_black = not (self.scale > 0.0 and np.any(w > 0.0))
            #: the integral of the luminance over the sphere (W / m^2; a cell's mean is a
            #: quarter of its corners' sum): the sky's power for the light selection
            #: (:class:`SkyEmitter`); a compensated copy keeps the map's own
            self.luminance_integral = (float(self.scale * peak * w.sum(dtype=np.float64) / 4.0)
                                       if peak > 0.0 else 0.0)

        if self.is_black:
            pdf = np.zeros((ny, W), np.float32)
            self._rows = _interleaved(np.ones(ny, np.float32), np.arange(ny, dtype=np.uint32))
            self._cols = _interleaved(np.ones(ny * W, np.float32), np.tile(np.arange(W, dtype=np.uint32), ny))
        else:
            w = _floored(w.astype(np.float64))
            q_cols, a_cols, p_cols = alias_tables(w)
            q_rows, a_rows, p_rows = alias_tables(_floored(w.sum(axis=1)[None, :]))
            pdf = (p_cols * (p_rows[0] / omega)[:, None]).astype(np.float32)
            self._rows = _interleaved(q_rows[0], a_rows[0])
            self._cols = _interleaved(q_cols.ravel(), a_cols.ravel())
        self._pdf = Float(pdf.ravel())

    def _compensate(self, lum: np.ndarray) -> None:
        """Rebuild the tables for MIS compensation (see :meth:`compensated`), unless the
        map is nearly constant."""
        offset = compensation_offset(lum)
        if offset > 0.0 and not self.is_black:
            self.offset = offset
            self._tables(lum)

    def compensated(self) -> "EnvironmentLight":
        """This map sampled with *MIS compensation* (Karlik et al. 2019, "MIS compensation:
        optimizing sampling techniques in multiple importance sampling"; Mitsuba's
        ``envmap`` ``mis_compensation``): the density follows ``max(luminance - offset,
        0)`` instead of the luminance, ``offset`` the mean texel luminance
        (:func:`compensation_offset`), so that next-event estimation spends its samples
        on the bright parts and leaves the rest to the BSDF or phase sample that MIS
        combines with it. The density is 0 where all four texels around a direction are
        below the mean: **unbiased only where another technique covers those
        directions**, never for a technique used alone (light tracing, bdpt's light
        subpaths, Whitted's direct light). The radiance (``eval``) is the map's. Shares the
        texel data; returns ``self`` for a nearly constant or black map (nothing to move).
        """
        if self.offset > 0.0 or self.is_black:
            return self
        lum = self._data.numpy().reshape(self.height, self.width, 4)[:, :, :3] @ LUMINANCE
        out = copy.copy(self)
        out._compensate(lum)
        return out if out.offset > 0.0 else self

    @classmethod
    def from_file(cls, path: str | PathLike, scale: float = 1.0) -> "EnvironmentLight":
        """Load a lat-long ``.hdr``/``.exr``/... map (``SceneError`` if unreadable)."""
        return cls(read_image(path), scale=scale, name=Path(path).name)

    # ------------------------------------------------------------ lookup
    def _lookup(self, d: Array3f):
        """Cell (ix, iy) and bilinear weights (fx, fy) of a unit direction
        (not renormalised, exactly as Mitsuba's lookup)."""
        u = dr.atan2(d.x, -d.z) * (1.0 / (2.0 * math.pi))
        v = dr.safe_acos(d.y) * (1.0 / math.pi)
        x = u - self._half_texel
        x = (x - dr.floor(x)) * self.width
        y = v * self._ny
        ix = dr.minimum(UInt32(x), self.width - 1)
        iy = dr.minimum(UInt32(y), self._ny - 1)
        return ix, iy, x - Float(ix), y - Float(iy)

    def _corners(self, ix, iy, active):
        """The 4 texels of cell (ix, iy), each ``(r, g, b, luminance)``: ``v00, v10``
        on row iy (columns ix, ix+1), ``v01, v11`` on the row below."""
        W = self.width
        ix1 = dr.select(ix + 1 < W, ix + 1, 0)  # periodic in u
        r0 = iy * W
        r1 = dr.minimum(iy + 1, self.height - 1) * W
        return (dr.gather(Array4f, self._data, r0 + ix, active),
                dr.gather(Array4f, self._data, r0 + ix1, active),
                dr.gather(Array4f, self._data, r1 + ix, active),
                dr.gather(Array4f, self._data, r1 + ix1, active))

    def _eval_cell(self, corners, fx, fy) -> Array3f:
        v00, v10, v01, v11 = (Array3f(c.x, c.y, c.z) for c in corners)
        return _bilerp(v00, v10, v01, v11, fx, fy) * self.scale

    def _weight(self, c: Array4f) -> Float:
        """A texel's sampling weight: its luminance (stored with it), less :attr:`offset`
        (clamped at 0) where the map is compensated (no code for it otherwise)."""
        if self.offset > 0.0:
            return dr.maximum(c.w - self.offset, 0.0)
        return c.w

    def _band_fraction(self, d: Array3f, iy, active) -> Float:
        """``ft``: where ``cos theta`` of ``d`` lies in band ``iy``, in [0, 1]."""
        north = dr.gather(Bool, self._north, iy, active)
        t = dr.select(north, 1.0 - d.y, 1.0 + d.y)
        t0 = dr.gather(Float, self._t0, iy, active)
        dt = dr.gather(Float, self._dt, iy, active)
        return dr.clip((t - t0) / dt, 0.0, 1.0)

    def _pdf_cell(self, corners, ix, iy, fx, ft, active) -> Float:
        """Cell density times the bilinear in-cell density ``q(fx, ft)``."""
        c00, c10, c01, c11 = (self._weight(c) for c in corners)
        # each corner scaled first (exact): no overflow near the float32 maximum
        mean = (0.25 * c00 + 0.25 * c10) + (0.25 * c01 + 0.25 * c11)
        q = dr.select(mean > 0.0, _bilerp(c00, c10, c01, c11, fx, ft) / mean, 0.0)
        return dr.gather(Float, self._pdf, iy * self.width + ix, active) * q

    def _eval_pdf(self, d: Array3f, active, want_pdf: bool = True):
        ix, iy, fx, fy = self._lookup(d)
        corners = self._corners(ix, iy, active)
        le = dr.select(active, self._eval_cell(corners, fx, fy), 0.0)
        if not want_pdf:
            return le, None
        ft = self._band_fraction(d, iy, active)
        return le, dr.select(active, self._pdf_cell(corners, ix, iy, fx, ft, active), 0.0)

    # ------------------------------------------------------------ public
    def eval(self, d: Array3f, active=True) -> Array3f:
        """Radiance arriving from unit world direction ``d`` (toward the sky)."""
        return self._eval_pdf(d, Bool(active), want_pdf=False)[0]

    def pdf(self, d: Array3f, active=True) -> Float:
        """Solid-angle density with which :meth:`sample` returns ``d``."""
        return self._eval_pdf(d, Bool(active))[1]

    def eval_pdf(self, d: Array3f, active=True) -> tuple[Array3f, Float]:
        """``(eval(d), pdf(d))`` with one lookup."""
        return self._eval_pdf(d, Bool(active))

    def sample(self, u: Array2f, active=True) -> tuple[Array3f, Array3f, Float]:
        """Direction ``d`` toward the sky, its radiance ``eval(d)`` and ``pdf(d)``.

        ``pdf == 0`` (and radiance 0) for a black map or inactive lanes; the
        caller must skip those. ``u`` in ``[0, 1)^2``.
        """
        active = Bool(active)
        if self.is_black:
            z = dr.zeros(Float, dr.width(u))
            return Array3f(z, z + 1.0, z), Array3f(z, z, z), z
        ny, W = self._ny, self.width
        # row from the marginal alias table, column from that row's conditional one
        row, sy = _pick(self._rows, 0, ny, u.y)
        col, sx = _pick(self._cols, row * W, W, u.x)

        # inside the cell: the bilinear density of the corner luminances,
        # ft (fraction of the band's cos(theta) range) from its linear
        # marginal, then fx from the linear conditional
        corners = self._corners(col, row, active)
        c00, c10, c01, c11 = (self._weight(c) for c in corners)
        # halved sums (exact; _sample_linear is scale-free): no float32 overflow
        ft = _sample_linear(0.5 * c00 + 0.5 * c10, 0.5 * c01 + 0.5 * c11, sy)
        fx = _sample_linear(dr.lerp(c00, c01, ft), dr.lerp(c10, c11, ft), sx)
        # t = 1 -/+ cos(theta), accurate near either pole
        t = dr.fma(ft, dr.gather(Float, self._dt, row), dr.gather(Float, self._t0, row))
        north = dr.gather(Bool, self._north, row)
        cos_t = dr.select(north, 1.0 - t, t - 1.0)
        sin_t = dr.safe_sqrt(t * (2.0 - t))
        uu = (Float(col) + fx + 0.5) / W
        uu = dr.select(uu >= 1.0, uu - 1.0, uu)
        sin_p, cos_p = dr.sincos(uu * (2.0 * math.pi))
        d = Array3f(sin_p * sin_t, cos_t, -cos_p * sin_t)
        # the radiance and the density from the sampled cell's corners, no lookup of d
        pdf = dr.select(active, self._pdf_cell(corners, col, row, fx, ft, active), 0.0)
        le = dr.select(pdf > 0.0, self._eval_cell(corners, fx, self._row_fraction(cos_t, row)), 0.0)
        return d, le, pdf

    def _row_fraction(self, cos_t: Float, row: UInt32) -> Float:
        """``fy`` of :meth:`_lookup` (linear in theta) for a direction of ``cos theta`` ``cos_t``
        in band ``row``, clamped to the band."""
        v = dr.safe_acos(cos_t) * (1.0 / math.pi)
        return dr.clip(v * self._ny - Float(row), 0.0, 1.0)


def compensation_offset(lum: np.ndarray) -> float:
    """The luminance that MIS compensation subtracts from a map of texel luminances
    ``lum`` (``(H, W)``): their mean (each texel alike, as Mitsuba's ``envmap``), or 0
    (no compensation) where the map is nearly constant, its minimum within 1% of the
    mean (Mitsuba's rule: the compensated density would be all but empty)."""
    mean = float(np.mean(lum, dtype=np.float64))
    if not (mean > 0.0) or mean - float(np.min(lum)) <= 0.01 * mean:
        return 0.0
    return mean


def _texels(img: np.ndarray) -> Float:
    """The ``(H, W, 3)`` texels as one flat array of ``(r, g, b, luminance)`` per texel, the
    luminance computed by the device's float32 arithmetic of :func:`_luminance`, so that it
    is bit for bit what a kernel computing it from the texel would get."""
    rgb = img.reshape(-1, 3)
    c = Array3f(rgb[:, 0].copy(), rgb[:, 1].copy(), rgb[:, 2].copy())
    out = dr.ravel(Array4f(c.x, c.y, c.z, _luminance(c)))
    dr.eval(out)
    return out


def _luminance(c: Array3f) -> Float:
    return dr.fma(float(LUMINANCE[0]), c.x,
                  dr.fma(float(LUMINANCE[1]), c.y, float(LUMINANCE[2]) * c.z))


def _bilerp(v00, v10, v01, v11, fx, fy):
    gx = 1.0 - fx
    return dr.fma(1.0 - fy, dr.fma(gx, v00, fx * v10), fy * dr.fma(gx, v01, fx * v11))


def _sample_linear(a: Float, b: Float, u: Float) -> Float:
    """``x`` in [0, 1) with density proportional to ``lerp(a, b, x)`` (a, b >= 0,
    not both 0) from uniform ``u``: inverting the CDF
    ``(a x + (b - a) x^2 / 2) / ((a + b) / 2)`` in the cancellation-free form
    ``u (a + b) / (a + sqrt(lerp(a^2, b^2, u)))``, after scaling a and b by
    their maximum (no float32 overflow in the squares)."""
    m = dr.maximum(a, b)
    inv = dr.select(m > 0.0, dr.rcp(m), 0.0)
    a, b = a * inv, b * inv
    den = a + dr.sqrt(dr.lerp(a * a, b * b, u))
    x = dr.select(den > 0.0, u * (a + b) / den, u)
    return dr.minimum(x, _ONE_MINUS_EPS)


def _floored(w: np.ndarray) -> np.ndarray:
    """``w`` (rows of non-negative float64 weights) with each positive weight raised to
    ``WEIGHT_FLOOR`` times its row's total (a copy), so that no positive cell's alias threshold
    is too small for the uniform input's resolution to reach."""
    floor = WEIGHT_FLOOR * w.sum(axis=1, keepdims=True)
    return np.where(w > 0.0, np.maximum(w, floor), 0.0)


def alias_tables(w: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Walker's alias tables of the rows of ``w`` (``(R, N)``, non-negative): ``(q, alias,
    prob)``. Cell ``i`` of a row, picked uniformly, is kept where a uniform ``f`` in [0, 1)
    is below its float32 threshold ``q[i]`` and is replaced by ``alias[i]`` (uint32)
    otherwise; ``prob`` (float64) is what these float32 tables realise,
    ``(q[i] + sum over j with alias[j] == i of (1 - q[j])) / N``, proportional to the row
    to float32 rounding of the thresholds. A cell of zero weight is never picked
    (``prob`` 0); a row of zero total gives ``prob`` 0 everywhere.

    Built by Vose's pairing, all rows at once, with no sort and no loop over the cells (any
    order of the smalls and of the larges gives a valid table). With ``v`` the cell's weight
    times ``N / total``, the smalls (``v < 1``) and the larges (the rest; a row whose cells
    all round below 1 keeps its largest cell as a large) are each taken in cell order. With
    ``D_i`` the deficit ``sum (1 - v)`` of the row's smalls ``0..i`` and ``E_j`` the excess
    ``sum (v - 1)`` of its larges ``0..j`` (each one flattened cumulative sum less the sum
    before the row), small ``i`` is filled by the first large ``j`` with ``E_j >= D_{i-1}``
    (``D_{-1} = 0``); large ``j`` runs out at the first small ``i*`` with ``D_{i*} > E_j``
    and is then a small itself, with threshold ``1 - (D_{i*} - E_j)``, filled by large
    ``j + 1``; a large that never runs out, and the row's last one, keeps threshold 1 (its
    own alias). One ``searchsorted`` over the flattened smalls (each row's sums offset by its
    own key range) finds every large's ``i*``; the large of small ``i`` is then the number
    of the row's larges with ``i* < i``, a count. Built a block of rows at a time
    (:data:`_BLOCK_CELLS`: large temporaries cost more than the arithmetic), written into
    the outputs."""
    w = np.asarray(w, np.float64)
    R, N = w.shape
    q, alias, prob = np.empty((R, N), np.float32), np.empty((R, N), np.uint32), np.empty((R, N))
    step = max(1, _BLOCK_CELLS // max(N, 1))
    for r in range(0, R, step):
        _alias_rows(w[r:r + step], q[r:r + step], alias[r:r + step], prob[r:r + step])
    return q, alias, prob


#: cells per block of rows :func:`alias_tables` builds at once: its float64 temporaries
#: (4 MiB each) stay in the cache and in the allocator's reused memory
_BLOCK_CELLS = 1 << 19


def _alias_rows(w: np.ndarray, q_out: np.ndarray, alias_out: np.ndarray, prob_out: np.ndarray) -> None:
    """:func:`alias_tables` of a block of rows ``w`` (float64), written to ``q_out``,
    ``alias_out`` and ``prob_out`` (views of its outputs)."""
    R, N = w.shape
    total = w.sum(axis=1)
    empty = ~(total > 0.0)
    v = w * (N / np.where(empty, 1.0, total))[:, None]
    v[empty] = 1.0  # every cell a large of its own: thresholds 1 (prob set to 0 below)
    small = v < 1.0
    # a row whose cells all round below 1 keeps its largest cell as a large
    ns = small.sum(axis=1)
    forced = np.flatnonzero(ns == N)
    forced = forced * N + np.argmax(v[forced], axis=1)
    small.ravel()[forced] = False
    ns[ns == N] -= 1
    nl = N - ns
    v, small = v.ravel(), small.ravel()
    si = np.flatnonzero(small)  # row-major: grouped by row, any order inside a row
    li = np.flatnonzero(~small)
    rows = np.arange(R)
    rs, rl = np.repeat(rows, ns), np.repeat(rows, nl)
    cs, cl = np.cumsum(ns) - ns, np.cumsum(nl) - nl  # each row's first small, first large
    # D: the smalls' cumulative deficit within their row, E: the larges' cumulative excess
    D = np.cumsum(1.0 - v[si])
    E = np.cumsum(np.maximum(v[li] - 1.0, 0.0))
    for S, c, n in ((D, cs, ns), (E, cl, nl)):  # less the sum before the row's first entry
        if S.size:
            S -= np.repeat(np.where(c > 0, S[np.maximum(c - 1, 0)], 0.0), n)
    key = np.arange(R, dtype=np.float64) * (2 * N + 2)  # the sums lie in [0, N]
    # large k of a row: runs out at the first small i* with D_{i*} > E_k (never: i* = its
    # row's count of smalls), then a small itself with threshold 1 - (D_{i*} - E_k),
    # filled by the row's next large; the last keeps 1
    i = np.searchsorted(D + key[rs], E + key[rl], side="right") - cs[rl]
    k = np.arange(li.size) - cl[rl]
    out = (k < nl[rl] - 1) & (i < ns[rl])
    g = np.flatnonzero(out)
    q = np.minimum(v, 1.0)  # the smalls' thresholds, 1 for the larges unless they run out
    q[forced] = 1.0
    alias = np.arange(R * N)  # a threshold of 1 aliases its own cell
    q[li[g]] = 1.0 - (D[cs[rl[g]] + i[g]] - E[g])
    alias[li[g]] = li[g + 1]
    # small i: filled by the first large k with E_k >= D_{i-1}, that is the first whose i*
    # is at least i: the number of the row's larges with i* < i (i* rises with k)
    pos = cs[rl] + rl + i  # keyed so that each row has its own range, ns + 1 long
    ran_out = np.bincount(pos, minlength=si.size + R)
    before = np.cumsum(ran_out) - ran_out
    ks = before[np.arange(si.size) + rs] - cl[rs]  # small g of row r: position cs[r] + r + i = g + r
    np.minimum(ks, nl[rs] - 1, out=ks)
    alias[si] = li[cl[rs] + ks]
    np.clip(q, 0.0, 1.0, out=q)
    qc = q_out.reshape(-1)
    qc[:] = q
    q[:] = qc  # the stored float32 thresholds, in float64
    prob = prob_out.reshape(-1)
    prob[:] = np.bincount(alias, 1.0 - q, R * N)
    prob += q
    prob /= N
    prob_out[empty] = 0.0
    alias -= np.repeat(np.arange(R, dtype=np.int64) * N, N)
    alias_out.reshape(-1)[:] = alias


def _interleaved(q: np.ndarray, alias: np.ndarray) -> UInt32:
    """An alias table's thresholds ``q`` (float32, their bits) and aliases (uint32) in one
    device array, each cell's two side by side (:func:`_pick`): the alias, read after the
    threshold, is in the cache line the threshold's read brought in, where two arrays would
    make a pick on a large table miss the cache twice."""
    out = np.empty((len(q), 2), np.uint32)
    out[:, 0] = np.asarray(q, np.float32).view(np.uint32)
    out[:, 1] = alias
    return UInt32(out.ravel())


def _pick(table: UInt32, base, n: int, u: Float) -> tuple[UInt32, Float]:
    """A cell of the alias table at ``base`` (``n`` cells; :func:`alias_tables`, stored by
    :func:`_interleaved`) from uniform ``u``, and ``u`` remapped to a uniform number in
    [0, 1) for use inside the cell."""
    x = u * n
    i = dr.minimum(UInt32(x), n - 1)
    f = x - Float(i)
    j = (base + i) * 2
    qi = dr.reinterpret_array(Float, dr.gather(UInt32, table, j))
    keep = f < qi
    cell = dr.select(keep, i, dr.gather(UInt32, table, j + 1))
    s = dr.select(keep, f / qi, (f - qi) / (1.0 - qi))
    return cell, dr.clip(s, 0.0, _ONE_MINUS_EPS)


class UniformSphereSampling:
    """The same sky sampled uniformly over the sphere (pdf ``1 / 4 pi``).

    Only for comparison: it shows what luminance importance sampling buys
    (``python -m drpt render --env-sampling uniform``; benchmarks/env_sampling.py).
    Same interface as :class:`EnvironmentLight`; radiance lookups delegate to it.
    """

    PDF = 1.0 / (4.0 * math.pi)

    def __init__(self, env: EnvironmentLight):
        self.env = env
        self.is_black = env.is_black
        self.warnings = env.warnings
        self.luminance_integral = env.luminance_integral

    def eval(self, d: Array3f, active=True) -> Array3f:
        return self.env.eval(d, active)

    def pdf(self, d: Array3f, active=True) -> Float:
        return dr.select(Bool(active), Float(self.PDF), 0.0)

    def eval_pdf(self, d: Array3f, active=True) -> tuple[Array3f, Float]:
        return self.env.eval(d, active), self.pdf(d, active)

    def sample(self, u: Array2f, active=True) -> tuple[Array3f, Array3f, Float]:
        active = Bool(active)
        z = 1.0 - 2.0 * u.y
        r = dr.safe_sqrt(1.0 - z * z)
        s, c = dr.sincos(2.0 * math.pi * u.x)
        d = Array3f(r * c, z, r * s)
        return d, self.eval(d, active), self.pdf(d, active)


class RotatedEnvironment:
    """An environment map turned by a rotation ``R`` (Mitsuba envmap's ``to_world``):
    the radiance along world ``d`` is the map's along ``R^T d``; samples are the
    map's turned by ``R``. Densities are unchanged (a rotation keeps solid angle).
    Same interface as :class:`EnvironmentLight`."""

    def __init__(self, env, rotation):
        r = np.asarray(rotation, dtype=np.float64).reshape(3, 3)
        if not np.allclose(r.T @ r, np.eye(3), atol=1e-6) or np.linalg.det(r) < 0:
            raise DrptError("environment map rotation must be a rotation matrix")
        self.env = env
        self.is_black = env.is_black
        self.warnings = env.warnings
        self.luminance_integral = env.luminance_integral
        self.rows = [tuple(float(x) for x in row) for row in r]  # R, row by row
        self.cols = [tuple(float(x) for x in r[:, k]) for k in range(3)]  # rows of R^T

    @staticmethod
    def _apply(rows, d: Array3f) -> Array3f:
        return Array3f(*(d.x * a + d.y * b + d.z * c for a, b, c in rows))

    def to_map(self, d: Array3f) -> Array3f:
        return self._apply(self.cols, d)

    def eval(self, d: Array3f, active=True) -> Array3f:
        return self.env.eval(self.to_map(d), active)

    def pdf(self, d: Array3f, active=True) -> Float:
        return self.env.pdf(self.to_map(d), active)

    def eval_pdf(self, d: Array3f, active=True) -> tuple[Array3f, Float]:
        return self.env.eval_pdf(self.to_map(d), active)

    def sample(self, u: Array2f, active=True) -> tuple[Array3f, Array3f, Float]:
        d, le, pdf = self.env.sample(u, active)
        return self._apply(self.rows, d), le, pdf


class SkyEmitter:
    """The sky as an :class:`~drpt.render.lights.Emitter` of one slot (next-event
    estimation through the scene's light selection): ``env`` is an
    :class:`EnvironmentLight` (or its :class:`UniformSphereSampling` or
    :class:`RotatedEnvironment`), ``radius`` that of a sphere of the lit geometry's mean
    cross-section (:func:`drpt.render.lights.reach.receivers`; else the scene's bounding
    sphere's). Its power is ``pi R^2`` times the integral of its luminance over the sphere:
    what enters that sphere (pbrt-v4's ``ImageInfiniteLight::Phi``, over the scene's
    bounding sphere)."""

    count = 1
    delta = False
    infinite = True

    def __init__(self, env, radius: float):
        self.env = env
        self.radius = float(radius)
        self.bind(None)

    def power(self) -> np.ndarray:
        return np.array([math.pi * self.radius ** 2 * getattr(self.env, "luminance_integral", 1.0)])

    def units(self) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros(1, np.int64), np.ones(1)

    def bind(self, prob: np.ndarray | None) -> None:
        """The sky's selection probability, included in its densities (``None``: 1)."""
        self.prob = 1.0 if prob is None else float(prob[0])

    def sample_direction(self, ref: Array3f, slot: UInt32, u: Array2f, active: Bool):
        """A direction toward the sky by the map's luminance (``dist`` infinite)."""
        wo, le, pdf = self.env.sample(u, active)
        if self.prob != 1.0:
            pdf = pdf * self.prob
        return EmitterSample(wo, Array3f(ref), le, pdf, Bool(active) & (pdf > 0.0),
                             dr.full(Float, dr.inf, dr.width(pdf)), False)

    def eval_direction(self, d: Array3f, active: Bool, density: bool = True) -> tuple[Array3f, Float | None]:
        """The radiance along unit ``d`` and the density of :meth:`sample_direction` for it
        (``density`` False: ``None``, and only the radiance is looked up)."""
        if not density:
            return self.env.eval(d, active), None
        le, pdf = self.env.eval_pdf(d, active)
        return le, (pdf * self.prob if self.prob != 1.0 else pdf)

    def pdf_direction(self, si, d: Array3f, active: Bool, ref: Array3f | None = None) -> Float:
        """The density of the direction ``d`` of a ray that escaped (0 where ``si`` is a hit)."""
        return self.eval_direction(d, active & ~si.valid)[1]
