"""``drpt profile``: megakernel and wavefront, kernel history, stages, occupancy, verdict, chart and JSON;
light tracing (ptracer, bdpt): query counts by kind against counts that follow from a scene's geometry."""

from __future__ import annotations

import argparse
import json

import pytest

from drpt.errors import DrptError
from drpt.tools import profile


def _parse(argv):
    parser = argparse.ArgumentParser(prog="drpt")
    profile.add_parser(parser.add_subparsers(dest="command", required=True))
    return parser.parse_args(["profile", *argv])


@pytest.fixture(scope="module")
def run(tmp_path_factory, cornell):
    out = tmp_path_factory.mktemp("profile") / "cb.png"
    # the BVH: its traversal loops are what the stage checks below look at
    args = _parse([str(cornell), "--size", "16", "16", "--spp", "2", "--accel", "bvh",
                   "--out", str(out)])
    assert args.func is profile.main
    rc = args.func(args)
    return rc, out, json.loads(out.with_suffix(".json").read_text())


def test_defaults():
    args = _parse(["x.txt"])
    assert tuple(args.size) == (128, 128) and args.spp == 16 and args.out is None
    assert args.integrator == "path" and args.max_depth == -1 and args.accel == "auto"
    assert args.mode == "both"


@pytest.mark.slow
def test_writes_chart_and_json(run):
    rc, out, data = run
    assert rc == 0
    assert out.is_file() and out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert set(data["modes"]) == {"megakernel", "wavefront"}
    assert data["options"]["width"] == 16 and data["options"]["spp"] == 2


@pytest.mark.slow
def test_both_modes_launch_kernels(run):
    _, _, data = run
    mk, wf = data["modes"]["megakernel"], data["modes"]["wavefront"]
    for m in (mk, wf):
        assert m["jit_kernels"] > 0 and m["launches"] >= m["jit_kernels"]
        assert m["seconds"] > 0 and m["kernel_ms"] > 0 and m["samples_per_second"] > 0
        assert m["samples"] == 16 * 16 * 2
        assert m["warmup_seconds"] > 0
        # the watermark covers at least the 16x16 RGB float32 film the render accumulates
        assert m["peak_bytes"] >= 16 * 16 * 3 * 4
        assert len(m["kernels"]) == m["launches"]
        # every launch carries its time from Dr.Jit's kernel history, a JIT kernel's above 0 (a
        # single launch may read 0.0: nanothread's task_time returns 0 where a task's start or
        # end stamp is missing or out of order; seen once in a full run of the tests)
        times = [k["execution_ms"] for k in m["kernels"]]
        assert all(t >= 0.0 for t in times)
        assert max(k["execution_ms"] for k in m["kernels"] if k["type"] == "JIT") > 0.0
    # Between its kernels the wavefront keeps each path's state in memory (at least ray
    # origin, direction, throughput and radiance: 12 floats); the megakernel in registers.
    assert wf["peak_bytes"] >= 16 * 16 * 2 * 12 * 4 and wf["peak_bytes"] > mk["peak_bytes"]
    # A kernel per stage and bounce: many more launches than the fused kernel.
    assert wf["launches"] > mk["launches"] and wf["jit_kernels"] > mk["jit_kernels"]
    assert wf["unsorted_seconds"] > 0 and wf["unsorted_stages"]


@pytest.mark.slow
def test_megakernel_stages_partition_the_history(run):
    _, _, data = run
    mk = data["modes"]["megakernel"]
    st = mk["stages"]
    assert sum(s["launches"] for s in st) == mk["launches"]
    assert sum(s["kernel_ms"] for s in st) == pytest.approx(mk["kernel_ms"], rel=1e-9)
    fused = [s for s in st if s["name"] == profile.FUSED]
    assert fused and fused[0]["jit_kernels"] >= 1 and fused[0]["kernel_ms"] > 0


