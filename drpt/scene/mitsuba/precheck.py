"""Checks of a Mitsuba XML scene and its meshes before Mitsuba reads them.

Mitsuba's parser and mesh loaders trust their input: an XML file nested
thousands of elements deep overflows the parser's stack, a binary PLY or
serialized mesh whose faces name vertices it does not have is read out of
bounds (both crash the process), and an ``<include>`` of a FIFO blocks
forever. :func:`check_xml` and :func:`check_mesh` look first and raise a
one-line :class:`~drpt.errors.SceneError` at the file and line instead.

* XML (:func:`check_xml`, the scene and each file it includes, found in the
  ``<path>`` folders, the including file's folder or the scene's): elements nested at most
  :data:`MAX_DEPTH` deep; every ``<include>`` that exists is a regular file.
  Malformed XML is left to Mitsuba's parser, which reports it.
* PLY (:func:`check_ply`): an ASCII header (``ply``, ``format``, ``element``,
  ``property`` lines, ``end_header`` within :data:`MAX_HEADER` bytes) of
  known types; for the binary formats, a body as long as the header says and
  face indices within the vertex count. ASCII bodies are checked after
  Mitsuba's loader (see :func:`check_indices`).
* Serialized (:func:`check_serialized`, versions 3 to 5): the header, the
  compressed record of the ``shape_index`` asked for as long as its counts
  say, and face indices (and version 5's vertex maps) within range.
"""

from __future__ import annotations

import os
import re
import stat
import struct
import xml.parsers.expat
import zlib
from pathlib import Path

import numpy as np

from ...errors import Loc, SceneError

#: deepest element nesting accepted (Mitsuba's scenes nest a handful of levels)
MAX_DEPTH = 100
#: includes within includes followed at most this deep
MAX_INCLUDES = 16
#: the longest PLY header read
MAX_HEADER = 1 << 16
#: the most decompressed bytes one serialized mesh may claim
MAX_SERIALIZED = 1 << 34


def _regular(path: Path) -> bool:
    try:
        return stat.S_ISREG(os.stat(path).st_mode)
    except OSError:
        return False


# ------------------------------------------------------------------ XML
def check_xml(path: Path, defines: dict[str, str] | None = None, *, _depth: int = 0,
              _stack: tuple = (), _root: Path | None = None) -> None:
    """Raise a SceneError where ``path`` (or a file it includes) nests too deep,
    includes something that is not a regular file or itself, or gives one
    plugin a parameter twice."""
    defines = dict(defines or {})
    data = Path(path).read_bytes()
    p = xml.parsers.expat.ParserCreate()
    depth = _depth
    includes: list[tuple[str, int, int]] = []
    names: list[set] = [set()]
    folders: list[str] = []  # <path> folders, last first (Mitsuba's file resolver)

    def start(name, attrs):
        nonlocal depth
        depth += 1
        if depth > MAX_DEPTH:
            raise SceneError(Loc(path, p.CurrentLineNumber),
                             f"<{name}> is nested more than {MAX_DEPTH} elements deep")
        if name in _XYZ_TAGS and "value" in attrs:
            _check_xyz(path, p.CurrentLineNumber, name, attrs, defines)
        param = attrs.get("name")
        if param is not None and name not in ("default", "include", "scene"):
            if param in names[-1]:
                raise SceneError(Loc(path, p.CurrentLineNumber), f"parameter '{param}' is given twice "
                                 "in one element (Mitsuba refuses it)")
            names[-1].add(param)
        names.append(set())
        if name == "default" and "name" in attrs and "value" in attrs:
            defines.setdefault(attrs["name"], attrs["value"])
        if name == "include" and "filename" in attrs:
            includes.append((attrs["filename"], p.CurrentLineNumber, depth))
        if name == "path" and "value" in attrs:
            folders.insert(0, attrs["value"])

    def end(name):
        nonlocal depth
        depth -= 1
        names.pop()

    p.StartElementHandler = start
    p.EndElementHandler = end
    try:
        p.Parse(data, True)
    except xml.parsers.expat.ExpatError:
        pass  # malformed: Mitsuba's parser says where
    for name, line, at in includes:
        for k, v in defines.items():
            name = name.replace(f"${k}", v)
        if "$" in name:
            continue
        target = Path(name).expanduser()
        if not target.is_absolute():
            here = Path(path).parent
            bases = [here / f for f in folders] + [here, Path(_root or path).parent]
            target = next((b / target for b in bases if os.path.lexists(b / target)), here / target)
        if not os.path.lexists(target):
            continue  # Mitsuba reports a missing file
        if not _regular(target):
            raise SceneError(Loc(path, line), f"<include> {name}: not a regular file")
        stack = _stack + (os.path.realpath(path),)
        if os.path.realpath(target) in stack:
            raise SceneError(Loc(path, line), f"<include> {name}: the file includes itself")
        if len(stack) < MAX_INCLUDES:
            check_xml(target, defines, _depth=at - 1, _stack=stack, _root=_root or path)


