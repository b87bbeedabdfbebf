"""The pilot light selection (``--light-sampler pilot``): each emitter's share measured at
what the camera sees, before rendering.

``power`` weighs an emitter by what it emits in all directions, which is not what reaches
the points the camera sees: a point light below the camera, the sky weighed by the
scene's bounding sphere, a directional light over a large floor. The pilot measures it
instead: :data:`PILOT_LANES` camera rays through random film positions (a fixed seed, so
that every render of the scene, and every chunk of a distributed one, gets the same
selection), at each first hit one next-event estimate with ``uniform`` selection (the
BSDF times the emitter's radiance over the sample's density, occluded or not, with the
power heuristic's weight against BSDF sampling as the path tracer's: where BSDF sampling
finds a light well, a small sharp highlight, next-event estimation has little to do
there), and the second moment ``M_j`` of the estimate given emitter ``j`` (the estimate times
``j``'s uniform probability), each square divided by ``b^2 + 0.01``, ``b`` the mean of the
pilot's direct-light estimates (next-event estimation's and one BSDF sample's, below) in the
lane's tile of the film (at most 64 x 64 tiles): the relative
error the benchmarks measure (``benchmarks/light_sampler.py``), where a dark wall's noise
counts as much as a bright highlight's (weighed by absolute squares, the pilot gave the
large light of Veach's MIS scene 18% of the samples, its small bright spheres with their
bright reflections the rest, and the dim room the large light lights was noisier than
under ``uniform``). A static
selection's (weighted) variance is ``sum_j M_j / p_j`` less a constant, smallest for
``p_j`` proportional to ``sqrt(M_j)``; the pilot's selection is

    p = (1 - DEFENSIVE) * sqrt(M_j) / sum sqrt(M)  +  DEFENSIVE * uniform

(an emitter's slots split as ``uniform`` splits them: by area), so that every emitter keeps
a share of its uniform probability for the points the pilot does not see (deeper bounces,
points in media). ``M_j`` misses what the selection does to BSDF sampling: a lower ``p_j``
raises the MIS weight of BSDF samples that reach ``j``, which is costly where the BSDF finds
``j`` poorly (a thin sheet lit through by the sky), and the MIS weights move with ``p``.
So each first hit also takes one BSDF sample, and :meth:`Measurement.second_moment`
computes for any selection ``p`` the weighted second moment of the whole direct-light
estimate (next-event estimation's, reweighted from the ``uniform`` draws, plus BSDF
sampling's, every MIS weight recomputed for ``p``), weighed as above (the relative error)
and with every lane alike (the absolute error, which the equal-time comparisons with Mitsuba
measure: ``benchmarks/equal_time_vs_mitsuba.py``). The candidates (:data:`CANDIDATES`): the
rule above, the same with ``M_j`` weighed absolutely, ``uniform`` and ``mixed``; the pilot's
selection is the one whose worse ratio to the least second moment, relative or absolute, is
least (:attr:`PilotSelection.choice`): where the two errors want different shares (a sphere
lit by a point light: the absolute error is the highlight's, the relative error the dim
side's) neither is given up for the other.
Where no pilot estimate carries light it is ``mixed``'s, and so it is for the integrators
of :data:`LIGHT_TRACERS`, whose light subpaths pick as ``mixed`` and which never ask the
selection: they run no pilot.
"""

from __future__ import annotations

import drjit as dr
import numpy as np
from drjit.auto import PCG32, Array2f, Bool, Float, UInt32

from ..integrators.common import DirectLight
from .selection import LightSelection, slot_weights

#: the integrators that trace no next-event estimation through the selection
LIGHT_TRACERS = ("ptracer", "bdpt")
#: camera rays of the pilot
PILOT_LANES = 1 << 16
#: each emitter's share of its uniform probability that the pilot's measurement cannot take away
DEFENSIVE = 0.5
SEED = 0x5EED
#: the selections the pilot chooses among (:class:`PilotSelection`)
CANDIDATES = ("pilot", "pilot absolute", "uniform", "mixed")
#: tiles of the film per axis at most, over which the pilot estimates the image's brightness
TILES = 64


