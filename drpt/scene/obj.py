"""Wavefront OBJ loader: triangulated, unwelded, per-corner arrays.

Grammar accepted (one statement per line, ``#`` starts a comment anywhere)::

    v x y z [w]             position (w and any vertex colors after it ignored)
    vt u [v [w]]            texture coordinate (v defaults to 0, w ignored)
    vn x y z                normal (normalized on load)
    f c1 c2 c3 [c4 ...]     polygon, fan-triangulated (c1,c2,c3), (c1,c3,c4), ...
                            each corner is  v | v/t | v//n | v/t/n ; indices are
                            1-based, negative ones count back from the last
                            element defined so far (-1 = the latest)
    usemtl NAME             material for the following faces
    mtllib A.mtl [B.mtl]    material libraries, relative to the OBJ file
    g/o/s/l/p ...           ignored (lines and points are not rendered)

Anything else is ignored with one warning per keyword. Positive indices are
checked against the whole file's counts (index 0 or out of range is an error;
like most loaders, a face may name a vertex defined further down), negative
ones against the elements defined before the face. A face needs
at least 3 corners, numbers must be finite, and every ``usemtl`` name must be
defined by one of the file's ``mtllib`` libraries; each of these errors is a
:class:`~drpt.errors.SceneError` at the OBJ file and line.

Normals: zero-length ``vn`` and corners without a normal get the face's
geometric normal ``normalize(cross(p1 - p0, p2 - p0))`` ((0, 0, 1) for a
zero-area face). Zero-area faces are kept. :attr:`ObjMesh.normals` is ``None``
when no face references a normal, :attr:`ObjMesh.uvs` when no face references
a texture coordinate (corners without one then get (0, 0)).

The loop is plain Python over lines; arrays are built with numpy once at the
end, so a 500k-triangle file loads in a few seconds.
"""

from __future__ import annotations

import math
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import Loc, SceneError, SceneWarning
from .files import resolve
from .model import Material
from .mtl import load_mtl
from .tokens import read_text, split_lines
from .transform import normalize

MtlCache = dict[Path, dict[str, Material]]

_IGNORED = {"g", "o", "s", "l", "p"}


@dataclass
class ObjMesh:
    """One OBJ file, triangulated, in the file's own (object) space."""

    path: Path
    positions: np.ndarray  # (F, 3, 3) float64
    face_material: np.ndarray  # (F,) int32, index into material_names, -1 = no usemtl
    material_names: list[str]  # distinct usemtl names, in order of first use
    materials: dict[str, Material] = field(default_factory=dict)  # from all mtllibs
    normals: np.ndarray | None = None  # (F, 3, 3) unit
    uvs: np.ndarray | None = None  # (F, 3, 2)

    def __len__(self) -> int:
        return int(self.positions.shape[0])

    def face_materials(self) -> list[Material]:
        """The Material of each name in :attr:`material_names`."""
        return [self.materials[n] for n in self.material_names]


def geometric_normals(positions: np.ndarray) -> np.ndarray:
    """Unit ``cross(p1 - p0, p2 - p0)`` per face; (0, 0, 1) for zero-area faces."""
    with np.errstate(all="ignore"):  # huge coordinates: inf/nan, replaced below
        g = np.cross(positions[:, 1] - positions[:, 0], positions[:, 2] - positions[:, 0])
        length = np.linalg.norm(g, axis=1)
    ok = (length > 0) & np.isfinite(length)
    out = np.zeros_like(g)
    out[:, 2] = 1.0
    out[ok] = g[ok] / length[ok, None]
    bad = ~ok & (np.abs(g).max(axis=1) > 0)  # a length that overflowed (or nan)
    if bad.any():
        n = normalize(g[bad])
        out[bad] = np.where(n.any(axis=1, keepdims=True), n, out[bad])
    return out