#: tags whose ``value`` Mitsuba's parser splits into x, y, z (one value or three)
_XYZ_TAGS = ("translate", "rotate", "scale", "point", "vector")


def _check_xyz(path: Path, line: int, tag: str, attrs: dict, defines: dict) -> None:
    """What Mitsuba's parser refuses in a ``value`` of x, y, z without saying where."""
    value = attrs["value"]
    for k, v in defines.items():
        value = value.replace(f"${k}", v)
    if "$" in value:
        return  # an undefined $name: Mitsuba says where
    if any(k in attrs for k in "xyz"):
        raise SceneError(Loc(path, line), f"<{tag}> gives 'value' and x/y/z: give one or the other")
    tokens = [t for t in re.split(r"[, ]", value) if t]
    if len(tokens) not in (1, 3):
        raise SceneError(Loc(path, line), f"<{tag}> value {attrs['value']!r} must have 1 or 3 numbers, "
                         f"has {len(tokens)}")


_OFFSET = re.compile(r'Parsing of XML file "(.+?)" failed: (.*) \(byte offset (\d+)\)$', re.S)


_ROOT = re.compile(r'Error while loading XML file "(.+?)": (.*)$', re.S)


def located_offset(text: str) -> SceneError | None:
    """Mitsuba's parser error that gives a byte offset (where its location
    lookup fails), at the line of that offset; one about the root element
    (its version), at that element's line."""
    m = _OFFSET.search(text)
    if m is None:
        m = _ROOT.search(text)
        if m is None:
            return None
        path = Path(m.group(1))
        data = path.read_bytes() if _regular(path) else b""
        root = re.search(rb"<[A-Za-z_]", data)
        line = data[:root.start()].count(b"\n") + 1 if root else 1
        return SceneError(Loc(path, line), " ".join(m.group(2).split()))
    path, offset = Path(m.group(1)), int(m.group(3))
    try:
        data = path.read_bytes() if _regular(path) else b""
    except OSError:
        data = b""
    line = data[:offset].count(b"\n") + 1
    return SceneError(Loc(path, line), "malformed XML: " + " ".join(m.group(2).split()))


def not_utf8(path: Path, defines: dict[str, str] | None = None) -> SceneError:
    """The error for a file Mitsuba's parser fails on with a message Python
    cannot decode (it quotes the file's bytes): at the first line of the scene
    or a file it includes that is not UTF-8 text."""
    todo, seen = [Path(path)], set()
    while todo:
        f = todo.pop(0)
        if f in seen or not _regular(f) or len(seen) > MAX_INCLUDES:
            continue
        seen.add(f)
        data = f.read_bytes()
        try:
            data.decode("utf-8")
        except UnicodeDecodeError as e:
            return SceneError(Loc(f, data[:e.start].count(b"\n") + 1),
                              f"malformed XML: byte {data[e.start]:#04x} is not UTF-8 text")
        for m in re.finditer(rb'<include[^>]*filename="([^"$]*)"', data):
            todo.append(f.parent / m.group(1).decode())
    return SceneError(Loc(path), "malformed XML: Mitsuba's parser failed on bytes that are not UTF-8 text")


