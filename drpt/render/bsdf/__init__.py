"""BSDF lobes, one module each: ``diffuse``, ``phong``, ``cook_torrance``,
``dielectric``, ``mirror``, ``null``,
``plastic``, ``roughplastic`` (its coating tables precomputed by
``roughplastic_tables``), ``conductor``, ``roughconductor``, ``thindielectric``,
``roughdielectric``, ``principled``, ``principledthin``; every microfacet lobe
draws on the one ``microfacet.Distribution`` (GGX and Beckmann). (``normalmap`` and
``bumpmap`` are no lobes: they perturb the frame a lobe sees, :mod:`drpt.render.perturb`.)

:data:`REGISTRY` maps each leaf kind of :mod:`drpt.materials.bsdf_kinds` to its
module; :class:`drpt.render.material.MaterialTable` finds a kind's lobe
there (:func:`lobe`) and traces only the kinds a scene has. A new BSDF is one
module implementing :class:`BSDF`, one entry in :data:`REGISTRY`, its
parameters in :data:`drpt.materials.bsdf_kinds.PARAMS` (and, if MTL statements should
produce it, a rule in :mod:`drpt.materials.interpret`; the Mitsuba exporter maps kinds
named after a Mitsuba plugin by their names).

The lobe interface
------------------
All directions are *local* to the shading frame (``+z`` = shading normal),
unit length. ``wi`` points toward the viewer (where the path came from),
``wo`` toward the next vertex (where light comes from). Every lobe module
provides, besides the constants and ``params`` of :class:`BSDF`, three
functions over wide Dr.Jit arrays:

``eval(p, wi, wo) -> Array3f``
    ``f(wi, wo) * |cos(wo)|``. Zero for delta lobes.
``pdf(p, wi, wo) -> Float``
    solid-angle density with which ``sample`` produces ``wo``. Zero for
    delta lobes.
``sample(p, wi, u1: Float, u2: Array2f) -> BSDFSample``
    a direction and its weight ``f * |cos(wo)| / pdf`` (for delta lobes the
    ratio of the Dirac terms).

``p`` is the lobe's parameter record (see each module), gathered per lane by
:mod:`drpt.render.material`. Sidedness is the material layer's: inside a
``twosided`` spec the frame is flipped to the viewer's side (``wi.z > 0``);
elsewhere the lobe sees the unflipped frame and behaves as the Mitsuba
plugin does from behind (a reflective lobe returns zero when ``wi.z <= 0``;
a transmissive one decides inside/outside from the sign of ``wi.z``).

No lobe may return NaN or Inf, or a negative value, for any unit input,
including ``cos`` of 1e-6, roughness 0 and 1, and IOR 1.
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from typing import Any, ClassVar, Protocol

from drjit.auto import Array2f, Array3f, Bool, Float


class BSDFSample:
    """A sampled direction: ``wo`` (local), ``weight = f*|cos|/pdf``, its ``pdf``
    (0 for delta lobes), ``valid``, ``delta`` (a Dirac lobe was chosen) and
    ``eta`` (relative IOR crossed: 1 for reflection; used by Russian roulette)."""

    DRJIT_STRUCT = {"wo": Array3f, "weight": Array3f, "pdf": Float, "valid": Bool,
                    "delta": Bool, "eta": Float}

    def __init__(self, wo=None, weight=None, pdf=None, valid=None, delta=None, eta=None):
        self.wo = wo if wo is not None else Array3f(0.0, 0.0, 1.0)
        self.weight = weight if weight is not None else Array3f(0.0)
        self.pdf = pdf if pdf is not None else Float(0.0)
        self.valid = valid if valid is not None else Bool(False)
        self.delta = delta if delta is not None else Bool(False)
        self.eta = eta if eta is not None else Float(1.0)


class BSDF(Protocol):
    """What a lobe module provides (module-level names; see the module docs).

    ``FIELDS`` names the per-component values the material table uploads
    when the kind is present: ``"rgb"``, ``"float"`` or ``("table", N)`` (N
    samples over [0, 1], read with ``table.table_lerp``). A field's value is
    the spec's parameter of that name or, when the module defines
    ``derive(params) -> dict`` (host side, once per component, ``ValueError``
    for a bad parameter), that function's output
    (:class:`drpt.materials.layout.MaterialLayout` lays them out). ``params(table,
    si, active)`` gathers the lobe's parameter record with ``table.value`` and
    may decide what to trace from ``table.specs_of(kind)``; ``table`` is the
    lanes' rows of the material table (:class:`drpt.render.material.Rows`). ``DELTA``: only
    Dirac components (``eval`` and ``pdf`` are 0, next-event estimation is
    skipped); a lobe mixing a Dirac and a smooth part sets ``delta`` per
    sample instead. Optional ``COLOR``: the field the Whitted ambient term
    multiplies.
    """

    FIELDS: ClassVar[Mapping[str, Any]]
    DELTA: ClassVar[bool]

    def params(self, table: Any, si: Any, active: Bool) -> Any: ...

    def eval(self, p: Any, wi: Array3f, wo: Array3f) -> Array3f: ...

    def pdf(self, p: Any, wi: Array3f, wo: Array3f) -> Float: ...

    def sample(self, p: Any, wi: Array3f, u1: Float, u2: Array2f) -> BSDFSample: ...


#: BSDF kind (``BSDFSpec.kind``) -> module of this package that implements it.
REGISTRY: dict[str, str] = {
    "diffuse": "diffuse",
    "phong": "phong",
    "cook_torrance": "cook_torrance",
    "dielectric": "dielectric",
    "mirror": "mirror",
    "null": "null",
    "conductor": "conductor",
    "roughconductor": "roughconductor",
    "principled": "principled",
    "principledthin": "principledthin",
    "thindielectric": "thindielectric",
    "roughdielectric": "roughdielectric",
    "plastic": "plastic",
    "roughplastic": "roughplastic",
}


def lobe(kind: str) -> BSDF:
    """The module implementing BSDF ``kind`` (imported on first use)."""
    return importlib.import_module(f"{__name__}.{REGISTRY[kind]}")  # type: ignore[return-value]
