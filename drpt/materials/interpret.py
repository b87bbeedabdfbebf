"""How a scene's materials are read: from file statements to one BSDF tree per material.

Backend-free. The renderer (through :mod:`drpt.materials.layout`) and the
Mitsuba exporter both call :func:`interpret_scene`, so what drpt renders and what
Mitsuba is given cannot drift apart.

A material is a :class:`~drpt.materials.spec.BSDFSpec` tree in the vocabulary of
:mod:`drpt.materials.bsdf_kinds` (Mitsuba's plugin names and parameters, plus drpt's
own ``phong``, ``cook_torrance``, ``mirror``). A material that carries an
explicit ``bsdf`` (a Mitsuba XML scene) is used as given; every other one
is read from its MTL (or 6.837) statements by the *mode*:

``auto`` (no ``--bsdf`` flag, no seed ``-input``): each material's own statements decide
    First match wins. ``r`` is the roughness (PBR ``Pr`` or the seed's
    ``Roughness``), clamped to [0, 1]; the GGX width is ``alpha = r^2``.

    ======================================================  ==============================================
    statements                                               BSDF
    ======================================================  ==============================================
    ``Ke`` without ``Kd``                                    black (``diffuse`` with ``kd = 0``): it only emits
    see-through: ``Tf``/``Kt`` with ``illum`` not 0-2,       ``dielectric`` (``int_ior = Ni``, 1.5 when absent;
    ``d < 1`` with ``Ni``, ``illum`` 4, 6, 7 or 9, or a      ``specular_transmittance = Tf``); ``roughdielectric``
    6.837 ``transparentColor``                               (GGX, ``alpha = r^2``) when ``r > 0``
    6.837 ``reflectiveColor``; ``illum 3`` with ``Ks`` and   ``conductor`` (``specular_reflectance = Ks``, no
    no diffuse color                                         Fresnel); ``roughconductor`` (GGX) when ``r > 0``
    any PBR statement (``Pr Pm Ps Pc Pcr aniso`` or their    ``principled``: ``base_color = Kd``/``map_Kd``,
    maps)                                                    ``roughness = Pr``, ``metallic = Pm``, ``sheen =
                                                             Ps``, ``clearcoat = Pc``, ``clearcoat_gloss = 1 -
                                                             Pcr``, ``anisotropic = aniso``, ``eta = Ni`` (when
                                                             1 < Ni <= 4)
    the seed's ``Roughness``/``Mentalness``                  ``cook_torrance`` (``alpha = Roughness^2``)
    ``Ks > 0``                                               ``phong`` (``Kd``, ``Ks``, ``Ns``)
    otherwise                                                ``diffuse`` (``Kd`` or ``map_Kd``)
    ======================================================  ==============================================

    Then: ``d < 1`` (or ``Tr > 0``) on a material that is not see-through, or
    a ``map_d``, wraps it in ``mask`` with that opacity; reflective models are
    wrapped in ``twosided`` (drpt's surfaces reflect on both sides). Values
    outside their range are clamped with a note.

``phong`` (the seed's default) and ``cook-torrance`` (the seed's ``-cook_torrance``)
    The seed's meaning, as its renderer reads the same files: see-through
    materials (``d < 1``, ``Tr > 0``, ``illum`` 4, 6, 7, a ``transparentColor``)
    are smooth ``dielectric``; a ``reflectiveColor``, or ``illum 3`` with no
    diffuse color, a ``mirror``; everything else ``phong`` (``Ks > 0``) or
    ``diffuse``, respectively ``cook_torrance`` with ``alpha = Roughness^2``
    (the seed's parser stores ``Roughness * Roughness`` and its GGX squares it
    again) and ``Roughness = 0.95`` when absent, as the seed's parser defaults it.

``diffuse``
    Lambertian everywhere, ``Kd`` or ``map_Kd``.

In every mode a material with ``Ke`` and no ``Kd`` reflects nothing.

Textures: a ``map_*`` becomes a :class:`Texture` parameter, looked up at the
triangles' texture coordinates (OBJ ``vt``). In a scene without any texture
coordinates there is nothing to look a texture up at, so
:func:`interpret_scene` replaces each texture by its fallback value (the
material's ``Kd``, ``Pr``, ...), in drpt and in the exported Mitsuba scene
alike, and a note names the material.

Energy: a Phong material with ``Kd + Ks > 1`` in some channel (the course's
Cornell box has ``Kd 1``, ``Ks 1``) would reflect more than it receives;
both are scaled down by the same factor so that ``max(Kd + Ks) = 1``, and
:func:`interpret` reports it (``BSDFSpec.notes``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..scene.model import Material, Scene
from .spec import BSDFSpec, MeshAttribute, Texture, complete

MODES = ("auto", "phong", "cook-torrance", "diffuse")
#: The seed parser's Roughness when a material gives none.
SEED_ROUGHNESS = 0.95
#: statements (and map_* keys) of the PBR extension, which make a material ``principled``
_PBR_KEYS = frozenset({"pr", "pm", "ps", "pc", "pcr", "aniso", "anisor"})


# ---------------------------------------------------------------- reading MTL
def _positive(c) -> bool:
    return c is not None and max(c) > 0.0


def _clamp01(v: float, what: str, m: Material, notes: list[str]) -> float:
    c = min(max(float(v), 0.0), 1.0)
    if c != v:
        notes.append(f"material '{m.name}': {what} {v:g} clamped to {c:g}")
    return c


def _tex(m: Material, key: str, fallback):
    """The texture of statement ``map_<key>`` (``None`` when absent)."""
    path = m.map_kd if key == "kd" else m.maps.get(key)
    return None if path is None else Texture(path, fallback, loc=getattr(path, "named_at", None))


def _color(m: Material) -> Any:
    kd = tuple(float(x) for x in m.kd)
    return _tex(m, "kd", kd) or kd


def _black(m: Material) -> bool:
    """``Ke`` without ``Kd``: the material only emits."""
    return m.is_emissive and "kd" not in m.given and m.map_kd is None


def _two(spec: BSDFSpec) -> BSDFSpec:
    return BSDFSpec("twosided", children=[spec])


def _phong(m: Material, notes: list[str]) -> BSDFSpec:
    kd = tuple(float(x) for x in m.kd)
    ks = tuple(float(x) for x in m.ks)
    total = max(a + b for a, b in zip(kd, ks))
    if total > 1.0:
        kd, ks = tuple(x / total for x in kd), tuple(x / total for x in ks)
        notes.append(f"material '{m.name}': Kd + Ks = {total:g} > 1 reflects more than it receives; "
                     f"both scaled by 1/{total:g}")
    col = _tex(m, "kd", kd) or kd
    return BSDFSpec("phong", {"kd": col, "ks": ks, "ns": max(float(m.ns), 0.0)})


def _ior(m: Material, notes: list[str]) -> float:
    if m.ior is not None and m.ior > 0:
        return float(m.ior)
    notes.append(f"material '{m.name}': see-through without Ni; using IOR 1.5")
    return 1.5


def _seed(m: Material, mode: str, notes: list[str]) -> BSDFSpec:
    """The seed's reading (modes phong and cook-torrance)."""
    see_through = m.dissolve < 1.0 or m.illum in (4, 6, 7) or _positive(m.transparent)
    if see_through:
        ior = m.ior if (m.ior is not None and m.ior > 0) else 1.5
        return BSDFSpec("dielectric", {"int_ior": float(ior), "ext_ior": 1.0})
    if _positive(m.reflective):
        return _two(BSDFSpec("mirror", {"ks": tuple(float(x) for x in m.reflective)}))
    if m.illum == 3 and not _positive(m.kd) and m.map_kd is None:
        ks = m.ks if _positive(m.ks) else (1.0, 1.0, 1.0)
        return _two(BSDFSpec("mirror", {"ks": tuple(float(x) for x in ks)}))
    if _black(m):
        return _two(BSDFSpec("diffuse", {"kd": (0.0, 0.0, 0.0)}))
    if mode == "cook-torrance":
        r = SEED_ROUGHNESS if m.roughness is None else _clamp01(m.roughness, "Roughness", m, notes)
        metal = 0.0 if m.metalness is None else _clamp01(m.metalness, "Mentalness", m, notes)
        return _two(BSDFSpec("cook_torrance", {"kd": _color(m), "alpha": r * r, "metalness": metal}))
    if _positive(m.ks):
        return _two(_phong(m, notes))
    return _two(BSDFSpec("diffuse", {"kd": _color(m)}))


