"""Scene description (:mod:`.model`) and its loaders.

``load_scene(path)`` reads drpt's text scene format (see :mod:`.parser` for
the grammar) with its OBJ meshes (:mod:`.obj`) and MTL libraries (:mod:`.mtl`)
into a world-space :class:`Scene`. Every input file is opened through
:mod:`.files` (regular files only; files named by another file remember
that file and line). A file ending in ``.xml`` is a Mitsuba scene, read by
:func:`.mitsuba.load_mitsuba_xml` (``defines`` fill its ``$name`` references).
"""

import contextlib
import contextvars
from pathlib import Path

from ..errors import Loc, note
from .model import (
    Background,
    Camera,
    DirectionalLight,
    Light,
    Material,
    OrthographicCamera,
    PerspectiveCamera,
    Planes,
    PointLight,
    ProjectorLight,
    RenderSettings,
    Scene,
    Skybox,
    Spheres,
    SpotLight,
    Triangles,
)

#: load_scene's XML keyword arguments where a caller gives none (see :func:`xml_flags`)
_XML_FLAGS: contextvars.ContextVar[dict | None] = contextvars.ContextVar("drpt_xml_flags", default=None)


@contextlib.contextmanager
def xml_flags(**flags):
    """Within the block, :func:`load_scene` reads Mitsuba XML with these keyword
    arguments (``defines``, ``ignore_unsupported``, ``strict``) unless given: the
    command line sets them once for whichever command loads the scene."""
    token = _XML_FLAGS.set(dict(flags))
    try:
        yield
    finally:
        _XML_FLAGS.reset(token)


def load_scene(path, *, defines: dict[str, str] | None = None, ignore_unsupported: bool | None = None,
               strict: bool | None = None) -> Scene:
    """Load a scene file: drpt's text format, or Mitsuba XML for a ``.xml`` file
    (``defines``, ``ignore_unsupported`` and ``strict`` apply to XML only, a note
    says so when given for another file; ``None`` takes :func:`xml_flags`' value,
    else none / False)."""
    # the loaders, here and not at the top: they import drpt.materials and drpt.imageio, which
    # import drpt.scene.model, so importing this package must not import them
    if Path(path).suffix.lower() == ".xml":
        from .mitsuba import load_mitsuba_xml  # cycle: it imports drpt.materials, which imports drpt.scene.model

        ctx = _XML_FLAGS.get() or {}
        return load_mitsuba_xml(
            path, ctx.get("defines") if defines is None else defines,
            ignore_unsupported=bool(ctx.get("ignore_unsupported", False) if ignore_unsupported is None
                                    else ignore_unsupported),
            strict=bool(ctx.get("strict", False) if strict is None else strict))
    ctx = _XML_FLAGS.get() or {}
    given = [name for name, on in (("-D", defines or ctx.get("defines")),
                                   ("--ignore-unsupported", ignore_unsupported or ctx.get("ignore_unsupported")),
                                   ("--strict", strict or ctx.get("strict"))) if on]
    if given:
        verb = "applies" if len(given) == 1 else "apply"
        note(f"{' and '.join(given)} {verb} to Mitsuba XML scenes only: ignored", Loc(path))
    from .parser import load_scene as load_drpt_scene  # cycle: as load_mitsuba_xml above

    return load_drpt_scene(path)


__all__ = [
    "load_scene",
    "xml_flags",
    "Background",
    "Camera",
    "DirectionalLight",
    "Light",
    "Material",
    "OrthographicCamera",
    "PerspectiveCamera",
    "Planes",
    "PointLight",
    "ProjectorLight",
    "RenderSettings",
    "Scene",
    "Skybox",
    "Spheres",
    "SpotLight",
    "Triangles",
]
