"""Loader for drpt's text scene format (descended from MIT 6.837's).

:func:`load_scene` reads a scene file and returns a world-space
:class:`~drpt.scene.model.Scene`. Pure Python and numpy, no rendering backend.

Grammar
-------
Tokens are whitespace separated; ``{``/``}`` are tokens even when glued to a
word; ``#`` and ``//`` start comments (see :mod:`drpt.scene.tokens`). Keywords
are case-sensitive. ``v3`` below means three finite numbers, ``[..]`` optional.
Fields inside a block may come in any order, each at most once. ::

    scene      := block*          (a camera is required unless the file has no
                                   blocks at all; every block at most once,
                                   in any order)
    block      := PerspectiveCamera { center v3 direction v3 up v3 angle deg
                                      [apertureRadius a] [focusDistance f] }
                | OrthographicCamera { center v3 direction v3 up v3 size s }
                | Background { [color v3] [ambientLight v3] }
                | Lights { numLights N light* }
                | Materials { numMaterials N material* }
                | Group
    light      := DirectionalLight { direction v3 color v3 }
                | PointLight { position v3 color v3 [attenuation c l q] }
                | Skybox { FILE [R r] }                  (R defaults to 1000)
    material   := Material { field* } | PhongMaterial { field* }
       fields:    diffuseColor v3  specularColor v3  exponent e
                  reflectiveColor v3  transparentColor v3  indexOfRefraction n
                  texture FILE
                  and MTL statements (case-insensitive), each taking the values
                  after it on the same line, up to the next field name:
                  Kd Ks Ke Le Ns Ni d Tr illum Roughness Mentalness Pr Pm map_Kd
    Group      := Group { numObjects N (MaterialIndex i | object)* }
    object     := Group
                | Sphere { center v3 radius r [mtl NAME] }
                | Plane { normal v3 offset d [mtl NAME] }       dot(n, x) = d
                | Triangle { vertex0 v3 vertex1 v3 vertex2 v3 [mtl NAME] }
                | TriangleMesh { obj_file FILE }
                | Transform { op* object }
    op         := Translate v3 | Scale v3 | UniformScale s
                | XRotate deg | YRotate deg | ZRotate deg
                | Rotate { [axis] v3 [angle] deg } | Rotate v3 deg
                | Matrix { 16 numbers, row-major, last row 0 0 0 1 }

Semantics
---------
* A scene without a ``Group`` has no geometry (the renderer shows the
  background or sky, with a warning). A file with no blocks at all (an
  empty file, ``/dev/null``) gets a default camera at the origin looking
  down -Z, with a warning; otherwise a missing camera is an error.
* ``numObjects`` counts objects only (``MaterialIndex`` is not counted) and
  must match, like ``numLights`` and ``numMaterials``; a mismatch is an error
  at the block's line. (The seed's scene files all match.)
* Cameras: ``angle`` is the full vertical field of view, in (0, 180);
  ``size`` > 0; ``direction`` and ``up`` non-zero and not parallel.
  ``apertureRadius`` (>= 0, world units; 0, the default, is a pinhole) makes
  the perspective camera a thin lens (depth of field, Mitsuba's
  ``thinlens``), sharp at ``focusDistance`` (> 0, along ``direction``),
  which it then requires; a ``focusDistance`` without an aperture has no
  effect (a warning).
* Transform operations compose left to right, ``M = Op1 @ Op2 @ ...``, and
  nest as ``M_parent @ M`` (6.837 semantics). Triangles and meshes get their
  positions transformed and normals by the inverse-transpose; a mirroring
  transform swaps corners to keep the winding's front side outside. Spheres
  stay spheres under similarities, otherwise they are tessellated (1984
  triangles, smooth normals) with a warning. Planes transform exactly.
  Groups and Transforms nest to any depth (they are read with an explicit
  stack, not by recursion). An operation that makes the composed matrix
  overflow float64 is an error at its line; a singular (or numerically
  singular) matrix is an error at the object it applies to.
* Extent: world-space coordinates (vertices, sphere center plus radius,
  plane offsets, the camera's center, point lights) must be at most
  :data:`~drpt.scene.model.MAX_COORDINATE` (1e12) in magnitude, an error at
  the object's line otherwise (the renderer works in float32). Direction
  vectors with a component beyond 1e12 (or all below 1e-12) are stored
  normalized.
* Colours: negative light colours (``PointLight``/``DirectionalLight``
  ``color``, ``Background`` ``color`` and ``ambientLight``) and negative
  emission (``Ke``/``Le``) are errors; negative reflectances
  (``diffuseColor``, ``specularColor``, ``reflectiveColor``,
  ``transparentColor``, ``Kd``, ``Ks``) are clamped to 0 with a warning.
  Colours and material numbers beyond float32's range are errors.
* Materials: ``MaterialIndex i`` selects entry ``i`` of the ``Materials``
  block for the objects after it in the same Group and in the Groups and
  Transforms nested in it (it does not leak out of its Group). Objects
  with no material get a built-in material named ``"default"`` (kd 0.8).
  ``mtl NAME`` looks NAME up among all MTL libraries loaded anywhere in the
  scene (resolved after the whole file is read, so forward references work;
  if several libraries define NAME differently the first loaded wins, with a
  warning). OBJ faces use their ``usemtl`` material, or the current
  material when they have none.
* ``Scene.materials`` lists each material object once: all ``Materials``
  block entries first, in file order (so ``MaterialIndex i`` is
  ``Scene.materials[i]``), then MTL materials and ``"default"`` in order of
  first use. Unused MTL materials are left out.
* File names are relative to the file naming them and stored as absolute
  paths; a file that is missing or not a regular file (a directory, FIFO,
  device, symbolic link loop; ``/dev/null`` reads as empty) is an error at
  the referencing line (:mod:`drpt.scene.files`). Textures and the sky are
  stored as :class:`~drpt.scene.files.NamedPath`, so that a corrupt image,
  read only when rendering or exporting, is reported at that line too.
  Skybox files are checked after the geometry, so a scene missing both its
  OBJ and its sky reports the OBJ.

Every mistake raises :class:`~drpt.errors.SceneError` with the file and line.
"""

