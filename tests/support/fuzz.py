"""Seeded mutations of drpt's input files, for tests/robustness/test_fuzz.py.

A :class:`Case` names one input file of a bundled scene (or a small image),
one mutation and one seed; :func:`build` copies the scene's folder into a
fresh directory, applies the mutation there with ``random.Random(seed)`` and
returns the file to load. The same case always yields the same bytes, so a
failing case id (``TARGET-MUTATION-sSEED``) reproduces alone with
``pytest tests/robustness/test_fuzz.py -k ID``.

:func:`check_error` is the contract every rejected input must meet: a
:class:`~drpt.errors.DrptError` whose message is one line beginning with
``FILE:LINE: `` (text formats: scene, OBJ, MTL; LINE within FILE's lines)
or ``FILE: `` (images).
"""

from __future__ import annotations

import os
import random
import re
import shutil
import zlib
from dataclasses import dataclass, fields, is_dataclass
from pathlib import Path

import numpy as np

from drpt.errors import DrptError

from . import SCENES

# Numbers at and past the ends of float64 and of integer types.
EXTREMES = ("1e308", "-1e308", "1e-320", "nan", "inf", "-inf", "1e999", "-0", "-0.0",
            "123456789012345678901234567890", "4294967296", "-1", "0", "1e-45", "-1e999")

TEXT_MUTATIONS = ("truncate", "token_swap", "token_delete", "token_dup", "extreme", "random_bytes",
                  "utf16", "latin1", "utf8_bom", "crlf", "nul")
BRACE_MUTATIONS = ("brace_drop", "brace_dup")  # scene files only
IMAGE_MUTATIONS = ("truncate", "random_bytes", "header", "empty", "huge_size")
NESTINGS = ("group600", "group10k", "transform600", "transform10k")
REF_MUTATIONS = ("ref_missing", "ref_dir", "ref_fifo", "ref_symloop")

# A small stand-in for the showcase's 1.9 MB car (same materials, textures,
# uv and normal indices), so that mutating the showcase scene stays quick.
SHOWCASE_OBJ = """\
# two textured quads using the showcase materials
mtllib showcase.mtl
v -1 0 -1
v 1 0 -1
v 1 0 1
v -1 0 1
vt 0 0
vt 1 0
vt 1 1
vt 0 1
vn 0 1 0
usemtl grille
f 1/1/1 2/2/1 3/3/1 4/4/1
usemtl plate
f -4/-4/-1 -2/-2/-1 -1/-1/-1
usemtl car_paint
f 1//1 3//1 4//1
f 1 2 3
"""

# Every production of the scene grammar (drpt/scene/parser.py) in one file,
# laid out beside the Cornell box's OBJ and MTL and the showcase's textures
# and sky: the bundled scenes use only cameras, Lights/Skybox and Groups.
GRAMMAR_SCENE = """\
# every block and field of the scene format
OrthographicCamera { center 0 0 10 direction 0 0 -1 up 0 1 0 size 5 }
Background { color 0.1 0.2 0.3 ambientLight 0.01 0.01 0.01 }
Lights {
    numLights 3
    DirectionalLight { direction -1 -1 -1 color 0.5 0.5 0.5 }
    PointLight { position 0 4 0 color 10 10 10 attenuation 1 0.1 0.01 }
    Skybox { sky_day.exr R 500 }
}
Materials {
    numMaterials 3
    Material { diffuseColor 0.8 0.1 0.1 }
    PhongMaterial { diffuseColor 0.5 0.5 0.5 specularColor 0.3 0.3 0.3 exponent 40
        reflectiveColor 0.1 0.1 0.1 transparentColor 0 0 0 indexOfRefraction 1.5 texture grille.png }
    Material { Kd 0.2 0.3 0.4 Ks 0.1 Ns 20 Roughness 0.3 Mentalness 0.5 Ni 1.4 d 1 illum 2 map_Kd plate.png }
}
Group {
    numObjects 7
    MaterialIndex 0
    Sphere { center 0 0 0 radius 1 }
    Plane { normal 0 1 0 offset -1 mtl white }
    Triangle { vertex0 0 0 0 vertex1 1 0 0 vertex2 0 1 0 mtl light }
    TriangleMesh { obj_file cornellbox.obj }
    Transform {
        Translate 1 2 3 Scale 1 2 1 UniformScale 0.5 XRotate 10 YRotate 20 ZRotate 30
        Rotate { axis 0 1 0 angle 45 } Rotate 1 0 0 15
        Matrix { 1 0 0 0  0 1 0 0  0 0 1 0  0 0 0 1 }
        Sphere { center 0 0 0 radius 0.5 }
    }
    Group { numObjects 1 MaterialIndex 2 Transform { Scale -1 1 1 TriangleMesh { obj_file cornellbox.obj } } }
    Group { numObjects 1 MaterialIndex 1 Transform { Scale 1 2 3 Sphere { center 0 0 0 radius 1 } } }
}
"""

