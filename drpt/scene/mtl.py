"""Wavefront MTL material library parser.

Grammar accepted (one statement per line; keywords case-insensitive; ``#``
starts a comment anywhere on a line; blank lines ignored)::

    newmtl NAME                 start a material (NAME may contain spaces)
    Kd r g b | Kd v             diffuse color (one value means gray)
    Ks r g b | Ks v             specular color
    Ke/Le r g b | v             emitted radiance (``ke`` too: case-insensitive)
    Ns v                        Phong exponent
    Ni v                        index of refraction
    d v  [or d -halo v]         dissolve (opacity)
    Tr v                        transparency: dissolve = 1 - v
    Tf r g b | Kt r g b         transmission filter (tints what passes through)
    illum n                     illumination model (integer)
    Roughness v | Pr v          roughness (the seed's keyword, PBR extension)
    Mentalness v | Metalness v | Pm v
                                metalness (the seed spells it "Mentalness")
    Ps v  Pc v  Pcr v           PBR sheen, clearcoat, clearcoat roughness
    aniso v  anisor v           PBR anisotropy and its rotation
    map_Kd [options] FILE       diffuse texture, relative to the MTL file
    map_Pr map_Pm map_d map_Ks map_Ps map_Pc map_Pcr map_Ke map_Ns [options] FILE
                                textures of those parameters

How these statements become a BSDF is :mod:`drpt.materials.interpret`'s table. The
parser keeps the file's own meaning and records which statements each
material gave (``Material.given``).

Ignored silently: ``Ka``, ``map_Ka``, ``sharpness``. Other texture
statements (``bump``, ``map_bump``, ``disp``, ``decal``, ``refl``, ``norm``)
and unknown statements are ignored with one warning per keyword and file.
``map_*`` options (``-s u v w``, ``-o``, ``-t``, ``-mm``, ``-bm``, ``-boost``,
``-texres``, ``-clamp``, ``-blendu``, ``-blendv``, ``-cc``, ``-imfchan``,
``-type``) are skipped with a warning; any other ``-option`` is an error.

Negative colours: a negative ``Kd``, ``Ks`` or ``Tf`` channel is clamped to
0 with a warning; negative emission (``Ke``/``Le``) is an error, and so is a
colour channel beyond float32's range (3.4e38).

Errors (:class:`~drpt.errors.SceneError` at the MTL file and line): a
statement before any ``newmtl``, a bad or non-finite number, a wrong number of
values, negative emission, a texture file that is missing or not a regular
file. Each :class:`Material` gets ``loc``, the
:class:`~drpt.errors.Loc` of its ``newmtl``. A name defined twice in one file
warns; the later definition wins.
"""

from __future__ import annotations

import os
import warnings
from dataclasses import replace
from pathlib import Path

from ..errors import Loc, SceneError, SceneWarning
from .files import check_input, named, resolve
from .model import Material
from .tokens import parse_number, read_text, split_lines

# map_* options and how many arguments each takes.
_MAP_OPTIONS = {
    "-s": 3, "-o": 3, "-t": 3, "-mm": 2, "-bm": 1, "-boost": 1, "-texres": 1,
    "-clamp": 1, "-blendu": 1, "-blendv": 1, "-cc": 1, "-imfchan": 1, "-type": 1,
}
_IGNORED = {"ka", "map_ka", "sharpness"}
_OTHER_MAPS = {"bump", "map_bump", "disp", "decal", "refl", "norm"}
#: map_* statements kept in ``Material.maps`` (by the parameter's lower-case key)
PARAM_MAPS = ("ks", "ns", "d", "pr", "pm", "ps", "pc", "pcr", "ke")
# PBR scalars: key -> Material field
_PBR_SCALARS = {"ps": "sheen", "pc": "clearcoat", "pcr": "clearcoat_roughness", "aniso": "anisotropy",
                "anisor": "anisotropy_rotation"}


def _numbers(args: list[str], loc: Loc, key: str) -> list[float]:
    out = []
    for a in args:
        v = parse_number(a)
        if v is None:
            raise SceneError(loc, f"{key}: expected a finite number, found '{a}'")
        out.append(v)
    return out


def _color(args: list[str], loc: Loc, key: str) -> tuple[float, float, float]:
    if args and args[0].lower() in ("spectral", "xyz"):
        raise SceneError(loc, f"{key} {args[0]} colors are not supported; give r g b")
    vals = _numbers(args, loc, key)
    if len(vals) == 1:
        return (vals[0], vals[0], vals[0])
    if len(vals) == 3:
        return (vals[0], vals[1], vals[2])
    raise SceneError(loc, f"{key}: expected 1 or 3 numbers, found {len(vals)}")