from __future__ import annotations

import difflib
import warnings
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

import numpy as np

from ..errors import Loc, SceneError, SceneWarning
from ..materials.spec import BSDFSpec
from . import transform as tf
from .files import check_input, named, resolve
from .model import (
    MAX_COORDINATE,
    Background,
    DirectionalLight,
    Material,
    Medium,
    OrthographicCamera,
    PerspectiveCamera,
    Planes,
    PointLight,
    RenderSettings,
    Scene,
    Skybox,
    Spheres,
    Triangles,
)
from .mtl import apply_field, check_range, reflectance
from .obj import MtlCache, ObjMesh, geometric_normals, load_obj
from .tokens import Token, TokenStream, read_text

__all__ = ["load_scene", "DEFAULT_MATERIAL_NAME"]

DEFAULT_MATERIAL_NAME = "default"

_TOP_BLOCKS = ("PerspectiveCamera", "OrthographicCamera", "Background", "Lights", "Materials", "Media", "Group")
_OBJECTS = ("Group", "Sphere", "Plane", "Triangle", "TriangleMesh", "Transform")
_LIGHTS = ("DirectionalLight", "PointLight", "Skybox")
_OPS = ("Translate", "Scale", "UniformScale", "XRotate", "YRotate", "ZRotate", "Rotate", "Matrix")
_KNOWN = set(_TOP_BLOCKS + _OBJECTS + _LIGHTS + _OPS + ("MaterialIndex", "Material", "PhongMaterial", "Medium"))
_MTL_KEYS = {"kd", "ks", "ke", "le", "ns", "ni", "d", "tr", "tf", "kt", "illum", "roughness", "mentalness",
             "metalness", "pr", "pm", "ps", "pc", "pcr", "aniso", "anisor", "map_kd"}


def load_scene(path: str | Path) -> Scene:
    """Load the scene file at ``path`` into a world-space :class:`Scene`.

    Raises :class:`~drpt.errors.SceneError` (file, line, message) for any
    problem in the scene or in the OBJ, MTL and image files it names.
    Non-fatal oddities (ignored OBJ/MTL statements, tessellated spheres) are
    reported with :func:`warnings.warn`.
    """
    path = resolve(path)
    text = read_text(path, what="scene file")
    return _Parser(path, text).parse()


# ------------------------------------------------------------ material refs
@dataclass(frozen=True)
class _ByIndex:
    index: int
    line: int


@dataclass(frozen=True)
class _ByName:
    name: str
    line: int


_Ref = Material | _ByIndex | _ByName | None  # None: the default material


@dataclass
class _Block:
    """An open Group or Transform while its contents are read."""

    opened: Token  # the 'Group' or 'Transform' keyword
    m: np.ndarray  # the world matrix around the block
    world: np.ndarray  # the world matrix of the objects in it (Transform: m @ local)
    current: _Ref  # the material for objects without their own
    declared: int = 0  # Group: numObjects
    found: int = 0  # objects read (a Transform holds at most one)
    local: np.ndarray | None = None  # Transform: its operations composed so far


def _direction(v) -> tuple[float, float, float]:
    """A direction as written, or normalized when float32 could not hold it
    or its square (a component beyond 1e12, or all below 1e-12): its length
    does not matter."""
    big = max(abs(c) for c in v)
    if 1e-12 <= big <= 1e12:
        return v
    return tuple(float(c) for c in tf.normalize(v))


def _hint(word: str, choices) -> str:
    close = difflib.get_close_matches(word, list(choices), n=1)
    return f" (did you mean '{close[0]}'?)" if close else ""