# scene file loaded for a mutated dependency, per scene folder
ENTRY = {"cornellbox": "cornellbox.txt", "newscene": "newscene.txt", "showcase": "showcase_day.txt",
         "grammar": "grammar.txt"}


@dataclass(frozen=True)
class Case:
    folder: str  # scenes/<folder>; "images": the image corpus; "extremes": EXTREME_SCENES
    target: str  # file name inside the folder, or the EXTREME_SCENES name
    mutation: str = ""
    seed: int = 0

    @property
    def id(self) -> str:
        if self.folder == "extremes":
            return f"extremes/{self.target}"
        return f"{self.folder}/{self.target}-{self.mutation}-s{self.seed}"


def scene_cases(seeds: int = 3) -> list[Case]:
    cases = []
    texts = {"cornellbox": ["cornellbox.txt", "cornellbox.obj", "cornellbox.mtl"],
             "newscene": ["newscene.txt", "newscene_hard.txt", "newscene.obj", "newscene.mtl"],
             "showcase": ["showcase_day.txt", "showcase_dusk.txt", "showcase.obj", "showcase.mtl"],
             "grammar": ["grammar.txt"]}
    for folder, files in texts.items():
        for target in files:
            muts = TEXT_MUTATIONS + (BRACE_MUTATIONS if target.endswith(".txt") else ())
            cases += [Case(folder, target, m, s) for m in muts for s in range(seeds)]
    cases += [Case("cornellbox", "cornellbox.txt", m, 0) for m in NESTINGS]
    refs = [("cornellbox", "cornellbox.obj"), ("cornellbox", "cornellbox.mtl"),
            ("showcase", "grille.png"), ("showcase", "sky_day.exr")]
    cases += [Case(folder, target, m, 0) for folder, target in refs for m in REF_MUTATIONS]
    return cases


def image_cases(seeds: int = 4) -> list[Case]:
    return [Case("images", target, m, s)
            for target in ("grille.png", "plate.png", "small.hdr", "small.exr", "sky_day.exr")
            for m in IMAGE_MUTATIONS for s in range(seeds if m not in ("empty",) else 1)
            ] + [Case("images", "small.exr", "nonfinite", 0)]


# ------------------------------------------------------------------ setup
def make_images(folder: Path) -> None:
    """The image corpus: the showcase's PNGs and day sky, and a small .hdr
    and .exr written by drpt itself."""
    from drpt.imageio import write_image

    folder.mkdir(parents=True, exist_ok=True)
    for name in ("grille.png", "plate.png", "sky_day.exr"):
        shutil.copy(SCENES / "showcase" / name, folder / name)
    rgb = np.random.default_rng(0).uniform(0, 4, (5, 7, 3)).astype(np.float32)
    write_image(folder / "small.hdr", rgb)
    write_image(folder / "small.exr", rgb)


def rng_for(case: Case) -> random.Random:
    return random.Random(case.id)


def build(case: Case, root: Path, images: Path) -> tuple[Path, Path]:
    """Lay the case out under ``root``; return (file to load, mutated file)."""
    rng = rng_for(case)
    if case.folder == "images":
        target = root / case.target
        shutil.copy(images / case.target, target)
        target.write_bytes(mutate_image(target.read_bytes(), case.target, case.mutation, rng))
        return target, target
    if case.folder == "grammar":
        for f in ("cornellbox/cornellbox.obj", "cornellbox/cornellbox.mtl", "showcase/grille.png",
                  "showcase/plate.png", "showcase/sky_day.exr"):
            shutil.copy(SCENES / f, root)
        (root / "grammar.txt").write_text(GRAMMAR_SCENE)
    else:
        for f in (SCENES / case.folder).iterdir():
            if f.is_file():
                shutil.copy(f, root / f.name)
    if case.folder == "showcase":
        (root / "showcase.obj").write_text(SHOWCASE_OBJ)
    entry = root / (case.target if case.target.endswith(".txt") else ENTRY[case.folder])
    target = root / case.target
    if case.mutation in REF_MUTATIONS:
        replace_reference(target, case.mutation)
    elif case.mutation in NESTINGS:
        target.write_text(nested_scene(case.mutation))
    else:
        target.write_bytes(mutate_text(target.read_bytes(), case.mutation, rng))
    return entry, target


