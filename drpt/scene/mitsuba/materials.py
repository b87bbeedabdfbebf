"""Mitsuba ``<bsdf>`` and ``<texture>`` nodes as :class:`drpt.materials.spec.BSDFSpec` trees.

A BSDF node becomes ``BSDFSpec(kind, params, children, notes, loc)`` with
``kind`` the Mitsuba plugin name and ``params`` under Mitsuba's parameter
names (the vocabulary of :mod:`drpt.materials.bsdf_kinds`), with one exception:
``diffuse``'s ``reflectance`` is drpt's ``kd``. Values: RGB triples (from
``<rgb>``, a uniform ``<spectrum>`` or a ``<float>`` on a color parameter),
floats, strings (``material``, ``distribution``, named IORs such as
``int_ior="water"``: the lobe resolves them), booleans, or
:class:`~drpt.materials.spec.Texture` for a ``bitmap`` on a parameter the kind
allows to be textured (:data:`drpt.materials.bsdf_kinds.TEXTURABLE`).

Composites: ``twosided`` (one child; Mitsuba's two-child form, a different
BSDF on each side, is not supported), ``blendbsdf`` (two children,
``weight``), ``mask`` (one child, ``opacity``).

``bitmap`` keeps Mitsuba's ``filter_type`` (bilinear, nearest), ``wrap_mode``
(repeat, mirror, clamp), ``raw`` (its stored values, no sRGB decoding) and
``to_uv``; ``rawconstant`` is its constant value; ``checkerboard`` becomes
:class:`~drpt.materials.spec.Checkerboard`, ``mesh_attribute``
:class:`~drpt.materials.spec.MeshAttribute` (the reader loads the attribute with the mesh).

Perturbed frames: ``normalmap`` (the texture ``normalmap``, or a ``rawconstant`` one:
one normal everywhere) and ``bumpmap``
(its one nested texture, whatever its name; ``scale``), each around one BSDF,
with ``flip_invalid_normals`` and ``use_shadowing_function``.

What is refused (an "unsupported" error, or with ``--ignore-unsupported`` a
warning and a fallback): BSDF plugins outside the vocabulary (``measured``,
``hair``, polarizers, ...; fallback: Mitsuba's
default ``diffuse``, reflectance 0.5) and other texture plugins (volumes...;
fallback: 0.5). Parameters the plugin does
not read (``int_ior`` on ``roughconductor``) are left unread, for the
reader's one warning listing them (:meth:`~drpt.scene.mitsuba.reader.Reader.check_unread`).
A tree drpt's material layer refuses (:func:`drpt.materials.spec.complete`:
``twosided`` around a transmissive BSDF, ...) is an error at the BSDF's line.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ...materials import bsdf_kinds
from ...materials.spec import BSDFSpec, Checkerboard, MeshAttribute, Texture, complete
from .nodes import Node


def default_bsdf(black: bool = False) -> BSDFSpec:
    """Mitsuba's BSDF for a shape without one: diffuse 0.5, or 0 when the shape is an
    area emitter (``Shape::Shape``)."""
    kd = (0.0, 0.0, 0.0) if black else bsdf_kinds.GRAY
    return BSDFSpec("diffuse", {"kd": kd}, [], [], "Mitsuba's default BSDF")


#: Mitsuba parameter name -> drpt parameter name, per kind (all others keep their names).
RENAMED = {"diffuse": {"reflectance": "kd"}}

#: bitmap string parameters and their values (Mitsuba's)
_BITMAP_OPTIONS = {"filter_type": ("bilinear", "nearest"), "wrap_mode": ("repeat", "mirror", "clamp")}
_BITMAP_SILENT = ("format", "accel")  # storage/acceleration choices: no effect on the image
_SPECTRAL_OR_TEXTURE = frozenset({"eta", "k"})


class Materials:
    """Builds specs for a reader (shared between shapes: one spec per node)."""

    def __init__(self, reader):
        self.reader = reader
        self.cache: dict[int, BSDFSpec] = {}

    def spec(self, node: Node) -> BSDFSpec:
        if node.index not in self.cache:
            spec = self._spec(node)
            self._check(node, spec)
            self.cache[node.index] = spec
        return self.cache[node.index]

    @staticmethod
    def _check(node: Node, spec: BSDFSpec) -> None:
        """drpt's own checks of a tree (:func:`drpt.materials.spec.complete`: e.g. ``twosided``
        around a transmissive BSDF), as located errors."""
        try:
            complete(spec)
        except ValueError as e:
            raise node.error(f"{node.label}: {e}") from None

    def _spec(self, node: Node) -> BSDFSpec:
        r = self.reader
        kind = node.plugin
        loc = node.loc
        if kind in bsdf_kinds.PERTURBING:
            spec = self._perturbing(node)
        elif kind in bsdf_kinds.COMPOSITES:
            want, params_def = bsdf_kinds.COMPOSITES[kind]
            kids = [c for c in node.children() if c.kind == "bsdf"]
            for c in node.children():
                if c.kind != "bsdf":
                    r.unsupported(c, f"{c.label} inside {node.label}")
            if kind == "twosided" and len(kids) == 2:
                r.unsupported(node, "twosided with two BSDFs (a different one on each side)")
                kids = kids[:1]
            if len(kids) != want:
                raise node.error(f"{node.label} needs {want} nested BSDF{'s' if want > 1 else ''}, "
                                 f"got {len(kids)}")
            params = {}
            for name in params_def:
                if node.has(name):
                    params[name] = self._value(node, kind, name, float(params_def[name]), texturable=True)
            spec = BSDFSpec(kind, params, [self.spec(k) for k in kids], [], loc)
        elif kind == "null":  # a pure boundary (of a medium): the ray passes straight through
            spec = BSDFSpec("null", {}, [], [], loc)
        elif kind in bsdf_kinds.PARAMS and kind not in ("phong", "cook_torrance", "mirror", "null"):
            renamed = RENAMED.get(kind, {})
            to_mitsuba = {d: m for m, d in renamed.items()}
            accepted = {to_mitsuba.get(d, d) for d in bsdf_kinds.PARAMS[kind]}
            params = {}
            for name in node.names():
                if name not in accepted:
                    continue  # left unread: the unused-parameter warning lists it
                drpt_name = renamed.get(name, name)
                default = bsdf_kinds.PARAMS[kind][drpt_name]
                texturable = drpt_name in bsdf_kinds.TEXTURABLE.get(kind, ())
                params[drpt_name] = self._value(node, kind, name, default, texturable)
            spec = BSDFSpec(kind, params, [], [], loc)
            for c in node.children():
                r.unsupported(c, f"{c.label} inside {node.label}")
        else:
            r.unsupported(node, f"BSDF plugin '{kind}'", fallback="Mitsuba's default diffuse BSDF")
            # (one warning: r.unsupported's; a note on the spec would print it again)
            return BSDFSpec("diffuse", {"kd": bsdf_kinds.GRAY}, [], [], loc)
        r.check_unread(node)
        return spec

    def _perturbing(self, node: Node) -> BSDFSpec:
        """``normalmap`` (its texture is the parameter ``normalmap``) or ``bumpmap`` (its
        texture is the one nested texture, whatever its name), around one BSDF."""
        kind = node.plugin
        refs = [(k, node.ref(k)) for k in list(node.props.keys()) if node.is_ref(k)]
        kids = [n for _, n in refs if n.kind == "bsdf"]
        if len(kids) != 1:
            raise node.error(f"{node.label} needs 1 nested BSDF, got {len(kids)}")
        if kind == "normalmap":
            texs = [n for k, n in refs if k == "normalmap"]
            if not texs or texs[0].kind != "texture":
                raise node.error(f"{node.label} needs a texture 'normalmap'")
            fallback: Any = (0.5, 0.5, 1.0)  # the unperturbed normal
        else:
            texs = [n for _, n in refs if n.kind == "texture"]
            if len(texs) != 1:
                raise node.error(f"{node.label} needs 1 nested texture, got {len(texs)}")
            fallback = 0.0  # a flat height
        for _, n in refs:
            if n.kind not in ("bsdf", "texture"):
                self.reader.unsupported(n, f"{n.label} inside {node.label}")
        tex = texs[0]
        if kind == "normalmap" and tex.plugin == "rawconstant":  # one normal everywhere
            value: Any = tex.vector("value") if tex.has("value") and tex._type("value") == "Vector" \
                else tex.color("value")
            if value is None:
                raise tex.error(f"{tex.label} needs a 'value'")
            self.reader.check_unread(tex)
        elif kind == "bumpmap" and tex.plugin != "bitmap":  # Mitsuba's has no gradient for it
            self.reader.unsupported(tex, f"{tex.label} as a bump map (only bitmap has a gradient)",
                                    fallback="no bump")
            return self.spec(kids[0])
        else:
            value = self.texture(tex, scalar=kind == "bumpmap", fallback=fallback)
        params: dict[str, Any] = {bsdf_kinds.PERTURBING[kind]: value}
        for name in ("flip_invalid_normals", "use_shadowing_function"):
            if node.has(name):
                params[name] = node.bool(name)
        if kind == "bumpmap" and node.has("scale"):
            params["scale"] = node.float("scale")
            if not math.isfinite(params["scale"]):
                raise node.error(f"{node.label}: scale must be finite, got {params['scale']}")
        return BSDFSpec(kind, params, [self.spec(kids[0])], [], node.loc)

    # ------------------------------------------------------------ values
    def _value(self, node: Node, kind: str, name: str, default: Any, texturable: bool) -> Any:
        if node.is_ref(name):
            tex = node.ref(name)
            if tex.kind != "texture":
                raise node.error(f"{node.label}: parameter '{name}' must be a value or a texture, "
                                 f"got {tex.label}")
            if not texturable:
                raise node.error(f"{node.label}: parameter '{name}' cannot be a texture in drpt "
                                 f"(give a constant value)")
            scalar = not isinstance(default, tuple) and name not in _SPECTRAL_OR_TEXTURE
            if default is None:  # alpha_u / alpha_v: the isotropic alpha's default
                default = bsdf_kinds.PARAMS[kind].get("alpha", 0.1) if scalar else bsdf_kinds.GRAY
            return self.texture(tex, scalar=scalar, fallback=default)
        if isinstance(default, bool):
            return node.bool(name)
        if isinstance(default, str):
            return node.str(name)
        if isinstance(default, tuple):
            return node.color(name)
        if isinstance(default, float):
            if name in ("int_ior", "ext_ior") and node._type(name) == "String":
                return node.str(name)  # a named material ("water", "bk7"): the lobe resolves it
            return node.float(name)
        # no default: eta / k of conductors are spectra; alpha_u / alpha_v, principled eta floats
        if name in _SPECTRAL_OR_TEXTURE and kind in ("conductor", "roughconductor"):
            return node.color(name)
        return node.float(name)

    def texture(self, node: Node, scalar: bool = False, fallback: Any = None) -> Any:
        """A texture node as a parameter value: :class:`Texture` for ``bitmap``, whose
        ``fallback`` (the value where there are no texture coordinates) is the parameter's
        default."""
        r = self.reader
        if node.plugin == "bitmap":
            filename = node.str("filename")
            if filename is None:
                r.unsupported(node, "bitmap without 'filename' (in-memory data)",
                              fallback="0.5")
                return 0.5 if scalar else bsdf_kinds.GRAY
            path = node.resolve_file(filename)
            opts = {}
            for key, choices in _BITMAP_OPTIONS.items():
                got = node.str(key)
                if got is not None:
                    if got not in choices:
                        raise node.error(f"{node.label}: {key} must be one of {', '.join(choices)}, "
                                         f"got {got!r}")
                    opts[key] = got
            opts["raw"] = bool(node.bool("raw", False))
            if node.has("to_uv"):
                m = node.transform("to_uv")
                if not np.allclose(m, np.eye(4)):
                    opts["to_uv"] = _uv_matrix(m)
            for key in _BITMAP_SILENT:
                node.get(key)
            r.check_unread(node)
            if fallback is None:
                fallback = 0.5 if scalar else bsdf_kinds.GRAY
            return Texture(path, fallback, **opts, loc=node.loc)
        if node.plugin == "checkerboard":
            for name in ("color0", "color1"):
                if node.is_ref(name):
                    raise node.error(f"{node.label}: {name} must be a color (drpt's checkerboard "
                                     "takes no nested texture)")
            c0 = node.color("color0", (0.4, 0.4, 0.4))
            c1 = node.color("color1", (0.2, 0.2, 0.2))
            m = node.transform("to_uv")
            r.check_unread(node)
            if fallback is None:
                fallback = 0.5 if scalar else bsdf_kinds.GRAY
            return Checkerboard(fallback=fallback, color0=c0, color1=c1, to_uv=_uv_matrix(m), loc=node.loc)
        if node.plugin == "rawconstant":
            # a constant taken as given (no spectral upsampling): a vector or a float
            t = node._type("value") if node.has("value") else None
            if t == "Vector":
                v = node.vector("value")
            elif t is None:
                raise node.error(f"{node.label} needs a 'value'")
            else:
                v = node.float("value")
            r.check_unread(node)
            if scalar and isinstance(v, tuple):
                raise node.error(f"{node.label}: a 3-valued rawconstant on a float parameter "
                                 "(Mitsuba's eval_1 refuses it)")
            return v if isinstance(v, tuple) or scalar else (v, v, v)
        if node.plugin == "mesh_attribute":
            name = node.str("name")
            if name is None or not (name.startswith("vertex_") or name.startswith("face_")):
                raise node.error(f"{node.label}: 'name' must start with 'vertex_' or 'face_', got {name!r}")
            scale = node.float("scale", 1.0)
            r.check_unread(node)
            if fallback is None:
                fallback = 0.5 if scalar else bsdf_kinds.GRAY
            return MeshAttribute(fallback=fallback, name=name, scale=scale, loc=node.loc)
        r.unsupported(node, f"texture plugin '{node.plugin}'", fallback="0.5")
        return 0.5 if scalar else bsdf_kinds.GRAY


def _uv_matrix(m: np.ndarray) -> tuple:
    """Mitsuba's ``Transform4f -> Transform3f`` of a ``to_uv``: the 2x2 block and the
    translation (x, y), as a row-major 3x3 tuple."""
    uv = np.array([[m[0, 0], m[0, 1], m[0, 3]], [m[1, 0], m[1, 1], m[1, 3]], [0.0, 0.0, 1.0]])
    return tuple(float(x) for x in uv.ravel())


def legacy_fields(spec: BSDFSpec) -> dict:
    """Material fields (``kd``, ``map_kd``) for drpt's renderer before it reads
    ``Material.bsdf``: a diffuse spec's reflectance, nothing for other kinds."""
    if spec.kind == "twosided" and spec.children:
        return legacy_fields(spec.children[0])
    if spec.kind != "diffuse":
        return {}
    kd = spec.params.get("kd", bsdf_kinds.GRAY)
    if isinstance(kd, tuple):
        return {"kd": kd}
    if isinstance(kd, Texture) and not isinstance(kd, Checkerboard) and kd.is_plain:
        return {"map_kd": kd.path}
    return {}
