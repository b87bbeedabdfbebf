"""drpt/options.py (the options, their checks, the accelerator names, the scene's
settings) and drpt/cli/args.py (the shared render flags that build them)."""

import argparse

import pytest

from drpt.backend import policy
from drpt.cli.args import FLAGS, add_render_flags, given_settings, options_from_args
from drpt.errors import DrptError
from drpt.options import (
    PathOptions,
    RenderOptions,
    parse_accel,
    parse_accel_list,
    resolve_sampler,
    with_scene_settings,
)


def _args(argv, **kw):
    p = argparse.ArgumentParser()
    add_render_flags(p, **kw)
    return p.parse_args(argv)


def test_parse_accel():
    assert parse_accel("bvh") == ("bvh", None)
    assert parse_accel("bvh-sah") == ("bvh", "sah")
    assert parse_accel("bvh2-ploc") == ("bvh2", "ploc")
    for bad in ("kd", "grid-sah", "bvh-octree", "bvh-", ""):
        with pytest.raises(DrptError, match="unknown accelerator"):
            parse_accel(bad)
    assert parse_accel_list("auto, bvh-median,grid") == ["auto", "bvh-median", "grid"]
    with pytest.raises(DrptError, match="at least one"):
        parse_accel_list(" , ")


def test_defaults_match_render_options():
    # one set of defaults: no flags give RenderOptions() itself
    o = options_from_args(_args([]))
    assert o == RenderOptions()
    assert (o.width, o.height, o.spp, o.accel, o.bvh_method, o.integrator, o.bsdf) == (
        512, 512, 64, "auto", "auto", "path", "auto")
    assert o.path == PathOptions() and o.max_lanes is None and o.progress
    # every flag's parser default is the dataclass's (a command's own defaults aside)
    p = argparse.ArgumentParser()
    add_render_flags(p)
    base = RenderOptions()
    for a in p._actions:
        if hasattr(base, a.dest) and a.default is not None:
            assert a.default == getattr(base, a.dest), a.dest
    # the negative control: a command's own default is not the dataclass's
    assert options_from_args(_args([], spp=3)) != RenderOptions()


def test_lanes_are_resolved_in_one_place():
    assert RenderOptions().lanes == policy().max_lanes == 1 << 21
    assert RenderOptions(max_lanes=70).lanes == 70
    assert options_from_args(_args(["--max-lanes", "70"])).lanes == 70


def test_accel_names_and_flags_agree():
    o = options_from_args(_args(["--accel", "bvh-threshold", "--sah-threshold", "7"]))
    assert (o.accel, o.bvh_method, o.sah_threshold) == ("bvh", "threshold", 7)
    o = options_from_args(_args(["--accel", "grid", "--resolution", "9"]))
    assert (o.accel, o.grid_resolution) == ("grid", 9)
    with pytest.raises(DrptError, match="disagree"):
        options_from_args(_args(["--accel", "bvh-sah", "--bvh", "ploc"]))


def test_omitted_flags_take_the_dataclass_defaults():
    args = _args([], omit=("spp", "accel", "max_depth"), size=(8, 6))
    assert not hasattr(args, "spp") and not hasattr(args, "accel")
    o = options_from_args(args, spp=3)
    assert (o.width, o.height, o.spp, o.accel, o.path.max_depth) == (8, 6, 3, "auto", -1)
    with pytest.raises(ValueError):
        add_render_flags(argparse.ArgumentParser(), omit=("nosuch",))
    assert set(FLAGS) >= {"size", "spp", "accel", "backend", "quiet"}


@pytest.mark.parametrize("opts, needle", [
    (RenderOptions(spp=0), "--spp must be positive"),
    (RenderOptions(width=0), "size must be positive"),
    (RenderOptions(max_lanes=0), "--max-lanes"),
    (RenderOptions(path=PathOptions(max_depth=0)), "--max-depth"),
    (RenderOptions(path=PathOptions(rr_prob=0.0)), "Russian roulette"),
    (RenderOptions(path=PathOptions(rr_threshold=-0.1)), "--rr-threshold"),
    (RenderOptions(path=PathOptions(rr_threshold=1.5)), "--rr-threshold"),
    (RenderOptions(path=PathOptions(rr_threshold=float("nan"))), "--rr-threshold"),
    (RenderOptions(accel="kd"), "--accel must be one of"),
    (RenderOptions(accel="bvh", bvh_method="octree"), "--bvh must be one of"),
    (RenderOptions(bsdf="lambert"), "--bsdf"),
    (RenderOptions(integrator="mlt"), "--integrator"),
    (RenderOptions(env_sampling="cosine"), "--env-sampling"),
    (RenderOptions(accel="grid", grid_resolution=999), "between 1 and 256"),
    (RenderOptions(accel="bvh", bvh_method="sah", sah_threshold=5), "applies to --bvh threshold"),
    (RenderOptions(accel="bvh", bvh_method="threshold", sah_threshold=-1), "must be >= 0"),
    (RenderOptions(accel="bvh", bvh_min_leaf=0), "must be >= 1"),
    (RenderOptions(accel="bvh", bvh_method="morton", bvh_min_leaf=2), "not morton"),
])
def test_validate(opts, needle):
    with pytest.raises(DrptError, match=needle.replace("(", r"\(")):
        opts.validate()


