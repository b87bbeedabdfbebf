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

from ...errors import Loc, SceneError, SceneWarning
from ..files import named
from .precheck import bare_load_crashes, check_xml, located_offset, not_utf8

VARIANT = "scalar_rgb"

#: A uniform ``<spectrum value="1">`` on an emitter in Mitsuba 3's RGB variants: the
#: D65 illuminant in linear sRGB (float32 values read from Mitsuba 3.9's point emitter;
#: tests/scene/mitsuba/test_mitsuba_xml.py checks them against the installed Mitsuba)
D65_RGB = (1.204793930053711, 0.948291003704071, 0.9089160561561584)

#: kinds of nested plugins that are parameters by name (``<texture name="reflectance">``,
#: ``<ref name="interior" id=..>``); other kinds are children whatever their name
NAMED_KINDS = frozenset({"texture", "medium", "volume"})

#: parameters Mitsuba reads with ``get_unbounded_texture`` (a spectrum given by wavelengths
#: is not clamped to [0, 1] there): conductors' ``eta`` and ``k``, roughnesses
UNBOUNDED = frozenset({"eta", "k", "alpha", "alpha_u", "alpha_v", "sigma_a", "theta", "delta"})

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
        raise SceneError(Loc(), f"reading Mitsuba XML needs the mitsuba package ({e})") from None
    if mi.variant() != VARIANT and VARIANT in mi.variants():
        if mi.variant() is None:
            mi.set_variant(VARIANT)
    return mi


_UNREFERENCED = re.compile(r'^\s*- \S+ "([^"]+)"', re.M)
_UNRESOLVED = re.compile(r'unresolved reference to "(.*?)" in property "(.*?)"\. Make sure the object '
                         r'with id=".*?" exists\.')


def _one_line(text: str) -> str:
    text = " ".join(_TAG.sub("", text).split())
    # Mitsuba names an unnamed <ref> by its internal key (property "_arg_0")
    return _UNRESOLVED.sub(lambda m: (f'<ref id="{m.group(1)}"' if m.group(2).startswith("_arg_")
                                      else f'<ref name="{m.group(2)}" id="{m.group(1)}"')
                           + f'/>: no object has id "{m.group(1)}"', text)


