"""Emitters, one module per family: ``area`` (emissive triangles and spheres), ``delta``
(point, spot, projector and directional lights), ``envmap`` (the environment map), and
``selection`` (the one discrete distribution next-event estimation picks an emitter from).

Every family implements :class:`Emitter`, the interface
:class:`drpt.render.scene.DeviceScene` builds its emitter queries on
(:meth:`~drpt.render.scene.DeviceScene.sample_emitter` and
:meth:`~drpt.render.scene.DeviceScene.pdf_emitter`). A family is a list of *slots*: the
units the light selection chooses among (an emissive triangle or sphere, one delta
light, the sky). The selection (:class:`~drpt.render.lights.selection.LightSelection`)
weighs the slots of all families by their :meth:`Emitter.power` (or each emitter alike)
and picks one per vertex; the family then samples a direction toward the chosen slot
with a density *conditional on that slot*, and the scene multiplies it by the slot's
probability. An integrator therefore traces one shadow ray per vertex and never asks
which family it got.

Light tracing (:mod:`drpt.render.lights.rays`) uses the families' own queries instead,
for rays that leave the emitters: :meth:`AreaLights.sample
<drpt.render.lights.area.AreaLights.sample>` (a point chosen by the family's own
selection), :meth:`DeltaLights.samples <drpt.render.lights.delta.DeltaLights.samples>`
(every light) and the environment's ``sample``/``eval_pdf``.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
from drjit.auto import Array2f, Array3f, Bool, Float, UInt32


class EmitterSample:
    """A direction from a reference point toward an emitter, for next-event estimation.

    * ``wo``: unit direction from the reference point toward the emitter;
    * ``p``: the end of the shadow ray, where ``dist`` is finite: a point on an area
      emitter moved off it toward the reference point by its rounding-error bound
      (:func:`drpt.render.spawn.origin`), or a point light's position;
    * ``dist``: distance from the reference point to the emitter (``inf``: the sky or a
      directional light, whose shadow ray has no end);
    * ``le``: the radiance arriving along ``-wo``; for a delta emitter the irradiance
      it gives a surface facing it (the estimate is then ``f * le / pdf`` without MIS);
    * ``pdf``: the solid-angle density of ``wo`` (for a delta emitter the probability
      of the choice alone); from a family, conditional on the slot; from
      :meth:`~drpt.render.scene.DeviceScene.sample_emitter`, times the slot's
      selection probability;
    * ``delta``: lanes whose emitter is a delta light (BSDF sampling cannot hit it: no
      MIS); a plain ``False`` where the scene has none;
    * ``valid``: the sample carries light (it faces the reference point, its density is
      positive).
    """

    def __init__(self, wo, p, le, pdf, valid, dist=None, delta=False):
        self.wo: Array3f = wo
        self.p: Array3f = p
        self.le: Array3f = le
        self.pdf: Float = pdf
        self.valid: Bool = valid
        self.dist: Float | None = dist  # None: finite, |p - reference| (area emitters)
        self.delta: Bool | bool = delta


class Emitter(Protocol):
    """What every emitter family provides (:class:`~drpt.render.lights.area.AreaLights`,
    :class:`~drpt.render.lights.delta.DeltaLights`,
    :class:`~drpt.render.lights.envmap.SkyEmitter`).

    A family is a *surface* family (its slots are primitives of the scene, whose radiance
    is their material's emission: :meth:`pdf_direction` and :meth:`slot_of` for what a ray
    hit), a *delta* one (``delta``: never hit, no density) or an *infinite* one (``infinite``
    and not ``delta``: seen by the rays that escape, :meth:`eval_direction`)."""

    #: slots the selection can choose (0: the family is absent and traces no code)
    count: int
    #: every slot is a delta light (reached by shadow rays only)
    delta: bool
    #: some slot is at infinity (its samples have ``dist = inf``)
    infinite: bool

    def power(self) -> np.ndarray:
        """Each slot's power in watts that reaches the lit geometry (an estimate: the
        selection's weight; :mod:`drpt.render.lights.reach`)."""
        ...

    def units(self) -> tuple[np.ndarray, np.ndarray]:
        """``(emitter, share)`` per slot: the id (within the family) of the emitter the
        slot belongs to and the slot's share of it (an emissive triangle's fraction of
        its shape's area; 1 for a slot that is a whole emitter). ``uniform``
        selection gives each emitter the same probability, split by the shares."""
        ...

    def bind(self, prob: np.ndarray | None) -> None:
        """The slots' selection probabilities, which :meth:`sample_direction` and the
        densities include from now on (``None``: 1 each, densities conditional on the
        slot, for a selection that varies in space)."""
        ...

    def sample_direction(self, ref: Array3f, slot: UInt32, u: Array2f, active: Bool) -> EmitterSample:
        """A direction from ``ref`` toward the family's ``slot`` (lanes' indices within
        the family): its solid-angle density times the bound probability."""
        ...

    def pdf_direction(self, si, d: Array3f, active: Bool, ref: Array3f | None = None) -> Float:
        """The density :meth:`sample_direction` has for what a ray of unit direction
        ``d`` reached: the interaction ``si`` seen from ``ref`` (None: from where the ray
        started, ``si.t`` back along it) or, for an infinite family, the direction of a
        ray that escaped. 0 where the ray reached none of the family's slots."""
        ...

    # surface families:
    def slot_of(self, prim: UInt32, active: Bool) -> UInt32:
        """The slot of primitive ``prim``."""
        ...

    # infinite families:
    def eval_direction(self, d: Array3f, active: Bool, density: bool = True) -> tuple[Array3f, Float | None]:
        """The radiance arriving along unit ``-d`` from direction ``d`` and the density of
        :meth:`sample_direction` for ``d`` (``density`` False: ``None``)."""
        ...
