"""benchmarks/equal_time_vs_mitsuba.py: the size and spp rules, and a run on one scene (not its
timings)."""

from __future__ import annotations

import importlib.util
import sys

import pytest

from support import REPO

_PATH = REPO / "benchmarks" / "equal_time_vs_mitsuba.py"
_spec = importlib.util.spec_from_file_location("equal_time_bench", _PATH)
bench = importlib.util.module_from_spec(_spec)
sys.modules["equal_time_bench"] = bench  # (its dataclass looks its module up there)
_spec.loader.exec_module(bench)


def test_scale_makes_the_longer_side_at_least_min_size():
    assert bench.scale_for(48, 48, 192) == 4
    assert bench.scale_for(64, 48, 192) == 3
    assert bench.scale_for(200, 120, 192) == 1
    assert bench.scale_for(128, 72, 192) == 2


def test_spp_is_the_files_cut_to_the_sample_budget():
    assert bench.spp_for(32, 192 * 192, 1_000_000) == 27
    assert bench.spp_for(16, 64 * 64, 1_000_000) == 16
    assert bench.spp_for(128, 1000 * 1000, 1_000_000) == 4  # at least 4
    assert bench.spp_for(2, 1000 * 1000, 1_000_000) == 2  # never more than the file's


def test_the_list_has_every_target_scene(tmp_path):
    from drpt.tools.reference import REFERENCES

    names = [c.name for c in bench.cases([], False, tmp_path)]
    assert names[: len(REFERENCES)] == list(REFERENCES)
    assert names[len(REFERENCES):] == ["veach_mis.xml", "living_room"]
    assert (tmp_path / "living_room.xml").is_file()


@pytest.mark.slow
@pytest.mark.mitsuba
def test_runs_on_one_scene(capsys):
    rows = bench.main(["--only", "veach", "--no-corpus", "--rounds", "2", "--min-size", "32",
                       "--max-samples", "20000"])
    assert [r["scene"] for r in rows] == ["veach_mis.xml"]
    r = rows[0]
    assert (r["width"], r["height"], r["spp"]) == (64, 48, 6) and r["target"] == 1.5
    assert r["efficiency_ratio"] > 0 and r["drpt_variance"] > 0
    assert "| veach_mis.xml | 64x48 | 6 |" in capsys.readouterr().out


def test_sampler_applies_to_the_bundled_scenes_only(monkeypatch, tmp_path):
    """``--sampler`` reaches drpt's options on a bundled scene and leaves an XML file's own
    sampler alone (Mitsuba's renders are not built: make_mitsuba is replaced)."""
    from drpt.tools import converge

    seen = []
    monkeypatch.setattr(converge, "make_drpt", lambda scene, opts: (seen.append(opts.sampler), None))
    monkeypatch.setattr(converge, "make_mitsuba", lambda *a, **k: (None, 0.0))
    cases = {c.name: c for c in bench.cases(["cornellbox", "veach"], False, tmp_path, ["_ct", "media"])}
    bench.prepare(cases["cornellbox"], 32, 20_000, sampler="ldsampler")
    bench.prepare(cases["cornellbox"], 32, 20_000)
    bench.prepare(cases["veach_mis.xml"], 32, 20_000, sampler="ldsampler")
    assert seen == ["ldsampler", "auto", "independent"]  # auto: drpt's default (the renderer resolves it)


def test_the_table_lists_the_pixels_left_out():
    """A row whose Mitsuba image lost pixels to NaN is measured on the rest: it has its
    efficiency, counts in the mean, and the pixels each renderer lost are listed under the
    table. Negative control: a row without lost pixels adds no such list."""
    from types import SimpleNamespace

    a = SimpleNamespace(rounds=8, min_size=192, max_samples=1_000_000, commit="abc")
    row = {"scene": "diningroom", "target": 2.0, "width": 192, "height": 192, "spp": 16,
           "drpt_seconds": 0.5, "mitsuba_seconds": 0.7, "time_ratio": 1.4, "variance_ratio": 0.9,
           "efficiency_ratio": 1.4 / 0.9, "drpt_nonfinite_pixels": 0, "mitsuba_nonfinite_pixels": 1}
    text = bench.format_table([row], [], a, 0.5)
    assert "| diningroom | 192x192 | 16 | 0.500 | 0.700 | 1.40 | 0.90 | 1.56 | 2x **no** |" in text
    assert "geometric mean of the efficiency ratios 1.56" in text and "(over" not in text
    assert "* diningroom: drpt 0, Mitsuba 1 of 36864" in text
    clean = bench.format_table([{**row, "mitsuba_nonfinite_pixels": 0}], [], a, 0.5)
    assert "not finite" not in clean and "Mitsuba 1 of" not in clean