def parser_error(path: Path, error: Exception) -> SceneError:
    """The one-line :class:`SceneError` for an exception of ``mitsuba.parser``."""
    text = str(error)
    # nested errors (<include>) repeat the chain; the innermost is the last
    last = text.split("\n")[-1] if "\n" in text else text
    m = _MESSAGE.search(_TAG.sub("", last))
    if m:
        return SceneError(Loc(_locate(path, m.group(1)), int(m.group(2))), _one_line(m.group(3)))
    m = _XML_FAILED.search(_TAG.sub("", text))
    if m:
        return SceneError(Loc(_locate(path, m.group(1)), int(m.group(3))),
                          f"malformed XML: {_one_line(m.group(2))}")
    return located_offset(_TAG.sub("", text)) or SceneError(Loc(path), _one_line(text))


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
        check_xml(path, defines)  # what would crash or block Mitsuba's parser
        config = mp.ParserConfig(VARIANT)
        # Mitsuba's load_file: a copy of the global file resolver with the scene's folder
        # first, on which the parser prepends each <path> folder (and, while it reads an
        # <include>d file, that file's folder); plugins resolve their files on what is left
        backup = mi.file_resolver()
        fs = mi.FileResolver(backup)
        fs.prepend(str(path.parent))
        mi.set_file_resolver(fs)
        try:
            state = mp.parse_file(config, str(path), **{k: str(v) for k, v in defines.items()})
            mp.transform_upgrade(config, state)
            mp.transform_resolve(config, state)
        except RuntimeError as e:
            raise parser_error(path, e) from None
        except UnicodeDecodeError:  # its message quotes bytes that are not UTF-8
            raise not_utf8(path, defines) from None
        finally:
            mi.set_file_resolver(backup)
        #: where a relative file name is looked for, first match wins (Mitsuba's order:
        #: the <path> folders, last first, then the scene's folder, then Mitsuba's defaults)
        self.search = [Path(str(p)) for p in fs]
        self.added = self.search[:len(self.search) - len(backup)]  # <path> folders, scene folder
        self.resolver = fs
        self.mi = mi
        self.mp = mp
        self.state = state
        self.files = [Path(str(f)) for f in state.files]
        self.nodes: dict[int, Node] = {}
        self.notes: list[SceneWarning] = []  # warnings found while reading values (clamped spectra)
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
        m = _LOCATION.match(state.mp.file_location(state.state, raw))
        #: the XML file that holds the element (an <include>d one, or the scene's)
        self.file: Path = self._file(m.group(1)) if m else state.path
        #: the element's place, for messages (line None: Mitsuba did not say)
        self.loc = Loc(self.file, int(m.group(2)) if m else None)
        self.read: set[str] = set()

    def _file(self, name: str) -> Path:
        idx = self.raw.file_index
        files = self.state.files
        if 0 <= idx < len(files) and files[idx].is_absolute():
            return files[idx]
        return _locate(self.state.path, name)

    # ------------------------------------------------------------ messages
    @property
    def line(self) -> int | None:
        return self.loc.line

    @property
    def label(self) -> str:
        return f"{self.kind} '{self.plugin}'" + (f" (id '{self.id}')" if self.id else "")

    def error(self, message: str) -> SceneError:
        return SceneError(self.loc, message)

    def resolve_file(self, name: str) -> Path:
        """A file name of this node as an absolute path, found as Mitsuba's file resolver
        finds it (:attr:`State.search`: the ``<path>`` folders, the scene's folder), then
        next to the XML file that holds the node; a missing one is an error at the node."""
        p = Path(name).expanduser()
        if not p.is_absolute():
            for base in (*self.state.search, self.file.parent):
                if (base / p).exists():
                    p = base / p
                    break
            else:
                folders = list(dict.fromkeys(str(b) for b in (*self.state.added, self.file.parent)))
                raise self.error(f"{self.label}: {name}: no such file (looked in {', '.join(folders)})")
        if not p.is_file():
            what = "not a regular file" if p.exists() else "no such file"
            raise self.error(f"{self.label}: {name}: {what}")
        # an image read at render time names this node's line in its errors
        return named(p.resolve(), self.loc if self.loc.line is not None else None)

    # ------------------------------------------------------------ params
    def _is_child(self, key: str) -> bool:
        """Whether parameter ``key`` is a nested plugin that Mitsuba's plugins find by its
        type, whatever its name (``<bsdf name="bsdf">``, ``<ref name="bsdf" id=..>``: a
        shape's BSDF and emitter, a composite's BSDFs, a film's rfilter, a sensor's film),
        rather than by its name (textures, media and volumes are named parameters)."""
        if self._type(key) != "ResolvedReference":
            return False
        return key.startswith("_arg_") or self.state.node(self.props[key].index()).kind not in NAMED_KINDS

    def names(self) -> list[str]:
        """The parameters, without the nested plugins :meth:`children` returns."""
        return [k for k in self.props.keys() if not self._is_child(k)]

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
        """An RGB triple from ``<rgb>``, a ``<spectrum>`` or a ``<float>``.

        A spectrum given by wavelengths (or an ``.spd`` file) becomes the color
        Mitsuba's RGB variants make of it (:meth:`_spectrum_rgb`). With
        ``emission`` (an emitter's radiance, intensity or irradiance), a uniform
        ``<spectrum value="v">`` is what Mitsuba's RGB variants make of it: ``v``
        times the D65 illuminant in linear sRGB, :data:`D65_RGB` (``<rgb>`` and
        ``<float>`` stay gray)."""
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
            return _finite(self, name, self._spectrum_rgb(name, s, emission))
        raise self._wrong(name, "a color (<rgb>, <spectrum> or <float>)")

    def _spectrum_rgb(self, name: str, s, emission: bool) -> tuple[float, float, float]:
        """A spectrum given by wavelengths (``value="400:0.1, 500:0.5"`` or an ``.spd``
        file), as Mitsuba's RGB variants read it (``Properties::get_texture_impl``): its
        linear sRGB color integrated against the CIE 1931 curves
        (``mi.spectrum_list_to_srgb``), times the D65 illuminant unless it is an emitter's;
        clamped to [0, 1] unless it is an emitter's or an unbounded parameter's
        (:data:`UNBOUNDED`), which are clamped at 0. A clamp is noted as a warning."""
        mi = self.state.mi
        bounded = not (emission or name in UNBOUNDED)
        wl, values = [float(x) for x in s.wavelengths], [float(x) for x in s.values]
        logger = mi.logger()
        level = logger.log_level()
        logger.set_log_level(mi.LogLevel.Error)  # drpt reports the clamp itself, once, located
        try:
            raw = mi.spectrum_list_to_srgb(wl, values, bounded=False, d65=not emission)
            rgb = mi.spectrum_list_to_srgb(wl, values, bounded=bounded, d65=not emission)
        except RuntimeError as e:
            raise self.error(f"{self.label}: parameter '{name}': {_one_line(str(e))}") from None
        finally:
            logger.set_log_level(level)
        out = (float(rgb[0]), float(rgb[1]), float(rgb[2]))
        if out != (float(raw[0]), float(raw[1]), float(raw[2])) or min(out) == 0.0 < max(values):
            self.state.notes.append(SceneWarning(self.loc, f"{self.label}: the spectrum of '{name}' is out of "
                                                 f"the sRGB gamut: clamped to {tuple(round(c, 6) for c in out)}, "
                                                 "as Mitsuba's RGB variants clamp it"))
        return out

    def ref(self, name: str) -> Node:
        self.read.add(name)
        return self.state.node(self.props[name].index())

    def objects(self) -> list[tuple[str, Node]]:
        """Every nested or referenced plugin as ``(parameter name, node)`` in file order
        (the name is ``_arg_<i>`` for one given without a name)."""
        return [(k, self.state.node(self.props[k].index())) for k in self.props.keys()
                if self._type(k) == "ResolvedReference"]

    def children(self) -> list[Node]:
        """Nested or referenced plugins that Mitsuba finds by type (:meth:`_is_child`),
        named or not, in file order."""
        return [self.state.node(self.props[k].index()) for k in self.props.keys() if self._is_child(k)]

    def mitsuba_unread(self) -> set[str] | None:
        """The parameters Mitsuba's plugin itself leaves unread (it refuses them), found by
        loading the plugin with this node's parameters (not its nested plugins) in
        Mitsuba; ``None`` when that load fails for another reason (a required nested
        plugin, a file) and the question stays open."""
        mi = self.state.mi
        d = {"type": self.plugin}
        for k in self.props.keys():
            if self._type(k) != "ResolvedReference":
                d[k] = self.props[k]
        if bare_load_crashes(self.plugin, d):
            return None
        backup = mi.file_resolver()
        mi.set_file_resolver(self.state.resolver)
        logger = mi.logger()
        level = logger.log_level()
        logger.set_log_level(mi.LogLevel.Error)
        try:
            mi.load_dict(d, parallel=False)
        except Exception as e:  # noqa: BLE001 - any failure leaves the question open
            text = str(e)
            if "unreferenced propert" not in text:
                return None
            return set(_UNREFERENCED.findall(text))
        finally:
            mi.set_file_resolver(backup)
            logger.set_log_level(level)
        return set()

    def unread(self, ignore=()) -> list[str]:
        """Parameters (not nested plugins) drpt did not read, in file order."""
        return [k for k in self.names() if k not in self.read and k not in ignore]


def _finite(node: Node, name: str, v: tuple) -> tuple:
    """``v``, or a located error when a component is NaN or infinite."""
    if not all(abs(x) < float("inf") for x in v):
        raise node.error(f"{node.label}: parameter '{name}' must be finite, got {v}")
    return v
