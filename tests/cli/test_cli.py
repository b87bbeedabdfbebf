"""The command line (drpt/cli/): seed flags, outputs, user errors."""

import subprocess
import sys

import numpy as np
import pytest

from drpt.cli import main
from drpt.imageio import read_image
from support import SCENES

# a module constant, not the cornell fixture: the parametrize tables below name it
CORNELL = str(SCENES / "cornellbox" / "cornellbox.txt")


def run(args):
    return subprocess.run([sys.executable, "-m", "drpt", *args], capture_output=True, text=True,
                          timeout=300)


def test_all_seed_flags_as_written_in_the_report(tmp_path, capsys):
    out = tmp_path / "x.tga"
    code = main(["render", "-input", CORNELL, "-size", "16", "12", "-output", str(out),
                 "-spp", "2", "-MonteCarlo", "-cook_torrance", "-RR_cutdown", "0.6",
                 "-Gamma", "2.2", "-SpatialTree", "-resolution", "5", "-SAH", "2000"])
    assert code == 0
    img = read_image(out, linear=False)
    assert img.shape == (12, 16, 3) and img.max() > 0
    # every seed flag is built: nothing to announce (-gui opens the viewer,
    # tests/view/test_view.py drives it)
    assert "drpt:" not in capsys.readouterr().err


def _spy_options(monkeypatch):
    import drpt.render.renderer as renderer

    seen = []
    real = renderer.Renderer.__init__

    def spy(self, scene, options):
        seen.append(options)
        real(self, scene, options)

    monkeypatch.setattr(renderer.Renderer, "__init__", spy)
    return seen


@pytest.mark.parametrize("args, expect", [
    # the seed's flags as its report writes them: -SpatialTree picks its BVH,
    # whose default is the threshold rule with K = 2000
    (["-input", CORNELL, "-SpatialTree"], ("bvh", "threshold", None, 1)),
    (["-input", CORNELL, "-SpatialTree", "-resolution", "5", "-SAH", "2000"],
     ("bvh", "threshold", 2000, 5)),
    (["-input", CORNELL, "-SpatialTree", "-SAHeuristic", "0"], ("bvh", "threshold", 0, 1)),
    (["-input", CORNELL, "-resolution", "7"], ("grid", None, None, None)),
    # modern flags; drpt's default accelerator is auto (inline for the Cornell
    # box's 32 triangles), and BVH flags ask for the BVH
    ([CORNELL], ("auto", "auto", None, 1)),
    ([CORNELL, "--accel", "inline"], ("inline", "auto", None, 1)),
    ([CORNELL, "--accel", "auto", "--bvh", "sah"], ("bvh", "sah", None, 1)),
    ([CORNELL, "--bvh", "median", "--min-leaf", "3"], ("bvh", "median", None, 3)),
    ([CORNELL, "--sah-threshold", "50"], ("bvh", "threshold", 50, 1)),
    ([CORNELL, "--bvh", "threshold", "-resolution", "2", "--min-leaf", "2"],
     ("bvh", "threshold", None, 2)),
    ([CORNELL, "--bvh", "morton"], ("bvh", "morton", None, 1)),
    ([CORNELL, "--bvh", "ploc"], ("bvh", "ploc", None, 1)),
    ([CORNELL, "--accel", "bvh4", "--bvh", "median", "--min-leaf", "2"],
     ("bvh4", "median", None, 2)),
])
def test_bvh_flags(tmp_path, monkeypatch, capsys, args, expect):
    seen = _spy_options(monkeypatch)
    assert main(["render", *args, "-size", "4", "4", "-spp", "1",
                 "-output", str(tmp_path / "a.png"), "--quiet"]) == 0
    (o,) = seen
    if expect[0] == "grid":
        assert o.accel == "grid" and o.grid_resolution == 7
    else:
        assert (o.accel, o.bvh_method, o.sah_threshold, o.bvh_min_leaf) == expect
    assert "drpt: note" not in capsys.readouterr().err


def test_seed_defaults_are_whitted_and_grid(tmp_path, capsys, monkeypatch):
    import drpt.render.renderer as renderer

    seen = {}
    real = renderer.Renderer.__init__

    def spy(self, scene, options):
        seen["integrator"], seen["bsdf"], seen["accel"] = (options.integrator, options.bsdf,
                                                           options.accel)
        real(self, scene, options)

    monkeypatch.setattr(renderer.Renderer, "__init__", spy)
    assert main(["render", "-input", CORNELL, "-size", "4", "4", "-spp", "1",
                 "-output", str(tmp_path / "a.png"), "--quiet"]) == 0
    assert seen == {"integrator": "whitted", "bsdf": "phong", "accel": "grid"}