#: Largest colour channel the renderer can hold (float32's maximum).
FLOAT32_MAX = 3.4028234663852886e38


def check_range(color, loc: Loc, key: str) -> None:
    """A :class:`SceneError` at ``loc`` if a channel of ``color`` does
    not fit float32 (it would become infinite in the renderer)."""
    if max(abs(c) for c in color) > FLOAT32_MAX:
        raise SceneError(loc, f"{key} {' '.join(f'{c:g}' for c in color)}: beyond float32's "
                         f"range ({FLOAT32_MAX:.3g}), which the renderer uses")


def reflectance(color: tuple[float, float, float], loc: Loc, key: str) -> tuple[float, float, float]:
    """``color`` with negative channels clamped to 0, with a warning at ``loc``
    (:func:`check_range` first)."""
    check_range(color, loc, key)
    if min(color) >= 0.0:
        return color
    warnings.warn(SceneWarning(loc, f"{key} {' '.join(f'{c:g}' for c in color)} has a negative channel; "
                               "clamped to 0"), stacklevel=3)
    return tuple(max(c, 0.0) for c in color)


def emission(color: tuple[float, float, float], loc: Loc, key: str) -> tuple[float, float, float]:
    """``color`` if no channel is negative, else a :class:`SceneError` at ``loc``
    (:func:`check_range` first)."""
    check_range(color, loc, key)
    if min(color) < 0.0:
        raise SceneError(loc, f"{key} {' '.join(f'{c:g}' for c in color)}: emitted radiance "
                         "must not be negative")
    return color


def _scalar(args: list[str], loc: Loc, key: str) -> float:
    vals = _numbers(args, loc, key)
    if len(vals) != 1:
        raise SceneError(loc, f"{key}: expected 1 number, found {len(vals)}")
    check_range(vals, loc, key)
    return vals[0]


def texture_path(args: list[str], base: Path, loc: Loc, key: str) -> Path:
    """Resolve a ``map_*`` statement's file name (after skipping options).

    ``base`` is the directory names are relative to; errors are reported at
    ``loc``. The file must be a regular file
    (:func:`~drpt.scene.files.check_input`); it is returned as a
    :class:`~drpt.scene.files.NamedPath` named at ``loc``, where
    problems found when the image is read are reported.
    """
    i = 0
    skipped = []
    while i < len(args) and args[i].startswith("-") and parse_number(args[i]) is None:
        opt = args[i].lower()
        if opt not in _MAP_OPTIONS:
            raise SceneError(loc, f"{key}: unsupported option '{args[i]}'")
        skipped.append(args[i])
        i += 1
        if opt in ("-s", "-o", "-t"):  # 1 to 3 numbers
            k = 0
            while k < 3 and i < len(args) - 1 and parse_number(args[i]) is not None:
                i += 1
                k += 1
            if k == 0:
                raise SceneError(loc, f"{key}: option '{opt}' needs 1 to 3 numbers")
        else:
            n = _MAP_OPTIONS[opt]
            if len(args) - i < n:
                raise SceneError(loc, f"{key}: option '{opt}' needs {n} value(s)")
            i += n
    if i >= len(args):
        raise SceneError(loc, f"{key}: missing file name")
    if skipped:
        warnings.warn(SceneWarning(loc, f"{key} options {' '.join(skipped)} are ignored"), stacklevel=2)
    name = " ".join(args[i:])
    tex = resolve(base / name)
    if not os.path.lexists(tex) and "\\" in name:
        alt = resolve(base / name.replace("\\", "/"))
        if os.path.lexists(alt):
            tex = alt
    check_input(tex, ref=loc, what="texture file")
    return named(tex, loc)


