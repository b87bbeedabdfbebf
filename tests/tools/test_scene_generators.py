"""The procedural scene generators (drpt.tools.scenegen.diningroom and .showcase):
they write loadable scenes with the promised content, the dining room's
tessellation follows ``--triangles`` (and reaches 500k by default, counted in
memory without writing it), and every scene renders finite, non-black pixels
at a tiny size with Cook-Torrance."""

from __future__ import annotations

import numpy as np
import pytest

from drpt.imageio import read_image
from drpt.materials.interpret import interpret
from drpt.options import RenderOptions
from drpt.render.renderer import Renderer
from drpt.scene import load_scene


@pytest.fixture(scope="module")
def diningroom():
    from drpt.tools.scenegen import diningroom

    return diningroom


@pytest.fixture(scope="module")
def showcase():
    from drpt.tools.scenegen import showcase

    return showcase


def _tiny_render(scene) -> np.ndarray:
    opts = RenderOptions(width=16, height=12, spp=2, bsdf="cook-torrance", progress=False)
    img = Renderer(scene, opts).render().image
    assert img.shape == (12, 16, 3)
    assert np.isfinite(img).all()
    assert img.mean() > 1e-3
    return img


def _materials(scene) -> dict:
    used = set(np.unique(scene.triangles.material).tolist())
    return {m.name: m for i, m in enumerate(scene.materials) if i in used}


def test_diningroom_triangle_counts_scale(diningroom):
    counts = [diningroom.triangle_count(n) for n in (20_000, 80_000)]
    for n, c in zip((20_000, 80_000), counts):
        assert n <= c <= 1.1 * n
    assert diningroom.DEFAULT_TRIANGLES >= 500_000
    assert diningroom.triangle_count() >= 500_000  # built in memory, not written


@pytest.mark.slow
def test_diningroom_scene(diningroom, tmp_path):
    n = diningroom.main(tmp_path, triangles=20_000)
    assert 20_000 <= n <= 22_000
    scene = load_scene(tmp_path / "diningroom.txt")
    assert len(scene.triangles) == n
    mats = _materials(scene)
    glass = [m for m in mats.values() if m.dissolve < 1]
    assert {m.name for m in glass} >= {"table_glass", "wine_glass"}
    assert all(m.ior == 1.5 and interpret(m, "cook-torrance").kind == "dielectric" for m in glass)
    for mode, kind in (("cook-torrance", "cook_torrance"), ("phong", "phong")):
        assert interpret(mats["vase_brass"], mode).leaves()[0].kind == kind
    assert mats["vase_brass"].metalness == 1 and mats["brushed_steel"].metalness == 1
    lights = [m for m in mats.values() if m.is_emissive]
    assert [m.name for m in lights] == ["ceiling_light"]
    for m in mats.values():  # both --bsdf phong and cook-torrance have their parameters
        assert m.roughness is not None and m.metalness is not None, m.name
    # the lights face down (one-sided emitters): geometric normals point to -y
    tri = scene.triangles
    li = tri.positions[tri.material == scene.materials.index(lights[0])]
    nrm = np.cross(li[:, 1] - li[:, 0], li[:, 2] - li[:, 0])
    assert (nrm[:, 1] < 0).all() and np.allclose(nrm[:, [0, 2]], 0)
    # the floor is textured, with uvs, and the texture loads
    floor = mats["floor_wood"]
    assert floor.map_kd is not None and floor.map_kd.is_file()
    tex = read_image(floor.map_kd)
    assert tex.shape[2] == 3 and tex.std() > 0.01
    assert tri.uvs is not None
    _tiny_render(scene)


