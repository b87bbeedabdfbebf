"""A material as a tree: :class:`BSDFSpec` nodes in the vocabulary of
:mod:`drpt.materials.bsdf_kinds`, and the texture-valued parameters they may hold.

Backend-free. Every reader produces these trees (the MTL rules of
:mod:`drpt.materials.interpret`, the Mitsuba XML reader
:mod:`drpt.scene.mitsuba.materials`, a material's explicit ``bsdf``),
:func:`complete` fills in the defaults and refuses what drpt cannot render,
and the consumers read them: the host layout (:mod:`drpt.materials.layout`),
and through it the device (:mod:`drpt.render.material`), and the Mitsuba
exporter (:mod:`drpt.export.mitsuba_bsdf`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from ..errors import Loc
from . import bsdf_kinds


@dataclass(frozen=True)
class Texture:
    """A texture-valued parameter: an image file (looked up at the surface's
    uv) and the value the parameter takes where it cannot be looked up.

    The lookup is Mitsuba's ``bitmap``'s: ``filter_type`` ``"bilinear"`` or
    ``"nearest"``, ``wrap_mode`` ``"repeat"``, ``"mirror"`` or ``"clamp"``, ``raw``
    (8-bit values taken as stored, without the sRGB decoding) and ``to_uv`` (None,
    or a row-major 3x3 2D affine matrix applied to Mitsuba's uv, as
    :class:`Checkerboard`'s)."""

    path: Path
    fallback: Any = 0.0
    filter_type: str = "bilinear"
    wrap_mode: str = "repeat"
    raw: bool = False
    to_uv: tuple | None = None
    #: where the file defines it (not part of == nor repr: alike textures share one upload)
    loc: Loc | None = field(default=None, compare=False, repr=False)

    @property
    def is_plain(self) -> bool:
        """A bilinear, repeating, sRGB-decoded image at the surface's own uv (an MTL map)."""
        options = (self.filter_type, self.wrap_mode, self.raw, self.to_uv)
        return type(self) is Texture and options == ("bilinear", "repeat", False, None)


@dataclass(frozen=True)
class Checkerboard(Texture):
    """Mitsuba's ``checkerboard`` texture, procedural (no image): at ``(s, t) = to_uv
    (u, v)``, with ``a = frac(s) > 1/2`` and ``b = frac(t) > 1/2``, ``color0`` where
    ``a == b`` and ``color1`` elsewhere (an RGB parameter, Mitsuba's ``eval``); a
    float parameter reads the channel mean of ``color0`` where ``a != b`` and of
    ``color1`` elsewhere (Mitsuba's ``eval_1`` swaps the two, and reads an rgb
    value's mean, not its luminance as a bitmap's). ``to_uv`` is a row-major
    3x3 2D affine matrix, ``s = a00 u + a01 v + a02``: the XML's 4x4 transform's
    2x2 block and x/y translation (Mitsuba's ``Transform4f -> Transform3f``)."""

    path: Path | None = None
    color0: tuple = (0.4, 0.4, 0.4)
    color1: tuple = (0.2, 0.2, 0.2)
    to_uv: tuple = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)


@dataclass(frozen=True)
class MeshAttribute(Texture):
    """Mitsuba's ``mesh_attribute`` texture: the shape's attribute ``name`` (``vertex_*``:
    interpolated with the hit's barycentric coordinates; ``face_*``: the face's value; 1 or
    3 channels, :attr:`drpt.scene.model.Triangles.attributes`) times ``scale``. A
    1-channel attribute on a color parameter is gray; a float parameter reads a
    3-channel one's luminance (Mitsuba 3.9's ``eval_1`` gives 0 there)."""

    path: Path | None = None
    name: str = ""
    scale: float = 1.0


@dataclass
class BSDFSpec:
    """One node of a material's BSDF tree: a kind of :mod:`drpt.materials.bsdf_kinds`,
    its parameters by name (defaults filled in by :func:`complete`) and, for
    composites, its children. ``notes`` are messages for the user about the
    material at ``loc``, where it was defined."""

    kind: str
    params: dict[str, Any] = field(default_factory=dict)
    children: list[BSDFSpec] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    loc: Loc | None = None
    dropped: list[Path] = field(default_factory=list)  # textures replaced by their fallback

    def __getitem__(self, name: str) -> Any:
        return self.params[name]

    def leaves(self) -> list[BSDFSpec]:
        """The leaf specs of the tree, depth first."""
        if not self.children:
            return [self]
        return [leaf for c in self.children for leaf in c.leaves()]

    def textures(self) -> list[Texture]:
        return [v for s in self.walk() for v in s.params.values() if isinstance(v, Texture)]

    def walk(self) -> list[BSDFSpec]:
        """Every node of the tree, depth first, this one first."""
        return [self] + [n for c in self.children for n in c.walk()]


def complete(spec: BSDFSpec) -> BSDFSpec:
    """``spec`` (and its children) with every parameter of its kind present:
    missing ones at their default. ``ValueError`` for an unknown kind or
    parameter, a wrong number of children, or a texture where the kind takes none."""
    kind = spec.kind
    if kind not in bsdf_kinds.ALL_KINDS:
        raise ValueError(f"unknown BSDF kind '{kind}'")
    params = bsdf_kinds.defaults(kind)
    unknown = sorted(set(spec.params) - set(params))
    if unknown:
        raise ValueError(f"BSDF '{kind}' has no parameter {', '.join(repr(u) for u in unknown)}")
    params.update(spec.params)
    if kind in bsdf_kinds.COMPOSITES:
        n = bsdf_kinds.COMPOSITES[kind][0]
        if not (len(spec.children) == n or (kind == "twosided" and len(spec.children) == 2)):
            raise ValueError(f"BSDF '{kind}' needs {n} nested BSDF(s), found {len(spec.children)}")
    elif spec.children:
        raise ValueError(f"BSDF '{kind}' takes no nested BSDF")
    allowed = bsdf_kinds.TEXTURABLE.get(kind, frozenset()) | ({"weight", "opacity", "normalmap", "texture"}
                                                                if kind in bsdf_kinds.COMPOSITES else set())
    tex = bsdf_kinds.PERTURBING.get(kind)
    if tex is not None and not (isinstance(params[tex], Texture) or (
            kind == "normalmap" and isinstance(params[tex], tuple) and len(params[tex]) == 3)):
        raise ValueError(f"BSDF '{kind}' needs a texture '{tex}'"
                         + (" (or an RGB value)" if kind == "normalmap" else ""))
    for name, v in params.items():
        if isinstance(v, Texture) and name not in allowed:
            raise ValueError(f"BSDF '{kind}': parameter '{name}' cannot be a texture")
    children = [complete(c) for c in spec.children]
    if tex is not None:
        inner = [n.kind for c in children for n in c.walk() if n.kind in bsdf_kinds.PERTURBING]
        if inner:
            raise ValueError(f"{inner[0]} inside {kind} is not supported")
    if kind == "twosided":
        for c in children:
            trans = [leaf.kind for leaf in c.leaves() if bsdf_kinds.transmits(leaf.kind, leaf.params)]
            if trans:
                raise ValueError(f"twosided cannot hold the transmissive BSDF '{trans[0]}'")
    return replace(spec, params=params, children=children)