def load_obj(path: str | Path, *, ref: Loc | None = None,
             mtl_cache: MtlCache | None = None) -> ObjMesh:
    """Load the OBJ file at ``path`` (see the module docstring).

    ``ref`` is the place that named the OBJ, where a missing file is
    reported. ``mtl_cache`` maps absolute MTL paths to parsed libraries so a
    library shared by several OBJ files yields the same Material objects.
    """
    path = resolve(path)
    text = read_text(path, ref=ref, what="OBJ file")
    return parse_obj_text(text, path, mtl_cache=mtl_cache)


def _locate(lines: list[str], key: str, index: int) -> int:
    """1-based line number of the ``index``-th (0-based) statement ``key``."""
    seen = -1
    for lineno, line in enumerate(lines, 1):
        parts = line.split(None, 1)
        if parts and parts[0] == key:
            seen += 1
            if seen == index:
                return lineno
    return len(lines)


def _mtllib(args: list[str], path: Path, lineno: int, cache: MtlCache) -> list[Path]:
    """Resolve an ``mtllib`` line's file names (spaces in a name are tolerated
    when the joined name exists and the split ones do not)."""
    if not args:
        raise SceneError(Loc(path, lineno), "mtllib without a file name")
    base = path.parent
    names = args
    if len(args) > 1 and not all((base / a).is_file() for a in args):
        joined = " ".join(args)
        if (base / joined).is_file():
            names = [joined]
    out = []
    for name in names:
        p = resolve(base / name)
        if p not in cache:
            cache[p] = load_mtl(p, ref=Loc(path, lineno))
        out.append(p)
    return out


# Faces whose corners all have one plain form (positive indices, no zero):
# the hot path. Anything else (negative indices, mixed forms, errors) goes
# through the general per-corner code.
_F_V = re.compile(r"f(?:[ \t]+[1-9]\d*){3,}[ \t]*\Z")
_F_VT = re.compile(r"f(?:[ \t]+[1-9]\d*/[1-9]\d*){3,}[ \t]*\Z")
_F_VN = re.compile(r"f(?:[ \t]+[1-9]\d*//[1-9]\d*){3,}[ \t]*\Z")
_F_VTN = re.compile(r"f(?:[ \t]+[1-9]\d*/[1-9]\d*/[1-9]\d*){3,}[ \t]*\Z")


