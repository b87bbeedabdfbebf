"""Numerics at the extremes and hostile input: scenes without primitives, flag
limits, radiance near the float32 maximum, lazy pass planning."""

import dataclasses
import tracemalloc

import numpy as np
import pytest

from drpt.cli import main
from drpt.errors import DrptError
from drpt.imageio import read_image, write_image
from drpt.options import RenderOptions

CAMERA = "PerspectiveCamera { center 0 0 0 direction 0 0 -1 up 0 1 0 angle 30 }\n"
EMPTY_WARNING = "the scene has no primitives"

pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")  # no numpy RuntimeWarning on these paths


def _render(path, monkeypatch=None, min_lanes=None, **fields):
    from drpt import backend
    from drpt.render import renderer
    from drpt.scene import load_scene

    if min_lanes is not None:
        policy = dataclasses.replace(backend.policy(), min_lanes=min_lanes)
        monkeypatch.setattr(renderer, "policy", lambda: policy)
    r = renderer.Renderer(load_scene(path), RenderOptions(progress=False, **fields))
    return r, r.render()


# ------------------------------------------------------------------ scenes without primitives
@pytest.mark.parametrize("integrator", ["path", "whitted"])
@pytest.mark.parametrize("accel", ["auto", "inline", "bvh", "bvh2", "grid", "brute"])
def test_empty_group_renders_its_background(tmp_path, accel, integrator):
    (tmp_path / "s.txt").write_text(CAMERA + "Background { color 0.25 0.5 2 }\n"
                                    "Group { numObjects 0 }\n")
    r, res = _render(tmp_path / "s.txt", width=5, height=3, spp=3, accel=accel,
                     integrator=integrator)
    assert [w for w in r.warnings if EMPTY_WARNING in w] == r.warnings and len(r.warnings) == 1
    assert np.array_equal(res.image, np.broadcast_to(np.float32([0.25, 0.5, 2.0]), (3, 5, 3)))
    assert res.nonfinite == 0 and np.all(res.variance == 0.0)


@pytest.mark.parametrize("obj", ["", "v 0 0 0\nv 1 0 0\nv 0 1 0\n"], ids=["empty", "vertices"])
def test_obj_without_faces_renders_the_sky_with_one_warning(tmp_path, capsys, obj):
    write_image(tmp_path / "sky.exr", np.full((4, 8, 3), 0.5, np.float32))
    (tmp_path / "m.obj").write_text(obj)
    (tmp_path / "s.txt").write_text(CAMERA + "Lights { numLights 1 Skybox { sky.exr } }\n"
                                    "Group { numObjects 1 TriangleMesh { obj_file m.obj } }\n")
    out = tmp_path / "o.exr"
    assert main(["render", str(tmp_path / "s.txt"), "--size", "4", "3", "--spp", "2", "-q",
                 "-o", str(out)]) == 0
    err = capsys.readouterr().err
    assert err.count(EMPTY_WARNING) == 1
    img = read_image(out)
    assert img.shape == (3, 4, 3) and np.allclose(img, 0.5)


def test_export_of_an_empty_scene_has_no_shapes_and_warns_once(tmp_path, capsys):
    (tmp_path / "s.txt").write_text(CAMERA + "Background { color 0.1 0.2 0.3 }\n"
                                    "Group { numObjects 0 }\n")
    xml = tmp_path / "x.xml"
    assert main(["export", str(tmp_path / "s.txt"), str(xml), "--size", "4", "4"]) == 0
    assert capsys.readouterr().err.count(EMPTY_WARNING) == 1
    text = xml.read_text()
    assert "<shape" not in text and 'type="constant"' in text


@pytest.mark.slow
@pytest.mark.mitsuba
def test_compare_of_an_empty_scene(tmp_path, capsys):
    pytest.importorskip("mitsuba")
    (tmp_path / "s.txt").write_text(CAMERA + "Background { color 0.1 0.2 0.3 }\n"
                                    "Group { numObjects 0 }\n")
    assert main(["compare", str(tmp_path / "s.txt"), "--size", "4", "4", "--spp", "2",
                 "--ref-spp", "8", "--no-cache", "-q", "--out", str(tmp_path / "cmp")]) == 0
    assert capsys.readouterr().err.count(EMPTY_WARNING) == 1
    assert np.allclose(read_image(tmp_path / "cmp" / "drpt.exr"),
                       read_image(tmp_path / "cmp" / "reference.exr"))


