"""Whole-render properties with analytic answers: the white furnace, light
selection that does not get noisier with the emitter's triangle count, and
the seed's scene files in Whitted mode."""

import numpy as np
import pytest

from drpt.cli import main
from drpt.imageio import read_image, write_image
from drpt.options import PathOptions, RenderOptions
from drpt.render.renderer import Renderer
from drpt.scene import load_scene


def test_white_furnace(tmp_path):
    # A white (Kd 1) diffuse sphere under a constant white sky: every pixel,
    # on the sphere or not, has radiance exactly 1 in expectation.
    write_image(tmp_path / "white.exr", np.ones((4, 8, 3), np.float32))
    (tmp_path / "s.txt").write_text("""
PerspectiveCamera { center 0 0 4  direction 0 0 -1  up 0 1 0  angle 30 }
Lights { numLights 1  Skybox { white.exr } }
Materials { numMaterials 1  Material { diffuseColor 1 1 1 } }
Group { numObjects 2  MaterialIndex 0  Sphere { center 0 0 0 radius 1 }
        Sphere { center 0.6 0.6 1.2 radius 0.2 } }
""")
    r = Renderer(load_scene(tmp_path / "s.txt"),
                 RenderOptions(width=32, height=32, spp=64, progress=False)).render()
    img = r.image
    assert abs(img.mean() - 1.0) < 0.01
    # per pixel within 5 standard errors (pixels on the background have none)
    z = np.abs(img - 1.0) / np.sqrt(r.variance + 1e-12)
    assert np.all((z < 5) | (np.abs(img - 1.0) < 1e-5))


def light_scene(tmp_path, n):
    """A floor lit by a 1x1 square light split into 2 n^2 triangles."""
    v, f = [], []
    g = np.linspace(-0.5, 0.5, n + 1)
    for i in range(n):
        for j in range(n):
            k = len(v)
            v += [(g[i], 2, g[j]), (g[i + 1], 2, g[j]), (g[i + 1], 2, g[j + 1]), (g[i], 2, g[j + 1])]
            f.append(f"f {k + 1} {k + 2} {k + 3} {k + 4}")  # normal -y: emits down
    lines = ["mtllib l.mtl", "usemtl floor", "v -3 0 -3", "v -3 0 3", "v 3 0 3", "v 3 0 -3",
             "f 1 2 3 4", "usemtl light"]
    lines += [f"v {x} {y} {z}" for x, y, z in v]
    lines += [" ".join(["f"] + [str(int(t) + 4) for t in line.split()[1:]]) for line in f]
    d = tmp_path / f"n{n}"
    d.mkdir()
    (d / "l.obj").write_text("\n".join(lines) + "\n")
    (d / "l.mtl").write_text("newmtl floor\nKd 0.5 0.5 0.5\nnewmtl light\nKd 0 0 0\nKe 5 5 5\n")
    (d / "s.txt").write_text("PerspectiveCamera { center 0 1 4  direction 0 -0.3 -1  up 0 1 0 "
                             "angle 40 }\nGroup { numObjects 1  TriangleMesh { obj_file l.obj } }\n")
    return load_scene(d / "s.txt")


@pytest.mark.slow
def test_many_emissive_triangles_are_not_noisier(tmp_path):
    opts = RenderOptions(width=32, height=24, spp=32, progress=False, path=PathOptions(max_depth=2))
    few = Renderer(light_scene(tmp_path, 1), opts).render()
    many = Renderer(light_scene(tmp_path, 16), opts).render()  # 512 triangles
    floor = few.image.mean(2) < 2.0  # exclude pixels that see the light itself
    assert abs(many.image[floor].mean() / few.image[floor].mean() - 1) < 0.02
    ratio = many.variance[floor].mean() / few.variance[floor].mean()
    assert 0.8 < ratio < 1.25, ratio


@pytest.mark.slow
@pytest.mark.parametrize("name", ["cornellbox.txt", "newscene.txt"])
def test_seed_scenes_render_in_whitted_mode(seed_dir, tmp_path, name, capsys):
    out = tmp_path / "w.png"
    assert main(["render", "-input", str(seed_dir / "scenes" / name), "-size", "24", "24",
                 "-spp", "2", "-output", str(out), "--quiet"]) == 0
    assert read_image(out).mean() > 0.01
