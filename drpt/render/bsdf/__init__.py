"""BSDF lobes, one module each: ``diffuse``, ``phong``, ``cook_torrance``
(with ``microfacet`` for GGX), ``dielectric``, ``mirror``.

The lobe interface
------------------
All directions are *local* to the shading frame (``+z`` = shading normal),
unit length. ``wi`` points toward the viewer (where the path came from),
``wo`` toward the next vertex (where light comes from). Every lobe module
provides three functions over wide Dr.Jit arrays:

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

from drjit.auto import Array3f, Bool, Float


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