# ------------------------------------------------------------------ flag limits
@pytest.mark.parametrize("flags, needle", [
    (["--min-leaf", "9"], "at most 8 with the 4-wide BVH"),
    (["--accel", "bvh", "-resolution", "20"], "at most 8"),
    (["--rr-depth", "-1"], "--rr-depth"),
    (["--rr-depth", str(2 ** 32)], "--rr-depth"),
    (["--max-depth", str(2 ** 32)], "--max-depth"),
    (["--spp", str(2 ** 32)], "--spp must be at most"),
    (["--size", str(2 ** 16 + 1), "4"], "at most 65536 pixels per side"),
    (["--size", "65536", "65536", "--spp", "300000000"], "width * height * spp"),
    (["--max-lanes", str(2 ** 32)], "--max-lanes"),
    (["--seed", "-1"], "--seed"),
    (["--seed", str(2 ** 64)], "--seed"),
    (["--gamma", "inf"], "--gamma"),
    (["--gamma", "nan"], "--gamma"),
    (["--output", ""], "--output is empty"),
])
def test_render_flag_limits(tmp_path, capsys, flags, needle, cornell):
    args = ["render", str(cornell), "--size", "4", "4", "--spp", "1", "-q", "-o", str(tmp_path / "x.png")]
    assert main(args + flags) == 2
    err = capsys.readouterr().err
    assert needle in err and err.count("\n") == 1 and err.startswith("drpt: error:")
    assert not (tmp_path / "x.png").exists()


def test_flag_limits_allow_their_bounds():
    RenderOptions(seed=2 ** 64 - 1, bvh_min_leaf=8, accel="bvh",
                  path=dataclasses.replace(RenderOptions().path, rr_depth=0)).validate()
    RenderOptions(accel="bvh2", bvh_min_leaf=100).validate()
    RenderOptions(width=2 ** 16, height=1, spp=2 ** 32 - 1, max_lanes=2 ** 32 - 1).validate()


@pytest.mark.parametrize("flags, needle", [
    (["--max-depth", "0"], "--max-depth"), (["--max-depth", "-5"], "--max-depth"),
    (["--spp", "0"], "--spp"), (["--spp", str(2 ** 32)], "--spp"),
    (["--size", "0", "4"], "size must be positive"),
])
def test_export_validates_as_render(tmp_path, capsys, flags, needle, cornell):
    xml = tmp_path / "x.xml"
    assert main(["export", str(cornell), str(xml), *flags]) == 2
    err = capsys.readouterr().err
    assert needle in err and err.count("\n") == 1
    assert not xml.exists()


# ------------------------------------------------------------------ float32 extremes
@pytest.mark.parametrize("min_lanes", [1, None], ids=["lane-sums", "block-sums"])
@pytest.mark.parametrize("integrator", ["path", "whitted"])
def test_radiance_near_float32_max_averages_without_overflow(tmp_path, monkeypatch, min_lanes,
                                                             integrator):
    """64 samples of 1e37 (and of 3e38) sum beyond float32 in a lane (one
    lane per pixel) or across a pixel's lanes: the mean is still exact."""
    (tmp_path / "s.txt").write_text(CAMERA + "Background { color 1e37 2e37 3e38 }\n"
                                    "Group { numObjects 1 Sphere { center 0 0 50 radius 1 } }\n")
    _, res = _render(tmp_path / "s.txt", monkeypatch, min_lanes=min_lanes, width=4, height=3,
                     spp=64, integrator=integrator)
    assert np.array_equal(res.image, np.broadcast_to(np.float32([1e37, 2e37, 3e38]), (3, 4, 3)))
    assert np.all(np.isfinite(res.variance)) and res.nonfinite == 0