@pytest.mark.slow
def test_wavefront_stages_are_consistent(run):
    _, _, data = run
    wf = data["modes"]["wavefront"]
    st = {s["name"]: s for s in wf["stages"]}
    for name in ("compact + sort", "closest hit", "interaction", "emission", "shade", "shadow rays"):
        assert name in st, name
        assert st[name]["launches"] > 0 and st[name]["kernel_ms"] > 0
    # The instrumented render launches exactly the timed render's kernels (it only
    # synchronises between them), and each is attributed to one stage.
    assert sum(s["launches"] for s in st.values()) == wf["launches"]
    assert sum(s["wall_ms"] for s in st.values()) == pytest.approx(wf["staged_seconds"] * 1e3, rel=1e-6)
    occ = wf["occupancy"]
    lanes = 16 * 16 * 2
    assert occ["live_per_bounce"][0] == lanes  # every camera ray, then the survivors
    assert all(b <= a for a, b in zip(occ["live_per_bounce"], occ["live_per_bounce"][1:]))
    # one closest-hit ray per live path and bounce; shadow rays traced as their own stage
    assert st["closest hit"]["rays"] == occ["closest_hit_rays"] == occ["lane_bounces"] >= lanes
    assert st["shadow rays"]["rays"] == occ["shadow_rays"] > 0
    assert 0 < occ["live_fraction"] <= 1


@pytest.mark.slow
def test_megakernel_occupancy_and_rays(run):
    _, _, data = run
    mk, wf = data["modes"]["megakernel"], data["modes"]["wavefront"]
    occ = mk["occupancy"]
    assert occ["simd_width_assumed"] in (4, 8, 16)
    assert 0 < occ["occupancy"] <= 1
    assert occ["lane_iterations"] <= occ["executed_lane_iterations"]
    # same estimator, other random streams: about the wavefront's ray counts
    assert occ["closest_hit_rays"] == pytest.approx(wf["occupancy"]["closest_hit_rays"], rel=0.25)
    assert occ["shadow_rays"] == pytest.approx(wf["occupancy"]["shadow_rays"], rel=0.25)
    fused = next(s for s in mk["stages"] if s["name"] == profile.FUSED)
    assert fused["rays"] == occ["closest_hit_rays"] + occ["shadow_rays"]


@pytest.mark.slow
def test_verdict_names_the_winner_with_numbers(run):
    _, _, data = run
    text = "\n".join(data["verdict"])
    assert ("megakernel wins" in text) != ("wavefront wins" in text)
    for word in ("kernel time", "occupancy", "launches", "peak", "coherence sort", "why:"):
        assert word in text, word


@pytest.mark.slow
def test_inline_accelerator_profile(tmp_path, cornell):
    """The Cornell box's default (inline) accelerator, one mode only."""
    out = tmp_path / "cb.png"
    assert profile.main(_parse([str(cornell), "--size", "8", "8", "--spp", "1", "--mode", "wavefront",
                                "--out", str(out)])) == 0
    data = json.loads(out.with_suffix(".json").read_text())
    assert set(data["modes"]) == {"wavefront"}
    st = {s["name"]: s for s in data["modes"]["wavefront"]["stages"]}
    assert st["closest hit"]["rays"] >= 64 and st["shadow rays"]["rays"] > 0


@pytest.mark.slow
def test_table_mentions_both_modes(run):
    _, _, data = run
    # format_table works on the in-memory results; rebuild one from the JSON-side numbers.
    r = profile.ModeResult("wavefront", 0.1, 1.0, 0.2, 512, 1024, [],
                           [profile.Stage("x", kernel_ms=1.0, wall_ms=2.0, launches=3, rays=512)],
                           staged_seconds=0.25)
    text = profile.format_table(r)
    assert "wavefront" in text and "Mrays/s" in text and "total" in text


def test_missing_scene_is_an_error(tmp_path):
    args = _parse([str(tmp_path / "nope.txt"), "--size", "8", "8", "--spp", "1",
                   "--out", str(tmp_path / "p.png")])
    with pytest.raises(DrptError):
        profile.main(args)


