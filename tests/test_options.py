"""drpt/options.py: the shared render flags, their checks, the accelerator names."""

import argparse

import pytest

from drpt.errors import DrptError
from drpt.options import (
    FLAGS,
    PathOptions,
    RenderOptions,
    add_render_flags,
    options_from_args,
    parse_accel,
    parse_accel_list,
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
    o = options_from_args(_args([]))
    assert (o.width, o.height, o.spp, o.accel, o.bvh_method, o.integrator, o.bsdf) == (
        512, 512, 64, "auto", "auto", "path", "auto")
    assert o.path == PathOptions() and o.max_lanes == 1 << 21 and o.progress


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