def units(families: list) -> np.ndarray:
    """Each slot's emitter, numbered across the families."""
    out, base = [], 0
    for f in families:
        unit = np.asarray(f.units()[0])
        ids, inverse = np.unique(unit, return_inverse=True)
        out.append(base + inverse)
        base += len(ids)
    return np.concatenate(out) if out else np.zeros(0, int)


class Measurement:
    """What the pilot's camera rays found at their first hits, lane by lane (numpy, float64):

    * ``k``: the emitter (:func:`units`) next-event estimation picked (``uniform``; ``pmf``
      the probability of its slot), ``nee``
      its estimate without the MIS weight (the channels' mean of ``f L / e``, 0 where
      occluded or invalid), ``e`` its density (times ``uniform``'s probability), ``b`` the
      BSDF's density for its direction, ``delta`` whether the emitter is a delta light;
    * ``j``: the emitter a BSDF sample reached (-1: none), ``bsdf`` the estimate ``f L / b``
      without the MIS weight, ``e_b`` the emitter's density for it (times ``uniform``'s
      probability), ``b_b`` the BSDF's density (0: a Dirac lobe, which takes no MIS weight);
    * ``w``: each lane's weight, ``1 / (b^2 + 0.01)`` for the mean ``b`` of the direct-light
      estimates (both techniques', MIS-weighted as under ``uniform``) in its film tile (the
      relative error's weighing);
    * ``uniform``: each emitter's ``uniform`` probability.
    """

    def __init__(self, **arrays):
        self.__dict__.update(arrays)

    def moments(self, relative: bool = True) -> np.ndarray:
        """``M_j``: the weighted second moment of next-event estimation's estimate given
        emitter ``j``, MIS-weighted as under ``uniform`` (times ``j``'s probability);
        ``relative`` False: every lane weighs 1 (the absolute error's second moment)."""
        n = len(self.uniform)
        w = self.w if relative else 1.0
        # the estimate given emitter j is v / P(j), drawn with probability P(j) = 1 / n
        v = self.nee * _heuristic(self.e, self.b, self.delta) * self.pmf
        return np.bincount(self.k, weights=w * (v * n) ** 2, minlength=n) / (len(self.k) / n)

    def second_moment(self, p: np.ndarray, relative: bool = True) -> float:
        """The weighted second moment of one vertex's direct-light estimate, next-event
        estimation's and BSDF sampling's together, were the emitters chosen with the
        probabilities ``p`` (per emitter, slots split as ``uniform`` splits them): the
        lanes' draws from ``uniform`` reweighted, every MIS weight recomputed for ``p``;
        ``relative`` as in :meth:`moments`."""
        s = np.asarray(p, np.float64) / self.uniform  # each density's factor under p
        sk = s[self.k]
        x = self.nee * _heuristic(self.e * sk, self.b, self.delta)
        nee = np.where(sk > 0.0, x * x / np.maximum(sk, 1e-300), np.where(x != 0.0, np.inf, 0.0))
        hit = self.j >= 0
        sj = np.where(hit, s[np.maximum(self.j, 0)], 0.0)
        wb = np.where(self.b_b > 0.0, _heuristic(self.b_b, self.e_b * sj, False), 1.0)
        y = np.where(hit, self.bsdf * wb, 0.0)
        return float(np.mean((self.w if relative else 1.0) * (nee + y * y)))


def _heuristic(a, b, delta):
    """The power heuristic's weight of the technique with density ``a`` against ``b`` (1 for
    delta lights)."""
    a2, b2 = a * a, b * b
    w = np.where(a2 > 0.0, a2 / np.maximum(a2 + b2, 1e-300), 0.0)
    return np.where(delta, 1.0, w)