def test_bad_options_are_errors(tmp_path, cornell):
    with pytest.raises(DrptError):
        profile.main(_parse([str(cornell), "--spp", "0"]))
    with pytest.raises(DrptError):
        profile.main(_parse([str(cornell), "--out", str(tmp_path / "p.jpg")]))
    with pytest.raises(DrptError, match="integrator"):
        profile.main(_parse([str(cornell), "--integrator", "whitted", "--out", str(tmp_path / "p.png")]))


# --------------------------------------------------------------------------- light tracing
#
# A scene whose query counts at --max-depth 2 follow from its geometry alone: a diffuse
# infinite plane z = -1 seen straight down by the camera (every camera ray hits it), and an
# emissive triangle at z = 3 facing down, outside the camera's view (nothing it could
# occlude lies between the plane's visible points and the camera). With N = W H spp lanes:
#
# * bdpt: the light subpath traces one closest hit per lane (N); the camera subpath two
#   (its first hit on the plane, then the diffuse bounce that ends the path at two
#   segments: 2N); next-event estimation traces one shadow ray at each first hit (the
#   light faces every point of the plane: N); a connection s, t >= 2 needs three segments
#   (none); a light vertex is splatted where it projects into the image and its ray to
#   the camera is clear (always here), so splats equal the t = 1 shadow rays, 0 < . < N.
# * ptracer: N light-subpath hits; the emitter is outside the view (no emitter shadow ray).
#
# Negative control: the same triangle wound the other way faces up, away from the plane:
# no next-event shadow ray, no splat (the counts follow the geometry, not the lane count).

PLANE_SCENE = """PerspectiveCamera {{ center 0 0 5 direction 0 0 -1 up 0 1 0 angle 40 }}
Lights {{ numLights 0 }}
Background {{ color 0 0 0 }}
Materials {{ numMaterials 2
  Material {{ diffuseColor 0.5 0.5 0.5 }}
  Material {{ diffuseColor 0 0 0 Ke 5 5 5 }}
}}
Group {{ numObjects 2
  MaterialIndex 0
  Plane {{ normal 0 0 1 offset -1 }}
  MaterialIndex 1
  Triangle {{ vertex0 2 0 3 vertex1 {v1} vertex2 {v2} }}
}}
"""
DOWN = {"v1": "2 1 3", "v2": "3 0 3"}  # normal (v1 - v0) x (v2 - v0) = -z: toward the plane
UP = {"v1": "3 0 3", "v2": "2 1 3"}


def _plane_profile(tmp_path, integrator, facing, max_depth=2):
    from drpt.options import PathOptions, RenderOptions

    path = tmp_path / f"plane_{integrator}_{max_depth}_{'down' if facing is DOWN else 'up'}.txt"
    path.write_text(PLANE_SCENE.format(**facing))
    popt = profile.ProfileOptions(RenderOptions(width=8, height=8, spp=2, seed=3, integrator=integrator,
                                                path=PathOptions(max_depth=max_depth)))
    (r,) = profile.run_profile(path, popt, modes=("megakernel",))  # the light tracer alone
    assert r.mode == integrator and r.samples == 8 * 8 * 2
    return r.occupancy


N = 8 * 8 * 2


@pytest.mark.slow
def test_bdpt_counts_at_depth_two(tmp_path):
    occ = _plane_profile(tmp_path, "bdpt", DOWN)
    k = occ["rays_by_kind"]
    assert k["closest hit: light subpath"] == N
    assert k["closest hit: camera subpath"] == 2 * N
    assert k["shadow: next-event (s = 1)"] == N
    assert k["shadow: connection (s, t >= 2)"] == 0
    assert 0 < k["splat into the film"] == k["shadow: light vertex to camera (t = 1)"] < N
    assert occ["closest_hit_rays"] == 3 * N and occ["splats"] == k["splat into the film"]
    # every shadow ray the integrator names is one the scene traced
    assert occ["shadow_rays"] == occ["shadow_rays_seen_by_scene"] == N + k["splat into the film"]
    assert occ["loops"]["closest hit: light subpath"]["max_iterations_per_lane"] == 1
    assert occ["loops"]["closest hit: camera subpath"]["occupancy"] == 1.0  # two per lane, every lane


