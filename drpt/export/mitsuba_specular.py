"""Mitsuba 3 counterparts of drpt's delta lobes (plain ``mi.load_dict`` dicts).

* ``dielectric`` -> ``{"type": "dielectric", "int_ior": ior, "ext_ior": 1.0}``.
  ``ext_ior`` is always given: Mitsuba's default is air (1.000277), drpt's
  outside is vacuum. It is *not* wrapped in ``twosided``: the dielectric
  tells inside from outside by the side of the normal, in both renderers.
* ``mirror`` -> ``twosided(conductor)`` with ``material="none"`` (Fresnel
  factor 1) and ``specular_reflectance`` = the reflectance ``ks``.

See :mod:`drpt.render.bsdf.dielectric` and :mod:`drpt.render.bsdf.mirror`
for the equivalences (checked sample for sample by the lobes' tests).
"""

from __future__ import annotations

import math
from typing import Any

__all__ = ["to_mitsuba"]


def to_mitsuba(spec: Any) -> dict:
    """The Mitsuba dict of a :class:`drpt.shading.BSDFSpec` of kind
    ``"dielectric"`` or ``"mirror"``."""
    if spec.kind == "dielectric":
        ior = float(spec.ior)
        if not (math.isfinite(ior) and ior > 0.0):
            raise ValueError(f"to_mitsuba: bad index of refraction {spec.ior!r}")
        return {"type": "dielectric", "int_ior": ior, "ext_ior": 1.0}
    if spec.kind == "mirror":
        ks = [float(x) for x in spec.ks]
        return {"type": "twosided",
                "material": {"type": "conductor", "material": "none",
                             "specular_reflectance": {"type": "rgb", "value": ks}}}
    raise ValueError(f"to_mitsuba: expected a 'dielectric' or 'mirror' BSDFSpec, "
                     f"got {spec.kind!r}")