class _Parser:
    def __init__(self, path: Path, text: str):
        self.path = path
        self.base = path.parent
        self.ts = TokenStream(path, text)
        self.camera = None
        self.background = Background()
        self.lights: list = []
        self.block_materials: list[Material] = []
        self.media: list[Medium] = []
        self.medium_refs: list[tuple[int, int]] = []  # (line, medium index) of Material interior/exterior
        self.seen: dict[str, int] = {}
        self.skyboxes: list[tuple[Path, int]] = []
        self.mtl_cache: MtlCache = {}
        self.obj_cache: dict[Path, ObjMesh] = {}
        # geometry, material references are indices into self.refs
        self.refs: list[_Ref] = []
        self._ref_ids: dict[object, int] = {}
        self.tri_chunks: list[tuple[np.ndarray, np.ndarray | None, np.ndarray | None, np.ndarray]] = []
        self.sph: list[tuple[np.ndarray, float, int]] = []
        self.pln: list[tuple[np.ndarray, float, int]] = []

    # ------------------------------------------------------------ helpers
    def error(self, line: int | None, message: str) -> SceneError:
        return SceneError(self.loc(line), message)

    def loc(self, line: int | None) -> Loc:
        return Loc(self.path, line)

    def ref(self, r: _Ref) -> int:
        key = id(r) if isinstance(r, Material) else r
        i = self._ref_ids.get(key)
        if i is None:
            i = self._ref_ids[key] = len(self.refs)
            self.refs.append(r)
        return i

    def fields(self, name: str, opened: Token, readers: dict[str, Callable[[Token], object]],
               extra: Callable[[Token], bool] | None = None) -> dict[str, tuple[object, int]]:
        """Read ``{ field value ... }``. ``readers`` maps field names to
        functions reading the value; ``extra`` may consume other tokens
        (returns False to reject). Returns ``{field: (value, line)}``."""
        self.ts.expect("{", f"after '{name}'")
        out: dict[str, tuple[object, int]] = {}
        while True:
            tok = self.ts.next(f"a field or '}}' to close {name} (opened at line {opened.line})")
            if tok.text == "}":
                return out
            reader = readers.get(tok.text)
            if reader is None:
                if extra is not None and extra(tok):
                    continue
                raise self.unknown(tok, f"field in {name}", readers)
            if tok.text in out:
                raise self.error(tok.line, f"'{tok.text}' given twice in {name}")
            out[tok.text] = (reader(tok), tok.line)

    def unknown(self, tok: Token, what: str, choices) -> SceneError:
        if tok.text == "{":
            return self.error(tok.line, f"unexpected '{{' where a {what} was expected")
        msg = f"unknown {what} '{tok.text}'"
        if tok.text in _KNOWN:
            msg += " (is a '}' missing before it?)"
        else:
            msg += _hint(tok.text, choices)
        choices = list(choices)
        if choices:
            msg += "; expected one of: " + ", ".join(choices)
        return self.error(tok.line, msg)

    def require(self, got: dict, name: str, opened: Token, keys) -> None:
        for k in keys:
            if k not in got:
                raise self.error(opened.line, f"{name} is missing '{k}'")

    def vec(self, what):
        return lambda tok: self.ts.vec3(what)

    def num(self, what):
        return lambda tok: self.ts.number(what)

    def material_number(self, what):
        """A material parameter: a finite number that fits float32."""
        def read(tok):
            value = self.ts.number(what)
            check_range((value,), self.loc(tok.line), what)
            return value
        return read

    def word(self, what):
        return lambda tok: self.ts.word(what)

    def count(self, keyword: str, block: str, opened: Token) -> int:
        tok = self.ts.next(f"'{keyword}' in {block}")
        if tok.text != keyword:
            raise self.error(tok.line, f"{block} must start with '{keyword} N', found '{tok.text}'")
        n = self.ts.integer(keyword)
        if n < 0:
            raise self.error(tok.line, f"{keyword} must not be negative")
        return n

    def check_count(self, keyword: str, block: str, opened: Token, declared: int, found: int, what: str):
        if declared != found:
            raise self.error(opened.line, f"{block} declares {keyword} {declared} but contains {found} {what}")

    def file_ref(self, tok: Token) -> Path:
        return resolve(self.base / tok.text)

    # ------------------------------------------------------------ top level
    def parse(self) -> Scene:
        ts = self.ts
        while not ts.at_end():
            tok = ts.next("a block")
            if tok.text not in _TOP_BLOCKS:
                if tok.text in _OBJECTS or tok.text in ("MaterialIndex",):
                    raise self.error(tok.line, f"'{tok.text}' must be inside a Group block")
                raise self.unknown(tok, "block", _TOP_BLOCKS)
            kind = "camera" if tok.text.endswith("Camera") else tok.text
            if kind in self.seen:
                raise self.error(tok.line, f"a second {kind} block (the first is at line {self.seen[kind]})")
            self.seen[kind] = tok.line
            if kind == "camera":
                self.parse_camera(tok)
            elif kind == "Background":
                self.parse_background(tok)
            elif kind == "Lights":
                self.parse_lights(tok)
            elif kind == "Materials":
                self.parse_materials(tok)
            elif kind == "Media":
                self.parse_media(tok)
            else:
                self.parse_group(tok, tf.identity(), None)
        if self.camera is None and not self.seen:
            # An empty file (/dev/null, only comments): nothing to frame, the
            # image is the background whatever the view.
            warnings.warn(SceneWarning(self.loc(None), "the scene file has no blocks; it renders the "
                                       "background through a default camera"), stacklevel=2)
            self.camera = PerspectiveCamera((0.0, 0.0, 0.0), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0), 45.0)
        if self.camera is None:
            raise self.error(ts.last_line, "no camera: add a PerspectiveCamera or OrthographicCamera block")
        for line, k in self.medium_refs:
            if k >= len(self.media):
                have = (f"the Media block defines {len(self.media)}" if "Media" in self.seen
                        else "there is no Media block")
                raise self.error(line, f"medium {k} is out of range ({have})")
        materials, index = self.resolve_materials()
        for sky, line in self.skyboxes:
            check_input(sky, ref=self.loc(line), what="skybox file")
        return Scene(
            path=self.path,
            camera=self.camera,
            materials=materials,
            triangles=self.build_triangles(index),
            spheres=self.build_spheres(index),
            planes=self.build_planes(index),
            lights=self.lights,
            background=self.background,
            media=self.media,
            # a scene with media renders with volpath unless --integrator says otherwise
            settings=RenderSettings(integrator="volpath") if self.media else None,
        )

    # --------------------------------------------------------------- camera
    def parse_camera(self, opened: Token) -> None:
        persp = opened.text == "PerspectiveCamera"
        last = "angle" if persp else "size"
        readers = {
            "center": self.vec("center"),
            "direction": self.vec("direction"),
            "up": self.vec("up"),
            last: self.num(last),
        }
        if persp:
            readers["apertureRadius"] = self.num("apertureRadius")
            readers["focusDistance"] = self.num("focusDistance")
        got = self.fields(opened.text, opened, readers)
        self.require(got, opened.text, opened, ("center", "direction", "up", last))
        self.check_extent(got["center"][1], "camera center", got["center"][0])
        d = tf.normalize(got["direction"][0])
        u = tf.normalize(got["up"][0])
        if not d.any():
            raise self.error(got["direction"][1], "camera direction has zero length")
        if not u.any():
            raise self.error(got["up"][1], "camera up has zero length")
        if np.linalg.norm(np.cross(d, u)) < 1e-6:
            raise self.error(got["up"][1], "camera up is parallel to its direction")
        value, line = got[last]
        if persp:
            if not 0.0 < value < 180.0:
                raise self.error(line, f"camera angle must be in (0, 180) degrees, got {value:g}")
            aperture, focus = self.lens(got, opened)
            self.camera = PerspectiveCamera(got["center"][0], _direction(got["direction"][0]),
                                            _direction(got["up"][0]), value, aperture, focus)
        else:
            if not value > 0.0:
                raise self.error(line, f"camera size must be positive, got {value:g}")
            self.camera = OrthographicCamera(got["center"][0], _direction(got["direction"][0]),
                                             _direction(got["up"][0]), value)

    def lens(self, got: dict, opened: Token) -> tuple[float, float | None]:
        """A PerspectiveCamera's ``(apertureRadius, focusDistance)``, checked."""
        aperture, a_line = got.get("apertureRadius", (0.0, None))
        focus, f_line = got.get("focusDistance", (None, None))
        if not 0.0 <= aperture <= MAX_COORDINATE:
            raise self.error(a_line, f"apertureRadius must be between 0 and {MAX_COORDINATE:g} "
                                     f"(world units), got {aperture:g}")
        if focus is not None and not 0.0 < focus <= MAX_COORDINATE:
            raise self.error(f_line, f"focusDistance must be positive and at most "
                                     f"{MAX_COORDINATE:g} (world units), got {focus:g}")
        if aperture > 0.0 and focus is None:
            raise self.error(a_line, "apertureRadius needs focusDistance: the distance, along "
                                     "the camera direction, of the plane in focus")
        if aperture == 0.0 and focus is not None:
            warnings.warn(SceneWarning(self.loc(f_line), "focusDistance has no effect without an "
                                       "apertureRadius above 0 (a pinhole camera is sharp everywhere)"),
                          stacklevel=2)
        return aperture, focus

    def parse_background(self, opened: Token) -> None:
        got = self.fields("Background", opened, {
            "color": self.vec("color"), "ambientLight": self.vec("ambientLight")})
        for key, (value, line) in got.items():
            self.check_light(line, f"Background {key}", value)
        self.background = Background(
            color=got.get("color", ((0.0, 0.0, 0.0), 0))[0],
            ambient=got.get("ambientLight", ((0.0, 0.0, 0.0), 0))[0],
        )

    # --------------------------------------------------------------- lights
    def parse_lights(self, opened: Token) -> None:
        ts = self.ts
        ts.expect("{", "after 'Lights'")
        n = self.count("numLights", "Lights", opened)
        found = 0
        while True:
            tok = ts.next(f"a light or '}}' to close Lights (opened at line {opened.line})")
            if tok.text == "}":
                break
            if tok.text == "DirectionalLight":
                got = self.fields(tok.text, tok, {"direction": self.vec("direction"), "color": self.vec("color")})
                self.require(got, tok.text, tok, ("direction", "color"))
                if not tf.normalize(got["direction"][0]).any():
                    raise self.error(got["direction"][1], "light direction has zero length")
                self.check_light(got["color"][1], "DirectionalLight color", got["color"][0])
                self.lights.append(DirectionalLight(_direction(got["direction"][0]), got["color"][0],
                                                    loc=self.loc(tok.line)))
            elif tok.text == "PointLight":
                got = self.fields(tok.text, tok, {"position": self.vec("position"), "color": self.vec("color"),
                                                  "attenuation": self.vec("attenuation")})
                self.require(got, tok.text, tok, ("position", "color"))
                self.check_extent(got["position"][1], "PointLight position", got["position"][0])
                self.check_light(got["color"][1], "PointLight color", got["color"][0])
                # No attenuation given: physical inverse-square falloff.
                att, line = got.get("attenuation", ((0.0, 0.0, 1.0), tok.line))
                if min(att) < 0 or max(att) <= 0:
                    raise self.error(line, "attenuation must be non-negative and not all zero")
                self.lights.append(PointLight(got["position"][0], got["color"][0], att, loc=self.loc(tok.line)))
            elif tok.text == "Skybox":
                self.parse_skybox(tok)
            else:
                raise self.unknown(tok, "light", _LIGHTS)
            found += 1
        self.check_count("numLights", "Lights", opened, n, found, "lights")

    def parse_skybox(self, opened: Token) -> None:
        ts = self.ts
        ts.expect("{", "after 'Skybox'")
        file_tok = None
        radius = 1000.0
        while True:
            tok = ts.next(f"a file name, 'R' or '}}' to close Skybox (opened at line {opened.line})")
            if tok.text == "}":
                break
            if tok.text == "R":
                radius = ts.number("Skybox R")
                if not radius > 0:
                    raise self.error(tok.line, f"Skybox R must be positive, got {radius:g}")
            elif tok.text == "{":
                raise self.error(tok.line, "unexpected '{' in Skybox")
            elif file_tok is None:
                file_tok = tok
            else:
                raise self.error(tok.line, f"Skybox takes one file name; unexpected '{tok.text}'"
                                 + (" (is a '}' missing before it?)" if tok.text in _KNOWN else ""))
        if file_tok is None:
            raise self.error(opened.line, "Skybox needs a file name, e.g. 'Skybox { sky.hdr R 1000 }'")
        p = named(self.file_ref(file_tok), self.loc(file_tok.line))
        self.skyboxes.append((p, file_tok.line))
        self.lights.append(Skybox(p, radius, loc=self.loc(opened.line)))

    # ------------------------------------------------------------ materials
    def parse_materials(self, opened: Token) -> None:
        ts = self.ts
        ts.expect("{", "after 'Materials'")
        n = self.count("numMaterials", "Materials", opened)
        while True:
            tok = ts.next(f"a material or '}}' to close Materials (opened at line {opened.line})")
            if tok.text == "}":
                break
            if tok.text not in ("Material", "PhongMaterial"):
                raise self.unknown(tok, "material type", ("Material", "PhongMaterial"))
            self.block_materials.append(self.parse_material(tok, len(self.block_materials)))
        self.check_count("numMaterials", "Materials", opened, n, len(self.block_materials), "materials")

    def parse_media(self, opened: Token) -> None:
        """``Media { numMedia N Medium { [sigmaT v3] [albedo v3] [scale s] [g g] }* }``:
        homogeneous media (:class:`~drpt.scene.model.Medium`), Mitsuba's defaults."""
        ts = self.ts
        ts.expect("{", "after 'Media'")
        n = self.count("numMedia", "Media", opened)
        while True:
            tok = ts.next(f"a Medium or '}}' to close Media (opened at line {opened.line})")
            if tok.text == "}":
                break
            if tok.text != "Medium":
                raise self.unknown(tok, "block in Media", ("Medium",))
            got = self.fields("Medium", tok, {"sigmaT": self.vec("sigmaT"), "albedo": self.vec("albedo"),
                                              "scale": self.num("scale"), "g": self.num("g")})
            sigma_t, _ = got.get("sigmaT", ((1.0, 1.0, 1.0), 0))
            albedo, _ = got.get("albedo", ((0.75, 0.75, 0.75), 0))
            scale, _ = got.get("scale", (1.0, 0))
            g, _ = got.get("g", (0.0, 0))
            lines = {key: got[key][1] if key in got else tok.line for key in ("sigmaT", "albedo", "g")}
            if not all(0.0 <= x <= 3.4e38 for x in sigma_t) or not 0.0 <= scale <= 3.4e38 or \
                    not max(sigma_t) * scale <= 1e30:
                raise self.error(lines["sigmaT"], "Medium sigmaT and scale must be >= 0 (sigmaT * scale at "
                                 "most 1e30)")
            if not all(0.0 <= x <= 1.0 for x in albedo):
                raise self.error(lines["albedo"], f"Medium albedo must be in [0, 1], got {albedo}")
            if not -1.0 < g < 1.0:
                raise self.error(lines["g"], f"Medium g must be in (-1, 1), got {g:g}")
            self.media.append(Medium(f"medium_{len(self.media)}", tuple(sigma_t), tuple(albedo), float(scale),
                                     "hg" if g else "isotropic", float(g), self.loc(tok.line)))
        self.check_count("numMedia", "Media", opened, n, len(self.media), "media")

    def parse_material(self, opened: Token, i: int) -> Material:
        mat = Material(name=f"material_{i}", loc=self.loc(opened.line))
        ts = self.ts

        def texture(tok):
            return self.texture_file(ts.word("texture file name"))

        def mtl_style(tok: Token) -> bool:
            nonlocal mat
            key = tok.text.lower()
            if key not in _MTL_KEYS:
                return False
            # Values: the rest of the line, up to a brace or the next field name.
            args = []
            while ((nxt := ts.peek()) is not None and nxt.line == tok.line and nxt.text not in ("{", "}")
                   and nxt.text.lower() not in _MTL_KEYS and nxt.text not in readers):
                args.append(ts.next("value").text)
            mat = apply_field(mat, key, args, self.loc(tok.line), self.base)
            return True

        readers = {
            "diffuseColor": self.vec("diffuseColor"),
            "specularColor": self.vec("specularColor"),
            "exponent": self.material_number("exponent"),
            "reflectiveColor": self.vec("reflectiveColor"),
            "transparentColor": self.vec("transparentColor"),
            "indexOfRefraction": self.material_number("indexOfRefraction"),
            "texture": texture,
            "interior": lambda tok: self.ts.integer("interior"),
            "exterior": lambda tok: self.ts.integer("exterior"),
            "passThrough": lambda tok: True,
        }
        got = self.fields(opened.text, opened, readers, extra=mtl_style)
        media = {}
        for key in ("interior", "exterior"):
            if key in got:
                k, line = got.pop(key)
                if k < 0:
                    raise self.error(line, f"{key} must be a medium index >= 0, got {k}")
                self.medium_refs.append((line, k))
                media[key] = k
        if "passThrough" in got:  # a pure boundary (Mitsuba's null BSDF)
            _, line = got.pop("passThrough")
            if got or mat.given:
                raise self.error(line, "passThrough takes no other appearance fields (the surface is invisible)")
            return replace(mat, bsdf=BSDFSpec("null", {}, [], [], mat.loc), **media)
        mat = replace(mat, **media)
        for key in ("diffuseColor", "specularColor", "reflectiveColor", "transparentColor"):
            if key in got:
                got[key] = (reflectance(got[key][0], self.loc(got[key][1]), key), got[key][1])
        names = {"diffuseColor": "kd", "specularColor": "ks", "exponent": "ns", "reflectiveColor": "reflective",
                 "transparentColor": "transparent", "indexOfRefraction": "ior", "texture": "map_kd"}
        given = {"diffuseColor": "kd", "specularColor": "ks", "exponent": "ns", "indexOfRefraction": "ni",
                 "texture": "map_kd"}
        return replace(mat, **{names[k]: v for k, (v, _) in got.items()},
                       given=tuple(sorted(set(mat.given) | {given[k] for k in got if k in given})))

    def texture_file(self, tok: Token) -> Path:
        p = self.file_ref(tok)
        check_input(p, ref=self.loc(tok.line), what="texture file")
        return named(p, self.loc(tok.line))

    # -------------------------------------------------------------- objects
    def parse_group(self, root: Token, m: np.ndarray, current: _Ref) -> None:
        """The top-level Group and everything nested in it.

        Groups and Transforms nest to any depth: open blocks are kept on an
        explicit stack of :class:`_Block` (no recursion), and a leaf object
        is read by its own method with the world matrix and current
        material of the block around it."""
        ts = self.ts
        stack = [self.open_block(root, m, current)]
        while stack:
            top = stack[-1]
            if top.opened.text == "Group":
                tok = ts.next(f"an object or '}}' to close Group (opened at line {top.opened.line})")
            else:
                tok = ts.next("a transform operation, an object or '}' to close Transform "
                              f"(opened at line {top.opened.line})")
            t = tok.text
            if t == "}":
                self.close_block(stack.pop())
                if stack:
                    stack[-1].found += 1
                continue
            if top.opened.text == "Group":
                if t == "MaterialIndex":
                    i = ts.integer("MaterialIndex")
                    if i < 0:
                        raise self.error(tok.line, f"MaterialIndex {i} is negative")
                    top.current = _ByIndex(i, tok.line)
                    continue
                if t not in _OBJECTS:
                    raise self.unknown(tok, "object", _OBJECTS)
            else:
                if t in _OPS:
                    if top.found:
                        raise self.error(tok.line, f"'{t}' after the Transform's object: operations come first")
                    top.local = tf.compose(top.local, self.parse_op(tok))
                    top.world = tf.compose(top.m, top.local)
                    if not tf.is_finite(top.world):
                        raise self.error(tok.line, f"'{t}' makes the transform overflow (matrix entries beyond "
                                         "the float64 range)")
                    continue
                if t not in _OBJECTS:
                    raise self.unknown(tok, "transform operation or object", _OPS + _OBJECTS)
                if top.found:
                    raise self.error(tok.line, f"a Transform holds exactly one object; found a second one, '{t}'"
                                     " (wrap several objects in a Group)")
            if t in ("Group", "Transform"):
                stack.append(self.open_block(tok, top.world, top.current))
                continue
            {"Sphere": self.parse_sphere, "Plane": self.parse_plane, "Triangle": self.parse_triangle,
             "TriangleMesh": self.parse_mesh}[t](tok, top.world, top.current)
            top.found += 1

    def open_block(self, opened: Token, m: np.ndarray, current: _Ref) -> "_Block":
        """Read a Group's ``{ numObjects N`` or a Transform's ``{``."""
        self.ts.expect("{", f"after '{opened.text}'")
        if opened.text == "Group":
            n = self.count("numObjects", "Group", opened)
            return _Block(opened, m, m, current, declared=n)
        return _Block(opened, m, m, current, local=tf.identity())

    def close_block(self, block: "_Block") -> None:
        if block.opened.text == "Group":
            self.check_count("numObjects", "Group", block.opened, block.declared, block.found, "objects")
        elif not block.found:
            raise self.error(block.opened.line, "Transform has no object")

    def material_of(self, got: dict, current: _Ref) -> _Ref:
        if "mtl" in got:
            name, line = got["mtl"]
            return _ByName(name.text, line)
        return current

    def check_light(self, line: int, what: str, color) -> None:
        """Light colours (and the background's radiance) must not be negative
        and must fit float32."""
        check_range(color, self.loc(line), what)
        if min(color) < 0.0:
            raise self.error(line, f"{what} {' '.join(f'{c:g}' for c in color)} must not be negative")

    def check_extent(self, line: int, what: str, *values) -> None:
        """World-space values must be within :data:`MAX_COORDINATE` (the
        renderer's float32 arithmetic)."""
        with np.errstate(all="ignore"):
            big = max((float(np.abs(np.asarray(v, np.float64)).max()) for v in values if np.size(v)), default=0.0)
        if not big <= MAX_COORDINATE:
            raise self.error(line, f"{what} reaches {big:.3g} in world space, beyond drpt's limit of "
                             f"{MAX_COORDINATE:g} (float32 rendering); scale the scene down")

    def check_matrix(self, m: np.ndarray, opened: Token) -> None:
        if not tf.is_invertible(m):
            raise self.error(opened.line, f"the Transform around this {opened.text} is singular or nearly so "
                             "(not invertible)")

    def parse_sphere(self, opened: Token, m: np.ndarray, current: _Ref) -> None:
        got = self.fields("Sphere", opened, {"center": self.vec("center"), "radius": self.num("radius"),
                                             "mtl": self.word("material name")})
        self.require(got, "Sphere", opened, ("center", "radius"))
        radius, rline = got["radius"]
        if not radius > 0:
            raise self.error(rline, f"sphere radius must be positive, got {radius:g}")
        center = np.array(got["center"][0], dtype=np.float64)
        ref = self.ref(self.material_of(got, current))
        if tf.is_identity(m):
            self.check_extent(opened.line, "Sphere", np.abs(center) + radius)
            self.sph.append((center, radius, ref))
            return
        self.check_matrix(m, opened)
        s = tf.similarity_scale(m)
        if s is not None:
            c = tf.transform_points(m, center)
            self.check_extent(opened.line, "Sphere", np.abs(c) + radius * s)
            self.sph.append((c, radius * s, ref))
            return
        with np.errstate(all="ignore"):  # an overflow is refused by check_extent
            p, n = tf.tessellate_sphere(center, radius)
        p, n, _ = tf.transform_triangles(m, p, n)
        self.check_extent(opened.line, "Sphere", p)
        warnings.warn(SceneWarning(self.loc(opened.line), "Sphere under a non-uniform Transform was "
                                   f"tessellated into {len(p)} triangles"), stacklevel=2)
        self.tri_chunks.append((p, n, None, np.full(len(p), ref, np.int64)))

    def parse_plane(self, opened: Token, m: np.ndarray, current: _Ref) -> None:
        got = self.fields("Plane", opened, {"normal": self.vec("normal"), "offset": self.num("offset"),
                                            "mtl": self.word("material name")})
        self.require(got, "Plane", opened, ("normal", "offset"))
        n = np.array(got["normal"][0], dtype=np.float64)
        length = tf.length(n)
        if not length > 0:
            raise self.error(got["normal"][1], "plane normal has zero length")
        n, d = tf.normalize(n), got["offset"][0] / length
        if not tf.is_identity(m):
            self.check_matrix(m, opened)
            n, d = tf.transform_plane(m, n, d)
        self.check_extent(opened.line, "Plane offset", d)
        self.pln.append((n, d, self.ref(self.material_of(got, current))))

    def parse_triangle(self, opened: Token, m: np.ndarray, current: _Ref) -> None:
        got = self.fields("Triangle", opened, {"vertex0": self.vec("vertex0"), "vertex1": self.vec("vertex1"),
                                               "vertex2": self.vec("vertex2"), "mtl": self.word("material name")})
        self.require(got, "Triangle", opened, ("vertex0", "vertex1", "vertex2"))
        p = np.array([[got["vertex0"][0], got["vertex1"][0], got["vertex2"][0]]], dtype=np.float64)
        if not tf.is_identity(m):
            self.check_matrix(m, opened)
            p, _, _ = tf.transform_triangles(m, p, None)
        self.check_extent(opened.line, "Triangle", p)
        self.tri_chunks.append((p, None, None, np.array([self.ref(self.material_of(got, current))], np.int64)))

    def parse_mesh(self, opened: Token, m: np.ndarray, current: _Ref) -> None:
        got = self.fields("TriangleMesh", opened, {"obj_file": self.word("OBJ file name")})
        self.require(got, "TriangleMesh", opened, ("obj_file",))
        name_tok, line = got["obj_file"]
        p = self.file_ref(name_tok)
        mesh = self.obj_cache.get(p)
        if mesh is None:
            mesh = self.obj_cache[p] = load_obj(p, ref=self.loc(line), mtl_cache=self.mtl_cache)
        if not len(mesh):
            warnings.warn(SceneWarning(self.loc(line), f"{p.name} has no faces"), stacklevel=2)
            return
        # face_material == -1 (no usemtl) picks the table's last entry.
        # Register materials in the order faces first use them; slot -1 (no
        # usemtl) is the current material and indexes the table's last entry.
        mats = mesh.face_materials()
        table = np.full(len(mats) + 1, -1, np.int64)
        _, first = np.unique(mesh.face_material, return_index=True)
        for slot in mesh.face_material[np.sort(first)]:
            table[slot] = self.ref(mats[slot] if slot >= 0 else current)
        refs = table[mesh.face_material]
        pos, nrm, uvs = mesh.positions, mesh.normals, mesh.uvs
        if not tf.is_identity(m):
            self.check_matrix(m, opened)
            pos, nrm, flipped = tf.transform_triangles(m, pos, nrm)
            if flipped and uvs is not None:
                uvs = uvs[:, [0, 2, 1]]
        self.check_extent(line, f"{p.name}", pos)
        self.tri_chunks.append((pos, nrm, uvs, refs))

    # ------------------------------------------------------------ transform
    def parse_op(self, tok: Token) -> np.ndarray:
        ts = self.ts
        t = tok.text
        if t == "Translate":
            return tf.translate(*ts.vec3("Translate"))
        if t == "Scale":
            s = ts.vec3("Scale")
            if 0.0 in s:
                raise self.error(tok.line, "Scale by zero makes the transform singular")
            return tf.scale(*s)
        if t == "UniformScale":
            s = ts.number("UniformScale")
            if s == 0.0:
                raise self.error(tok.line, "UniformScale 0 makes the transform singular")
            return tf.scale(s, s, s)
        if t in ("XRotate", "YRotate", "ZRotate"):
            deg = ts.number(t)
            return {"X": tf.rotate_x, "Y": tf.rotate_y, "Z": tf.rotate_z}[t[0]](deg)
        if t == "Rotate":
            return self.parse_rotate(tok)
        # Matrix
        ts.expect("{", "after 'Matrix'")
        vals = [ts.number(f"Matrix element {k + 1} of 16") for k in range(16)]
        end = ts.next("'}' to close Matrix")
        if end.text != "}":
            raise self.error(end.line, f"Matrix takes exactly 16 numbers; expected '}}', found '{end.text}'")
        mat = np.array(vals, dtype=np.float64).reshape(4, 4)
        if not np.allclose(mat[3], (0.0, 0.0, 0.0, 1.0), rtol=0.0, atol=1e-12):
            raise self.error(tok.line, "Matrix: the last row must be 0 0 0 1 (projective matrices are not supported)")
        if not tf.is_invertible(mat):
            raise self.error(tok.line, "Matrix is singular (not invertible)")
        return mat

    def parse_rotate(self, tok: Token) -> np.ndarray:
        ts = self.ts
        braced = ts.peek() is not None and ts.peek().text == "{"
        if braced:
            ts.next("'{'")
        axis = deg = None
        for _ in range(2):
            nxt = ts.peek()
            if nxt is not None and nxt.text == "axis":
                ts.next("axis")
                axis = ts.vec3("Rotate axis")
            elif nxt is not None and nxt.text == "angle":
                ts.next("angle")
                deg = ts.number("Rotate angle")
            elif axis is None:
                axis = ts.vec3("Rotate axis")
            elif deg is None:
                deg = ts.number("Rotate angle")
        if axis is None or deg is None:
            raise self.error(tok.line, "Rotate needs an axis and an angle")
        if braced:
            end = ts.next("'}' to close Rotate")
            if end.text != "}":
                raise self.error(end.line, f"expected '}}' to close Rotate, found '{end.text}'")
        if not tf.normalize(axis).any():
            raise self.error(tok.line, "Rotate axis has zero length")
        return tf.rotate_axis(axis, deg)

    # ------------------------------------------------------------ assembly
    def resolve_materials(self) -> tuple[list[Material], np.ndarray]:
        """Turn self.refs into (Scene.materials, ref -> material index)."""
        named: dict[str, Material] = {}
        for _lib_path, lib in self.mtl_cache.items():
            for name, mat in lib.items():
                first = named.setdefault(name, mat)
                if first is not mat and first != mat:  # (Material.loc takes no part in ==)
                    warnings.warn(SceneWarning(mat.loc, f"material '{name}' is also defined at {first.loc}; "
                                               "'mtl' references use the first"), stacklevel=3)
        default = None
        resolved: list[Material] = []
        for r in self.refs:
            if isinstance(r, _ByIndex):
                if r.index >= len(self.block_materials):
                    have = (f"the Materials block defines {len(self.block_materials)}"
                            if "Materials" in self.seen else "there is no Materials block")
                    raise self.error(r.line, f"MaterialIndex {r.index} is out of range ({have})")
                r = self.block_materials[r.index]
            elif isinstance(r, _ByName):
                if r.name not in named:
                    libs = ", ".join(p.name for p in self.mtl_cache) or "none loaded"
                    raise self.error(r.line, f"unknown material '{r.name}' (MTL libraries: {libs})"
                                     + _hint(r.name, named))
                r = named[r.name]
            elif r is None:
                if default is None:
                    default = Material(name=DEFAULT_MATERIAL_NAME, kd=(0.8, 0.8, 0.8))
                r = default
            resolved.append(r)
        materials = list(self.block_materials)
        ids = {id(mat): i for i, mat in enumerate(materials)}
        index = np.zeros(len(resolved), np.int32)
        for k, mat in enumerate(resolved):
            if id(mat) not in ids:
                ids[id(mat)] = len(materials)
                materials.append(mat)
            index[k] = ids[id(mat)]
        return materials, index

    def build_triangles(self, index: np.ndarray) -> Triangles:
        if not self.tri_chunks:
            return Triangles.empty()
        pos = np.concatenate([c[0] for c in self.tri_chunks]).astype(np.float64, copy=False)
        mat = index[np.concatenate([c[3] for c in self.tri_chunks])].astype(np.int32)
        normals = uvs = None
        if any(c[1] is not None for c in self.tri_chunks):
            normals = np.concatenate([
                c[1] if c[1] is not None else np.repeat(geometric_normals(c[0])[:, None], 3, axis=1)
                for c in self.tri_chunks])
        if any(c[2] is not None for c in self.tri_chunks):
            uvs = np.concatenate([c[2] if c[2] is not None else np.zeros((len(c[0]), 3, 2))
                                  for c in self.tri_chunks])
        return Triangles(positions=pos, material=mat, normals=normals, uvs=uvs)

    def build_spheres(self, index: np.ndarray) -> Spheres:
        if not self.sph:
            return Spheres.empty()
        return Spheres(center=np.array([s[0] for s in self.sph], np.float64).reshape(-1, 3),
                       radius=np.array([s[1] for s in self.sph], np.float64),
                       material=index[[s[2] for s in self.sph]].astype(np.int32))

    def build_planes(self, index: np.ndarray) -> Planes:
        if not self.pln:
            return Planes.empty()
        return Planes(normal=np.array([p[0] for p in self.pln], np.float64).reshape(-1, 3),
                      offset=np.array([p[1] for p in self.pln], np.float64),
                      material=index[[p[2] for p in self.pln]].astype(np.int32))