def test_validate_returns_the_options():
    o = RenderOptions(accel="bvh", bvh_method="threshold", sah_threshold=0, bvh_min_leaf=4)
    assert o.validate() is o


class _Settings:
    """A Mitsuba XML's render settings (drpt.scene.model.RenderSettings), as far as
    with_scene_settings reads them."""

    def __init__(self, **kw):
        self.width, self.height, self.spp = 32, 24, 8
        self.integrator = self.max_depth = self.rr_depth = self.hide_emitters = None
        self.rfilter, self.rfilter_params = "box", {}
        self.fov = (40.0, "x")
        self.__dict__.update(kw)


def _xml_scene(**settings):
    from pathlib import Path

    from drpt.scene.model import PerspectiveCamera, Scene

    camera = PerspectiveCamera(center=(0, 0, 0), direction=(0, 0, -1), up=(0, 1, 0), fov=30.0)
    return Scene(path=Path("s.xml"), camera=camera, materials=[], settings=_Settings(**settings))


def test_scene_settings_apply_where_not_given():
    scene = _xml_scene(max_depth=3)
    opts, out = with_scene_settings(RenderOptions(), scene)
    assert (opts.width, opts.height, opts.spp, opts.path.max_depth) == (32, 24, 8, 3)
    assert out is scene  # the film's own aspect: the camera stays
    opts, _ = with_scene_settings(RenderOptions(spp=5, path=PathOptions(max_depth=2)), scene,
                                  {"spp", "max_depth"})
    assert (opts.spp, opts.path.max_depth) == (5, 2)
    with pytest.raises(ValueError, match="unknown settings"):
        with_scene_settings(RenderOptions(), scene, {"width"})
    plain = _xml_scene()
    plain.settings = None  # the seed's format: nothing to apply
    assert with_scene_settings(RenderOptions(), plain) == (RenderOptions(), plain)


def test_scene_settings_return_a_new_camera_and_change_nothing():
    """Another aspect than the file's film keeps the fov along fov_axis (x here): the
    camera comes back new, the scene passed in keeps its own."""
    from drpt.scene.model import vertical_fov

    scene = _xml_scene()
    before = scene.camera
    opts, out = with_scene_settings(RenderOptions(width=64, height=64), scene, {"size"})
    assert (opts.width, opts.height) == (64, 64)
    assert scene.camera is before and scene.camera.fov == 30.0  # unchanged
    assert out is not scene and out.camera is not before
    assert out.camera.fov == pytest.approx(vertical_fov(40.0, "x", 1.0))
    assert out.camera.fov != pytest.approx(vertical_fov(40.0, "x", 32 / 24))  # the film's aspect: not it
    assert out.materials is scene.materials  # a shallow copy: the rest is shared


@pytest.mark.parametrize("integrator, mode, adaptive, expected", [
    ("path", "megakernel", False, "ldsampler"),
    ("path", "wavefront", False, "ldsampler"),
    ("volpath", "megakernel", False, "ldsampler"),
    ("volpath", "wavefront", False, "ldsampler"),
    ("whitted", "megakernel", False, "ldsampler"),
    ("ptracer", "megakernel", False, "independent"),
    ("bdpt", "megakernel", False, "ldsampler"),
    ("path", "megakernel", True, "independent"),  # --adaptive draws independent samples
    ("volpath", "megakernel", True, "independent"),
])
def test_auto_sampler_resolves_by_integrator(integrator, mode, adaptive, expected):
    assert RenderOptions().sampler == "auto"
    opts = RenderOptions(integrator=integrator, mode=mode, adaptive=adaptive).validate()
    out = resolve_sampler(opts)
    assert out.sampler == expected
    assert resolve_sampler(out) == out  # resolving again changes nothing
    assert opts.sampler == "auto"  # a new object: the argument is unchanged
    # a checkpoint's sampler wins over the rule (a resumed render draws what it drew)
    other = "independent" if expected == "ldsampler" else "ldsampler"
    assert resolve_sampler(opts, recorded=other).sampler == other


@pytest.mark.parametrize("name", ["independent", "ldsampler", "zsobol", "stratified"])
def test_named_samplers_are_kept(name):
    for integrator in ("path", "ptracer"):
        opts = RenderOptions(integrator=integrator, sampler=name)
        assert resolve_sampler(opts) is opts
        assert resolve_sampler(opts, recorded="ldsampler") is opts


def test_scene_files_sampler_wins_over_auto():
    """A Mitsuba XML's ``<sampler>`` is the render's unless ``--sampler`` names another;
    ``--sampler auto`` on the command line means the file's too."""
    scene = _xml_scene(sampler="independent")
    opts, _ = with_scene_settings(RenderOptions(), scene)
    assert resolve_sampler(opts).sampler == "independent"
    for argv, expected in ((["--sampler", "auto"], "independent"), ([], "independent"),
                           (["--sampler", "zsobol"], "zsobol")):
        args = _args(argv)
        opts, _ = with_scene_settings(options_from_args(args), scene, given_settings(args))
        assert resolve_sampler(opts).sampler == expected, argv
    # a file that names none: auto is the rule's
    opts, _ = with_scene_settings(RenderOptions(), _xml_scene())
    assert resolve_sampler(opts).sampler == "ldsampler"