# ------------------------------------------------------------------ plugins
def bare_load_crashes(plugin: str, params) -> bool:
    """Whether Mitsuba 3.9 crashes (a segmentation fault, not an exception)
    instantiating ``plugin`` with only ``params``, without its nested plugins:
    ``blendbsdf`` without its two BSDFs, ``bitmap`` without a ``filename``."""
    return plugin == "blendbsdf" or (plugin == "bitmap" and "filename" not in params)


# ------------------------------------------------------------------ meshes
def check_mesh(plugin: str, path: Path, where, shape_index: int = 0) -> None:
    """Check the mesh file ``path`` of a ``ply`` or ``serialized`` shape;
    ``where`` is the node whose :meth:`error` locates a problem."""
    try:
        if plugin == "ply":
            check_ply(path)
        elif plugin == "serialized":
            check_serialized(path, shape_index)
    except _Bad as e:
        raise where.error(f"{where.label}: {path.name}: {e}") from None


class _Bad(Exception):
    """A problem in a mesh file (the caller adds the location)."""


PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
             "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
             "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}
_INDEX_NAMES = ("vertex_indices", "vertex_index")


def _ply_header(data: bytes) -> tuple[str, list, int]:
    """(format, elements, offset of the body); each element ``[name, count,
    properties]``, a property ``(name, type)`` or ``(name, count type, item type)``."""
    if not re.match(rb"ply\r?\n", data):
        raise _Bad("not a PLY file (it does not start with 'ply')")
    m = re.search(rb"end_header[ \t]*\r?\n", data[:MAX_HEADER])
    if m is None:
        raise _Bad(f"no 'end_header' line in the first {MAX_HEADER} bytes")
    try:
        text = data[:m.start()].decode("ascii")
    except UnicodeDecodeError:
        raise _Bad("the header is not ASCII text") from None
    fmt = None
    elements: list = []
    for n, line in enumerate(text.splitlines()[1:], start=2):
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        if words[0] == "format" and len(words) == 3:
            fmt = words[1]
            if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
                raise _Bad(f"header line {n}: unknown format {fmt!r}")
        elif words[0] == "element" and len(words) == 3:
            if not words[2].isdigit():
                raise _Bad(f"header line {n}: element count {words[2]!r} is not a number")
            elements.append([words[1], int(words[2]), []])
        elif words[0] == "property" and elements:
            if len(words) == 3 and words[1] in PLY_TYPES:
                elements[-1][2].append((words[2], PLY_TYPES[words[1]]))
            elif (len(words) == 5 and words[1] == "list" and words[2] in PLY_TYPES
                  and words[3] in PLY_TYPES and PLY_TYPES[words[2]][0] in "iu"):
                elements[-1][2].append((words[4], PLY_TYPES[words[2]], PLY_TYPES[words[3]]))
            else:
                raise _Bad(f"header line {n}: malformed property {line.strip()!r}")
        else:
            raise _Bad(f"header line {n}: unexpected {line.strip()[:40]!r}")
    if fmt is None:
        raise _Bad("no 'format' line in the header")
    return fmt, elements, m.end()


def check_ply(path: Path) -> None:
    data = Path(path).read_bytes()
    fmt, elements, pos = _ply_header(data)
    if fmt == "ascii":
        return  # Mitsuba's ASCII reader stays in bounds; indices: check_indices
    order = "<" if fmt == "binary_little_endian" else ">"
    vertices = next((count for name, count, _ in elements if name == "vertex"), 0)
    for name, count, props in elements:
        lists = [p for p in props if len(p) == 3]
        if not lists:
            size = count * sum(np.dtype(t).itemsize for _, t in props)
            if pos + size > len(data):
                raise _Bad(f"the file ends inside element '{name}' ({count} records)")
            pos += size
            continue
        pos, indices = _ply_list_element(data, pos, order, name, count, props)
        if name == "face" and indices is not None and indices.size:
            bad = (indices < 0) | (indices >= vertices)
            if bad.any():
                raise _Bad(f"face {int(np.argmax(bad.reshape(len(indices), -1).any(axis=1)))} "
                           f"names vertex {int(indices[bad][0])}, but there are {vertices}")


