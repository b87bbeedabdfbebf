"""The BSDF vocabulary: every kind drpt renders, its parameters and their defaults.

Backend-free (no Dr.Jit): the scene readers, :mod:`drpt.materials.interpret`, the
Mitsuba exporter and the Mitsuba XML importer all describe materials with
these names, and :mod:`drpt.render.material` uploads them.

Kinds named after a Mitsuba 3 plugin (``conductor``, ``roughconductor``,
``dielectric``, ``thindielectric``, ``roughdielectric``, ``plastic``,
``roughplastic``, ``principled``, ``principledthin``) take that plugin's parameter names and
defaults, so a parameter means the same in drpt and in Mitsuba; each one's
lobe module (:mod:`drpt.render.bsdf`) states the math. drpt's own kinds
(``diffuse``, ``phong``, ``cook_torrance``, ``mirror``) keep the names of
the fields they are read from (MTL ``Kd``, ``Ks``, ``Ns``; the seed's
``Roughness``, ``Mentalness``). ``null`` is the pass-through of ``mask``.

Composite kinds (:data:`COMPOSITES`) hold other specs as children:
``twosided`` (one child, shown from both sides; reflective children only,
as in Mitsuba), ``blendbsdf`` (two children mixed as ``(1 - weight) a +
weight b``), ``mask`` (one child, seen with probability ``opacity``,
else the ray passes straight through), and ``normalmap`` / ``bumpmap``
(one child, seen in a shading frame perturbed by a texture: Mitsuba's
plugins of those names, :mod:`drpt.render.perturb`).

Values are floats, RGB triples, :class:`drpt.materials.spec.Texture` (where a
kind's :data:`TEXTURABLE` allows it), or for string/bool parameters a
Python ``str``/``bool`` (decided when a kernel is traced).
"""

from __future__ import annotations

import numbers
from typing import Any

#: Mitsuba's default index of refraction of its named media (``lookup_ior``).
AIR = 1.000277
BK7 = 1.5046
POLYPROPYLENE = 1.49

GRAY = (0.5, 0.5, 0.5)
WHITE = (1.0, 1.0, 1.0)

#: kind -> {parameter: default}. ``None`` means "not given" (the lobe derives it).
PARAMS: dict[str, dict[str, Any]] = {
    # drpt's own kinds
    "diffuse": {"kd": GRAY},
    "phong": {"kd": GRAY, "ks": (0.0, 0.0, 0.0), "ns": 1.0},
    "cook_torrance": {"kd": GRAY, "alpha": 1.0, "metalness": 0.0},
    "mirror": {"ks": WHITE},
    "null": {},
    # Mitsuba 3's plugins, their names and defaults
    "conductor": {"material": "none", "eta": None, "k": None, "specular_reflectance": WHITE},
    "roughconductor": {"material": "none", "eta": None, "k": None, "specular_reflectance": WHITE,
                       "distribution": "beckmann", "alpha": 0.1, "alpha_u": None, "alpha_v": None,
                       "sample_visible": True},
    "dielectric": {"int_ior": BK7, "ext_ior": AIR, "specular_reflectance": WHITE,
                   "specular_transmittance": WHITE},
    "thindielectric": {"int_ior": BK7, "ext_ior": AIR, "specular_reflectance": WHITE,
                       "specular_transmittance": WHITE},
    "roughdielectric": {"int_ior": BK7, "ext_ior": AIR, "specular_reflectance": WHITE,
                        "specular_transmittance": WHITE, "distribution": "beckmann", "alpha": 0.1,
                        "alpha_u": None, "alpha_v": None, "sample_visible": True},
    "plastic": {"diffuse_reflectance": GRAY, "specular_reflectance": WHITE,
                "int_ior": POLYPROPYLENE, "ext_ior": AIR, "nonlinear": False},
    "roughplastic": {"diffuse_reflectance": GRAY, "specular_reflectance": WHITE,
                     "int_ior": POLYPROPYLENE, "ext_ior": AIR, "nonlinear": False,
                     "distribution": "beckmann", "alpha": 0.1, "sample_visible": True},
    "principled": {"base_color": GRAY, "roughness": 0.5, "metallic": 0.0, "specular": 0.5,
                   "eta": None, "spec_tint": 0.0, "anisotropic": 0.0, "sheen": 0.0,
                   "sheen_tint": 0.0, "clearcoat": 0.0, "clearcoat_gloss": 0.0,
                   "spec_trans": 0.0, "flatness": 0.0, "diffuse_reflectance_sampling_rate": 1.0,
                   "main_specular_sampling_rate": 1.0, "clearcoat_sampling_rate": 1.0},
    "principledthin": {"base_color": GRAY, "roughness": 0.5, "anisotropic": 0.0, "spec_trans": 0.0,
                       "sheen": 0.0, "sheen_tint": 0.0, "flatness": 0.0, "spec_tint": 0.0, "eta": 1.5,
                       "diff_trans": 0.0, "specular_reflectance_sampling_rate": 1.0,
                       "specular_transmittance_sampling_rate": 1.0,
                       "diffuse_transmittance_sampling_rate": 1.0,
                       "diffuse_reflectance_sampling_rate": 1.0},
}