@pytest.mark.parametrize("color, wide", [("0.5 0.5 0.5", [False]), ("1e37 1 1", [False, True])])
def test_float64_sums_only_for_passes_whose_float32_sums_overflowed(tmp_path, monkeypatch,
                                                                      color, wide):
    from drpt.render import renderer

    seen = []
    real = renderer.Renderer._trace_pass

    def spy(self, *args, wide):
        seen.append(wide)
        return real(self, *args, wide=wide)

    monkeypatch.setattr(renderer.Renderer, "_trace_pass", spy)
    (tmp_path / "s.txt").write_text(CAMERA + f"Background {{ color {color} }}\n"
                                    "Group { numObjects 1 Sphere { center 0 0 50 radius 1 } }\n")
    _, res = _render(tmp_path / "s.txt", width=3, height=2, spp=4)
    assert seen == wide and np.all(np.isfinite(res.image))


def test_a_pixel_mean_beyond_float32_is_an_error(tmp_path, monkeypatch):
    from drpt.render import renderer

    (tmp_path / "s.txt").write_text(CAMERA + "Group { numObjects 0 }\n")

    def huge(self, pass_index):
        _s0, k, r0, rows = self.plan.at(pass_index)
        s = np.full((rows, self.opt.width, 3), 1e39 * k)
        return renderer.PassSums(r0, s, s * 1e39, 0)

    monkeypatch.setattr(renderer.Renderer, "render_pass", huge)
    with pytest.raises(DrptError, match="beyond the float32 maximum"):
        _render(tmp_path / "s.txt", width=2, height=2, spp=2)


def test_sky_texel_near_float32_max_keeps_its_sampling_weight():
    from drjit.auto import Array2f, Float

    from drpt.render.lights.envmap import LUMINANCE, EnvironmentLight

    img = np.ones((9, 16, 3), np.float32)
    img[4, 5] = img[4, 6] = 3e38  # two neighbours: their sums overflow float32
    env = EnvironmentLight(img)
    assert not env.is_black
    rng = np.random.default_rng(3)
    n = 4096
    u = Array2f(Float(rng.random(n, dtype=np.float32)), Float(rng.random(n, dtype=np.float32)))
    d, le, pdf = env.sample(u)
    le, pdf = np.asarray(le, np.float64), pdf.numpy()
    assert np.all(np.isfinite(np.asarray(d))) and np.all(np.isfinite(le)) and np.all(np.isfinite(pdf))
    assert np.all(pdf > 0.0) and np.all(le.max(axis=0) > 1.0)  # all in the hot cells
    # the density follows the luminance: luminance / pdf is nearly constant
    w = (LUMINANCE @ le) / pdf
    assert w.std() < 0.05 * w.mean()


# ------------------------------------------------------------------ pass planning
def _passes_as_listed(width, height, spp, max_lanes):
    """The pass layout as a list (the order renders are seeded in)."""
    pixels = width * height
    if pixels <= max_lanes:
        k, rows = max(1, min(spp, max_lanes // pixels)), height
    else:
        k, rows = 1, max(1, max_lanes // width)
    return [(s0, min(k, spp - s0), r0, min(rows, height - r0))
            for s0 in range(0, spp, k) for r0 in range(0, height, rows)]


@pytest.mark.parametrize("w,h,spp,budget", [(1, 1, 1, 16), (7, 5, 33, 64), (100, 37, 3, 250),
                                            (3, 1, 5, 1), (64, 64, 256, 1 << 21)])
def test_lazy_plan_has_the_listed_layout(w, h, spp, budget):
    from drpt.render.renderer import plan_passes

    plan = plan_passes(w, h, spp, budget)
    listed = _passes_as_listed(w, h, spp, budget)
    assert len(plan) == len(listed) and list(plan) == listed
    assert [plan[i] for i in range(len(plan))] == listed
    with pytest.raises(IndexError):
        plan[len(plan)]


def test_planning_ten_million_spp_at_4096_squared_is_lazy():
    from drpt.render.renderer import plan_passes

    tracemalloc.start()
    plan = plan_passes(4096, 4096, 10 ** 7, 1 << 21)
    first = next(iter(plan))
    last = plan[plan.count - 1]
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert first == (0, 1, 0, 512) and last == (10 ** 7 - 1, 1, 3584, 512)
    assert plan.count == 8 * 10 ** 7
    assert peak < 100_000  # 8e7 passes: a list of them would take gigabytes
