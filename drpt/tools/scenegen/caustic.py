"""Writes caustic: a glass sphere on a diffuse floor under a small spherical light.

The caustic scene of the equal-time benchmarks (``benchmarks/bdpt_equal_time.py``,
``benchmarks/adaptive_vs_uniform.py``): a diffuse grey floor (0.7) and back wall, a
glass sphere (index 1.5, radius 0.6) resting on the floor, and a small spherical area
light (radius 0.05, radiance 400 380 340) above it and to the side, so the sphere
focuses the light into a bright caustic on the floor. A path tracer finds the caustic
only by BSDF sampling from the floor through the sphere onto the tiny light: its
pixels carry most of the image's error, a few paths of huge value among many of none.
The camera at (0, 1.2, 4) looks down at the sphere (40 degrees vertical field of
view). File: ``caustic.txt`` (no meshes).

    python -m drpt.tools.scenegen.caustic OUT_DIR
"""

from __future__ import annotations

from pathlib import Path

from .meshes import folder_cli

SCENE = """\
# caustic (drpt.tools.scenegen.caustic): a glass sphere on a diffuse floor under a small light.
PerspectiveCamera { center 0 1.2 4 direction 0 -0.3 -1 up 0 1 0 angle 40 }
Materials { numMaterials 3
  Material { diffuseColor 0.7 0.7 0.7 }
  Material { transparentColor 1 1 1 indexOfRefraction 1.5 }
  Material { Ke 400 380 340 }
}
Group { numObjects 6
  MaterialIndex 0
  Triangle { vertex0 -3 0 -3 vertex1 3 0 3 vertex2 3 0 -3 }
  Triangle { vertex0 -3 0 -3 vertex1 -3 0 3 vertex2 3 0 3 }
  Triangle { vertex0 -3 0 -2 vertex1 3 0 -2 vertex2 3 3 -2 }
  Triangle { vertex0 -3 0 -2 vertex1 3 3 -2 vertex2 -3 3 -2 }
  MaterialIndex 1
  Sphere { center 0 0.6 0 radius 0.6 }
  MaterialIndex 2
  Sphere { center 0.8 2.4 0.4 radius 0.05 }
}
"""


def main(out: Path) -> list[Path]:
    """Write ``caustic.txt`` into folder ``out`` (created if missing); return its path."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "caustic.txt"
    path.write_text(SCENE)
    return [path]


def cli(argv=None) -> None:
    """``python -m drpt.tools.scenegen.caustic OUT_DIR``."""
    folder_cli(main, __doc__.splitlines()[0], argv)


if __name__ == "__main__":
    cli()
