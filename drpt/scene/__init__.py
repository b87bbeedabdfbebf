"""Scene description (:mod:`.model`) and its loaders.

``load_scene(path)`` reads drpt's text scene format (see :mod:`.parser` for
the grammar) with its OBJ meshes (:mod:`.obj`) and MTL libraries (:mod:`.mtl`)
into a world-space :class:`Scene`. Every input file is opened through
:mod:`.files` (regular files only; files named by another file remember
that file and line).
"""

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
    Scene,
    Skybox,
    Spheres,
    Triangles,
)
from .parser import load_scene

__all__ = [
    "load_scene",
    "Background",
    "Camera",
    "DirectionalLight",
    "Light",
    "Material",
    "OrthographicCamera",
    "PerspectiveCamera",
    "Planes",
    "PointLight",
    "Scene",
    "Skybox",
    "Spheres",
    "Triangles",
]
