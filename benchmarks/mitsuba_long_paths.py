"""Mitsuba's longest paths on a bundled scene: where they bounce and what ends them (not a test).

Renders a bundled scene (an entry of :data:`drpt.tools.reference.REFERENCES`) as
``equal_time_vs_mitsuba.py`` hands it to Mitsuba (drpt's export, its size, spp, depths and
sampler) with a replica of Mitsuba's ``path`` integrator written in Python: the same sampler
calls in the same order, so the same image (the script prints where the replica's image and
``path``'s are not finite). Per lane it records the depth reached and, for the longest path,
every vertex: the shape, ``eta``, the throughput's largest channel, the roulette's survival
probability and its draw. It prints the ``--top`` longest paths, the shapes along the longest
one, its first and last vertices, and the distinct values its roulette drew.

Run: PYTHONPATH=. .venv/bin/python benchmarks/mitsuba_long_paths.py [diningroom] [--seed 3]
[--sampler ldsampler] [--top 5]
"""

from __future__ import annotations

import argparse
import collections
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import equal_time_vs_mitsuba as bench  # noqa: E402

HISTORY = 4096  # vertices recorded for the longest path


def main(argv=None) -> None:
    from drpt.backend import ensure, set_mitsuba_variant
    from drpt.tools.converge import to_mitsuba_dict

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene", nargs="?", default="diningroom")
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--sampler", default="ldsampler", help="Mitsuba's sampler plugin")
    ap.add_argument("--top", type=int, default=5)
    a = ap.parse_args(argv)
    ensure()
    set_mitsuba_variant()
    import drjit as dr
    import mitsuba as mi

    case = next(c for c in bench.cases([a.scene], False, Path(tempfile.mkdtemp())) if c.name == a.scene)
    scene, opts, _ = bench.setup(case, 192, 1_000_000)
    spp = 4 ** max(1, round(np.log(opts.spp) / np.log(4))) if a.sampler == "ldsampler" else opts.spp
    ms = mi.load_dict(to_mitsuba_dict(scene, opts.width, opts.height, 1, max_depth=opts.path.max_depth,
                                      rr_depth=opts.path.rr_depth, seed=0, bsdf=opts.bsdf,
                                      rfilter=opts.filter, sampler=a.sampler))
    max_depth = opts.path.max_depth if opts.path.max_depth >= 0 else 2**32 - 1
    rr_depth = opts.path.rr_depth
    n = opts.width * opts.height * spp
    depth_of = dr.zeros(mi.UInt32, n)
    first = {}  # the longest lane, found by a first render
    hist = {k: dr.zeros(mi.Float, HISTORY) for k in ("shape", "eta", "tmax", "rr_prob", "u")}

    def mis(a_, b_):
        a2, b2 = a_ * a_, b_ * b_
        w = a2 / (a2 + b2)
        return dr.select(dr.isfinite(w), w, 0)

    class Replica(mi.SamplingIntegrator):
        def sample(self, scn, sampler, ray_, medium=None, active=True):
            lane = dr.arange(mi.UInt32, dr.width(ray_.o))
            watch = mi.UInt32(first.get("lane", 2**32 - 1))
            ctx = mi.BSDFContext()
            ray = mi.Ray3f(ray_)
            state = (ray, scn.ray_intersect_preliminary(ray, True, active), mi.Spectrum(1.0), mi.Spectrum(0.0),
                     mi.Float(1.0), mi.UInt32(0), mi.Bool(False), dr.zeros(mi.Interaction3f), mi.Float(1.0),
                     mi.Bool(True), mi.Bool(active), sampler)

            def body(ray, pi, thr, res, eta, depth, valid, prev_si, prev_pdf, prev_delta, active, sampler):
                si = pi.compute_surface_interaction(ray, mi.RayFlags.All)
                emitter = si.emitter(scn)
                ds = mi.DirectionSample3f(scn, si, prev_si)
                em_pdf = scn.pdf_emitter_direction(prev_si, ds, ~prev_delta)
                res = dr.select(emitter != None, res + thr * emitter.eval(si, prev_pdf > 0)  # noqa: E711
                                * mis(prev_pdf, em_pdf), res)
                active_next = (depth + 1 < max_depth) & si.is_valid()
                valid |= (emitter != None) & ~active_next  # noqa: E711
                bsdf = si.bsdf(ray)
                active_em = active_next & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
                ds_e, em_w = scn.sample_emitter_direction(si, sampler.next_2d(), True, active_em)
                active_em &= ds_e.pdf != 0
                wo = si.to_local(ds_e.d)
                s1, s2 = sampler.next_1d(), sampler.next_2d()
                bv, bp, bs, bw = bsdf.eval_pdf_sample(ctx, si, wo, s1, s2, active_next)
                res = dr.select(active_em, res + thr * bv * em_w * dr.select(ds_e.delta, 1.0, mis(ds_e.pdf, bp)), res)
                ray = si.spawn_ray(si.to_world(bs.wo))
                thr = thr * bw
                eta = eta * bs.eta
                valid |= active_next & ~mi.has_flag(bs.sampled_type, mi.BSDFFlags.Null)
                prev_si, prev_pdf = mi.Interaction3f(si), bs.pdf
                prev_delta = mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta)
                depth = dr.select(si.is_valid(), depth + 1, depth)
                tmax = dr.max(thr)
                rr_prob = dr.minimum(tmax * eta * eta, 0.95)
                rr_active = depth >= rr_depth
                u = sampler.next_1d()
                thr = dr.select(rr_active, thr / rr_prob, thr)
                dr.scatter(depth_of, depth, lane, active_next)
                at = active_next & (lane == watch)
                for k, v in (("shape", mi.Float(dr.reinterpret_array(mi.UInt32, si.shape))), ("eta", eta),
                             ("tmax", tmax), ("rr_prob", rr_prob), ("u", u)):
                    dr.scatter(hist[k], v, dr.minimum(depth, HISTORY - 1), at)
                active = active_next & (~rr_active | (u < rr_prob)) & (tmax != 0)
                pi = scn.ray_intersect_preliminary(ray, False, active)
                return ray, pi, thr, res, eta, depth, valid, prev_si, prev_pdf, prev_delta, active, sampler

            state = dr.while_loop(state, lambda *s: s[10], body)
            return dr.select(state[6], state[3], 0.0), state[6], []

    mi.register_integrator("drpt_replica_path", lambda props: Replica(props))
    replica = mi.load_dict({"type": "drpt_replica_path"})
    img = np.asarray(mi.render(ms, spp=spp, seed=a.seed, integrator=replica))
    ref = np.asarray(mi.render(ms, spp=spp, seed=a.seed))
    print(f"{a.scene}, {opts.width}x{opts.height}, {spp} spp, seed {a.seed}, Mitsuba's {a.sampler}")
    print("pixels not finite (row, column): replica", np.argwhere(~np.isfinite(img).all(-1)).tolist(),
          "path", np.argwhere(~np.isfinite(ref).all(-1)).tolist())
    depth = depth_of.numpy()
    order = np.argsort(depth)[::-1][:a.top]
    for lane in order:
        pixel = lane // spp
        print(f"lane {lane}: pixel (row {pixel // opts.width}, column {pixel % opts.width}), depth {depth[lane]}")
    first["lane"] = int(order[0])
    mi.render(ms, spp=spp, seed=a.seed, integrator=replica)  # again, recording the longest lane
    names = {int(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(s))[0]): s.id() for s in ms.shapes()}
    h = {k: v.numpy() for k, v in hist.items()}
    d = min(int(depth[order[0]]), HISTORY - 1)
    print("shapes along the longest path:", dict(collections.Counter(names.get(int(x)) for x in h["shape"][1:d + 1])))
    for i in [*range(1, min(d, 12) + 1), *range(max(13, d - 5), d + 1)]:
        print(f"  vertex {i}: {names.get(int(h['shape'][i]))}, eta {h['eta'][i]:.4g}, "
              f"max throughput {h['tmax'][i]:.4g}, survival {h['rr_prob'][i]:.4g}, draw {h['u'][i]:.4f}")
    print("the roulette's distinct draws:", " ".join(f"{x:.4f}" for x in np.unique(h["u"][1:d + 1])))


if __name__ == "__main__":
    main()