def replace_reference(target: Path, how: str) -> None:
    target.unlink()
    if how == "ref_dir":
        target.mkdir()
    elif how == "ref_fifo":
        os.mkfifo(target)
    elif how == "ref_symloop":
        other = target.with_name(target.name + ".loop")
        other.symlink_to(target.name)
        target.symlink_to(other.name)


def nested_scene(how: str) -> str:
    """A Cornell-box camera and ``how``'s levels of Group or Transform around one sphere."""
    depth = 600 if how.endswith("600") else 10_000
    camera = "PerspectiveCamera { center 0 0 5 direction 0 0 -1 up 0 1 0 angle 40 }\n"
    if how.startswith("group"):
        opening, closing = "Group { numObjects 1\n", "}\n"
    else:
        opening, closing = "Transform { Translate 0 0 0\n", "}\n"
    return (camera + "Group { numObjects 1\n" + opening * depth
            + "Sphere { center 0 0 0 radius 1 }\n" + closing * depth + "}\n")


# -------------------------------------------------------------- mutations
_WORD = re.compile(rb"\S+")
_NUM = re.compile(rb"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")


def mutate_text(data: bytes, how: str, rng: random.Random) -> bytes:
    words = [m.span() for m in _WORD.finditer(data)]
    if how == "none":
        return data
    if how == "truncate":
        return data[: rng.randrange(len(data))]
    if how == "token_swap":
        (a0, a1), (b0, b1) = sorted(rng.sample(words, 2))
        return data[:a0] + data[b0:b1] + data[a1:b0] + data[a0:a1] + data[b1:]
    if how == "token_delete":
        for a, b in sorted(rng.sample(words, rng.randint(1, 3)), reverse=True):
            data = data[:a] + data[b:]
        return data
    if how == "token_dup":
        a, b = rng.choice(words)
        return data[:b] + b" " + data[a:b] * rng.randint(1, 3) + data[b:]
    if how == "extreme":
        nums = [m.span() for m in _NUM.finditer(data)]
        for a, b in sorted(rng.sample(nums, min(len(nums), rng.randint(1, 3))), reverse=True):
            data = data[:a] + rng.choice(EXTREMES).encode() + data[b:]
        return data
    if how == "random_bytes":
        out = bytearray(data)
        if rng.random() < 0.5:
            for _ in range(rng.randint(1, 8)):
                out[rng.randrange(len(out))] = rng.randrange(256)
        else:
            at = rng.randrange(len(out) + 1)
            out[at:at] = bytes(rng.randrange(256) for _ in range(rng.randint(1, 16)))
        return bytes(out)
    if how == "utf16":
        return data.decode("utf-8").encode("utf-16")  # with a BOM
    if how == "latin1":
        a, _ = rng.choice(words)
        text = (data[:a] + rng.choice(["é", "µ", "ß", "ÿ"]).encode("utf-8") + data[a:]).decode("utf-8")
        return text.encode("latin-1")
    if how == "utf8_bom":
        return b"\xef\xbb\xbf" + data
    if how == "crlf":
        return data.replace(b"\n", b"\r\n")
    if how == "nul":
        out = bytearray(data)
        for _ in range(rng.randint(1, 3)):
            out.insert(rng.randrange(len(out) + 1), 0)
        return bytes(out)
    if how in ("brace_drop", "brace_dup"):
        braces = [i for i, c in enumerate(data) if c in b"{}"]
        i = rng.choice(braces)
        return data[:i] + data[i:i + 1] * (0 if how == "brace_drop" else 2) + data[i + 1:]
    raise ValueError(how)


