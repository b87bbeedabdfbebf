"""Equal-time efficiency of drpt against Mitsuba 3 on every scene drpt is judged on (not a test).

Scenes, in this order (``--only`` keeps those whose name contains one of its words):

* the bundled scenes: every entry of :data:`drpt.tools.reference.REFERENCES` (the gallery's:
  the scene file, its material mode and depth; the dining room is generated when missing),
  which Mitsuba renders as drpt exports it;
* ``veach_mis.xml``: Veach's MIS scene as Mitsuba XML (``tests/data/xml``);
* ``living_room``: the textured multi-light room of :mod:`drpt.tools.scenegen.living_room`,
  generated into a temporary folder;
* the corpus: every ``test_*.xml`` / ``scene_*.xml`` of Mitsuba's render tests
  (``../shared/corpus/mitsuba-data/tests/scenes``, skipped when absent) that drpt renders with
  a path tracer (``path``, ``direct``, ``volpath``). A file drpt refuses (a plugin it lacks,
  a parameter it does not read) or renders by light tracing is listed under the table with
  the reason, not measured.

An XML scene renders with its own settings (film, filter, sampler, integrator and depths), drpt
reading the file and Mitsuba rendering that very file (:class:`drpt.tools.xmlref.MitsubaXML`),
both larger than authored: the film is scaled by the smallest integer ``k >= 1`` that makes its
longer side at least ``--min-size`` (default 192; Mitsuba's test scenes are 32 to 128 pixels
wide). The sample count is the file's (64 for the bundled scenes), cut to ``--max-samples``
per image (default 1e6, at least 4 spp) so that a round takes seconds; both renderers use the
same. Efficiency is ``1 / (seconds x mean per-pixel variance)``: each renderer renders the scene
once to compile, then the two take turns for ``--rounds`` rounds (default 5), round ``k`` with
seed ``k`` (:func:`drpt.tools.converge.efficiency_rounds`); seconds are the median wall time
of a render (drpt: ``Renderer.render``; Mitsuba: ``mi.render`` and the copy to numpy, with
Dr.Jit's own LLVM settings), the variance is across the rounds' images. The ratio
drpt/Mitsuba is what to read: the rounds interleave, so load from other processes slows both.
The variance ratio comes with its jackknife error over the rounds (``+- E``,
:func:`drpt.tools.converge.variance_ratio_error`): the seeds are fixed, so a row whose
variance sits in a few pixels (a sub-pixel highlight) reads the same draw of that tail in
every run, and the error says how far the draw may be from the expectation. A row whose error
is above ``--max-error`` (default 0.1) of its ratio renders more rounds, doubling, up to
``--max-rounds`` (default 256; round ``k`` still seed ``k``), and the table says how many it read
(a variance held by one sample in millions, a caustic path through glass, needs hundreds of rounds
before its draw says anything: docs/performance.md). A row whose error is still above its ratio
(leaving out one round moves the ratio by more than its value) is *undecided*: its efficiency is
one round's draw, neither a pass nor a failure, and it is left out of the count of decided rows
and of the mean.
The target is issue 27's: 2x on the bundled and corpus scenes, 1.5x on Veach's and the room.
A pixel that is NaN or infinite in any round of either renderer is left out of both renderers'
variance (the two are scored on the same pixels), and the table lists how many each lost.

Output: a Markdown table (stdout), the skipped scenes, and with ``--json FILE`` the numbers
(rewritten after every scene).

Run: PYTHONPATH=. .venv/bin/python benchmarks/equal_time_vs_mitsuba.py [--rounds 5] [--max-rounds 256]
[--max-error 0.1]
[--min-size 192] [--max-samples 1000000] [--only WORD,...] [--skip WORD,...] [--no-corpus]
[--json FILE] [--light-sampler RULE] [--env-compensation on|off] [--sampler NAME]
[--mitsuba-sampler NAME]

``--sampler`` sets drpt's sampler on the bundled scenes only (drpt's own format names none;
an XML file's sampler is the file's, in both renderers). A bundled scene's export names the
sampler drpt draws with (by default ``auto``'s choice, ``ldsampler`` for the path tracers), so
Mitsuba renders it with its plugin of that name: both renderers with the same settings (with
``ldsampler`` at the power of 4 nearest the scene's spp, as Mitsuba's plugin takes no other).
``--mitsuba-sampler`` names another Mitsuba plugin for the bundled scenes' export (drpt keeps
its own): Mitsuba's ``ldsampler`` is not a valid estimator on every scene (its 1-D draws take
a pixel's same ``spp`` values in every dimension, so where all are below 0.95 its roulette never
ends a path that keeps its throughput: in the dining room's glass table top such paths reach
values of 1e20-1e33 and NaN). Without ``--mitsuba-sampler``, a bundled row whose Mitsuba image
drawn with ``ldsampler`` has a mean more than 2x from drpt's is measured again against Mitsuba's
``independent`` sampler (drpt's settings kept), and the table names the plugin and the first
mean ratio: Mitsuba's valid estimate of the scene is the one to compare with.

The efficiency ratio compares two estimates of one image: a row whose two mean images (over
the scored pixels and the rounds) differ by more than 2x has no efficiency (``n/a``, short of
its target, out of the mean), and rows whose means differ by more than 10% are listed under
the table.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import subprocess
import sys
import tempfile
import time
import warnings
from dataclasses import dataclass, replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CORPUS = ROOT.parent / "shared" / "corpus" / "mitsuba-data" / "tests" / "scenes"
VEACH = ROOT / "tests" / "data" / "xml" / "veach_mis.xml"
#: issue 27's targets: drpt's efficiency over Mitsuba's
TARGET_MIS_ROOM, TARGET_OTHERS = 1.5, 2.0
BUNDLED_SPP = 64


@dataclass
class Case:
    name: str
    target: float
    path: Path
    bundled: tuple | None = None  # (width, height, depth, bsdf mode) of a REFERENCES entry


def scale_for(width: int, height: int, min_size: int) -> int:
    """The smallest integer factor ``k >= 1`` with ``k * max(width, height) >= min_size``."""
    return max(1, math.ceil(min_size / max(width, height)))


def spp_for(own: int, pixels: int, max_samples: int) -> int:
    """``own`` samples per pixel, cut to ``max_samples`` per image, at least 4 (or ``own``)."""
    return max(min(own, 4), min(own, max_samples // max(pixels, 1)))


def corpus_files() -> list[Path]:
    if not CORPUS.is_dir():
        return []
    return sorted(p for p in CORPUS.rglob("*.xml")
                  if re.match(r"(test|scene)_", p.name) and p.parent.name != "refs")


def cases(only: list[str], corpus: bool, room_dir: Path, skip: list[str] = ()) -> list[Case]:
    from drpt.tools import reference as refs
    from drpt.tools.scenegen import living_room

    out = []
    for name, (scene_file, w, h, _spp, depth, mode) in refs.REFERENCES.items():
        out.append(Case(name, TARGET_OTHERS, Path(scene_file), (w, h, depth, mode)))
    out.append(Case("veach_mis.xml", TARGET_MIS_ROOM, VEACH))
    out.append(Case("living_room", TARGET_MIS_ROOM, room_dir / "living_room.xml"))
    if corpus:
        out += [Case(str(p.relative_to(CORPUS)), TARGET_OTHERS, p) for p in corpus_files()]
    out = [c for c in out if (not only or any(w in c.name for w in only)) and not any(w in c.name for w in skip)]
    if any(c.name == "living_room" for c in out):
        living_room.main(room_dir)
    return out


def setup(case: Case, min_size: int, max_samples: int):
    """``(scene, options, source)``: drpt's scene and render options of ``case`` (its size,
    spp and settings, as the module docstring says) and the XML that Mitsuba renders (None
    for a bundled scene: drpt's export). Raises DrptError where drpt refuses the scene (or
    would not path trace it)."""
    from drpt.errors import DrptError
    from drpt.options import PathOptions, RenderOptions, with_scene_settings
    from drpt.scene import load_scene
    from drpt.tools import reference as refs
    from drpt.tools.xmlref import MitsubaXML

    source = None
    if case.bundled is not None:
        w, h, depth, mode = case.bundled
        scene = load_scene(refs.scene_path(str(case.path)))
        k = scale_for(w, h, min_size)
        opts = RenderOptions(width=k * w, height=k * h, spp=BUNDLED_SPP, bsdf=mode, progress=False,
                             integrator="volpath" if scene.media else "path",
                             path=PathOptions(max_depth=depth)).validate()
    else:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            scene = load_scene(case.path)
        not_read = list(getattr(scene.settings, "not_read", ()))
        if not_read:
            raise DrptError(f"drpt does not read all of the file ({not_read[0]})")
        own, _ = with_scene_settings(RenderOptions(progress=False), scene)
        if own.integrator not in ("path", "volpath"):
            raise DrptError(f"rendered by drpt's {own.integrator}, not a path tracer")
        k = scale_for(own.width, own.height, min_size)
        opts, scene = with_scene_settings(
            RenderOptions(width=k * own.width, height=k * own.height, progress=False), scene,
            given=frozenset({"size"}))
        source = MitsubaXML.for_scene(scene, opts)
    spp = spp_for(opts.spp, opts.width * opts.height, max_samples)
    return scene, replace(opts, spp=spp), source


def prepare(case: Case, min_size: int, max_samples: int, light_sampler: str | None = None,
            env_compensation: str | None = None, sampler: str | None = None,
            mitsuba_sampler: str | None = None):
    """``(ways, info)`` for :func:`~drpt.tools.converge.efficiency_rounds`: drpt's and Mitsuba's
    ``render(seed) -> image`` at the same size, spp and settings (:func:`setup`; drpt with
    ``light_sampler`` and ``env_compensation`` where given, else its defaults; ``sampler`` on a
    bundled scene only; ``mitsuba_sampler``, Mitsuba's plugin on a bundled scene where given,
    else the one of drpt's sampler). Raises DrptError
    where drpt refuses the scene (or would not path trace it)."""
    from drpt.options import resolve_sampler
    from drpt.tools.converge import make_drpt, make_mitsuba

    scene, opts, source = setup(case, min_size, max_samples)
    if light_sampler:
        opts = replace(opts, light_sampler=light_sampler)
    if env_compensation:
        opts = replace(opts, env_compensation=env_compensation)
    if sampler and case.bundled is not None:
        opts = replace(opts, sampler=sampler).validate()
    if case.bundled is not None and resolve_sampler(opts).sampler == "ldsampler":
        # Mitsuba's ldsampler takes a power of 4 (it rounds any other count up): both renderers
        # draw the same count, the nearest power of 4
        opts = replace(opts, spp=4 ** max(1, round(math.log(opts.spp, 4))))
    spp = opts.spp
    _, drpt_render = make_drpt(scene, opts)
    # a bundled scene's export names the sampler drpt draws with (Mitsuba's plugin of that name)
    mits_render, _ = make_mitsuba(scene, opts.width, opts.height, opts.path.max_depth,
                                  opts.path.rr_depth, 0, opts.bsdf, opts.filter, source,
                                  sampler=mitsuba_sampler or resolve_sampler(opts).sampler)
    ways = {"drpt": lambda seed: drpt_render(spp, seed).image,
            "mitsuba": lambda seed: mits_render(spp, seed)[0]}
    info = {"width": opts.width, "height": opts.height, "spp": spp, "integrator": opts.integrator}
    if case.bundled is not None:  # (the plugin Mitsuba drew with)
        info["mitsuba_sampler"] = mitsuba_sampler or resolve_sampler(opts).sampler
    return ways, info


def _cpu() -> str:
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True, check=False).stdout
        return next(line.split(":", 1)[1].strip() for line in out.splitlines() if line.startswith("Model name"))
    except (OSError, StopIteration):
        return "unknown CPU"


def _commit() -> str:
    out = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                         text=True, check=False)
    return out.stdout.strip() or "unknown"


def main(argv=None) -> list[dict]:
    from drpt.backend import ensure, set_mitsuba_variant
    from drpt.errors import DrptError
    from drpt.tools.converge import variance_ratio_error

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--max-rounds", type=int, default=256,
                    help="a row whose variance ratio's error is above --max-error renders more rounds, up to this")
    ap.add_argument("--max-error", type=float, default=0.1,
                    help="relative jackknife error of the variance ratio that asks for more rounds (0: never)")
    ap.add_argument("--min-size", type=int, default=192)
    ap.add_argument("--max-samples", type=int, default=1_000_000)
    ap.add_argument("--only", default="", help="comma-separated words; keep scenes whose name has one")
    ap.add_argument("--skip", default="", help="comma-separated words; leave out scenes whose name has one")
    ap.add_argument("--no-corpus", action="store_true")
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--light-sampler", default=None, help="drpt's --light-sampler (default: drpt's default)")
    ap.add_argument("--env-compensation", default=None, choices=("on", "off"),
                    help="drpt's --env-compensation (default: drpt's default)")
    ap.add_argument("--sampler", default=None,
                    help="drpt's --sampler on the bundled scenes (default: drpt's default)")
    ap.add_argument("--mitsuba-sampler", default=None,
                    help="Mitsuba's sampler plugin on the bundled scenes (default: drpt's sampler's)")
    a = ap.parse_args(argv)
    ensure()
    set_mitsuba_variant()
    rows, skipped = [], []
    load0 = os.getloadavg()[0]
    a.commit = _commit()  # (at the start: the checkout may move on while a long run goes on)
    with tempfile.TemporaryDirectory(prefix="drpt-eqtime-") as tmp:
        for case in cases([w for w in a.only.split(",") if w], not a.no_corpus, Path(tmp),
                          [w for w in a.skip.split(",") if w]):
            t0 = time.perf_counter()
            try:
                info, res = _rounds(case, a, a.mitsuba_sampler)
                apart = _mean_ratio(res)
                if (case.bundled is not None and a.mitsuba_sampler is None
                        and info.get("mitsuba_sampler") == "ldsampler" and not _same_image({"mean_ratio": apart}, 2.0)):
                    # Mitsuba's ldsampler is not an estimate of this scene (its roulette keeps
                    # paths trapped in glass: docs/performance.md): its independent sampler is
                    # Mitsuba's estimate to compare with, drpt's own settings kept
                    info, res = _rounds(case, a, "independent")
                    info["mitsuba_ldsampler_mean_ratio"] = apart
            except DrptError as e:
                skipped.append((case.name, str(e).splitlines()[0].replace(f"{CORPUS}/", "")))
                print(f"{case.name}: skipped: {skipped[-1][1]}", file=sys.stderr, flush=True)
                continue
            d, m = res["drpt"], res["mitsuba"]
            row = {"scene": case.name, "target": case.target, **info,
                   "drpt_seconds": d["seconds"], "mitsuba_seconds": m["seconds"],
                   "drpt_variance": d["variance"], "mitsuba_variance": m["variance"],
                   "time_ratio": m["seconds"] / d["seconds"],
                   "variance_ratio": d["variance"] / m["variance"] if m["variance"] > 0 else float("nan"),
                   "variance_ratio_error": variance_ratio_error(d, m), "rounds": d["rounds"], "first_rounds": a.rounds,
                   "efficiency_ratio": d["efficiency"] / m["efficiency"],
                   "drpt_nonfinite_pixels": d["nonfinite_pixels"],
                   "mitsuba_nonfinite_pixels": m["nonfinite_pixels"],
                   "mean_ratio": _mean_ratio(res), "load": os.getloadavg()[0]}
            rows.append(row)
            print(f"{case.name}: efficiency x{row['efficiency_ratio']:.2f} ({time.perf_counter() - t0:.0f} s, "
                  f"load {row['load']:.1f})", file=sys.stderr, flush=True)
            if a.json is not None:  # after every scene: a long run that is stopped keeps its rows
                _write_json(a, rows, skipped, load0)
    print(format_table(rows, skipped, a, load0))
    if a.json is not None:
        _write_json(a, rows, skipped, load0)
    return rows


def _rounds(case: Case, a, mitsuba_sampler: str | None) -> tuple[dict, dict]:
    """``(info, result)``: the row's renderers (:func:`prepare`, Mitsuba with
    ``mitsuba_sampler`` on a bundled scene where given) through
    :func:`~drpt.tools.converge.efficiency_rounds`."""
    from drpt.tools.converge import efficiency_rounds

    ways, info = prepare(case, a.min_size, a.max_samples, a.light_sampler, a.env_compensation,
                         a.sampler, mitsuba_sampler)
    return info, efficiency_rounds(ways, a.rounds, more=_still_uncertain(a.max_error), max_rounds=a.max_rounds)


def _mean_ratio(res: dict) -> float:
    """Mitsuba's mean image over drpt's (NaN where drpt's mean is 0)."""
    d, m = res["drpt"], res["mitsuba"]
    return m["mean"] / d["mean"] if d["mean"] else float("nan")


def _still_uncertain(max_error: float):
    """``more`` for :func:`~drpt.tools.converge.efficiency_rounds`: whether the variance
    ratio's jackknife error is above ``max_error`` of the ratio (0: never), on a row whose two
    mean images are within 2x of each other (a row without an efficiency gains nothing from
    more rounds)."""
    from drpt.tools.converge import variance_ratio_error

    def more(res: dict) -> bool:
        d, m = res["drpt"], res["mitsuba"]
        if max_error <= 0 or not m["variance"] > 0:
            return False
        if not _same_image({"mean_ratio": _mean_ratio(res)}, 2.0):
            return False
        ratio = d["variance"] / m["variance"]
        return variance_ratio_error(d, m) > max_error * ratio
    return more


def _write_json(a, rows: list[dict], skipped: list, load0: float) -> None:
    a.json.write_text(json.dumps({"commit": a.commit, "cpu": _cpu(), "load_at_start": load0,
                                  "args": {**vars(a), "json": str(a.json)}, "rows": rows,
                                  "skipped": skipped}, indent=1))


def _error(row: dict) -> str:
    """`` +- E``: the variance ratio's jackknife error over the rounds (none below 3 rounds)."""
    e = row.get("variance_ratio_error", float("nan"))
    n = row.get("rounds")
    more = f" ({n} rounds)" if n and n != row.get("first_rounds", n) else ""
    return (f" +- {e:.2f}" if math.isfinite(e) else "") + more


def _same_image(row: dict, factor: float) -> bool:
    """Whether the row's two mean images are within ``factor`` of each other (a row without
    the ratio passes)."""
    q = row.get("mean_ratio", 1.0)
    return math.isfinite(q) and 1.0 / factor <= q <= factor


def _measured(row: dict) -> bool:
    return (math.isfinite(row["variance_ratio"]) and row["efficiency_ratio"] > 0
            and _same_image(row, 2.0))


def _undecided(row: dict) -> bool:
    """Whether a measured row's variance ratio has a jackknife error above the ratio itself:
    leaving out one round moves it by more than its value, so one round's samples hold most
    of a renderer's variance, and the row's efficiency is that round's draw (neither a pass
    nor a failure; more rounds, ``--max-rounds``, may decide it)."""
    e = row.get("variance_ratio_error", float("nan"))
    return _measured(row) and math.isfinite(e) and e > row["variance_ratio"]


def _why_not_measured(rows: list[dict]) -> str:
    """Why the rows that are not :func:`_measured` are left out of the mean, by cause."""
    out = [r for r in rows if not _measured(r)]
    apart = sum(math.isfinite(r.get("mean_ratio", 1.0)) and not _same_image(r, 2.0) for r in out)
    parts = [f"{len(out) - apart} without a finite variance"] if len(out) > apart else []
    return ", ".join(parts + ([f"{apart} with mean images more than 2x apart"] if apart else []))


def format_table(rows: list[dict], skipped: list, a, load0: float) -> str:
    lines = [f"commit {getattr(a, 'commit', None) or _commit()}, {_cpu()}, {os.cpu_count()} cores; {a.rounds} rounds, "
             f"(more, up to {getattr(a, 'max_rounds', a.rounds)}, where the variance ratio's error is above "
             f"{getattr(a, 'max_error', 0):g} of it), "
             f"min size {a.min_size}, max samples {a.max_samples}; load average {load0:.1f} at the start"
             + (f"; drpt's light sampler {a.light_sampler}" if getattr(a, "light_sampler", None) else "")
             + (f"; drpt's env compensation {a.env_compensation}" if getattr(a, "env_compensation", None) else "")
             + (f"; drpt's sampler {a.sampler} (bundled scenes)" if getattr(a, "sampler", None) else "")
             + (f"; Mitsuba's sampler {a.mitsuba_sampler} (bundled scenes)"
                if getattr(a, "mitsuba_sampler", None) else ""),
             "",
             "| scene | size | spp | drpt s | Mitsuba s | Mitsuba s / drpt s | variance drpt / Mitsuba "
             "| efficiency drpt / Mitsuba | target |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        ok = "yes" if _measured(r) and r["efficiency_ratio"] >= r["target"] else "**no**"
        if _undecided(r):
            ok = "undecided (the variance ratio's error is above the ratio)"
        var, eff = f"{r['variance_ratio']:.2f}{_error(r)}", f"{r['efficiency_ratio']:.2f}"
        if not math.isfinite(r.get("mean_ratio", 1.0)):
            var = eff = "n/a (no pixel finite in every round of both)"
        elif not _same_image(r, 2.0):
            var = eff = f"n/a (Mitsuba's mean image {r['mean_ratio']:.3g}x drpt's)"
        scene = r["scene"]
        if "mitsuba_ldsampler_mean_ratio" in r:
            scene += (f" (Mitsuba's {r['mitsuba_sampler']} sampler: its ldsampler's mean image "
                      f"{r['mitsuba_ldsampler_mean_ratio']:.3g}x drpt's)")
        lines.append(f"| {scene} | {r['width']}x{r['height']} | {r['spp']} | {r['drpt_seconds']:.3f} "
                     f"| {r['mitsuba_seconds']:.3f} | {r['time_ratio']:.2f} | {var} "
                     f"| {eff} | {r['target']:g}x {ok} |")
    # (a pixel that is NaN or infinite in some round of either renderer is left out of both
    # renderers' variance, and listed below; a row with no pixel left has no variance to
    # compare, nor one whose renderers' mean images differ by more than 2x: such a row is
    # listed, counted as short of its target and left out of the mean)
    # (an undecided row is neither met nor short, and out of the mean)
    undecided = [r for r in rows if _undecided(r)]
    measured = [r for r in rows if _measured(r) and not _undecided(r)]
    if measured:
        g = math.exp(sum(math.log(r["efficiency_ratio"]) for r in measured) / len(measured))
        why = [_why_not_measured(rows)] if any(not _measured(r) for r in rows) else []
        why += [f"{len(undecided)} undecided"] if undecided else []
        lines.append(f"\n{sum(r['efficiency_ratio'] >= r['target'] for r in measured)} of "
                     + (f"{len(rows) - len(undecided)} decided scenes meet their target ({len(undecided)} "
                        f"of {len(rows)} undecided)" if undecided else f"{len(rows)} scenes meet their target")
                     + f"; geometric mean of the efficiency ratios {g:.2f}"
                     + (f" (over {len(measured)}: {', '.join(why)})" if len(measured) < len(rows) else ""))
    apart = [r for r in rows if not _same_image(r, 1.1)]
    if apart:
        lines.append("\nMean images more than 10% apart (Mitsuba's / drpt's):")
        lines += [f"* {r['scene']}: {r['mean_ratio']:.4g}" for r in apart]
    lost = [r for r in rows if r.get("drpt_nonfinite_pixels") or r.get("mitsuba_nonfinite_pixels")]
    if lost:
        lines.append("\nPixels not finite in some round (left out of both renderers' variance):")
        lines += [f"* {r['scene']}: drpt {r.get('drpt_nonfinite_pixels', 0)}, Mitsuba "
                  f"{r.get('mitsuba_nonfinite_pixels', 0)} of {r['width'] * r['height']}" for r in lost]
    if skipped:
        lines.append("\nNot measured:")
        lines += [f"* {name}: {why}" for name, why in skipped]
    return "\n".join(lines)


if __name__ == "__main__":
    main()