def measure(scene, camera, width: int, height: int, lanes: int = PILOT_LANES) -> Measurement:
    """The pilot's :class:`Measurement` of ``scene`` (a :class:`~drpt.render.scene.DeviceScene`)
    seen through ``camera`` (a :class:`~drpt.render.camera.RayCamera` of a ``width`` x
    ``height`` film). Binds the ``uniform`` selection into the scene."""
    families = scene.emitter_selection.families
    uni = LightSelection(families, "uniform")
    scene.set_light_selection(uni)
    rng = PCG32(lanes, SEED)
    x, y = rng.next_float32() * width, rng.next_float32() * height
    o, d = camera.ray(x, y)
    si = scene.intersect(o, d, dr.full(Bool, True, lanes))
    u_sel = rng.next_float32()
    u2 = Array2f(rng.next_float32(), rng.next_float32())
    k, pmf = uni.sample(u_sel, si.p, si.valid)
    es = scene.sample_emitter(si, u_sel, u2, si.valid)
    _, pdf_b = scene.eval_bsdf(si, es.wo)
    c = DirectLight(scene).emitter(si, u_sel, u2, si.valid, mis=False)  # f L / e, 0 where occluded
    nee = dr.select(si.valid, (c.x + c.y + c.z) / 3.0, 0.0)
    # one BSDF sample: what it reaches, and that emitter's density
    wo, bs = scene.sample_bsdf(si, rng.next_float32(), Array2f(rng.next_float32(), rng.next_float32()))
    ok = si.valid & bs.valid
    si2 = scene.intersect(scene.spawn(si, wo), wo, ok)
    le, e_b = scene.eval_emitter(si2, wo, ok, ref=si.p)  # (seen from the vertex, as next-event estimation)
    f_b = bs.weight * le
    slot = dr.full(UInt32, 0xFFFFFFFF, lanes)
    for family, off in zip(uni.families, uni.offsets):
        if family.delta:
            continue
        if family.infinite:
            slot = dr.select(ok & ~si2.valid, UInt32(off), slot)
        else:
            mine = ok & si2.valid & (family.pdf_direction(si2, wo, ok & si2.valid) > 0.0)
            slot = dr.select(mine, family.slot_of(si2.prim, mine) + off, slot)
    bsdf = dr.select(ok, (f_b.x + f_b.y + f_b.z) / 3.0, 0.0)
    b_b = dr.select(bs.delta, 0.0, bs.pdf)
    delta = Bool(es.delta) if not isinstance(es.delta, bool) else dr.full(Bool, es.delta, lanes)
    k, pmf, nee, e, pdf_b, slot, bsdf, e_b, b_b = (UInt32(k), Float(pmf), Float(nee), Float(es.pdf), Float(pdf_b),
                                                   UInt32(slot), Float(bsdf), Float(e_b), Float(b_b))
    dr.eval(k, pmf, nee, e, pdf_b, delta, slot, bsdf, e_b, b_b, x, y)
    unit = units(families)
    n_units = int(unit.max()) + 1 if len(unit) else 0
    uni_p = np.bincount(unit, weights=uni.probabilities, minlength=n_units)

    def finite(a):
        a = a.numpy().astype(np.float64)
        return np.where(np.isfinite(a), a, 0.0)

    slot = slot.numpy().astype(np.int64)
    j = np.where((slot >= 0) & (slot < len(unit)), unit[np.minimum(slot, len(unit) - 1)], -1)
    m = Measurement(k=unit[k.numpy().astype(np.int64)], pmf=finite(pmf), nee=finite(nee), e=finite(e), b=finite(pdf_b),
                    delta=delta.numpy().astype(bool), j=j, bsdf=finite(bsdf), e_b=finite(e_b),
                    b_b=finite(b_b), uniform=uni_p)
    # each lane's weight: 1 over its film tile's squared brightness
    tx, ty = min(width, TILES), min(height, TILES)
    tile = (np.minimum((x.numpy() * tx / width).astype(np.int64), tx - 1) * ty
            + np.minimum((y.numpy() * ty / height).astype(np.int64), ty - 1))
    # the lane's estimate of the direct light, both techniques' with uniform's MIS weights (next-event
    # estimation's alone misses what BSDF sampling finds: a sharp reflection of a small light)
    hit = m.j >= 0
    wb = np.where(m.b_b > 0.0, _heuristic(m.b_b, m.e_b, False), 1.0)
    full = m.nee * _heuristic(m.e, m.b, m.delta) + np.where(hit, m.bsdf * wb, 0.0)
    n = np.bincount(tile, minlength=tx * ty)
    b = np.bincount(tile, weights=full, minlength=tx * ty) / np.maximum(n, 1)
    m.w = 1.0 / (b[tile] ** 2 + 0.01)
    return m


