"""How a scene's materials are read: from file fields to one BSDF per material.

Backend-free. The renderer (:mod:`drpt.render.material`) and the Mitsuba
exporter both call :func:`interpret_scene`, so what drpt renders and what
Mitsuba is given cannot drift apart.

Rules, first match wins (``mode`` is ``"phong"`` — the seed's default — or
``"cook-torrance"`` — the seed's ``-cook_torrance``; ``"diffuse"`` forces
Lambertian everywhere):

1. **dielectric** (smooth glass) when the material is see-through: MTL
   ``d < 1``, ``Tr > 0``, ``illum`` 4, 6 or 7, or a 6.837 ``transparentColor``
   above zero. ``ior`` = ``Ni`` / ``indexOfRefraction`` (1.5 when missing);
   the outside is vacuum (IOR 1).
2. **mirror** (perfect specular reflection) for a 6.837
   ``reflectiveColor`` above zero (reflectance = that color), or MTL
   ``illum 3`` with no diffuse color (reflectance = ``Ks``, or white).
3. **cook_torrance** in cook-torrance mode: base color ``Kd`` (or the
   texture), ``alpha`` = the seed's ``Roughness`` / PBR ``Pr`` taken as the GGX
   alpha directly (as the seed's ``sampleGGX`` does), or, when missing,
   ``alpha = sqrt(2 / (Ns + 2))`` (the usual Phong-exponent match; 1 when no
   Ns); ``metalness`` = ``Mentalness`` / ``Pm`` (0 when missing).
4. **phong** in phong mode when ``Ks > 0``: diffuse ``Kd`` plus normalized
   specular ``Ks`` with exponent ``Ns``.
5. **diffuse** otherwise: ``Kd`` (or the texture).

Textures: drpt looks a ``map_Kd`` up at the triangles' texture coordinates
(OBJ ``vt``; faces without them read uv (0, 0)). In a scene without any
texture coordinates there is nothing to look a texture up at, so
:func:`interpret_scene` drops it: the material renders its ``Kd``, in drpt
and in the exported Mitsuba scene alike, and a note names the material.

Energy: a Phong material with ``Kd + Ks > 1`` in some channel (the course's
Cornell box has ``Kd 1``, ``Ks 1``) would reflect more than it receives;
both are scaled down by the same factor so that ``max(Kd + Ks) = 1``, and
:func:`interpret` reports it (``BSDFSpec.notes``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from .scene.model import Material, Scene, Vec3

KINDS = ("diffuse", "phong", "cook_torrance", "dielectric", "mirror")
MODES = ("phong", "cook-torrance", "diffuse")


@dataclass
class BSDFSpec:
    kind: str
    kd: Vec3 = (0.0, 0.0, 0.0)
    ks: Vec3 = (0.0, 0.0, 0.0)
    ns: float = 1.0
    alpha: float = 1.0
    metalness: float = 0.0
    ior: float = 1.5
    texture: Path | None = None  # replaces kd where present
    notes: list[str] = field(default_factory=list)
    dropped_texture: Path | None = None  # the map_Kd not used (no texture coordinates)


def _positive(c: Vec3) -> bool:
    return max(c) > 0.0


def interpret(m: Material, mode: str = "phong") -> BSDFSpec:
    if mode not in MODES:
        raise ValueError(f"unknown material mode {mode!r}")
    kd = tuple(float(x) for x in m.kd)
    if mode == "diffuse":
        return BSDFSpec("diffuse", kd=kd, texture=m.map_kd)
    see_through = (m.dissolve < 1.0 or (m.illum in (4, 6, 7)) or _positive(m.transparent))
    if see_through:
        ior = m.ior if (m.ior is not None and m.ior > 0) else 1.5
        return BSDFSpec("dielectric", ior=float(ior))
    if _positive(m.reflective):
        return BSDFSpec("mirror", ks=tuple(float(x) for x in m.reflective))
    if m.illum == 3 and not _positive(m.kd) and m.map_kd is None:
        ks = m.ks if _positive(m.ks) else (1.0, 1.0, 1.0)
        return BSDFSpec("mirror", ks=tuple(float(x) for x in ks))
    if mode == "cook-torrance":
        if m.roughness is not None:
            alpha = float(m.roughness)
        else:
            alpha = math.sqrt(2.0 / (max(m.ns, 0.0) + 2.0))
        alpha = min(max(alpha, 0.0), 1.0)
        metal = 0.0 if m.metalness is None else min(max(float(m.metalness), 0.0), 1.0)
        return BSDFSpec("cook_torrance", kd=kd, alpha=alpha, metalness=metal, texture=m.map_kd)
    if _positive(m.ks):
        ks = tuple(float(x) for x in m.ks)
        spec = BSDFSpec("phong", kd=kd, ks=ks, ns=max(float(m.ns), 0.0), texture=m.map_kd)
        total = max(a + b for a, b in zip(kd, ks))
        if total > 1.0:
            spec.kd = tuple(x / total for x in kd)
            spec.ks = tuple(x / total for x in ks)
            spec.notes.append(f"material '{m.name}': Kd + Ks = {total:g} > 1 reflects more "
                              f"than it receives; both scaled by 1/{total:g}")
        return spec
    return BSDFSpec("diffuse", kd=kd, texture=m.map_kd)


def interpret_scene(scene: Scene, mode: str = "phong") -> list[BSDFSpec]:
    """:func:`interpret` for every material of ``scene``, then the scene's
    texture rule: without texture coordinates anywhere in the scene a texture
    is dropped (``texture`` None, ``dropped_texture`` set, the material keeps
    its ``Kd``) with a note naming the material."""
    specs = [interpret(m, mode) for m in scene.materials]
    if scene.triangles.uvs is None:
        for m, spec in zip(scene.materials, specs):
            if spec.texture is not None:
                spec.dropped_texture, spec.texture = spec.texture, None
                spec.notes.append(untextured_note(m))
    return specs


def untextured_note(m: Material) -> str:
    """What is reported for a texture :func:`interpret_scene` drops."""
    return (f"material '{m.name}': texture {Path(m.map_kd).name} needs texture coordinates "
            "(OBJ vt) and the scene has none; using Kd")
