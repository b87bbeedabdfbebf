"""Writes scenes/cornellbox_media/cornellbox_media.txt: the Cornell box with a glass sphere
of scattering liquid on the short block and a layer of fog over the floor.

The fog is a box of invisible boundaries (``passThrough``) just inside the walls, from the
floor up to FOG_TOP (below the sphere, whose outside is vacuum), its triangles wound with
their normals outward (the medium is behind them). Run from the repository root:

    .venv/bin/python scenes/make_cornellbox_media.py
"""

from pathlib import Path

import numpy as np

FOG_LO = (0.02, 0.005, 0.01)
FOG_HI = (5.47, 0.8, 5.57)
FOG_TOP = FOG_HI[1]


def box_triangles(lo, hi):
    """The 12 triangles of an axis-aligned box, each wound with its normal outward."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    c = (lo + hi) / 2
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    out = []
    for axis in range(3):
        for side in (0, 1):
            value = (lo, hi)[side][axis]
            face = [p for p in corners if p[axis] == value]
            a, b = [k for k in range(3) if k != axis]
            # the four corners in order around the face
            face.sort(key=lambda p: np.arctan2(p[b] - c[b], p[a] - c[a]))
            for tri in ((face[0], face[1], face[2]), (face[0], face[2], face[3])):
                n = np.cross(tri[1] - tri[0], tri[2] - tri[0])
                if np.dot(n, tri[0] - c) < 0:
                    tri = (tri[0], tri[2], tri[1])
                out.append(tri)
    return out


OUT = Path(__file__).resolve().parent / "cornellbox_media" / "cornellbox_media.txt"


def main(path=OUT):
    f3 = lambda v: " ".join(f"{x:g}" for x in v)  # noqa: E731
    tris = box_triangles(FOG_LO, FOG_HI)
    lines = [
        "# The Cornell box with a glass sphere of scattering liquid (index 1.33) on the short",
        "# block and a layer of fog over the floor. Written by scenes/make_cornellbox_media.py.",
        "PerspectiveCamera {",
        "    center 2.78 2.73 -8.0",
        "    direction 0 0 1",
        "    up 0 1 0",
        "    angle 39.3",
        "}",
        "",
        "Media {",
        "    numMedia 2",
        "    # 0: the liquid (reddish, forward scattering)",
        "    Medium { sigmaT 1.2 2.0 2.8  albedo 0.98 0.9 0.8  g 0.4 }",
        "    # 1: the fog",
        "    Medium { sigmaT 0.4 0.4 0.4  albedo 0.95 0.95 0.95 }",
        "}",
        "",
        "Materials {",
        "    numMaterials 2",
        "    Material { transparentColor 1 1 1  indexOfRefraction 1.33  interior 0 }",
        "    Material { passThrough  interior 1 }",
        "}",
        "",
        "Group {",
        f"    numObjects {2 + len(tris)}",
        "    TriangleMesh {",
        "        obj_file ../cornellbox/cornellbox.obj",
        "    }",
        "    MaterialIndex 0",
        "    Sphere { center 2.1 2.36 1.7 radius 0.7 }",
        "    MaterialIndex 1",
    ]
    for t in tris:
        lines.append(f"    Triangle {{ vertex0 {f3(t[0])} vertex1 {f3(t[1])} vertex2 {f3(t[2])} }}")
    lines.append("}")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")
    return path


if __name__ == "__main__":
    print(main())