@pytest.mark.parametrize("size, spp", [((1, 1), 1), ((7, 3), 1), ((3, 9), 5)])
def test_tiny_and_non_square_images(tmp_path, size, spp):
    out = tmp_path / "img.exr"
    assert main(["render", CORNELL, "--size", *map(str, size), "--spp", str(spp),
                 "--output", str(out), "--quiet"]) == 0
    img = read_image(out)
    assert img.shape == (size[1], size[0], 3)
    assert np.all(np.isfinite(img)) and np.all(img >= 0)


def test_max_lanes_smaller_than_a_row_still_renders_everything(tmp_path):
    # Bounded memory: passes of 3 lanes for a 5x5 image (square: every pixel
    # sees the inside of the box, so a skipped pixel would stay black).
    a = tmp_path / "a.exr"
    assert main(["render", CORNELL, "--size", "5", "5", "--spp", "4", "-o", str(a),
                 "--quiet", "--max-lanes", "3"]) == 0
    assert np.all(read_image(a).sum(2) > 0)


def test_grid_and_bvh_render_the_same_image(tmp_path):
    imgs = []
    for extra in (["--accel", "grid", "-resolution", "7"], ["--accel", "grid"],
                  ["--accel", "bvh4"], []):
        out = tmp_path / f"g{len(imgs)}.exr"
        assert main(["render", CORNELL, "--size", "12", "12", "--spp", "2", "-o", str(out),
                     "--quiet", *extra]) == 0
        imgs.append(read_image(out))
    # Same samples, same hits (ties aside): the images agree closely.
    for img in imgs[:-1]:
        assert np.abs(img - imgs[-1]).max() < 1e-3


def test_passes_of_different_sizes(tmp_path):
    # 4x4 at 3 spp with 32 lanes: a pass of 2 spp (32 lanes), then one of 1
    # spp (16 lanes). Long-lived constants must not keep the first width.
    out = tmp_path / "p.exr"
    assert main(["render", CORNELL, "--size", "4", "4", "--spp", "3", "-o", str(out),
                 "--quiet", "--max-lanes", "32"]) == 0  # raised a size mismatch before
    img = read_image(out)
    assert np.all(np.isfinite(img)) and img.mean() > 0.05


def test_same_seed_same_image(tmp_path):
    a, b = tmp_path / "a.exr", tmp_path / "b.exr"
    for out in (a, b):
        assert main(["render", CORNELL, "--size", "8", "8", "--spp", "4", "--seed", "5",
                     "-o", str(out), "--quiet"]) == 0
    assert np.array_equal(read_image(a), read_image(b))
    c = tmp_path / "c.exr"
    main(["render", CORNELL, "--size", "8", "8", "--spp", "4", "--seed", "6", "-o", str(c), "--quiet"])
    assert not np.array_equal(read_image(a), read_image(c))


def test_one_line_summary(tmp_path):
    r = run(["render", CORNELL, "--size", "8", "8", "--spp", "1", "-o", str(tmp_path / "s.png"), "--quiet"])
    assert r.returncode == 0, r.stderr
    lines = r.stdout.strip().splitlines()
    assert len(lines) == 1 and "Msamples/s" in lines[0] and " s " in lines[0]


@pytest.mark.parametrize("args, needle", [
    (["render", "missing.txt"], "missing.txt"),
    (["render", CORNELL, "--spp", "0"], "spp must be positive"),
    (["render", CORNELL, "--size", "0", "5"], "size must be positive"),
    (["render", CORNELL, "-o", "out.jpg"], "unsupported image type"),
    (["render", CORNELL, "-o", "/nonexistent/dir/x.png"], "does not exist"),
    (["render", CORNELL, "--max-depth", "0"], "--max-depth"),
    (["render", CORNELL, "-RR_cutdown", "1.5"], "Russian roulette"),
    (["render"], "no scene given"),
    (["render", CORNELL, "--bvh", "octree"], "--bvh must be one of"),
    (["render", CORNELL, "--sah-threshold", "-3"], "must be >= 0"),
    (["render", "-input", CORNELL, "-SpatialTree", "-SAHeuristic", "many"], "must be an integer"),
    (["render", CORNELL, "--bvh", "median", "-SAH", "10"], "applies to --bvh threshold"),
    (["render", CORNELL, "--min-leaf", "0"], "--min-leaf"),
    (["render", "-input", CORNELL, "-SpatialTree", "-resolution", "-1"], "-resolution"),
    (["render", "-input", CORNELL, "-resolution", "999"], "between 1 and 256"),
    (["render", CORNELL, "--min-leaf", "2", "-resolution", "3"], "disagree"),
    (["render", CORNELL, "--accel", "grid", "--bvh", "sah"], "apply to the BVH only"),
    (["render", CORNELL, "--bvh", "morton", "--min-leaf", "2"], "not morton"),
    (["render", CORNELL, "--bvh", "ploc", "-resolution", "2"], "not ploc"),
])
def test_user_errors_exit_2_with_one_line(tmp_path, args, needle):
    r = run(args)
    assert r.returncode == 2
    assert needle in r.stderr and "Traceback" not in r.stderr
    assert r.stderr.strip().count("\n") == 0