def test_a_row_whose_mean_images_differ_has_no_efficiency():
    """Renderers whose mean images differ by more than 2x (Mitsuba's ldsampler in the dining
    room: fireflies of 1e20-1e33) estimate different images: the row reads n/a, is short of
    its target and out of the geometric mean; 10% apart is listed under the table. Negative
    control: the same row with equal means keeps its efficiency."""
    from types import SimpleNamespace

    a = SimpleNamespace(rounds=8, min_size=192, max_samples=1_000_000, commit="abc")
    base = {"target": 2.0, "width": 192, "height": 192, "spp": 16, "drpt_seconds": 0.5,
            "mitsuba_seconds": 0.7, "time_ratio": 1.4}
    bad = {**base, "scene": "diningroom", "variance_ratio": 1e-60, "efficiency_ratio": 1.4e60,
           "mean_ratio": 3e17}
    near = {**base, "scene": "other", "variance_ratio": 0.5, "efficiency_ratio": 2.8, "mean_ratio": 1.2}
    text = bench.format_table([bad, near], [], a, 0.5)
    assert "| diningroom | 192x192 | 16 | 0.500 | 0.700 | 1.40 | n/a (Mitsuba's mean image 3e+17x drpt's) " \
           "| n/a (Mitsuba's mean image 3e+17x drpt's) | 2x **no** |" in text
    assert "1 of 2 scenes meet their target; geometric mean of the efficiency ratios 2.80 (over 1: " \
           "1 with mean images more than 2x apart)" in text
    assert "* diningroom: 3e+17" in text and "* other: 1.2" in text
    same = bench.format_table([{**bad, "mean_ratio": 1.0}], [], a, 0.5)
    assert "n/a" not in same and "| 1400000000000000" in same and "apart" not in same
    # a row with no pixel finite in every round of both has no mean ratio either
    empty = bench.format_table([{**bad, "mean_ratio": float("nan"), "variance_ratio": float("nan")}, near],
                               [], a, 0.5)
    assert "n/a (no pixel finite in every round of both)" in empty and "nanx" not in empty
    assert "(over 1: 1 without a finite variance)" in empty


def test_more_rounds_only_where_the_ratio_is_uncertain_and_the_images_agree():
    """``_still_uncertain`` asks for more rounds where the variance ratio's jackknife error is
    above ``max_error`` of it, not where the two mean images are more than 2x apart (a row
    without an efficiency, which more rounds do not give one), nor with ``max_error`` 0.
    Control: the same uncertain row with equal means asks for more."""
    d = {"variance": 1.0, "mean": 1.0, "loo_variances": [1.0, 2.0, 0.5, 3.0]}
    m = {"variance": 1.0, "mean": 1.0, "loo_variances": [1.0, 1.0, 1.0, 1.0]}
    assert bench._still_uncertain(0.1)({"drpt": d, "mitsuba": m})  # control
    assert not bench._still_uncertain(0.0)({"drpt": d, "mitsuba": m})
    assert not bench._still_uncertain(0.1)({"drpt": d, "mitsuba": {**m, "mean": 1e30}})
    assert not bench._still_uncertain(0.1)({"drpt": {**d, "mean": 0.0}, "mitsuba": m})
    steady = {**d, "loo_variances": [1.0, 1.0, 1.0, 1.0]}
    assert not bench._still_uncertain(0.1)({"drpt": steady, "mitsuba": m})