def mutate_image(data: bytes, name: str, how: str, rng: random.Random) -> bytes:
    if how == "nonfinite":  # a well-formed .exr holding NaN, +-Inf, float32-max and negative texels
        return _nonfinite_exr(rng)
    if how == "truncate":
        return data[: rng.randrange(len(data))]
    if how == "empty":
        return b""
    if how == "random_bytes":
        out = bytearray(data)
        for _ in range(rng.randint(1, 16)):
            out[rng.randrange(len(out))] = rng.randrange(256)
        return bytes(out)
    if how == "header":  # damage the first 64 bytes, where every format keeps its header
        out = bytearray(data)
        for _ in range(rng.randint(1, 4)):
            out[rng.randrange(min(64, len(out)))] = rng.randrange(256)
        return bytes(out)
    if how == "huge_size":  # the header claims an enormous or zero size
        size = rng.choice([0, 1, 2**31 - 1, 2**32 - 1, 65536, 10**6])
        if name.endswith(".hdr"):
            return re.sub(rb"-Y \d+ \+X \d+", b"-Y %d +X %d" % (size, size), data, count=1)
        if name.endswith(".png"):  # IHDR width/height at bytes 16..24, then a fresh CRC
            ihdr = data[12:16] + (size % 2**32).to_bytes(4, "big") * 2 + data[24:29]
            return data[:12] + ihdr + zlib.crc32(ihdr).to_bytes(4, "big") + data[33:]
        # .exr: dataWindow box2i in the header (after the attribute name and type)
        at = data.find(b"dataWindow\0box2i\0")
        if at < 0:
            return data
        at += len(b"dataWindow\0box2i\0") + 4
        box = np.frombuffer(data[at:at + 16], "<i4").copy()
        box[2:] = np.int64(size % 2**31)
        return data[:at] + box.tobytes() + data[at + 16:]
    raise ValueError(how)


def _nonfinite_exr(rng: random.Random) -> bytes:
    import tempfile

    import OpenEXR

    rgb = np.ones((16, 32, 3), np.float32)
    for value in (np.nan, np.inf, -np.inf, np.finfo(np.float32).max, -5.0, 1e-45):
        rgb[rng.randrange(16), rng.randrange(32), rng.randrange(3)] = value
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "x.exr"
        OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                     {"RGB": rgb}).write(str(path))
        return path.read_bytes()


# ---------------------------------------------------------------- contract
_LINE_BREAK = re.compile(rb"\r\n|\r|\n")


def line_count(path: Path) -> int:
    """Lines as an editor numbers them (``\\n``, ``\\r\\n`` or ``\\r`` end a line)."""
    return len(_LINE_BREAK.split(path.read_bytes()))


def check_error(error: BaseException, root: Path, *, image: bool) -> None:
    """Assert ``error`` is a user error located the way drpt promises."""
    assert isinstance(error, DrptError), f"{type(error).__name__}: {error}"
    check_message(str(error), root, image=image)


def check_message(msg: str, root: Path, *, image: bool) -> None:
    """Assert a user error's message is one line naming a file under ``root``
    (and, unless ``image``, a line within it)."""
    assert len(msg.splitlines()) == 1, f"message is not one line: {msg!r}"
    m = re.match(r"(/[^:]*):(?:(\d+):)? \S", msg)
    assert m, f"message does not start with FILE:LINE: or FILE: : {msg!r}"
    where = Path(m.group(1))
    assert where.is_relative_to(root.resolve()) or where.is_relative_to(root), msg
    if image:
        return
    assert m.group(2) is not None, f"no line number in {msg!r}"
    line = int(m.group(2))
    lines = line_count(where) if where.is_file() else 1
    assert 1 <= line <= lines, f"line {line} outside {where.name}'s {lines} lines: {msg!r}"


def assert_finite(obj, where: str = "scene") -> None:
    """Every number in an accepted :class:`~drpt.scene.Scene` (cameras,
    lights, materials, geometry arrays) is finite."""
    if isinstance(obj, np.ndarray):
        if obj.dtype.kind == "f":
            assert np.isfinite(obj).all(), f"{where} has {int((~np.isfinite(obj)).sum())} non-finite values"
    elif isinstance(obj, float):
        assert np.isfinite(obj), f"{where} = {obj}"
    elif isinstance(obj, (list, tuple)):
        for i, x in enumerate(obj):
            assert_finite(x, f"{where}[{i}]")
    elif is_dataclass(obj):
        for f in fields(obj):
            assert_finite(getattr(obj, f.name), f"{where}.{f.name}")


