"""Rays that leak through a closed mesh with and without Embree's robust mode (not a test).

Rays start at 8 random points inside ``tests/data/xml/uvsphere.obj`` (a closed unit uv sphere,
576 triangles) and aim at its vertices and at 39 points along each triangle edge, where a
non-watertight triangle test lets rays slip between neighbours. Every ray must hit the
sphere; the script counts the misses with ``RTC_SCENE_FLAG_ROBUST`` (drpt's setting for its
own format) and without it (Mitsuba's default, and drpt's for an XML file that does not set
``embree_use_robust_intersections``).

Run: PYTHONPATH=. .venv/bin/python benchmarks/embree_robust_leak.py
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import drjit as dr
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OBJ = ROOT / "tests" / "data" / "xml" / "uvsphere.obj"
XML = """<scene version="3.0.0">
  <sensor type="perspective"><float name="fov" value="40"/>
    <transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film></sensor>
  <shape type="obj"><string name="filename" value="{obj}"/><bsdf type="diffuse"/></shape>
</scene>"""


def targets() -> np.ndarray:
    """The mesh's vertices and 39 points along each triangle edge."""
    verts, faces = [], []
    for line in OBJ.read_text().splitlines():
        p = line.split()
        if p and p[0] == "v":
            verts.append([float(x) for x in p[1:4]])
        elif p and p[0] == "f":
            faces.append([int(x.split("/")[0]) - 1 for x in p[1:]])
    v = np.array(verts)
    t = np.linspace(0.0, 1.0, 41)[1:-1, None]
    edges = [(1 - t) * v[a] + t * v[b] for f in faces for a, b in zip(f, f[1:] + f[:1])]
    return np.concatenate([v, *edges])


def main() -> None:
    from drjit.auto import Array3f, Bool, Float

    from drpt.backend import ensure
    from drpt.options import RenderOptions
    from drpt.render.scene import DeviceScene
    from drpt.scene import load_scene

    ensure()
    pts = targets()
    origins = np.random.default_rng(1).uniform(-0.3, 0.3, (8, 3))
    with tempfile.TemporaryDirectory() as tmp:
        xml = Path(tmp) / "sphere.xml"
        xml.write_text(XML.format(obj=OBJ))
        for robust in (True, False):
            model = load_scene(xml)
            model.settings.embree_robust = robust  # (the file's embree_use_robust_intersections)
            scene = DeviceScene(model, RenderOptions(accel="embree", progress=False))
            assert scene.accel.robust is robust
            misses = total = 0
            for o in origins:
                d = pts - o
                d /= np.linalg.norm(d, axis=1, keepdims=True)
                n = len(d)
                si = scene.intersect(Array3f(*[Float(np.full(n, o[i], np.float32)) for i in range(3)]),
                                     Array3f(*[Float(d[:, i].astype(np.float32)) for i in range(3)]),
                                     dr.full(Bool, True, n))
                misses += int(dr.sum(dr.select(si.valid, 0, 1))[0])
                total += n
            print(f"robust {'on ' if robust else 'off'}: {misses} of {total} rays miss")


if __name__ == "__main__":
    main()