def _auto(m: Material, notes: list[str]) -> BSDFSpec:
    """Each material's own statements decide (the table in the module docs)."""
    g = set(m.given)
    r = None if m.roughness is None else _clamp01(m.roughness, "Pr", m, notes)
    opaque_illum = m.illum in (0, 1, 2)
    see_through = ((_positive(m.tf) and not opaque_illum) or (m.dissolve < 1.0 and "ni" in g)
                   or m.illum in (4, 6, 7, 9) or _positive(m.transparent))
    if _black(m):
        spec = _two(BSDFSpec("diffuse", {"kd": (0.0, 0.0, 0.0)}))
    elif see_through:
        p = {"int_ior": _ior(m, notes), "ext_ior": 1.0}
        if m.tf is not None:
            p["specular_transmittance"] = tuple(float(x) for x in m.tf)
        if r:
            p.update(distribution="ggx", alpha=r * r)
            spec = BSDFSpec("roughdielectric", p)
        else:
            spec = BSDFSpec("dielectric", p)
    elif _positive(m.reflective) or (m.illum == 3 and not ("kd" in g and _positive(m.kd))
                                     and m.map_kd is None and (_positive(m.ks) or "ks" not in g)):
        ks = m.reflective if _positive(m.reflective) else (m.ks if "ks" in g else (1.0, 1.0, 1.0))
        p = {"specular_reflectance": tuple(float(x) for x in ks)}
        if r:
            spec = _two(BSDFSpec("roughconductor", {**p, "distribution": "ggx", "alpha": r * r}))
        else:
            spec = _two(BSDFSpec("conductor", p))
    elif (g & _PBR_KEYS) or any(k in m.maps for k in _PBR_KEYS):
        spec = _two(_principled(m, r, notes))
    elif {"roughness", "mentalness"} & g:
        rr = SEED_ROUGHNESS if r is None else r
        metal = 0.0 if m.metalness is None else _clamp01(m.metalness, "Mentalness", m, notes)
        spec = _two(BSDFSpec("cook_torrance", {"kd": _color(m), "alpha": rr * rr, "metalness": metal}))
    elif _positive(m.ks):
        spec = _two(_phong(m, notes))
    else:
        spec = _two(BSDFSpec("diffuse", {"kd": _color(m)}))
    if not see_through and (m.dissolve < 1.0 or "d" in m.maps):
        d = _clamp01(m.dissolve, "d", m, notes)
        spec = BSDFSpec("mask", {"opacity": _tex(m, "d", d) or d}, [spec])
    return spec


