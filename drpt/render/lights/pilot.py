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
pilot's estimates in the lane's tile of the film (at most 64 x 64 tiles): the relative
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
points in media). Where no pilot estimate carries light it is ``mixed``'s, and so it is
for the integrators of :data:`LIGHT_TRACERS`, whose light subpaths pick as ``mixed`` and
which never ask the selection: they run no pilot.
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


def second_moments(scene, camera, width: int, height: int, lanes: int = PILOT_LANES) -> np.ndarray:
    """``M_j`` of each emitter (:func:`units`) of ``scene`` (a
    :class:`~drpt.render.scene.DeviceScene`) seen through ``camera`` (a
    :class:`~drpt.render.camera.RayCamera` of a ``width`` x ``height`` film). Binds the
    ``uniform`` selection into the scene."""
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
    c = DirectLight(scene).emitter(si, u_sel, u2, si.valid, mis=True)
    v = dr.select(si.valid, (c.x + c.y + c.z) / 3.0 * pmf, 0.0)
    k, v, pmf = UInt32(k), Float(v), Float(pmf)
    dr.eval(k, v, pmf, x, y)
    k, v = k.numpy().astype(np.int64), v.numpy().astype(np.float64)
    v = np.where(np.isfinite(v), v, 0.0)
    # each lane's square over its film tile's brightness, as the relative error weighs it
    tx, ty = min(width, TILES), min(height, TILES)
    tile = (np.minimum((x.numpy() * tx / width).astype(np.int64), tx - 1) * ty
            + np.minimum((y.numpy() * ty / height).astype(np.int64), ty - 1))
    pm = pmf.numpy().astype(np.float64)
    full = np.where(pm > 0, v / np.maximum(pm, 1e-30), 0.0)  # the lane's estimate of all emitters' light
    n = np.bincount(tile, minlength=tx * ty)
    b = np.bincount(tile, weights=full, minlength=tx * ty) / np.maximum(n, 1)
    w = 1.0 / (b[tile] ** 2 + 0.01)
    unit = units(families)
    n_units = int(unit.max()) + 1 if len(unit) else 0
    # the estimate given emitter j is v / P(j), drawn with probability P(j) = 1 / n_units
    return np.bincount(unit[k], weights=w * (v * n_units) ** 2, minlength=n_units) / (lanes / n_units)


class PilotSelection(LightSelection):
    """The static selection of the pilot's measurement (:func:`second_moments`)."""

    def __init__(self, families: list, moments: np.ndarray):
        self.moments = moments
        uni = slot_weights(families, "uniform")
        uni = uni / uni.sum()
        root = np.sqrt(np.maximum(moments, 0.0))
        if not np.isfinite(root.sum()) or root.sum() <= 0.0:
            super().__init__(families, "mixed")
            return
        unit = units(families)
        unit_uniform = np.bincount(unit, weights=uni)  # each emitter's uniform probability
        pilot = root[unit] / root.sum() * uni / unit_uniform[unit]  # split as uniform splits
        super().__init__(families, "pilot", (1.0 - DEFENSIVE) * pilot + DEFENSIVE * uni)


def pilot_selection(scene, camera, width: int, height: int) -> LightSelection:
    """Measure (:func:`second_moments`) and return the pilot's selection."""
    families = scene.emitter_selection.families
    if scene.emitter_selection.count <= 1 or len(np.unique(units(families))) <= 1:
        return LightSelection(families, "mixed")
    return PilotSelection(families, second_moments(scene, camera, width, height))