@pytest.mark.slow
def test_showcase_scenes(showcase, tmp_path):
    n = showcase.main(tmp_path)
    assert (tmp_path / "showcase.obj").stat().st_size < 2_200_000
    for which in ("day", "dusk"):
        scene = load_scene(tmp_path / f"showcase_{which}.txt")
        assert len(scene.triangles) == n
        assert len(scene.lights) == 1 and scene.lights[0].path.name == f"sky_{which}.exr"
        sky = read_image(scene.lights[0].path)
        assert sky.shape == (256, 512, 3) and np.isfinite(sky).all() and sky.min() >= 0
        lum = sky @ [0.2126, 0.7152, 0.0722]
        upper = lum[: sky.shape[0] // 2]
        assert 1e4 <= lum.max() / np.median(upper) <= 1e5  # a small, very bright sun
        # the sun sits where make_sky puts it (texel of its direction is the brightest)
        d = showcase.sun_direction(which)
        u = np.arctan2(d[0], -d[2]) / (2 * np.pi) % 1.0
        v = np.arccos(d[1]) / np.pi
        r, c = np.unravel_index(np.argmax(lum), lum.shape)
        assert abs(r - v * 256) <= 2 and min(abs(c - u * 512), 512 - abs(c - u * 512)) <= 2
        mats = _materials(scene)
        assert interpret(mats["car_glass"], "cook-torrance").kind == "dielectric"
        assert interpret(mats["chrome"], "cook-torrance").leaves()[0]["metalness"] == 1
        assert not any(m.is_emissive for m in mats.values())
        for name in ("grille", "plate"):
            assert read_image(mats[name].map_kd).std() > 0.01
        _tiny_render(scene)


# ------------------------------------------- mixed-material test scenes (test_materials_mitsuba)
def _auto_leaves(scene) -> dict:
    """material name -> (kind of the outer node, its first leaf), auto mode, used materials only."""
    used = set(np.unique(scene.triangles.material).tolist())
    out = {}
    for i, m in enumerate(scene.materials):
        if i in used:
            spec = interpret(m, "auto")
            out[m.name] = (spec.kind, spec.leaves()[0])
    return out


def _edges_paired(positions) -> bool:
    """Every edge of the triangles ``positions`` (F, 3, 3) is used exactly twice, once in
    each direction: a closed, consistently wound (watertight) surface."""
    keys = {}
    for tri in np.round(positions, 6):
        for a, b in ((0, 1), (1, 2), (2, 0)):
            e = (tuple(tri[a]), tuple(tri[b]))
            keys[e] = keys.get(e, 0) + 1
    return all(n == 1 and keys.get((b, a)) == 1 for (a, b), n in keys.items())


def test_materials_cornell_scene(tmp_path):
    import warnings

    from drpt.tools.scenegen import materials_cornell

    files = materials_cornell.main(tmp_path)
    assert sum(f.stat().st_size for f in files) < 150_000
    mtl = (tmp_path / "materials_cornell.mtl").read_text()
    for key in ("Ns", "Ka", "Kd", "Ks", "Ke", "Ni", "d", "illum", "Pr", "Pm", "Tf"):
        assert f"\n{key} " in mtl, key
    for name, sphere_kind in (("materials_cornell", "principled"), ("materials_cornell_conductor", "roughconductor")):
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # every statement written is one drpt reads
            scene = load_scene(tmp_path / f"{name}.txt")
        kinds = _auto_leaves(scene)
        for wall in ("white", "red", "green", "light"):
            assert kinds[wall][0] == "twosided" and kinds[wall][1].kind == "diffuse"
        assert kinds["light"][1]["kd"] == (0.0, 0.0, 0.0)
        glass, water = kinds["frosted_glass"][1], kinds["water"][1]
        assert kinds["frosted_glass"][0] == "roughdielectric" and glass["distribution"] == "ggx"
        assert glass["alpha"] == pytest.approx(0.09) and glass["int_ior"] == 1.5
        assert glass["specular_transmittance"] == (0.7, 0.85, 1.0)
        assert kinds["water"][0] == "dielectric" and water["int_ior"] == 1.33
        plastic = kinds["blue_plastic"][1]
        assert plastic.kind == "principled" and plastic["metallic"] == 0 and plastic["roughness"] == 0.3
        sphere = kinds["gold_conductor" if sphere_kind == "roughconductor" else "gold"][1]
        assert sphere.kind == sphere_kind
        if sphere_kind == "principled":
            assert sphere["metallic"] == 1 and sphere["roughness"] == 0.4
        else:
            assert sphere["alpha"] == pytest.approx(0.04) and sphere["distribution"] == "ggx"
        # the dielectrics and the sphere are closed and wound outward; the light faces down
        tri = scene.triangles
        names = [m.name for m in scene.materials]
        for mat in ("frosted_glass", "water", "gold_conductor" if sphere_kind == "roughconductor" else "gold"):
            closed = tri.positions[tri.material == names.index(mat)]
            assert _edges_paired(closed), mat
            flipped = closed.copy()
            flipped[0] = closed[0, ::-1]  # one face wound inward
            assert not _edges_paired(closed[1:]) and not _edges_paired(flipped)
        li = tri.positions[tri.material == names.index("light")]
        assert (np.cross(li[:, 1] - li[:, 0], li[:, 2] - li[:, 0])[:, 1] < 0).all()
        # nothing intersects the floor: the dielectrics float 0.01 above it
        for mat in ("frosted_glass", "water"):
            assert tri.positions[tri.material == names.index(mat)][..., 1].min() == pytest.approx(0.01)


def test_veach_mis_scene(tmp_path):
    from drpt.tools.scenegen import veach_mis

    files = veach_mis.main(tmp_path)
    assert sum(f.stat().st_size for f in files) < 80_000
    scene = load_scene(tmp_path / "veach_mis.txt")
    kinds = _auto_leaves(scene)
    alphas = [kinds[f"plate{k}"][1]["alpha"] for k in range(4)]
    assert all(kinds[f"plate{k}"][1].kind == "roughconductor" for k in range(4))
    assert np.allclose(alphas, [0.005, 0.02, 0.05, 0.1], rtol=1e-4)
    assert kinds["base"][1].kind == "diffuse"
    lights = [m for m in scene.materials if m.is_emissive]
    radiance = [m.emission[0] for m in lights]
    assert radiance == sorted(radiance, reverse=True) and 890 < radiance[0] < 910 and 1.2 < radiance[-1] < 1.25
    # equal power: radiance * r^2 the same for each sphere (r from the triangles' extent)
    tri = scene.triangles
    names = [m.name for m in scene.materials]
    radii = [np.ptp(tri.positions[tri.material == names.index(m.name)][..., 1]) / 2 for m in lights]
    power = np.array(radiance) * np.array(radii) ** 2
    assert np.allclose(power, power[0], rtol=1e-3)
    # each plate mirrors the camera's ray through its center onto the middle of the light row
    cam = np.asarray(scene.camera.center)
    middle = np.array([0.0, veach_mis.LIGHT_Y, veach_mis.LIGHT_Z])
    for k in range(4):
        p = tri.positions[tri.material == names.index(f"plate{k}")]
        c = p.reshape(-1, 3).mean(0)
        n = np.cross(p[0, 1] - p[0, 0], p[0, 2] - p[0, 0])
        n /= np.linalg.norm(n)
        d = (c - cam) / np.linalg.norm(c - cam)
        r = d - 2 * np.dot(d, n) * n
        to_mid = (middle - c) / np.linalg.norm(middle - c)
        assert np.dot(r, to_mid) > 0.9999


def test_caustic_scene(tmp_path):
    """A glass sphere on a diffuse floor, lit only by a small emissive sphere: the scene
    of the equal-time benchmarks' caustic, and it renders finite, lit pixels."""
    from drpt.tools.scenegen import caustic

    (path,) = caustic.main(tmp_path)
    scene = load_scene(path)
    kinds = [interpret(m, "auto").kind for m in scene.materials]
    glass, light = scene.spheres.material
    assert kinds[glass] == "dielectric" and scene.materials[light].is_emissive
    assert [m.is_emissive for m in scene.materials].count(True) == 1
    assert np.allclose(scene.spheres.radius, [0.6, 0.05])
    img = Renderer(scene, RenderOptions(width=16, height=16, spp=16, progress=False)).render().image
    assert np.isfinite(img).all() and img.mean() > 0