def test_malformed_scene_names_file_and_line(tmp_path):
    bad = tmp_path / "bad.txt"
    bad.write_text("PerspectiveCamera {\n  center 0 0 1\n  direction 0 0 -1\n  up 0 1 0\n  angle sixty\n}\n")
    out = tmp_path / "never.png"
    r = run(["render", str(bad), "-o", str(out)])
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert f"{bad}:5" in r.stderr
    assert not out.exists()


@pytest.mark.mitsuba
def test_export_writes_loadable_xml(tmp_path):
    mi = pytest.importorskip("mitsuba")
    from drpt.backend import mitsuba_variant
    mi.set_variant(mitsuba_variant())
    xml = tmp_path / "cb.xml"
    assert main(["export", CORNELL, str(xml), "--size", "16", "16", "--spp", "4"]) == 0
    scene = mi.load_file(str(xml))
    img = np.asarray(mi.render(scene))
    assert img.shape == (16, 16, 3) and img.mean() > 0


# ------------------------------------------------------------ shared flags, every tool
@pytest.mark.parametrize("args, needle", [
    (["compare", CORNELL, "--spp", "0"], "--spp must be positive"),
    (["compare", CORNELL, "--accel", "grid", "--min-leaf", "2"], "apply to the BVH only"),
    (["converge", CORNELL, "--max-depth", "0"], "--max-depth"),
    (["converge", CORNELL, "--rr-prob", "2"], "Russian roulette"),
    (["knobs", CORNELL, "--spp", "1"], "at least 2"),
    (["gallery", "--spp", "0"], "--spp must be positive"),
    (["gallery", "--bvh", "ploc", "--min-leaf", "2"], "not ploc"),
    (["bench", CORNELL, "--accel", "bvh-octree"], "unknown accelerator"),
    (["bench", CORNELL, "--size", "0", "4"], "size must be positive"),
    (["profile", CORNELL, "--bvh", "median", "--sah-threshold", "5"],
     "applies to --bvh threshold"),
    (["profile", CORNELL, "--max-lanes", "0"], "--max-lanes"),
    (["render", CORNELL, "--accel", "bvh-sah", "--bvh", "median"], "disagree"),
    (["render", CORNELL, "--backend", "metal"], "backend must be one of llvm, cuda"),
])
def test_tool_flag_errors_exit_2_with_one_line(args, needle):
    r = run(args)
    assert r.returncode == 2, r.stderr
    assert needle in r.stderr and "Traceback" not in r.stderr
    assert r.stderr.strip().count("\n") == 0


def _has_cuda() -> bool:
    import drjit as dr

    return dr.has_backend(dr.JitBackend.CUDA)


@pytest.mark.parametrize("how", ["flag", "env"])
def test_backend_cuda_without_a_gpu_is_one_line(tmp_path, how):
    if _has_cuda():
        pytest.skip("this machine has a CUDA device")
    import os

    out = tmp_path / "never.png"
    args = ["render", CORNELL, "--size", "4", "4", "--spp", "1", "-o", str(out)]
    env = dict(os.environ)
    if how == "flag":
        args.append("--backend")
        args.append("cuda")
    else:
        env["DRPT_BACKEND"] = "cuda"
    r = subprocess.run([sys.executable, "-m", "drpt", *args], capture_output=True, text=True,
                       timeout=300, env=env)
    assert r.returncode == 2
    assert "cuda" in r.stderr.lower() and "Traceback" not in r.stderr
    assert r.stderr.strip().count("\n") == 0
    assert not out.exists()


def test_backend_flag_names_the_loaded_backend_in_process(tmp_path):
    # in this process the kernels are loaded on LLVM: --backend llvm is fine
    assert main(["render", CORNELL, "--size", "4", "4", "--spp", "1", "--backend", "llvm",
                 "-o", str(tmp_path / "a.png"), "--quiet"]) == 0


def test_scene_warnings_print_on_one_line_each(tmp_path, cornell):
    import shutil

    for f in cornell.parent.iterdir():
        shutil.copy(f, tmp_path / f.name)
    obj = tmp_path / "cornellbox.obj"
    obj.write_text(obj.read_text() + "zz 1 2 3\n")
    r = run(["render", str(tmp_path / "cornellbox.txt"), "--size", "4", "4", "--spp", "1",
             "-o", str(tmp_path / "w.png"), "--quiet"])
    assert r.returncode == 0, r.stderr
    lines = r.stderr.splitlines()
    assert lines and all(line.startswith("drpt: warning: ") for line in lines), r.stderr
    assert any(f"{obj}:" in line and "'zz'" in line for line in lines)