def second_moments(scene, camera, width: int, height: int, lanes: int = PILOT_LANES) -> np.ndarray:
    """``M_j`` of each emitter (:func:`units`) of ``scene`` seen through ``camera``
    (:meth:`Measurement.moments` of :func:`measure`). Binds the ``uniform`` selection."""
    return measure(scene, camera, width, height, lanes).moments()


class PilotSelection(LightSelection):
    """The static selection of the pilot's measurement: the ``sqrt(M_j)`` rule
    (:func:`second_moments`), or with ``measurement`` (a :class:`Measurement`) the candidate
    (:data:`CANDIDATES`) whose second moments are nearest the least under both errors."""

    def __init__(self, families: list, moments: np.ndarray, measurement: Measurement | None = None):
        self.moments = moments
        #: each candidate's measured second moments, ``(relative, absolute)``
        #: (:meth:`Measurement.second_moment`)
        self.candidates: dict = {}
        #: the candidate the selection is (``mixed`` where no estimate carried light)
        self.choice = "mixed"
        uni = slot_weights(families, "uniform")
        uni = uni / uni.sum()
        unit = units(families)
        unit_uniform = np.bincount(unit, weights=uni)  # each emitter's uniform probability

        def rule(m):
            root = np.sqrt(np.maximum(m, 0.0))
            if not np.isfinite(root.sum()) or root.sum() <= 0.0:
                return None
            pilot = root[unit] / root.sum() * uni / unit_uniform[unit]  # split as uniform splits
            return (1.0 - DEFENSIVE) * pilot + DEFENSIVE * uni

        weights = {"pilot": rule(moments)}
        if weights["pilot"] is None:
            super().__init__(families, "mixed")
            return
        self.choice = "pilot"
        if measurement is not None:
            weights.update({"pilot absolute": rule(measurement.moments(relative=False)), "uniform": uni,
                            "mixed": slot_weights(families, "mixed")})
            weights = {k: w / w.sum() for k, w in weights.items() if w is not None}
            for name, w in weights.items():
                p = np.bincount(unit, weights=w)
                self.candidates[name] = (measurement.second_moment(p), measurement.second_moment(p, relative=False))
            best = [min(c[i] for c in self.candidates.values()) for i in (0, 1)]
            # each candidate's worse ratio to the least, relative and absolute; the least of those
            worse = {k: max(c[0] / max(best[0], 1e-300), c[1] / max(best[1], 1e-300))
                     for k, c in self.candidates.items()}
            self.choice = min(worse, key=worse.get)
        super().__init__(families, "pilot", weights[self.choice])


def pilot_selection(scene, camera, width: int, height: int) -> LightSelection:
    """Measure (:func:`measure`) and return the pilot's selection."""
    families = scene.emitter_selection.families
    if scene.emitter_selection.count <= 1 or len(np.unique(units(families))) <= 1:
        return LightSelection(families, "mixed")
    m = measure(scene, camera, width, height)
    return PilotSelection(families, m.moments(), m)
