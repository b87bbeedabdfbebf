"""BSDF lobes, one module each: ``diffuse``, ``phong``, ``cook_torrance``
(with ``microfacet`` for GGX), ``dielectric``, ``mirror``, ``plastic``,
``roughplastic`` (its coating tables precomputed by ``roughplastic_tables``).

:data:`REGISTRY` maps each kind of :class:`drpt.shading.BSDFSpec` to its
module; :class:`drpt.render.material.MaterialTable` finds a kind's lobe
there (:func:`lobe`) and traces only the kinds a scene has. A new BSDF is one
module implementing :class:`BSDF` plus one entry in :data:`REGISTRY` (and the
rule in :func:`drpt.shading.interpret` that produces its kind; the Mitsuba
exporter needs its counterpart in :mod:`drpt.export`).

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
:mod:`drpt.render.material`. Reflection-only lobes assume the material
layer has flipped the frame to the viewer's side (``wi.z > 0``) and return
zero otherwise; transmissive lobes (``dielectric``) see the unflipped frame
and decide inside/outside from the sign of ``wi.z``.

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

    ``FIELDS`` names the :class:`~drpt.shading.BSDFSpec` fields besides
    ``kd`` the material table uploads per material when the kind is present
    (``"rgb"`` or ``"float"``); ``params(table, si, active)`` gathers the
    lobe's parameter record for the lanes' materials from it. ``DELTA``: a
    Dirac lobe (``eval`` and ``pdf`` are 0, next-event estimation is skipped).
    ``TWO_SIDED``: the material layer flips the shading frame to the viewer's
    side before calling the lobe; else the lobe sees the unflipped frame.
    """

    FIELDS: ClassVar[Mapping[str, str]]
    DELTA: ClassVar[bool]
    TWO_SIDED: ClassVar[bool]

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
    "plastic": "plastic",
    "roughplastic": "roughplastic",
}


def lobe(kind: str) -> BSDF:
    """The module implementing BSDF ``kind`` (imported on first use)."""
    return importlib.import_module(f"{__name__}.{REGISTRY[kind]}")  # type: ignore[return-value]
