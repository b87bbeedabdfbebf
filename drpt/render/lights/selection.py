"""The light selection: one discrete distribution over every emitter of a scene.

Next-event estimation picks one *slot* per vertex (an emissive triangle or sphere, a
delta light, the sky: the slots of the :class:`~drpt.render.lights.Emitter` families),
then samples a direction toward it. :class:`LightSelection` is that choice, by one of
the rules of ``--light-sampler``:

* ``power``: each slot by its power (:meth:`Emitter.power
  <drpt.render.lights.Emitter.power>`: ``pi A L`` for a triangle, ``4 pi I`` for a point
  light, ``pi R^2`` times the integrated luminance for the sky, ...), the part of it that
  reaches the lit geometry (:mod:`drpt.render.lights.reach`), so a dim emitter costs few
  shadow rays;
* ``uniform`` (Mitsuba's): each *emitter* (a shape, a delta light, the sky) alike, a
  shape's slots by their share of its area;
* ``mixed`` (the default): the mean of the two (a defensive mixture): power's
  allocation, but every emitter keeps at least half of its uniform share. Power's
  estimate fails where much of what reaches the lit geometry never reaches what the camera
  sees (occluded, or on surfaces out of view), and ``uniform`` where emitters differ much
  in power; ``mixed`` bounds both failures (measured in docs/performance.md, "Light
  selection").

The selection is *static*: its probabilities do not depend on the shading point, so the
families fold them into their density tables (:meth:`Emitter.bind
<drpt.render.lights.Emitter.bind>`) and the scene never multiplies them at run time. A
spatially varying selection (the light BVH,
:class:`~drpt.render.lights.light_bvh.BVHSelection`) sets ``static = False`` and implements
:meth:`sample` and :meth:`pmf` with the reference point ``ref``:
:class:`~drpt.render.scene.DeviceScene` then binds nothing and multiplies each
conditional density by :meth:`pmf` of the slot (:meth:`Emitter.slot_of
<drpt.render.lights.area.AreaLights.slot_of>` finds the slot a ray hit).

Slots are numbered family by family, in the order the families are given
(:attr:`offsets`); a family with no slot is left out. Where the path tracer reaches the
delta lights by shadow rays of their own (``--delta-lights each``,
:attr:`~drpt.render.scene.DeviceScene.delta_each`) their family is not given: the selection
picks among the other emitters.
"""

from __future__ import annotations

import drjit as dr
import numpy as np
from drjit.auto import Array2f, Array3f, Bool, Float, UInt32

from ..tables import Table, gather, search

RULES = ("mixed", "power", "uniform")  # drpt.options.LIGHT_SAMPLERS (also pilot.py's and light_bvh.py's)


def slot_weights(families: list, rule: str) -> np.ndarray:
    """The unnormalised probability of every slot of ``families`` under ``rule``."""
    if rule not in RULES:
        raise ValueError(f"light selection rule {rule!r}: not one of {', '.join(RULES)}")
    if rule == "mixed":  # half by power, half uniform: each emitter gets at least half its uniform share
        p, u = slot_weights(families, "power"), slot_weights(families, "uniform")
        if p.sum() > 0.0 and u.sum() > 0.0:
            return 0.5 * p / p.sum() + 0.5 * u / u.sum()
        return p if p.sum() > 0.0 else u
    if rule == "power":
        w = np.concatenate([np.asarray(f.power(), np.float64) for f in families] or [np.zeros(0)])
        return np.where(np.isfinite(w) & (w > 0.0), w, 0.0)
    parts, n_units = [], 0
    for f in families:
        unit, share = f.units()
        parts.append((unit, np.asarray(share, np.float64)))
        n_units += len(np.unique(unit))
    return np.concatenate([share / max(n_units, 1) for _, share in parts] or [np.zeros(0)])


class LightSelection:
    """One discrete distribution over the slots of ``families`` (``rule``: one of
    :data:`RULES`, or given ``weights``: the unnormalised probability of every slot of the
    families with slots, ``rule`` then only its name). ``count`` is 0 where no slot carries
    light."""

    static = True

    def __init__(self, families: list, rule: str = "power", weights: np.ndarray | None = None):
        self.rule = rule
        self.families = [f for f in families if f.count > 0]
        self.offsets = list(np.cumsum([0] + [f.count for f in self.families])[:-1].astype(int))
        w = slot_weights(self.families, rule) if weights is None else np.asarray(weights, np.float64)
        total = float(w.sum())
        self.count = len(w) if total > 0.0 else 0
        #: each slot's probability (float64, host side; for tests and tools)
        self.probabilities = w / total if total > 0.0 else np.zeros(len(w))
        if self.count:
            cdf = np.cumsum(w) / total
            cdf[-1] = 1.0
            # (small tables: read as literals where they are few, drpt.render.tables)
            self._cdf = Table(Float, cdf)
            self._pmf = Table(Float, self.probabilities)

    def family_probabilities(self, i: int) -> np.ndarray:
        """The probabilities of family ``i``'s slots (in :attr:`families`)."""
        o = self.offsets[i]
        return self.probabilities[o:o + self.families[i].count]

    def sample(self, u: Float, ref: Array3f | None = None, active=True) -> tuple[UInt32, Float]:
        """A slot for each lane from ``u`` in [0, 1), and its probability."""
        if self.count == 1:
            return dr.zeros(UInt32, dr.width(u)), dr.full(Float, 1.0, dr.width(u))
        k = dr.minimum(search(self._cdf, u), self.count - 1)
        return k, gather(Float, self._pmf, k, active)

    def pmf(self, index: UInt32, ref: Array3f | None = None, active=True) -> Float:
        """The probability that :meth:`sample` returns slot ``index``."""
        if self.count == 1:
            return dr.select(index == 0, 1.0, 0.0)
        return gather(Float, self._pmf, index, Bool(active) & (index < self.count))

    def reuse(self, u: Array2f, ref: Array3f | None = None, active=True) -> tuple[Float, Array2f]:
        """The selection drawn from ``u.x`` and ``u`` with ``u.x`` rescaled to the chosen
        slot's interval of the CDF, to pass on to the slot's own sampling (Mitsuba's
        sample reuse): one stratified 2-D sample then stays stratified over all the
        emitters (the low-discrepancy samplers' next-event estimation,
        :func:`drpt.render.sampler.light_sample`)."""
        if self.count <= 1:
            return u.x, u
        k, _ = self.sample(u.x, ref, active)
        hi = gather(Float, self._cdf, k, active)
        lo = dr.select(k > 0, gather(Float, self._cdf, dr.maximum(k, 1) - 1, active & (k > 0)), 0.0)
        x = (u.x - lo) / dr.maximum(hi - lo, 1e-30)
        return u.x, Array2f(dr.clip(x, 0.0, 0.99999994), u.y)