def _ply_list_element(data: bytes, pos: int, order: str, name: str, count: int, props):
    """Walk ``count`` records holding lists; return the end and the face indices
    (a flat array when every record has the same list lengths, else a list)."""
    # fast path: every record has the lengths of the first
    layout, first = [], pos
    for p in props:
        if len(p) == 2:
            layout.append((p[0], order + p[1]))
            first += np.dtype(p[1]).itemsize
        else:
            if first + np.dtype(p[1]).itemsize > len(data):
                raise _Bad(f"the file ends inside element '{name}'")
            n = int(np.frombuffer(data, order + p[1], 1, first)[0]) if count else 0
            if n < 0:
                raise _Bad(f"element '{name}': negative list length {n}")
            layout += [(p[0] + "#n", order + p[1]), (p[0], order + p[2], (n,))]
            first += np.dtype(p[1]).itemsize + n * np.dtype(p[2]).itemsize
    dt = np.dtype(layout)
    if count and dt.itemsize == 0:
        raise _Bad(f"element '{name}' has empty records")
    if pos + count * dt.itemsize > len(data):
        raise _Bad(f"the file ends inside element '{name}' ({count} records)")
    rec = np.frombuffer(data, dt, count, pos)
    lists = [p for p in props if len(p) == 3]
    if all((rec[p[0] + "#n"] == dt[p[0]].shape[0]).all() for p in lists):
        idx = next((rec[p[0]].astype(np.int64) for p in lists if p[0] in _INDEX_NAMES), None)
        return pos + count * dt.itemsize, idx
    # records of varying lengths: one at a time
    out = []
    for _ in range(count):
        for p in props:
            size = np.dtype(p[1]).itemsize
            if pos + size > len(data):
                raise _Bad(f"the file ends inside element '{name}'")
            if len(p) == 2:
                pos += size
                continue
            n = int(np.frombuffer(data, order + p[1], 1, pos)[0])
            pos += size
            item = np.dtype(p[2]).itemsize
            if n < 0 or pos + n * item > len(data):
                raise _Bad(f"the file ends inside element '{name}'")
            if p[0] in _INDEX_NAMES:
                out.append(np.frombuffer(data, order + p[2], n, pos).astype(np.int64))
            pos += n * item
    return pos, (np.concatenate(out) if out else None)


def check_indices(faces: np.ndarray, vertices: int, where) -> None:
    """After Mitsuba's loader: every face index names a vertex (an ASCII PLY
    or OBJ with a bad index loads, with the index as written)."""
    if faces.size and (faces.min() < 0 or faces.max() >= vertices):
        bad = int(faces[(faces < 0) | (faces >= vertices)][0])
        raise where.error(f"{where.label}: a face names vertex {bad}, but the mesh has {vertices}")