# Hand-written scenes at the ends of float64: each is accepted with finite
# world-space data or rejected at its line. A camera comes first.
EXTREME_SCENES = {
    "triangle_scale_overflow": "Group { numObjects 1 Transform { UniformScale 1e308 UniformScale 1e308"
                               " Triangle { vertex0 0 0 0 vertex1 1 0 0 vertex2 0 1 0 } } }",
    "sphere_scale_overflow": "Group { numObjects 1 Transform { UniformScale 1e308"
                             " Sphere { center 1e308 0 0 radius 1e308 } } }",
    "sphere_nonuniform_overflow": "Group { numObjects 1 Transform { Scale 1e308 1 1e-308"
                                  " Sphere { center 0 0 0 radius 1 } } }",
    "triangle_huge": "Group { numObjects 1 Triangle { vertex0 1e308 0 0 vertex1 -1e308 0 0 vertex2 0 1e308 0 } }",
    "triangle_denormal_scale": "Group { numObjects 1 Transform { UniformScale 1e-320"
                               " Triangle { vertex0 0 0 0 vertex1 1 0 0 vertex2 0 1 0 } } }",
    "scale_zero": "Group { numObjects 1 Transform { UniformScale 0 Sphere { center 0 0 0 radius 1 } } }",
    "plane_zero_normal": "Group { numObjects 1 Plane { normal 0 0 0 offset 1 } }",
    "plane_huge_normal": "Group { numObjects 1 Plane { normal 1e308 1e308 0 offset 1 } }",
    "sphere_radius_negative": "Group { numObjects 1 Sphere { center 0 0 0 radius -1 } }",
    "sphere_radius_huge": "Group { numObjects 1 Sphere { center 0 0 0 radius 1e308 } }",
    "sphere_radius_denormal": "Group { numObjects 1 Sphere { center 0 0 0 radius 1e-320 } }",
    "matrix_singular": "Group { numObjects 1 Transform { Matrix { 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 1 }"
                       " Sphere { center 0 0 0 radius 1 } } }",
    "rotate_huge_angle": "Group { numObjects 1 Transform { XRotate 1e308 Sphere { center 0 0 0 radius 1 } } }",
    "numobjects_huge": "Group { numObjects 123456789012345678901234567890 }",
    "numobjects_2_32": "Group { numObjects 4294967296 }",
    "materialindex_2_32": "Group { numObjects 1 MaterialIndex 4294967296 Sphere { center 0 0 0 radius 1 } }",
    "empty_group": "Group { numObjects 0 }",
    "pointlight_huge": "Lights { numLights 1 PointLight { position 0 0 3 color 1e308 1e308 1e308"
                       " attenuation 1e-320 0 0 } } Group { numObjects 1 Sphere { center 0 0 0 radius 1 } }",
    "camera_huge_center": "Group { numObjects 1 Sphere { center 0 0 0 radius 1 } }",
    "camera_huge_direction": "Group { numObjects 1 Sphere { center 0 0 0 radius 1 } }",
}
# valid scenes that must load (finite numbers that float32 holds after normalization;
# coordinates, radii and colours of 1e308 are refused with their line: float32 makes them inf)
MUST_ACCEPT = {"plane_huge_normal", "rotate_huge_angle", "camera_huge_direction", "empty_group"}
EXTREME_CAMERA = "PerspectiveCamera { center 0 0 5 direction 0 0 -1 up 0 1 0 angle 40 }\n"
EXTREME_CAMERAS = {
    "camera_huge_center": "PerspectiveCamera { center 1e308 -1e308 1e308 direction -1e308 1e308 1e-320"
                          " up 0 1 0 angle 179.999 }\n",
    "camera_huge_direction": "PerspectiveCamera { center 0 0 5 direction 0 0 -1e308 up 0 1e308 0 angle 40 }\n",
}


def extreme_cases() -> list[Case]:
    return [Case("extremes", name) for name in EXTREME_SCENES]


def extreme_scene(name: str, root: Path) -> Path:
    """Write EXTREME_SCENES[name] after its camera into ``root``; return its path."""
    p = root / f"{name}.txt"
    p.write_text(EXTREME_CAMERAS.get(name, EXTREME_CAMERA) + EXTREME_SCENES[name] + "\n")
    return p