def apply_field(mat: Material, key: str, args: list[str], loc: Loc,
                base: Path, warned: set[str] | None = None) -> Material:
    """Apply one MTL statement (``key`` lower-case, at ``loc``) to ``mat``; return the new material.

    Shared with the scene parser, which accepts MTL-style fields inside
    ``Material``/``PhongMaterial`` blocks. Unknown keys warn (once per key if
    ``warned`` is given) and leave ``mat`` unchanged. A statement that is read
    adds its key (``metalness`` as ``mentalness``, ``kt`` as ``tf``, ``le`` as
    ``ke``) to ``mat.given``: the seed's ``Roughness``/``Mentalness`` stay
    apart from the PBR extension's ``Pr``/``Pm``, which mean another model.
    """
    new = _apply(mat, key, args, loc, base)
    if new is None:
        if key in _IGNORED:
            return mat
        if warned is None or key not in warned:
            if warned is not None:
                warned.add(key)
            kind = "texture" if key.startswith("map_") or key in _OTHER_MAPS else "statement"
            warnings.warn(SceneWarning(loc, f"MTL {kind} '{key}' is not supported and is ignored"),
                          stacklevel=3)
        return mat
    canonical = {"metalness": "mentalness", "kt": "tf", "le": "ke"}
    return replace(new, given=tuple(sorted(set(mat.given) | {canonical.get(key, key)})))


def _apply(mat: Material, key: str, args: list[str], loc: Loc, base: Path) -> Material | None:
    if key == "kd":
        return replace(mat, kd=reflectance(_color(args, loc, "Kd"), loc, "Kd"))
    if key == "ks":
        return replace(mat, ks=reflectance(_color(args, loc, "Ks"), loc, "Ks"))
    if key in ("tf", "kt"):
        name = key.capitalize()
        return replace(mat, tf=reflectance(_color(args, loc, name), loc, name))
    if key in ("ke", "le"):
        name = key.capitalize()
        return replace(mat, emission=emission(_color(args, loc, name), loc, name))
    if key == "ns":
        return replace(mat, ns=_scalar(args, loc, "Ns"))
    if key == "ni":
        return replace(mat, ior=_scalar(args, loc, "Ni"))
    if key == "d":
        if args and args[0].lower() == "-halo":
            args = args[1:]
        return replace(mat, dissolve=_scalar(args, loc, "d"))
    if key == "tr":
        return replace(mat, dissolve=1.0 - _scalar(args, loc, "Tr"))
    if key == "illum":
        if len(args) != 1 or not args[0].lstrip("+-").isdigit():
            raise SceneError(loc, f"illum: expected one integer, found '{' '.join(args)}'")
        return replace(mat, illum=int(args[0]))
    if key in ("roughness", "pr"):
        return replace(mat, roughness=_scalar(args, loc, key))
    if key in ("mentalness", "metalness", "pm"):
        return replace(mat, metalness=_scalar(args, loc, key))
    if key in _PBR_SCALARS:
        return replace(mat, **{_PBR_SCALARS[key]: _scalar(args, loc, key)})
    if key == "map_kd":
        return replace(mat, map_kd=texture_path(args, base, loc, "map_Kd"))
    if key.startswith("map_") and key[4:] in PARAM_MAPS:
        tex = texture_path(args, base, loc, key)
        return replace(mat, maps={**mat.maps, key[4:]: tex})
    return None


def parse_mtl_text(text: str, path: Path) -> dict[str, Material]:
    """Parse MTL ``text`` (already read from ``path``); see the module docstring."""
    path = Path(path)
    base = path.parent
    materials: dict[str, Material] = {}
    current: Material | None = None
    warned: set[str] = set()

    def close():
        if current is not None:
            materials[current.name] = current

    for lineno, raw in enumerate(split_lines(text), 1):
        hash_at = raw.find("#")
        if hash_at >= 0:
            raw = raw[:hash_at]
        parts = raw.split()
        if not parts:
            continue
        key = parts[0].lower()
        if key == "newmtl":
            if len(parts) < 2:
                raise SceneError(Loc(path, lineno), "newmtl without a material name")
            close()
            name = " ".join(parts[1:])
            if name in materials:
                warnings.warn(SceneWarning(Loc(path, lineno), f"material '{name}' is defined again; "
                                           "the later definition wins"), stacklevel=2)
            current = Material(name=name, loc=Loc(path, lineno))
            continue
        if current is None:
            raise SceneError(Loc(path, lineno), f"'{parts[0]}' before any 'newmtl'")
        current = apply_field(current, key, parts[1:], Loc(path, lineno), base, warned)
    close()
    return materials


def load_mtl(path: str | Path, *, ref: Loc | None = None) -> dict[str, Material]:
    """Read and parse the MTL file at ``path``.

    Returns the materials by name, in file order. ``ref`` is the place
    that named this library, where a missing file is reported.
    """
    path = resolve(path)
    return parse_mtl_text(read_text(path, ref=ref, what="MTL file"), path)