def _principled(m: Material, r: float | None, notes: list[str]) -> BSDFSpec:
    p: dict[str, Any] = {"base_color": _color(m)}
    rough = 0.5 if r is None else r
    p["roughness"] = _tex(m, "pr", rough) or rough
    metal = 0.0 if m.metalness is None else _clamp01(m.metalness, "Pm", m, notes)
    p["metallic"] = _tex(m, "pm", metal) or metal
    for key, name, value in (("ps", "sheen", m.sheen), ("pc", "clearcoat", m.clearcoat)):
        v = 0.0 if value is None else _clamp01(value, key.capitalize(), m, notes)
        p[name] = _tex(m, key, v) or v
    if m.clearcoat_roughness is not None:
        p["clearcoat_gloss"] = 1.0 - _clamp01(m.clearcoat_roughness, "Pcr", m, notes)
    if m.anisotropy is not None:
        p["anisotropic"] = _clamp01(m.anisotropy, "aniso", m, notes)
    if m.anisotropy_rotation:
        notes.append(f"material '{m.name}': anisor (anisotropy rotation) is not supported; ignored")
    if m.ior is not None and 1.0 < m.ior <= 4.0:
        p["eta"] = float(m.ior)
    return BSDFSpec("principled", p)


def interpret(m: Material, mode: str = "auto") -> BSDFSpec:
    """The BSDF tree of material ``m`` in ``mode`` (see the module docs), complete."""
    if mode not in MODES:
        raise ValueError(f"unknown material mode {mode!r}")
    notes: list[str] = []
    if m.bsdf is not None:
        spec = m.bsdf
    elif mode == "diffuse":
        spec = _two(BSDFSpec("diffuse", {"kd": (0.0, 0.0, 0.0) if _black(m) else _color(m)}))
    elif mode == "auto":
        spec = _auto(m, notes)
    else:
        spec = _seed(m, mode, notes)
    spec = complete(spec)
    spec.notes = list(spec.notes) + notes
    spec.loc = spec.loc or m.loc
    return spec


def interpret_scene(scene: Scene, mode: str = "auto") -> list[BSDFSpec]:
    """:func:`interpret` for every material of ``scene``, then the scene's
    texture rule: without texture coordinates anywhere in the scene every
    texture parameter but a mesh attribute takes its fallback value, with a note naming the
    material and the texture."""
    specs = [interpret(m, mode) for m in scene.materials]
    if scene.triangles.uvs is None:
        for m, spec in zip(scene.materials, specs):
            for node in spec.walk():
                for name, v in list(node.params.items()):
                    if isinstance(v, Texture) and not isinstance(v, MeshAttribute):  # (no uv needed)
                        node.params[name] = v.fallback
                        spec.dropped.append(v.path or "checkerboard")
                        spec.notes.append(untextured_note(m, v.path or "checkerboard"))
    return specs


def untextured_note(m: Material, path: Path | None = None) -> str:
    """What is reported for a texture :func:`interpret_scene` drops."""
    path = path if path is not None else m.map_kd
    return (f"material '{m.name}': texture {Path(path).name} needs texture coordinates "
            "(OBJ vt) and the scene has none; using its constant value")
