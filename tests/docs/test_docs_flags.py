"""The docs' flag tables and synopses say what ``--help`` says.

Checked against the argparse parsers themselves (not a copy): every flag that
docs/cli.md's ``render`` table and README's flag table name exists, its
``A|B|C`` choices are the parser's, and its default column starts with the
parser's default (for a flag whose parser default is ``None``, with the value
:func:`drpt.options.options_from_args` gives); every ``[--flag A|B]`` of a
synopsis in docs/cli.md and docs/tools.md lists the choices of that command's
flag, and every flag of a synopsis exists; every ``render`` flag is in
cli.md's table; ``--help`` names every output type that ``render`` writes.
"""

from __future__ import annotations

import argparse
import re

import pytest

from support import REPO

ROOT = REPO


@pytest.fixture(scope="module")
def parsers():
    from drpt.cli import build_parser

    top = build_parser()
    sub = next(a for a in top._actions if isinstance(a, argparse._SubParsersAction))
    return top, dict(sub.choices)


def _action(parser, flag):
    for a in parser._actions:
        if flag in a.option_strings:
            return a
    return None


def _effective_default(top, action):
    """What a flag left out gives: the parser's default, or for ``None`` the option's."""
    if action.default is not None:
        d = action.default
        if isinstance(d, float):
            return f"{d:g}"
        return " ".join(map(str, d)) if isinstance(d, (tuple, list)) else str(d)
    from drpt.cli.args import options_from_args

    opts = options_from_args(top.parse_args(["render", "scene.txt"]))
    return {"bsdf": opts.bsdf, "accel": opts.accel, "integrator": opts.integrator,
            "bvh_method": opts.bvh_method}.get(action.dest)


def _table_rows(text):
    """``(flag, choices or None, default cell)`` of every row of a table whose last
    column is "default" and whose first cell starts with a ``--flag``."""
    rows = []
    header = None
    for line in text.splitlines():
        if not line.startswith("|"):
            header = None
            continue
        if header is None:
            header = [c.strip() for c in line.strip("|").split("|")]
            continue
        if header[-1] != "default":
            continue
        m = re.match(r"\|\s*`(--[a-z-]+)([^`]*)`[^|]*\|.*\|\s*(.*?)\s*\|\s*$", line)
        if m:
            arg = m.group(2).strip().replace("\\|", "|")
            choices = arg.split("|") if "|" in arg and " " not in arg else None
            rows.append((m.group(1), choices, m.group(3)))
    return rows


def _choices(action):
    """The flag's choices, or those its metavar spells (``--bvh``: ``auto|sah|...``)."""
    if action.choices is not None:
        return list(action.choices)
    if isinstance(action.metavar, str) and "|" in action.metavar:
        return action.metavar.split("|")
    return None


@pytest.mark.parametrize("doc", ["docs/cli.md", "README.md"])
def test_render_flag_tables_match_the_parser(parsers, doc):
    top, subs = parsers
    render = subs["render"]
    rows = _table_rows((ROOT / doc).read_text())
    assert len(rows) > 8, doc
    for flag, choices, default in rows:
        action = _action(render, flag)
        assert action is not None, f"{doc}: {flag} is not a render flag"
        if choices is not None:
            assert set(choices) == set(_choices(action)), f"{doc}: {flag} lists {choices}"
        want = _effective_default(top, action)
        if want is None or isinstance(action, argparse._StoreTrueAction) or action.default is False:
            continue
        cell = default.replace("`", "")
        assert cell.startswith(want), f"{doc}: {flag} default {default!r}, the parser's is {want!r}"


def test_every_render_flag_is_in_the_cli_table(parsers):
    _, subs = parsers
    text = (ROOT / "docs/cli.md").read_text()
    table = text[text.index("## render"):text.index("## view")]
    for a in subs["render"]._actions:
        longs = [o for o in a.option_strings if o.startswith("--") and o != "--help"]
        if longs:
            assert any(f"`{o}" in table for o in longs), f"docs/cli.md's render table lacks {longs}"


SYNOPSIS = re.compile(r"python -m drpt (\w+) (.*?)```", re.S)


@pytest.mark.parametrize("doc", ["docs/cli.md", "docs/tools.md"])
def test_synopses_match_the_parsers(parsers, doc):
    _, subs = parsers
    seen = 0
    for block in re.findall(r"```sh\n(.*?)```", (ROOT / doc).read_text(), re.S):
        lines = block.strip().splitlines()
        # a synopsis block: the first line names the command; continuation lines belong to it
        command = None
        for line in lines:
            m = re.match(r"python -m drpt (\w+)", line)
            if m:
                command = m.group(1)
            if command not in subs:
                continue
            parser = subs[command]
            for flag, arg in re.findall(r"\[(--[a-z-]+)(?: ([^\]\s]+))?", line):
                action = _action(parser, flag)
                assert action is not None, f"{doc}: `{command}` has no {flag}"
                if arg and "|" in arg and action.choices is not None and "[" not in arg:
                    assert set(arg.split("|")) == set(_choices(action)), \
                        f"{doc}: `{command} {flag}` lists {arg}, --help {_choices(action)}"
                seen += 1
    assert seen > 10


