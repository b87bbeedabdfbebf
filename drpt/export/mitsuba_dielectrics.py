"""What the Mitsuba export of ``dielectric``, ``thindielectric`` and
``roughdielectric`` needs beyond "``{"type": kind, **params}``" (backend-free).

:func:`adjust` takes a spec's kind and parameters (defaults filled in, values
as in :mod:`drpt.materials.bsdf_kinds`) and returns the Mitsuba plugin name and the
parameters to emit; converting the values (RGB tuples, textures) stays with
the generic exporter. The adjustments:

* parameters that are ``None`` (``alpha_u``/``alpha_v`` not given) are left
  out: Mitsuba takes no ``None``;
* ``roughdielectric`` with ``alpha_u`` and ``alpha_v`` emits those and not
  ``alpha`` (Mitsuba refuses both at once); with ``alpha_u == alpha_v`` it
  emits ``alpha`` (Mitsuba then also calls the lobe isotropic);
* ``roughdielectric`` whose relative IOR is exactly 1 in float32 (Mitsuba
  refuses ``int_ior == ext_ior``) becomes Mitsuba's ``dielectric`` with the
  same IORs and tints (and without the roughness parameters): an
  index-matched interface is invisible, and that is what drpt's
  :mod:`drpt.render.bsdf.roughdielectric` renders there (the lobe's tests
  check the two sample for sample);
* IOR names are passed through (Mitsuba knows the same names,
  :mod:`drpt.materials.iors`), numbers as floats.
"""

from __future__ import annotations

from typing import Any

from drpt.materials.iors import relative_ior

KINDS = ("dielectric", "thindielectric", "roughdielectric")
_ROUGH_ONLY = ("distribution", "alpha", "alpha_u", "alpha_v", "sample_visible")


def adjust(kind: str, params: dict[str, Any]) -> tuple[str, dict[str, Any]]:
    """``(mitsuba_plugin, params_to_emit)`` for a spec of one of :data:`KINDS`."""
    if kind not in KINDS:
        raise ValueError(f"mitsuba_dielectrics.adjust: not a dielectric kind: {kind!r}")
    out = {k: v for k, v in params.items() if v is not None}
    for k in ("int_ior", "ext_ior"):
        if k in out and not isinstance(out[k], str):
            out[k] = float(out[k])
    if kind != "roughdielectric":
        return kind, out
    if relative_ior(out.get("int_ior", "bk7"), out.get("ext_ior", "air")) == 1.0:
        return "dielectric", {k: v for k, v in out.items() if k not in _ROUGH_ONLY}
    if "alpha_u" in out or "alpha_v" in out:
        if out.get("alpha_u") == out.get("alpha_v"):
            out["alpha"] = out.pop("alpha_u")
            out.pop("alpha_v")
        else:
            out.pop("alpha", None)
    if "distribution" in out:
        out["distribution"] = str(out["distribution"]).lower()
    return kind, out
