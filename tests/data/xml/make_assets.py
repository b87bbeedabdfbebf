"""Writes the mesh, texture and sky files of the XML test corpus (run once; the outputs are committed).

    python tests/data/xml/make_assets.py

* ``quad.obj``: two triangles in the z = 0 plane, counter-clockwise seen from +z, with uvs;
* ``wedge.ply``: an ASCII PLY, a tetrahedron-like wedge with per-vertex normals;
* ``shapes.serialized``: a version 4 Mitsuba serialized file with two meshes (index 0: a
  triangle, index 1: a unit quad in z = 0 facing +z), single precision, zlib-compressed;
* ``checker.png``: an 8x8 sRGB texture, 2x2 tiles of red and white;
* ``sky.exr``: a 16x8 lat-long map, bright toward +x (u = 1/4), dim elsewhere;
* ``uvsphere.obj``: a unit sphere of 24 x 12 quads (as triangles) with normals and
  lat-long uvs (``u`` around z, a seam at ``u = 0``);
* ``bumps.png``: a 16x16 8-bit gray height map (bumps), for ``bumpmap`` (read ``raw``);
* ``normals.png``: a 16x16 8-bit tangent-space normal map (tilts of up to ~35 degrees
  in four directions), for ``normalmap`` (read ``raw``).
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def write_obj(path: Path) -> None:
    path.write_text("# a unit quad facing +z\n"
                    "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\n"
                    "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
                    "f 1/1 2/2 3/3\nf 1/1 3/3 4/4\n")


def write_ply(path: Path) -> None:
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    faces = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]
    c = v.mean(0)
    n = v - c
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    lines = ["ply", "format ascii 1.0", f"element vertex {len(v)}", "property float x",
             "property float y", "property float z", "property float nx", "property float ny",
             "property float nz", f"element face {len(faces)}", "property list uchar int vertex_indices",
             "end_header"]
    lines += [" ".join(f"{x:g}" for x in (*p, *q)) for p, q in zip(v, n)]
    lines += [f"3 {a} {b} {c_}" for a, b, c_ in faces]
    path.write_text("\n".join(lines) + "\n")


def _serialized_mesh(name: str, p: np.ndarray, f: np.ndarray) -> bytes:
    """One version 4 mesh: header, then a zlib stream of flags, name, counts, data."""
    flags = 0x1000  # single precision, positions only
    body = struct.pack("<I", flags) + name.encode() + b"\0"
    body += struct.pack("<QQ", len(p), len(f))
    body += np.asarray(p, "<f4").tobytes() + np.asarray(f, "<u4").tobytes()
    return struct.pack("<HH", 0x041C, 4) + zlib.compress(body)


def write_serialized(path: Path) -> None:
    meshes = [
        ("tri", np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]]), np.array([[0, 1, 2]])),
        ("quad", np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]]),
         np.array([[0, 1, 2], [0, 2, 3]])),
    ]
    out = b""
    offsets = []
    for name, p, f in meshes:
        offsets.append(len(out))
        out += _serialized_mesh(name, p, f)
    out += b"".join(struct.pack("<Q", o) for o in offsets) + struct.pack("<I", len(meshes))
    path.write_bytes(out)


def write_uvsphere(path: Path, slices: int = 24, stacks: int = 12) -> None:
    lines = ["# a unit uv sphere"]
    for i in range(stacks + 1):
        th = np.pi * i / stacks
        for j in range(slices + 1):
            ph = 2 * np.pi * j / slices
            x, y, z = np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)
            lines += [f"v {x:.6f} {y:.6f} {z:.6f}", f"vn {x:.6f} {y:.6f} {z:.6f}",
                      f"vt {j / slices:.6f} {1 - i / stacks:.6f}"]
    for i in range(stacks):
        for j in range(slices):
            a, b = i * (slices + 1) + j + 1, (i + 1) * (slices + 1) + j + 1
            quad = [a, b, b + 1, a + 1]
            for tri in ((0, 1, 2), (0, 2, 3)):
                lines.append("f " + " ".join(f"{quad[k]}/{quad[k]}/{quad[k]}" for k in tri))
    path.write_text("\n".join(lines) + "\n")


def main() -> None:
    from drpt.imageio import write_image

    write_obj(HERE / "quad.obj")
    write_ply(HERE / "wedge.ply")
    write_serialized(HERE / "shapes.serialized")
    tile = (np.arange(8)[:, None] // 4 + np.arange(8)[None] // 4) % 2
    img = np.where(tile[..., None] == 0, np.array([0.8, 0.1, 0.1]), np.array([0.9, 0.9, 0.9]))
    write_image(HERE / "checker.png", img.astype(np.float32))
    H, W = 8, 16
    v = (np.arange(H)[:, None] + 0.5) / H
    u = (np.arange(W)[None, :] + 0.5) / W
    d = np.stack([np.sin(2 * np.pi * u) * np.sin(np.pi * v), np.cos(np.pi * v) + 0 * u,
                  -np.cos(2 * np.pi * u) * np.sin(np.pi * v)], -1)
    bright = np.clip(d[..., 0], 0, None) ** 4
    sky = 0.2 + 4.0 * bright[..., None] * np.array([1.0, 0.9, 0.7])
    write_image(HERE / "sky.exr", sky.astype(np.float32))
    write_uvsphere(HERE / "uvsphere.obj")
    x = (np.arange(16) + 0.5) / 16
    height = 0.5 + 0.45 * np.sin(2 * np.pi * 2 * x)[None, :] * np.cos(2 * np.pi * 2 * x)[:, None]
    write_image(HERE / "bumps.png", np.repeat(height[..., None], 3, 2).astype(np.float32), gamma=1.0)
    tx = 0.6 * np.sign(np.sin(2 * np.pi * 2 * x))[None, :] + 0 * x[:, None]
    ty = 0.4 * np.sign(np.cos(2 * np.pi * 2 * x))[:, None] + 0 * x[None, :]
    n = np.stack([tx, ty, np.ones_like(tx)], -1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    write_image(HERE / "normals.png", (0.5 * n + 0.5).astype(np.float32), gamma=1.0)


if __name__ == "__main__":
    main()