def test_warn_and_note_format(capsys):
    from drpt.errors import Loc, SceneWarning, note, warn

    warn("two\nlines", Loc("a.txt", 3))
    warn("no place")
    note("ignored", Loc("b.mtl"))
    warn(SceneWarning(Loc("c.obj", 5), "its own place"))
    warn(SceneWarning(None, "built in code"))
    assert capsys.readouterr().err.splitlines() == [
        "drpt: warning: a.txt:3: two lines", "drpt: warning: no place",
        "drpt: note: b.mtl: ignored", "drpt: warning: c.obj:5: its own place",
        "drpt: warning: built in code"]


@pytest.mark.parametrize("args, needle", [
    (["render", CORNELL, "--accel", "bvh-foo"], "invalid choice: 'bvh-foo'"),
    (["render", CORNELL, "--spp", "abc"], "invalid int value: 'abc'"),
    (["nosuch"], "invalid choice: 'nosuch'"),
    ([], "required: command"),
    (["bench", "--repeat"], "expected one argument"),
])
def test_flag_parsing_errors_are_one_line(capsys, args, needle):
    # argparse's own error prints the whole usage; drpt's is one line, status 2
    with pytest.raises(SystemExit) as e:
        main(args)
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("drpt: error: ") and needle in err[0], err
    assert not err[0].startswith("drpt: error: drpt"), err  # no doubled prefix


# ------------------------------------------------------------ --hide-emitters
@pytest.mark.parametrize("command", ["render", "view", "export", "profile", "compare", "converge"])
def test_hide_emitters_flag_on_every_rendering_command(command):
    """``--hide-emitters on|off`` sets :attr:`~drpt.options.PathOptions.hide_emitters` and
    counts as given (a scene file's own ``hide_emitters`` does not replace it); without it
    the default is off and not given. Negative control: another value is refused."""
    from drpt.cli import build_parser
    from drpt.cli.args import given_settings, options_from_args

    extra = {"export": ["out.xml"]}.get(command, [])
    mode = {"profile": {"mode": "megakernel"}}.get(command, {})
    parse = build_parser().parse_args
    for value, want in (("on", True), ("off", False)):
        a = parse([command, CORNELL, *extra, "--hide-emitters", value])
        assert options_from_args(a, **mode).path.hide_emitters is want
        assert "hide_emitters" in given_settings(a)
    a = parse([command, CORNELL, *extra])
    assert options_from_args(a, **mode).path.hide_emitters is False and "hide_emitters" not in given_settings(a)
    with pytest.raises(SystemExit):
        parse([command, CORNELL, *extra, "--hide-emitters", "yes"])


def test_hide_emitters_flag_overrides_the_scene_file_and_is_exported(tmp_path):
    """A Mitsuba XML with ``hide_emitters`` true: without the flag the file's setting holds,
    ``--hide-emitters off`` replaces it; ``drpt export`` writes the setting into the XML's
    integrator, which reads back as written."""
    from drpt.options import RenderOptions, with_scene_settings
    from drpt.scene import load_scene
    from support.xml import XML

    scene = load_scene(XML / "hide_emitters.xml")
    assert with_scene_settings(RenderOptions(), scene)[0].path.hide_emitters is True
    assert with_scene_settings(RenderOptions(), scene, {"hide_emitters"})[0].path.hide_emitters is False
    for value in ("on", "off"):
        out = tmp_path / f"{value}.xml"
        assert main(["export", CORNELL, str(out), "--size", "8", "8", "--hide-emitters", value]) == 0
        assert load_scene(out).settings.hide_emitters is (value == "on")


@pytest.mark.parametrize("args, needle", [
    (["profile", "{folder}"], "scene file is a directory"),
    (["bench", "{folder}", "--size", "8", "8"], "scene file is a directory"),
    (["profile", "{folder}/missing.txt"], "scene file not found"),
    (["export", CORNELL, "{folder}/x.png"], "written as an .xml file"),
    (["export", CORNELL, "{folder}"], "is a folder"),
])
def test_tools_given_a_folder_or_a_wrong_output_say_so_in_one_line(tmp_path, capsys, args, needle):
    """A folder where a scene file goes, an image name where export's .xml goes: one line
    naming what is wrong, status 2 (profile and bench said "not found" of a folder, and
    export wrote its XML under the image's name)."""
    rc = main([a.format(folder=tmp_path) for a in args])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and err[0].startswith("drpt: error: ") and needle in err[0], err
    assert not (tmp_path / "x.png").exists()
