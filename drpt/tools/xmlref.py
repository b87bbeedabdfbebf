"""Mitsuba references rendered from the user's own XML file (``compare scene.xml``).

For a Mitsuba XML scene, ``compare`` does not export drpt's reading of the
file: Mitsuba renders *that very file* (:class:`MitsubaXML`), so the check does
not depend on drpt's reader. The file goes through Mitsuba's own pipeline, as
``mi.load_file(path, optimize=False, **defines)`` does it (``mitsuba.parser``:
``parse_file`` with the ``-D`` values, with the file's folder first on the file
resolver; ``transform_all`` without the mesh and equivalence merging, which
fail on some files; ``instantiate``), with two edits of the parsed scene
graph between ``transform_all`` and ``instantiate``, both only where the
command line asks for other settings than the file's:

* the film's ``width``/``height`` become the image size drpt renders when it
  differs from the file's (``--size``); a film with a crop window keeps its
  size and window, and an image size other than the window's is refused
  (Mitsuba cannot render that window at another resolution);
* ``--filter`` and ``--max-depth``/``--rr-depth``, when they differ from the
  file's own, replace the film's ``rfilter`` and the integrator (Mitsuba's
  ``path`` with drpt's depths and the file's ``hide_emitters``); otherwise the
  file's own filter and integrator (``direct`` too) render.

The sample count is the reference's (``mi.render(spp=...)``), not the file's.
The cache key (:meth:`MitsubaXML.key`) hashes the bytes of the file and of
every file it includes, the size, mtime and path of every file a ``filename``
parameter names (meshes, textures, environment maps), the defines, the edits,
this module's source and the render settings.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from ..errors import Loc, SceneError
from ..filters import parse_filter
from ..options import filter_spelling
from .reference import CACHE_VERSION


class MitsubaXML:
    """The user's Mitsuba XML file as Mitsuba renders it for a reference.

    Args:
        path: the XML file.
        defines: ``-D`` values (``Scene.settings.defines``).
        size: the image size to render, ``(width, height)``; None: the file's.
        rfilter: a :class:`~drpt.filters.PixelFilter` replacing the film's, or None.
        integrator: ``{"max_depth", "rr_depth", "hide_emitters"}`` of a ``path``
            integrator replacing the file's (where the render's depths or
            ``hide_emitters`` differ from the file's), or None.
    """

    def __init__(self, path, defines: dict | None = None, *, size=None,
                 rfilter=None, integrator: dict | None = None):
        self.path = Path(path).resolve()
        self.defines = {str(k): str(v) for k, v in (defines or {}).items()}
        self.size = None if size is None else (int(size[0]), int(size[1]))
        self.rfilter = rfilter
        self.integrator = None if integrator is None else dict(integrator)

    @classmethod
    def for_scene(cls, scene, options) -> MitsubaXML:
        """The reference source of a loaded XML ``scene`` rendered with ``options``
        (a validated :class:`~drpt.options.RenderOptions`): the film, filter and
        integrator edits are those where ``options`` differ from the file's own."""
        st = scene.settings
        size = (options.width, options.height)
        file_filter = parse_filter(filter_spelling(st.rfilter or "gaussian", st.rfilter_params))
        rfilter = options.pixel_filter if options.pixel_filter != file_filter else None
        depths = (st.max_depth if st.max_depth is not None else -1,
                  st.rr_depth if st.rr_depth is not None else 5)
        integrator = None
        if ((options.path.max_depth, options.path.rr_depth) != depths
                or options.path.hide_emitters != bool(st.hide_emitters)):
            integrator = {"max_depth": int(options.path.max_depth), "rr_depth": int(options.path.rr_depth),
                          "hide_emitters": bool(options.path.hide_emitters)}
            if options.integrator == "volpath":  # (Mitsuba's path would ignore the media)
                integrator["type"] = "volpath"
        return cls(scene.path, st.defines, size=size, rfilter=rfilter, integrator=integrator)

    # ------------------------------------------------------------ identity
    def edits(self) -> dict:
        """The edits of the file, JSON-ready (reports, the cache key)."""
        return {"file": str(self.path), "defines": self.defines,
                "size": None if self.size is None else list(self.size),
                "rfilter": None if self.rfilter is None else str(self.rfilter),
                "integrator": self.integrator}

    def key(self, settings: dict) -> str:
        """SHA-256 (hex) of a reference of this file with ``settings`` (module docs)."""
        import mitsuba as mi

        state, _, resolver = self._parse()
        h = hashlib.sha256()

        def add(tag: str, data: bytes) -> None:
            h.update(tag.encode() + b"\0" + len(data).to_bytes(8, "little") + data)

        add("meta", json.dumps({"cache_version": CACHE_VERSION, "mitsuba": mi.__version__,
                                "variant": mi.variant(), "settings": settings, "edits": self.edits()},
                               sort_keys=True).encode())
        for f in [Path(str(f)) for f in state.files]:
            add("xml:" + str(f), _read(f))
        deps = []
        for node in state.nodes:
            props = node.props
            for name in props.keys():
                if "filename" in name and str(props.type(name)).endswith("String"):
                    deps.append(_stat(self._resolve(str(props[name]), resolver)))
        add("deps", json.dumps(deps).encode())
        add("source", Path(__file__).read_bytes())
        return h.hexdigest()

    # ------------------------------------------------------------ loading
    def _resolve(self, name: str, resolver) -> Path:
        p = Path(name)
        return p if p.is_absolute() else Path(str(resolver.resolve(name)))

    def _parse(self):
        import mitsuba as mi
        import mitsuba.parser as mp

        config = mp.ParserConfig(mi.variant())
        config.merge_equivalent = False
        config.merge_meshes = False
        resolver = mi.file_resolver()
        local = mi.FileResolver(resolver)
        local.prepend(str(self.path.parent))
        mi.set_file_resolver(local)
        try:
            state = mp.parse_file(config, str(self.path), **self.defines)
            mp.transform_all(config, state)
        except RuntimeError as e:
            raise SceneError(Loc(self.path), f"Mitsuba cannot parse the file: {_short(e)}") from None
        finally:
            mi.set_file_resolver(resolver)
        # the resolver as the parser left it: the file's folder and its <path> folders,
        # where the plugins find their files when they are instantiated
        return state, config, local

    def load(self):
        """``(mi.Scene, integrator or None)``: the file with the edits, loaded by Mitsuba
        (its variant must be set)."""
        import mitsuba as mi
        import mitsuba.parser as mp

        state, config, local = self._parse()
        nodes = state.nodes
        sensors = [n for n in nodes if n.type == mi.ObjectType.Sensor]
        if sensors and (self.size is not None or self.rfilter is not None):
            self._edit_film(mi, mp, state, _child(mi, nodes, sensors[0], mi.ObjectType.Film))
        resolver = mi.file_resolver()
        mi.set_file_resolver(local)
        try:
            scene = mp.instantiate(config, state)
        except RuntimeError as e:
            raise SceneError(Loc(self.path), f"Mitsuba refuses the file: {_short(e)}") from None
        finally:
            mi.set_file_resolver(resolver)
        if not isinstance(scene, mi.Scene):
            raise SceneError(Loc(self.path), "not a Mitsuba scene")
        integrator = None
        if self.integrator is not None:
            integrator = mi.load_dict({"type": "path", **self.integrator})
        return scene, integrator

    def _edit_film(self, mi, mp, state, film) -> None:
        nodes = state.nodes
        if film is None:  # Mitsuba's default film: an hdrfilm of 768 x 576
            film_node = mp.SceneNode()
            film_node.type = mi.ObjectType.Film
            film_node.props.set_plugin_name("hdrfilm")
            nodes.append(film_node)
            index = len(nodes) - 1
            sensor = [n for n in nodes if n.type == mi.ObjectType.Sensor][0]
            sensor.props["film"] = mi.Properties.ResolvedReference(index)
            film = nodes[index]
        props = film.props
        if self.size is not None:
            w, h = props.get("width", 768), props.get("height", 576)
            crop = [props.get(k) for k in ("crop_offset_x", "crop_offset_y", "crop_width", "crop_height")]
            image = (props.get("crop_width", w), props.get("crop_height", h))
            if tuple(self.size) != tuple(image):
                if any(c is not None for c in crop):
                    raise SceneError(Loc(self.path), f"the film's crop window is {image[0]}x{image[1]}: Mitsuba "
                                     f"cannot render it at {self.size[0]}x{self.size[1]} (leave out --size)")
                props["width"], props["height"] = self.size
        if self.rfilter is not None:
            f = self.rfilter.to_mitsuba()
            old = _child(mi, nodes, film, mi.ObjectType.ReconstructionFilter)
            if old is None:
                node = mp.SceneNode()
                node.type = mi.ObjectType.ReconstructionFilter
                nodes.append(node)
                film.props["rfilter"] = mi.Properties.ResolvedReference(len(nodes) - 1)
                old = nodes[len(nodes) - 1]
            rp = old.props
            for k in list(rp.keys()):
                del rp[k]
            rp.set_plugin_name(f.pop("type"))
            for k, v in f.items():
                rp[k] = v


def _child(mi, nodes, parent, kind):
    props = parent.props
    for k in props.keys():
        if str(props.type(k)).endswith("ResolvedReference"):
            node = nodes[props[k].index()]
            if node.type == kind:
                return node
    return None


def _read(p: Path) -> bytes:
    try:
        return p.read_bytes()
    except OSError:
        return b""


def _stat(p: Path) -> list:
    try:
        st = p.stat()
        return [str(p.resolve()), st.st_size, st.st_mtime_ns]
    except OSError:
        return [str(p), None, None]


def _short(e: Exception) -> str:
    import re

    text = re.sub(r"\[[A-Za-z0-9_]+\.(?:cpp|h):\d+\] ", "", str(e))
    return " ".join(text.split())