def test_render_help_names_every_output_type(parsers):
    from drpt.imageio import WRITE_EXTENSIONS

    _, subs = parsers
    text = _action(subs["render"], "--output").help
    for ext in WRITE_EXTENSIONS:
        assert ext in text, ext


def test_every_command_that_renders_defaults_to_auto_materials(parsers):
    """``profile`` profiled Phong while ``render`` rendered ``auto``."""
    from drpt.cli.args import options_from_args

    top, subs = parsers
    argv = {"export": ["scene.txt", "out.xml"], "bench": ["--accel", "auto"], "compare": ["scene.txt"]}
    checked = []
    for name, p in subs.items():
        if _action(p, "--bsdf") is not None:
            ns = top.parse_args([name, *argv.get(name, ["scene.txt"])])
            extra = {"mode": "megakernel"} if name == "profile" else {}  # profile's --mode both
            assert options_from_args(ns, **extra).bsdf == "auto", name
            checked.append(name)
    assert {"render", "profile", "knobs", "compare", "export"} <= set(checked)


def test_rr_prob_help_and_docs_give_the_code_s_rule(parsers):
    _, subs = parsers
    rule = "min(max(throughput) * eta^2, 0.95)"
    assert rule in _action(subs["render"], "--rr-prob").help
    assert rule in (ROOT / "docs/cli.md").read_text()


@pytest.mark.slow
def test_wavefront_is_the_megakernel_s_image_exactly_as_far_as_the_docs_say():
    """README, cli.md and architecture.md say: the same image (up to float rounding)
    while spp <= ceil(min_lanes / pixels), with the independent sampler another one beyond
    (path regeneration: a stream per lane)."""
    import math

    import numpy as np

    from drpt.backend import policy
    from drpt.options import RenderOptions
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene

    n = policy().min_lanes
    for doc in ("README.md", "docs/cli.md", "docs/architecture.md"):
        assert f"{n:,}" in (ROOT / doc).read_text(), doc
    scene = load_scene(ROOT / "scenes/cornellbox/cornellbox.txt")
    w = h = 16
    edge = math.ceil(n / (w * h))

    def image(spp, mode):
        return Renderer(scene, RenderOptions(width=w, height=h, spp=spp, mode=mode, progress=False,
                                             sampler="independent")).render().image

    a, b = image(edge, "megakernel"), image(edge, "wavefront")
    np.testing.assert_allclose(b, a, rtol=1e-5, atol=1e-7)
    a, b = image(edge + 1, "megakernel"), image(edge + 1, "wavefront")
    assert not np.allclose(b, a, rtol=1e-3, atol=1e-5)


# flags of other programs the docs quote (dask worker's, git's, benchmarks/ scripts'), and
# cli.md's example of a mistyped one
OTHER_PROGRAMS = {"--nworkers", "--nthreads", "--short", "--tris", "--chunks", "--sizee", "--sp",
                  "--threshold", "--oracle",  # (benchmarks/adaptive_vs_uniform.py)
                  "--only", "--skip", "--min-size", "--max-samples", "--rounds", "--max-rounds", "--max-error",
                  "--no-corpus", "--mitsuba-sampler",  # (benchmarks/equal_time_vs_mitsuba.py)
                  "--scale", "--grid", "--blocks",  # (benchmarks/variance_vs_mitsuba.py)
                  "--all-textures",  # (benchmarks/kernel_ops.py)
                  "--variants", "--first",  # (benchmarks/bdpt_ld_share.py)
                  "--runs",  # (benchmarks/small_tables_ab.py)
                  "--shares", "--sweep", "--split",  # (benchmarks/light_selection_errors.py)
                  "--integrators",  # (benchmarks/far_light_paths.py)
                  "--seconds", "--renderer",  # (benchmarks/jit_hotspots.py)
                  "--agree",  # (benchmarks/env_compensation.py)
                  "--sort",  # (perf report, quoted in performance.md)
                  "--npz",  # (benchmarks/estimator_variants.py)
                  "--values",  # (benchmarks/flag_ab.py)
                  "--mitsuba", "--dump",  # (benchmarks/render_loop.py)
                  "--scenes", "--scene", "--seeds", "--repeat", "--reference", "--parts", "--depth",
                  "--path-sampler", "--bdpt-sampler",  # (bdpt_*.py)
                  "--spawned-hits", "--spawned-camera", "--no-visibility",  # (benchmarks/far_light_paths.py)
                  "--opacity", "--filter-type", "--raw"}  # (benchmarks/mask_opacity_vs_mitsuba.py)


def test_every_flag_the_docs_name_exists(parsers):
    _, subs = parsers
    known = {o for p in subs.values() for a in p._actions for o in a.option_strings}
    for doc in [*sorted((ROOT / "docs").glob("*.md")), ROOT / "README.md"]:
        for flag in set(re.findall(r"(?<![\w-])(--[a-z][a-z0-9-]*)", doc.read_text())):
            assert flag in known | OTHER_PROGRAMS, f"{doc.name} names {flag}, which no command has"
