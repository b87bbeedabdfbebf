"""A material's :class:`~drpt.materials.spec.BSDFSpec` tree as Mitsuba 3 BSDF dicts.

One node, one plugin (plain ``mi.load_dict`` dicts: RGB values as
``{"type": "rgb", "value": [r, g, b]}``, textures as ``bitmap`` with
``filter_type="bilinear"`` and ``wrap_mode="repeat"``, as drpt looks them up):

* ``twosided``, ``blendbsdf`` (``weight``; ``bsdf_0`` gets ``1 - weight``),
  ``mask`` (``opacity``), ``normalmap``, ``bumpmap`` -> the composites of the
  same name (a ``raw`` texture as a ``bitmap`` with ``raw``);
* kinds named after a Mitsuba plugin -> that plugin with the same
  parameters, leaving out the ones not given (``None``) and the ones the
  plugin would not read next to another (``alpha`` beside ``alpha_u``/
  ``alpha_v``, ``material`` beside ``eta``/``k``, ``specular`` beside
  ``eta``): Mitsuba refuses parameters its plugin does not read;
* ``diffuse`` -> ``diffuse`` (``reflectance = kd``);
* ``cook_torrance`` -> ``principled`` with ``base_color = kd``, ``metallic =
  metalness``, ``roughness = sqrt(alpha)`` (principled squares it) and
  ``specular = 0.5``: the lobe is principled's metallic/roughness subset
  (:mod:`drpt.render.bsdf.cook_torrance`);
* ``mirror`` -> ``conductor`` with ``material="none"`` and
  ``specular_reflectance = ks``;
* ``dielectric``, ``thindielectric``, ``roughdielectric``: as their plugins,
  after :func:`drpt.export.mitsuba_dielectrics.adjust` (an index-matched
  ``roughdielectric``, which Mitsuba refuses, becomes ``dielectric``);
* ``phong`` -> ``drpt_phong`` (:mod:`drpt.export.mitsuba_phong`, registered
  with ``mi.register_bsdf``: Mitsuba has no Phong).

Each equivalence is tested in the lobe's test module against the plugin.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import DrptError, Loc, SceneError
from ..materials.bsdf_kinds import COMPOSITES, PARAMS, PERTURBING
from ..materials.conductors import mitsuba_ior
from ..materials.spec import BSDFSpec, Checkerboard, MeshAttribute, Texture
from .mitsuba_dielectrics import KINDS as DIELECTRICS
from .mitsuba_dielectrics import adjust as adjust_dielectric
from .mitsuba_phong import PLUGIN_NAME
from .values import _Matrix, _Vector

__all__ = ["to_mitsuba"]


def _to_uv(m):
    """A 4x4 ``to_uv`` as the exporter writes transforms (its matrix wrapper)."""
    return _Matrix(m)


def _Vec(v):
    """A 3-vector as the exporter writes vectors (its wrapper: ``<vector>`` in XML)."""
    return _Vector(tuple(float(x) for x in v))


def _error(where: Loc | str, message: str) -> DrptError:
    """The error about a value of the material or light at ``where`` (its Loc, or a name
    such as ``"light 2"`` for one built in code)."""
    return SceneError(where, message) if isinstance(where, Loc) else DrptError(f"{where}: {message}")


def _value(v: Any, where: Loc | str) -> Any:
    if isinstance(v, Checkerboard):
        a = np.asarray(v.to_uv, float).reshape(3, 3)
        m = np.eye(4)
        m[:2, :2], m[:2, 3] = a[:2, :2], a[:2, 2]
        return {"type": "checkerboard", "color0": _value(tuple(v.color0), where),
                "color1": _value(tuple(v.color1), where), "to_uv": _to_uv(m)}
    if isinstance(v, MeshAttribute):
        return {"type": "mesh_attribute", "name": v.name, "scale": float(v.scale)}
    if isinstance(v, Texture):
        if not Path(v.path).is_file():
            raise _error(where, f"texture {v.path} not found")
        out = {"type": "bitmap", "filename": str(Path(v.path).resolve()),
               "filter_type": v.filter_type, "wrap_mode": v.wrap_mode}
        if v.raw:
            out["raw"] = True
        if v.to_uv is not None:
            a = np.asarray(v.to_uv, float).reshape(3, 3)
            m = np.eye(4)
            m[:2, :2], m[:2, 3] = a[:2, :2], a[:2, 2]
            out["to_uv"] = _to_uv(m)
        return out
    if isinstance(v, (tuple, list)):
        return {"type": "rgb", "value": [float(x) for x in v]}
    if isinstance(v, bool) or isinstance(v, str):
        return v
    x = float(v)
    if not math.isfinite(x):
        raise _error(where, f"parameter value {v!r} is not finite")
    return x


def _leaf(spec: BSDFSpec) -> dict:
    p, kind = spec.params, spec.kind

    def val(v):
        return _value(v, spec.loc or "material")

    if kind == "diffuse":
        return {"type": "diffuse", "reflectance": val(p["kd"])}
    if kind == "cook_torrance":
        alpha = min(max(float(p["alpha"]), 0.0), 1.0)
        return {"type": "principled", "base_color": val(p["kd"]),
                "metallic": min(max(float(p["metalness"]), 0.0), 1.0),
                "roughness": math.sqrt(alpha), "specular": 0.5}
    if kind == "mirror":
        return {"type": "conductor", "material": "none", "specular_reflectance": val(p["ks"])}
    if kind == "phong":
        return {"type": PLUGIN_NAME, "kd": val(p["kd"]), "ks": val(p["ks"]), "ns": float(p["ns"])}
    if kind == "null":
        return {"type": "null"}
    if kind not in PARAMS:
        raise _error(spec.loc or "material", f"BSDF kind '{kind}' has no Mitsuba counterpart")
    if kind in DIELECTRICS:  # e.g. an index-matched roughdielectric -> dielectric
        kind, p = adjust_dielectric(kind, p)
    out: dict[str, Any] = {"type": kind}
    skip = set()
    if kind in ("conductor", "roughconductor"):
        out.update({k: val(v) for k, v in mitsuba_ior(p).items()})
        skip |= {"material", "eta", "k"}
    if p.get("alpha_u") is not None or p.get("alpha_v") is not None:
        skip.add("alpha")
    if p.get("eta") is not None:
        skip.add("specular")
    for name, v in p.items():
        if v is None or name in skip:
            continue
        out[name] = val(v)
    return out


def to_mitsuba(spec: BSDFSpec) -> dict:
    """The Mitsuba dict of a complete :class:`~drpt.materials.spec.BSDFSpec` tree."""
    if spec.kind not in COMPOSITES:
        return _leaf(spec)
    kids = [to_mitsuba(c) for c in spec.children]
    if spec.kind == "twosided":
        return {"type": "twosided", **{f"bsdf_{i}": k for i, k in enumerate(kids)}}
    if spec.kind in ("normalmap", "bumpmap"):
        p = spec.params
        v = p[PERTURBING[spec.kind]]
        if not (isinstance(v, Texture) or (spec.kind == "normalmap" and isinstance(v, tuple))):
            return kids[0]  # its texture dropped (no uvs): nothing perturbs the child
        if isinstance(v, tuple):  # one normal everywhere: as stored, like drpt reads it
            p = {**p, "normalmap": None}
            const = {"type": "rawconstant", "value": _Vec(v)}
        out = {"type": spec.kind, "bsdf": kids[0],
               "flip_invalid_normals": bool(p["flip_invalid_normals"]),
               "use_shadowing_function": bool(p["use_shadowing_function"])}
        if spec.kind == "normalmap":
            out["normalmap"] = const if isinstance(v, tuple) else _value(v, spec.loc or "material")
        else:
            out["texture"], out["scale"] = _value(p["texture"], spec.loc or "material"), float(p["scale"])
        return out
    if spec.kind == "blendbsdf":
        return {"type": "blendbsdf", "weight": _value(spec.params["weight"], spec.loc or "material"),
                "bsdf_0": kids[0], "bsdf_1": kids[1]}
    return {"type": "mask", "opacity": _value(spec.params["opacity"], spec.loc or "material"), "bsdf": kids[0]}