#: Parameters of each kind that may be a texture (as Mitsuba allows).
TEXTURABLE: dict[str, frozenset[str]] = {
    "diffuse": frozenset({"kd"}),
    "phong": frozenset({"kd"}),
    "cook_torrance": frozenset({"kd"}),
    "mirror": frozenset(),
    "null": frozenset(),
    "conductor": frozenset({"specular_reflectance"}),
    "roughconductor": frozenset({"specular_reflectance", "alpha", "alpha_u", "alpha_v"}),
    "dielectric": frozenset({"specular_reflectance", "specular_transmittance"}),
    "thindielectric": frozenset({"specular_reflectance", "specular_transmittance"}),
    "roughdielectric": frozenset({"specular_reflectance", "specular_transmittance"}),
    "plastic": frozenset({"diffuse_reflectance", "specular_reflectance"}),
    "roughplastic": frozenset({"diffuse_reflectance", "specular_reflectance"}),
    # (Mitsuba reads principled's ``specular`` and ``eta`` as plain floats)
    "principled": frozenset({"base_color", "roughness", "metallic", "spec_tint", "anisotropic", "sheen",
                             "sheen_tint", "clearcoat", "clearcoat_gloss", "spec_trans", "flatness"}),
    # (drpt reads principledthin's ``eta`` as a plain float)
    "principledthin": frozenset({"base_color", "roughness", "anisotropic", "spec_trans", "sheen",
                                 "sheen_tint", "flatness", "spec_tint", "diff_trans"}),
}

#: Kinds holding other specs: name -> (number of children, their parameters and defaults).
COMPOSITES: dict[str, tuple[int, dict[str, Any]]] = {
    "twosided": (1, {}),
    "blendbsdf": (2, {"weight": 0.5}),
    "mask": (1, {"opacity": 0.5}),
    # the child seen in a perturbed shading frame: a tangent-space normal map (a texture,
    # required), or a height map's gradient (``texture``, required) times ``scale``
    "normalmap": (1, {"normalmap": None, "flip_invalid_normals": True, "use_shadowing_function": True}),
    "bumpmap": (1, {"texture": None, "scale": 1.0, "flip_invalid_normals": True,
                    "use_shadowing_function": True}),
}

#: Composites that perturb the shading frame of their child, and their texture parameter.
PERTURBING: dict[str, str] = {"normalmap": "normalmap", "bumpmap": "texture"}

#: Kinds that always transmit light: ``twosided`` refuses them, as Mitsuba's does. ``principled``
#: is not listed: it transmits (and Mitsuba's ``twosided`` refuses it) exactly when its
#: ``spec_trans`` is given and is not the number 0 -- a texture counts even if it is all 0
#: (Mitsuba's ``get_flag``: :func:`given`). :func:`transmits` is the whole rule, which
#: :func:`drpt.materials.spec.complete` applies. Without transmission principled is still one-sided
#: (black from behind: its lobe sees the unflipped frame) unless wrapped in ``twosided``.
TRANSMISSIVE = frozenset({"dielectric", "thindielectric", "roughdielectric", "null", "principledthin"})

#: Dirac-lobe kinds that send every ray they meet on in another direction (reflect or
#: refract); ``null`` and ``thindielectric``, Dirac too, let rays pass straight on.
BENDING = frozenset({"dielectric", "mirror", "conductor"})

LEAF_KINDS = tuple(PARAMS)
ALL_KINDS = LEAF_KINDS + tuple(COMPOSITES)


def given(v: Any) -> bool:
    """Mitsuba's ``get_flag`` (``principled``): a parameter counts as given unless it
    is absent (``None``) or the number 0; a texture counts whatever its values."""
    if v is None:
        return False
    if isinstance(v, numbers.Real) and not isinstance(v, bool):
        return float(v) != 0.0
    return True


def transmits(kind: str, params: dict[str, Any]) -> bool:
    """Whether a leaf of ``kind`` with ``params`` has a transmission component
    (what Mitsuba's ``twosided`` refuses): the :data:`TRANSMISSIVE` kinds, and
    ``principled`` with ``spec_trans`` :func:`given`."""
    return kind in TRANSMISSIVE or (kind == "principled" and given(params.get("spec_trans")))


def defaults(kind: str) -> dict[str, Any]:
    """A fresh copy of ``kind``'s parameters at their defaults."""
    if kind in COMPOSITES:
        return dict(COMPOSITES[kind][1])
    return dict(PARAMS[kind])