@pytest.mark.slow
def test_bdpt_counts_negative_controls(tmp_path):
    away = _plane_profile(tmp_path, "bdpt", UP)["rays_by_kind"]
    assert away["shadow: next-event (s = 1)"] == 0 and away["splat into the film"] == 0
    assert away["closest hit: light subpath"] == N  # queried, and missed everything
    # one segment more: the light subpath's bounce off the plane is traced too (the
    # camera subpath's second ray escapes to the sky, so it still traces 2N)
    deeper = _plane_profile(tmp_path, "bdpt", DOWN, max_depth=3)["rays_by_kind"]
    assert deeper["closest hit: light subpath"] == 2 * N != N


@pytest.mark.slow
def test_ptracer_counts_at_depth_two(tmp_path):
    occ = _plane_profile(tmp_path, "ptracer", DOWN)
    k = occ["rays_by_kind"]
    assert set(k) == {"closest hit: light subpath", "shadow: emitter seen by the camera",
                      "shadow: light vertex to camera (t = 1)", "splat into the film"}
    assert k["closest hit: light subpath"] == N
    assert k["shadow: emitter seen by the camera"] == 0  # outside the view
    assert 0 < k["splat into the film"] == k["shadow: light vertex to camera (t = 1)"] < N
    assert occ["shadow_rays"] == occ["shadow_rays_seen_by_scene"]
    away = _plane_profile(tmp_path, "ptracer", UP)["rays_by_kind"]
    assert away["splat into the film"] == 0 and away["closest hit: light subpath"] == N


@pytest.mark.slow
def test_light_tracing_report_and_json(tmp_path, cornell, capsys):
    """The command line on bdpt: the report's text, the JSON, the path megakernel beside it."""
    out = tmp_path / "bdpt.png"
    assert profile.main(_parse([str(cornell), "--integrator", "bdpt", "--size", "8", "8", "--spp", "1",
                                "--max-depth", "4", "--out", str(out)])) == 0
    text = capsys.readouterr().out
    data = json.loads(out.with_suffix(".json").read_text())
    assert set(data["modes"]) == {"bdpt", "megakernel"}
    b, mk = data["modes"]["bdpt"], data["modes"]["megakernel"]
    assert b["integrator"] == "bdpt" and mk["integrator"] == "path"
    assert b["samples"] == mk["samples"] == 64 and b["seconds"] > 0 and b["samples_per_second"] > 0
    occ = b["occupancy"]
    assert occ["rays_by_kind"]["closest hit: camera subpath"] >= 64
    assert occ["rays_by_kind"]["shadow: connection (s, t >= 2)"] > 0  # four segments: connections
    assert occ["shadow_rays"] == occ["shadow_rays_seen_by_scene"] > 0
    # the stages split the history by kernel; the fused kernel carries every ray
    assert sum(s["launches"] for s in b["stages"]) == b["launches"]
    fused = next(s for s in b["stages"] if s["name"] == profile.LIGHT_FUSED["bdpt"])
    assert fused["rays"] == occ["closest_hit_rays"] + occ["shadow_rays"] and fused["kernel_ms"] > 0
    assert any("per-stage times" in x for x in b["not_applicable"])
    for word in ("bdpt vs path (megakernel)", "rays per sample", "next-event (s = 1)",
                 "does not apply", "camera subpath loop"):
        assert word in text, word
    assert any("bdpt vs path" in line for line in data["verdict"])


def test_light_tracing_has_no_wavefront_mode(tmp_path, cornell):
    with pytest.raises(DrptError, match="no wavefront mode"):
        profile.main(_parse([str(cornell), "--integrator", "ptracer", "--mode", "wavefront",
                             "--out", str(tmp_path / "p.png")]))