def test_a_row_whose_variance_ratio_is_one_rounds_draw_is_undecided():
    """A measured row whose variance ratio's jackknife error is above the ratio (one round
    holds most of a renderer's variance) reads "undecided": neither met nor short, out of the
    count of decided rows and of the mean. Negative control: the same row with an error below
    its ratio is met, counted and in the mean."""
    from types import SimpleNamespace

    a = SimpleNamespace(rounds=8, min_size=192, max_samples=1_000_000, commit="abc")
    base = {"target": 2.0, "width": 192, "height": 192, "spp": 16, "drpt_seconds": 0.4,
            "mitsuba_seconds": 1.0, "time_ratio": 2.5, "mean_ratio": 1.0, "rounds": 256, "first_rounds": 8}
    draw = {**base, "scene": "media", "variance_ratio": 0.2, "variance_ratio_error": 5.3, "efficiency_ratio": 12.0}
    plain = {**base, "scene": "plain", "variance_ratio": 1.0, "variance_ratio_error": 0.05, "efficiency_ratio": 2.5}
    text = bench.format_table([draw, plain], [], a, 0.5)
    assert "| media | " in text and "| 2x undecided (the variance ratio's error is above the ratio) |" in text
    assert "1 of 1 decided scenes meet their target (1 of 2 undecided); geometric mean of the " \
           "efficiency ratios 2.50 (over 1: 1 undecided)" in text
    decided = bench.format_table([{**draw, "variance_ratio_error": 0.1}, plain], [], a, 0.5)  # control
    assert "undecided" not in decided and "2 of 2 scenes meet their target" in decided
    assert "efficiency ratios 5.48" in decided


def test_a_bundled_row_falls_back_to_mitsubas_independent_sampler(monkeypatch, capsys):
    """On a bundled scene where Mitsuba drew with its ldsampler (drpt's sampler's plugin) and
    the two mean images are more than 2x apart (Mitsuba's ldsampler is not an estimate of the
    dining room), the row is measured again against Mitsuba's independent sampler, drpt's
    settings kept, and the table names the plugin and the first mean ratio. Negative controls:
    an XML row and a bundled row whose images agree are measured once; ``--mitsuba-sampler``
    given is kept."""
    calls = []

    def way(mean, variance, seconds=1.0):
        return {"seconds": seconds, "variance": variance, "efficiency": 1.0 / (seconds * variance),
                "loo_variances": [variance] * 8, "mean": mean, "nonfinite_pixels": 0, "rounds": 8}

    def rounds(case, a, mitsuba_sampler):
        calls.append((case.name, mitsuba_sampler))
        used = mitsuba_sampler or ("ldsampler" if case.bundled else None)
        info = {"width": 8, "height": 8, "spp": 16, "integrator": "path"}
        if case.bundled:
            info["mitsuba_sampler"] = used
        bad = case.name == "room" and used == "ldsampler"
        return info, {"drpt": way(1.0, 1.0), "mitsuba": way(1e30 if bad else 1.0, 4.0, 1.5)}

    own = (8, 8, -1, "auto")
    fake = [bench.Case("room", 2.0, bench.ROOT, own), bench.Case("box", 2.0, bench.ROOT, own),
            bench.Case("file.xml", 2.0, bench.ROOT)]
    monkeypatch.setattr(bench, "_rounds", rounds)
    monkeypatch.setattr(bench, "cases", lambda *a, **k: fake)
    rows = bench.main(["--rounds", "8"])
    assert calls == [("room", None), ("room", "independent"), ("box", None), ("file.xml", None)]
    room = rows[0]
    assert room["mitsuba_sampler"] == "independent" and room["mitsuba_ldsampler_mean_ratio"] == 1e30
    assert room["efficiency_ratio"] == pytest.approx(6.0) and room["mean_ratio"] == 1.0
    assert "| room (Mitsuba's independent sampler: its ldsampler's mean image 1e+30x drpt's) |" \
        in capsys.readouterr().out
    assert "mitsuba_ldsampler_mean_ratio" not in rows[1] and rows[1]["mitsuba_sampler"] == "ldsampler"
    calls.clear()
    rows = bench.main(["--rounds", "8", "--mitsuba-sampler", "ldsampler"])  # control
    assert calls[:2] == [("room", "ldsampler"), ("box", "ldsampler")] and "mitsuba_ldsampler_mean_ratio" not in rows[0]
