"""Mitsuba's parsed scene graph, read with types, locations and bookkeeping.

:func:`parse` runs Mitsuba's own XML parser (``mitsuba.parser``: it reads
the file and its includes, fills ``$name`` from the defines and
``<default>`` elements, upgrades 0.5/0.6 files -- camelCase names become
snake_case -- and resolves references) and turns its errors into a
one-line :class:`~drpt.errors.SceneError` at the file and line it names.

:class:`Node` wraps one ``mitsuba.parser.SceneNode``: typed getters that
raise a located error on a parameter of the wrong type, and a record of
what was read, so that :meth:`Node.unread` lists the parameters drpt did
not look at (the importer warns about those, or refuses them with
``--strict``).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import SceneError

VARIANT = "scalar_rgb"

#: A uniform ``<spectrum value="1">`` on an emitter in Mitsuba 3's RGB variants: the
#: D65 illuminant in linear sRGB (float32 values read from Mitsuba 3.9's point emitter;
#: tests/test_mitsuba_xml.py checks them against the installed Mitsuba)
D65_RGB = (1.204793930053711, 0.948291003704071, 0.9089160561561584)

_LOCATION = re.compile(r"^(.*) \(line (\d+), col (\d+)\)$")
_MESSAGE = re.compile(r"Error while loading (.+?) \(line (\d+), col \d+\): (.*)$", re.S)
_XML_FAILED = re.compile(r'Parsing of XML file "(.+?)" failed: (.*) \(line (\d+), col \d+\)$', re.S)
_TAG = re.compile(r"\[[A-Za-z0-9_]+\.(?:cpp|h):\d+\] ")


def mitsuba():
    """``mitsuba`` with the scalar RGB variant set (the importer's only use of it:
    the parser, and the mesh loaders for obj/ply/serialized)."""
    try:
        import mitsuba as mi
    except ImportError as e:  # pragma: no cover - mitsuba is a dependency of the XML reader
        raise SceneError(None, None, f"reading Mitsuba XML needs the mitsuba package ({e})") from None
    if mi.variant() != VARIANT and VARIANT in mi.variants():
        if mi.variant() is None:
            mi.set_variant(VARIANT)
    return mi


def _one_line(text: str) -> str:
    return " ".join(_TAG.sub("", text).split())


def parser_error(path: Path, error: Exception) -> SceneError:
    """The one-line :class:`SceneError` for an exception of ``mitsuba.parser``."""
    text = str(error)
    # nested errors (<include>) repeat the chain; the innermost is the last
    last = text.split("\n")[-1] if "\n" in text else text
    m = _MESSAGE.search(_TAG.sub("", last))
    if m:
        return SceneError(_locate(path, m.group(1)), int(m.group(2)), _one_line(m.group(3)))
    m = _XML_FAILED.search(_TAG.sub("", text))
    if m:
        return SceneError(_locate(path, m.group(1)), int(m.group(3)),
                          f"malformed XML: {_one_line(m.group(2))}")
    from .precheck import located_offset

    return located_offset(_TAG.sub("", text)) or SceneError(path, None, _one_line(text))


def _locate(main: Path, name: str) -> Path:
    p = Path(name)
    if p.is_absolute():
        return p
    if p.name == main.name:
        return main
    return main.parent / p


class State:
    """The parsed, upgraded and resolved scene of one XML file."""

    def __init__(self, path: Path, defines: dict[str, str]):
        mi = mitsuba()
        import mitsuba.parser as mp

        self.path = path
        from .precheck import check_xml

        check_xml(path, defines)  # what would crash or block Mitsuba's parser
        config = mp.ParserConfig(VARIANT)
        try:
            state = mp.parse_file(config, str(path), **{k: str(v) for k, v in defines.items()})
            mp.transform_upgrade(config, state)
            mp.transform_resolve(config, state)
        except RuntimeError as e:
            raise parser_error(path, e) from None
        except UnicodeDecodeError:  # its message quotes bytes that are not UTF-8
            from .precheck import not_utf8

            raise not_utf8(path, defines) from None
        self.mi = mi
        self.mp = mp
        self.state = state
        self.files = [Path(str(f)) for f in state.files]
        self.nodes: dict[int, Node] = {}
        self.version = str(state.versions[0]) if len(state.versions) else ""

    def node(self, index: int) -> Node:
        if index not in self.nodes:
            self.nodes[index] = Node(self, index)
        return self.nodes[index]

    @property
    def root(self) -> Node:
        return self.node(0)


class Node:
    """One element (a plugin instance) of the scene graph."""

    def __init__(self, state: State, index: int):
        self.state = state
        self.index = index
        raw = state.state.nodes[index]
        self.raw = raw
        self.props = raw.props
        self.plugin: str = raw.props.plugin_name()
        self.kind: str = str(raw.type).rsplit(".", 1)[-1].lower()  # "shape", "bsdf", ...
        self.id: str = raw.props.id()
        loc = state.mp.file_location(state.state, raw)
        m = _LOCATION.match(loc)
        self.file = state.path
        self.line: int | None = None
        if m:
            self.file = self._file(m.group(1))
            self.line = int(m.group(2))
        self.read: set[str] = set()

    def _file(self, name: str) -> Path:
        idx = self.raw.file_index
        files = self.state.files
        if 0 <= idx < len(files) and files[idx].is_absolute():
            return files[idx]
        return _locate(self.state.path, name)

    # ------------------------------------------------------------ messages
    @property
    def where(self) -> str:
        return f"{self.file}:{self.line}" if self.line is not None else str(self.file)

    @property
    def label(self) -> str:
        return f"{self.kind} '{self.plugin}'" + (f" (id '{self.id}')" if self.id else "")

    def error(self, message: str) -> SceneError:
        return SceneError(self.file, self.line, message)

    def resolve_file(self, name: str) -> Path:
        """A file name of this node, relative to the XML file that holds it (then
        to the main file's folder), as an absolute path; a missing one is an error."""
        p = Path(name).expanduser()
        if not p.is_absolute():
            for base in (self.file.parent, self.state.path.parent):
                if (base / p).exists():
                    p = base / p
                    break
            else:
                p = self.file.parent / p
        if not p.is_file():
            what = "not a regular file" if p.exists() else "no such file"
            raise self.error(f"{self.label}: {name}: {what}")
        from ..files import named

        # an image read at render time names this node's line in its errors
        return named(p.resolve(), (self.file, self.line) if self.line is not None else None)

    # ------------------------------------------------------------ params
    def names(self) -> list[str]:
        return [k for k in self.props.keys() if not k.startswith("_arg_")]

    def has(self, name: str) -> bool:
        return name in self.props

    def _type(self, name: str) -> str:
        return str(self.props.type(name)).rsplit(".", 1)[-1]

    def _wrong(self, name: str, want: str) -> SceneError:
        got = self._type(name)
        shown = {"ResolvedReference": "an object (<ref> or nested plugin)", "Color": "an RGB color",
                 "Spectrum": "a spectrum", "Vector": "a point/vector", "String": "a string",
                 "Bool": "a boolean", "Integer": "an integer", "Float": "a float",
                 "Transform": "a transform"}.get(got, got)
        return self.error(f"{self.label}: parameter '{name}' must be {want}, got {shown}")

    def get(self, name: str, default: Any = None) -> Any:
        """The raw value (or ``default``), marking the parameter read."""
        if not self.has(name):
            return default
        self.read.add(name)
        return self.props[name]

    def float(self, name: str, default: float | None = None) -> float | None:
        if not self.has(name):
            return default
        if self._type(name) not in ("Float", "Integer"):
            raise self._wrong(name, "a float")
        v = float(self.get(name))
        if v != v:
            raise self.error(f"{self.label}: parameter '{name}' is NaN")
        return v

    def int(self, name: str, default: int | None = None) -> int | None:
        if not self.has(name):
            return default
        if self._type(name) != "Integer":
            raise self._wrong(name, "an integer")
        return int(self.get(name))

    def bool(self, name: str, default: bool | None = None) -> bool | None:
        if not self.has(name):
            return default
        if self._type(name) != "Bool":
            raise self._wrong(name, "a boolean")
        return bool(self.get(name))

    def str(self, name: str, default: str | None = None) -> str | None:
        if not self.has(name):
            return default
        if self._type(name) != "String":
            raise self._wrong(name, "a string")
        return str(self.get(name))

    def vector(self, name: str, default=None) -> tuple[float, float, float] | None:
        if not self.has(name):
            return default
        if self._type(name) != "Vector":
            raise self._wrong(name, "a point or vector")
        v = self.get(name)
        return _finite(self, name, (float(v[0]), float(v[1]), float(v[2])))

    def transform(self, name: str = "to_world") -> np.ndarray:
        """A 4x4 float64 matrix (identity when not given)."""
        if not self.has(name):
            return np.eye(4)
        if self._type(name) != "Transform":
            raise self._wrong(name, "a transform")
        return np.array(self.get(name).matrix, dtype=np.float64).reshape(4, 4)

    def is_ref(self, name: str) -> bool:
        return self.has(name) and self._type(name) == "ResolvedReference"

    def color(self, name: str, default=None, *, emission: bool = False) -> tuple[float, float, float] | None:
        """An RGB triple from ``<rgb>``, a uniform ``<spectrum>`` or a ``<float>``.

        A spectrum given by wavelengths is refused (drpt renders in RGB; so
        does Mitsuba's ``*_rgb`` variants' parser only for uniform values).
        With ``emission`` (an emitter's radiance, intensity or irradiance), a
        uniform ``<spectrum value="v">`` is what Mitsuba's RGB variants make of
        it: ``v`` times the D65 illuminant in linear sRGB, :data:`D65_RGB`
        (``<rgb>`` and ``<float>`` stay gray)."""
        if not self.has(name):
            return default
        t = self._type(name)
        if t in ("Float", "Integer"):
            v = float(self.get(name))
            return _finite(self, name, (v, v, v))
        if t == "Color":
            c = self.get(name)
            return _finite(self, name, (float(c[0]), float(c[1]), float(c[2])))
        if t == "Spectrum":
            s = self.get(name)
            if s.is_uniform():
                v = float(s.values[0])
                if emission:
                    return _finite(self, name, tuple(v * c for c in D65_RGB))
                return _finite(self, name, (v, v, v))
            raise self.error(f"{self.label}: parameter '{name}' is a spectrum given by wavelengths: "
                             "unsupported (drpt renders in RGB; give <rgb> or a uniform value)")
        raise self._wrong(name, "a color (<rgb>, <spectrum> or <float>)")

    def ref(self, name: str) -> Node:
        self.read.add(name)
        return self.state.node(self.props[name].index())

    def children(self) -> list[Node]:
        """Nested or referenced plugins without a parameter name, in file order."""
        out = []
        for k in self.props.keys():
            if k.startswith("_arg_") and self._type(k) == "ResolvedReference":
                out.append(self.state.node(self.props[k].index()))
        return out

    def unread(self, ignore=()) -> list[str]:
        """Parameters (not nested plugins) drpt did not read, in file order."""
        return [k for k in self.names() if k not in self.read and k not in ignore]


def _finite(node: Node, name: str, v: tuple) -> tuple:
    """``v``, or a located error when a component is NaN or infinite."""
    if not all(abs(x) < float("inf") for x in v):
        raise node.error(f"{node.label}: parameter '{name}' must be finite, got {v}")
    return v