def _to_float(values: list[str], lines: list[str], key: str) -> np.ndarray:
    """Convert number strings collected from ``key`` statements; a bad one
    raises SceneError at its statement's line."""
    width = 2 if key == "vt" else 3
    try:
        arr = np.array(values, dtype=np.float64)
    except ValueError:
        arr = None
    if arr is not None:
        bad = ~np.isfinite(arr)
        if not bad.any():
            return arr.reshape(-1, width)
        i = int(np.argmax(bad))
    else:
        i = next((k for k, v in enumerate(values) if not _finite(v)), None)
        if i is None:  # numpy refused something Python's float() accepts
            return np.array([float(v) for v in values], dtype=np.float64).reshape(-1, width)
    raise _NumberError(_locate(lines, key, i // width), key, values[i])


def _finite(text: str) -> bool:
    try:
        return "_" not in text and math.isfinite(float(text))
    except ValueError:
        return False


class _NumberError(Exception):
    def __init__(self, line: int, key: str, text: str):
        super().__init__(line, key, text)
        self.line, self.key, self.text = line, key, text


def _to_index(values: list[str]) -> np.ndarray:
    try:
        return np.array(values, dtype=np.int64)
    except (ValueError, OverflowError):
        return np.array([max(min(int(v), 2**62), -(2**62)) for v in values], dtype=np.int64)


def parse_obj_text(text: str, path: Path, *, mtl_cache: MtlCache | None = None) -> ObjMesh:
    """Parse OBJ ``text`` that was read from ``path`` (used for messages and
    for resolving ``mtllib``)."""
    path = Path(path)
    cache: MtlCache = {} if mtl_cache is None else mtl_cache
    lines = split_lines(text)

    # Everything is collected as strings and converted by numpy at the end.
    V: list[str] = []
    T: list[str] = []
    N: list[str] = []
    FV: list[str] = []  # per corner, 1-based, in file order
    FT: list[str] = []  # "0" = the corner has no texture coordinate
    FN: list[str] = []  # "0" = the corner has no normal
    K: list[int] = []  # corners per face
    mat_start: list[int] = []  # face index where a usemtl takes effect
    mat_slot: list[int] = []
    names: list[str] = []
    slots: dict[str, int] = {}
    usemtl_line: dict[str, int] = {}
    materials: dict[str, Material] = {}
    libs: list[Path] = []
    warned: set[str] = set()

    def err(msg: str) -> SceneError:
        return SceneError(Loc(path, lineno), msg)

    def general(parts: list[str]) -> None:
        """Every statement the hot paths in the loop below did not take."""
        key = parts[0]
        args = parts[1:]
        if key in ("v", "vn", "vt"):
            lo, hi, out, width = {"v": (3, 7, V, 3), "vn": (3, 3, N, 3), "vt": (1, 3, T, 2)}[key]
            if not lo <= len(args) <= hi:
                raise err(f"'{key}' needs {lo}" + (f" to {hi}" if hi > lo else "")
                          + f" numbers, found {len(args)}")
            for a in args:
                if not _finite(a):
                    raise err(f"'{key}': expected a finite number, found '{a}'")
            vals = (args + ["0"])[:width]
            out += vals
        elif key == "f":
            face(args)
        elif key == "usemtl":
            if not args:
                raise err("usemtl without a material name")
            name = " ".join(args)
            if name not in slots:
                slots[name] = len(names)
                names.append(name)
                usemtl_line[name] = lineno
            mat_start.append(len(K))
            mat_slot.append(slots[name])
        elif key == "mtllib":
            for lib in _mtllib(args, path, lineno, cache):
                libs.append(lib)
                materials.update(cache[lib])
        elif key in _IGNORED:
            pass
        elif key not in warned:
            warned.add(key)
            warnings.warn(SceneWarning(Loc(path, lineno), f"OBJ statement '{key}' is not supported and is ignored"),
                          stacklevel=4)

    def index(text: str, count: int, kind: str) -> str:
        try:
            i = int(text)
        except ValueError:
            raise err(f"bad {kind} index '{text}' in face") from None
        if i == 0:
            raise err(f"{kind} index 0 is invalid (OBJ indices start at 1)")
        if i < 0:
            if i + count < 0:
                raise err(f"{kind} index {i} is out of range ({count} defined so far)")
            return str(i + count + 1)
        return text

    def face(corners: list[str]) -> None:
        k = len(corners)
        if k < 3:
            raise err(f"face needs at least 3 vertices, found {k}")
        nv, nt, nn = len(V) // 3, len(T) // 2, len(N) // 3
        for c in corners:
            s = c.split("/")
            if len(s) > 3 or not s[0]:
                raise err(f"bad face corner '{c}' (expected v, v/t, v//n or v/t/n)")
            FV.append(index(s[0], nv, "vertex"))
            FT.append(index(s[1], nt, "texture coordinate") if len(s) > 1 and s[1] else "0")
            FN.append(index(s[2], nn, "normal") if len(s) > 2 and s[2] else "0")
        K.append(k)

    lineno = 0
    for lineno, line in enumerate(lines, 1):  # noqa: B007 (the error path reads it)
        if "#" in line:
            line = line[: line.index("#")]
        head = line[:2]
        if head == "f ":
            if _F_VTN.match(line):
                n = line[2:].replace("/", " ").split()
                FV += n[0::3]
                FT += n[1::3]
                FN += n[2::3]
                K.append(len(n) // 3)
                continue
            if _F_V.match(line):
                n = line[2:].split()
                k = len(n)
                FV += n
                FT += ["0"] * k
                FN += ["0"] * k
                K.append(k)
                continue
            if _F_VN.match(line):
                n = line[2:].replace("//", " ").split()
                k = len(n) // 2
                FV += n[0::2]
                FT += ["0"] * k
                FN += n[1::2]
                K.append(k)
                continue
            if _F_VT.match(line):
                n = line[2:].replace("/", " ").split()
                k = len(n) // 2
                FV += n[0::2]
                FT += n[1::2]
                FN += ["0"] * k
                K.append(k)
                continue
        parts = line.split()
        if not parts:
            continue
        if "_" not in line:
            if head == "v ":
                if len(parts) == 4:
                    V += parts[1:]
                    continue
            elif head == "vn":
                if len(parts) == 4 and parts[0] == "vn":
                    N += parts[1:]
                    continue
            elif head == "vt":
                if len(parts) == 3 and parts[0] == "vt":
                    T += parts[1:]
                    continue
        general(parts)

    for name in names:
        if name not in materials:
            where = ", ".join(p.name for p in dict.fromkeys(libs)) or "no mtllib was given"
            raise SceneError(Loc(path, usemtl_line[name]), f"usemtl '{name}': no such material ({where})")

    # ------------------------------------------------------------ arrays
    try:
        Varr = _to_float(V, lines, "v")
        Tarr = _to_float(T, lines, "vt")
        Narr = _to_float(N, lines, "vn")
    except _NumberError as e:
        raise SceneError(Loc(path, e.line), f"'{e.key}': expected a finite number, found '{e.text}'") from None

    K_arr = np.array(K, dtype=np.int64)
    F = len(K_arr)
    cv, ct, cn = _to_index(FV), _to_index(FT), _to_index(FN)
    for arr, count, kind, allow0 in ((cv, len(Varr), "vertex", False),
                                     (ct, len(Tarr), "texture coordinate", True),
                                     (cn, len(Narr), "normal", True)):
        bad = (arr > count) | (arr < (0 if allow0 else 1))
        if bad.any():
            corner = int(np.argmax(bad))
            f = int(np.searchsorted(np.cumsum(K_arr), corner, side="right"))
            raise SceneError(Loc(path, _locate(lines, "f", f)),
                             f"{kind} index {arr[corner]} is out of range (the file defines {count})")

    # Fan triangulation: face with corners c0..c{k-1} -> (c0, cj, cj+1).
    ntri = K_arr - 2
    first = np.cumsum(K_arr) - K_arr  # first corner of each face
    tri_face = np.repeat(np.arange(F), ntri)
    j = np.arange(len(tri_face)) - np.repeat(np.cumsum(ntri) - ntri, ntri) + 1
    c0 = first[tri_face]
    corners = np.stack([c0, c0 + j, c0 + j + 1], axis=1)  # (T, 3) indices into cv/ct/cn

    positions = Varr[cv[corners] - 1] if len(corners) else np.zeros((0, 3, 3))

    normals = None
    inn = cn[corners] - 1
    if len(corners) and (inn >= 0).any():
        normals = normalize(Narr[np.maximum(inn, 0)])
        ok = (inn >= 0) & normals.any(axis=2)
        normals = np.where(ok[..., None], normals, geometric_normals(positions)[:, None, :])

    uvs = None
    itt = ct[corners] - 1
    if len(corners) and (itt >= 0).any():
        uvs = np.where((itt >= 0)[..., None], Tarr[np.maximum(itt, 0)], 0.0)

    face_slot = np.full(F, -1, dtype=np.int32)
    if mat_start:
        which = np.searchsorted(np.array(mat_start), np.arange(F), side="right") - 1
        face_slot = np.where(which >= 0, np.array(mat_slot, np.int32)[np.maximum(which, 0)], -1)

    return ObjMesh(
        path=path,
        positions=positions,
        face_material=face_slot[tri_face].astype(np.int32),
        material_names=names,
        materials=materials,
        normals=normals,
        uvs=uvs,
    )
