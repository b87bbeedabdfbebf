"""drpt's Cook-Torrance lobe as a Mitsuba 3 built-in: ``twosided(principled)``.

:mod:`drpt.render.bsdf.cook_torrance` is, formula for formula, the
metallic/roughness subset of Mitsuba 3's ``principled`` BSDF (see its module
docs), so the export is exact, not a blend:

* ``base_color`` = ``kd`` (rgb), or the ``map_Kd`` bitmap where the material
  has one;
* ``metallic`` = ``metalness``;
* ``roughness`` = ``sqrt(alpha)``: drpt's parameter is the GGX alpha itself,
  principled squares its ``roughness`` to get alpha (then clamps it to
  >= 1e-3, as drpt does too);
* everything else at principled's defaults (``specular`` 0.5, i.e. IOR 1.5;
  ``spec_tint``, ``anisotropic``, ``sheen``, ``clearcoat``, ``spec_trans``,
  ``flatness`` all 0), written out explicitly as ``specular = 0.5`` only,
  since principled treats an explicitly given zero lobe weight as absent
  anyway.

Mitsuba's BSDFs are one-sided; drpt's surfaces two-sided, hence
``twosided`` (the same BSDF on both faces).
"""

from __future__ import annotations

import math
from typing import Any

__all__ = ["to_mitsuba"]


def to_mitsuba(spec: Any) -> dict:
    """``twosided(principled)`` dict for a :class:`drpt.shading.BSDFSpec` of
    kind "cook_torrance" (plain Mitsuba dict: rgb values as
    ``{"type": "rgb", "value": [...]}``)."""
    if spec.kind != "cook_torrance":
        raise ValueError(f"to_mitsuba: expected a 'cook_torrance' BSDFSpec, got {spec.kind!r}")
    alpha = float(spec.alpha)
    metal = float(spec.metalness)
    if not (math.isfinite(alpha) and math.isfinite(metal)):
        raise ValueError(f"to_mitsuba: bad alpha/metalness {spec.alpha!r}, {spec.metalness!r}")
    alpha = min(max(alpha, 0.0), 1.0)
    metal = min(max(metal, 0.0), 1.0)
    if spec.texture is not None:
        base: dict = {"type": "bitmap", "filename": str(spec.texture),
                      "filter_type": "bilinear", "wrap_mode": "repeat"}
    else:
        base = {"type": "rgb", "value": [float(x) for x in spec.kd]}
    material = {
        "type": "principled",
        "base_color": base,
        "metallic": metal,
        "roughness": math.sqrt(alpha),
        "specular": 0.5,
    }
    return {"type": "twosided", "material": material}