def check_serialized(path: Path, shape_index: int = 0) -> None:
    data = Path(path).read_bytes()
    if len(data) < 4:
        raise _Bad("not a serialized mesh (too short)")
    magic, version = struct.unpack_from("<HH", data)
    if magic != 0x041C:
        raise _Bad("not a serialized mesh (no 0x041C file identifier)")
    if version not in (3, 4, 5):
        raise _Bad(f"serialized version {version} (Mitsuba reads 3, 4 and 5)")
    start = 0
    if shape_index:
        if len(data) < 8:
            raise _Bad("no table of shapes at the end")
        (count,) = struct.unpack_from("<I", data, len(data) - 4)
        if shape_index >= count:
            raise _Bad(f"shape_index {shape_index}, but the file holds {count} shapes")
        if version >= 4:
            at = len(data) - 8 * (count - shape_index) - 4
            fmt = "<Q"
        else:
            at = len(data) - 4 * (count - shape_index + 1)
            fmt = "<I"
        if at < 0:
            raise _Bad("the table of shapes at the end is damaged")
        (start,) = struct.unpack_from(fmt, data, at)
        if start + 4 > len(data):
            raise _Bad(f"shape {shape_index} starts past the end of the file")
        (magic2, version2) = struct.unpack_from("<HH", data, start)
        if (magic2, version2) != (magic, version):
            raise _Bad(f"shape {shape_index} does not start with a serialized header")
    z = zlib.decompressobj()
    buf = bytearray()
    comp = memoryview(data)[start + 4:]

    def need(n: int) -> memoryview:
        """At least ``n`` decompressed bytes, or an error."""
        nonlocal comp
        if n > MAX_SERIALIZED:
            raise _Bad(f"its counts claim {n} bytes")
        try:
            while len(buf) < n:
                chunk = z.decompress(comp, n - len(buf))
                comp = z.unconsumed_tail
                if not chunk:
                    break
                buf.extend(chunk)
        except zlib.error as e:
            raise _Bad(f"damaged compressed data ({e})") from None
        if len(buf) < n:
            raise _Bad(f"the data ends early ({len(buf)} of {n} bytes)")
        return memoryview(buf)

    (flags,) = struct.unpack_from("<I", need(4))
    pos = 4
    if version == 5:
        (n,) = struct.unpack_from("<I", need(pos + 4), pos)
        pos += 4 + n
        v, f, np_, nn = struct.unpack_from("<4Q", need(pos + 32), pos)
        pos += 32
        if np_ > v or nn > v:
            raise _Bad("invalid header (more surface points or normal groups than vertices)")
        pos += 32 * v
        faces_at = pos
        pos += 16 * f
        maps = []
        for n in (np_, nn):
            if n:
                maps.append((pos, n))
                pos += 4 * v
        buf_ = need(pos + 4)
        faces = np.frombuffer(buf_, "<u4", 4 * f, faces_at).reshape(-1, 4)[:, :3] if f else None
        for at, n in maps:
            m = np.frombuffer(buf_, "<u4", v, at)
            if v and int(m.max()) >= n:
                raise _Bad(f"a vertex map entry {int(m.max())} is out of range ({n})")
        (attrs,) = struct.unpack_from("<I", buf_, pos)
        pos += 4
        for _ in range(attrs):
            (n,) = struct.unpack_from("<I", need(pos + 4), pos)
            name = bytes(need(pos + 4 + n)[pos + 4:pos + 4 + n])
            pos += 4 + n
            (dim,) = struct.unpack_from("<I", need(pos + 5), pos + 1)
            pos += 5
            if not 1 <= dim <= 4:
                raise _Bad(f"attribute {name[:40]!r} has {dim} channels (1 to 4)")
            pos += 4 * dim * (f if name.startswith(b"face_") else v)
            need(pos)
    else:
        if version == 4:  # a NUL-terminated name
            k = pos
            while True:
                i = bytes(need(k + 1)[k:]).find(b"\0")
                if i >= 0:
                    pos = k + i + 1
                    break
                k = len(buf)
                if k - pos > 1 << 20:
                    raise _Bad("the shape's name does not end")
        v, f = struct.unpack_from("<2Q", need(pos + 16), pos)
        pos += 16
        fsize = 8 if flags & 0x2000 else 4
        per_vertex = 3 + (3 if flags & 0x1 else 0) + (2 if flags & 0x2 else 0) + (3 if flags & 0x8 else 0)
        pos += fsize * per_vertex * v
        faces = np.frombuffer(need(pos + 12 * f), "<u4", 3 * f, pos) if f else None
    if faces is not None and v and faces.size and int(faces.max()) >= v:
        raise _Bad(f"a face names vertex {int(faces.max())}, but there are {v}")
    if faces is not None and faces.size and not v:
        raise _Bad("faces but no vertices")
