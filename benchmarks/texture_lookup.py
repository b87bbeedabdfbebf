"""Texture lookups alone, by storage (not a test): the float32 texture against 8-bit codes.

    PYTHONPATH=. .venv/bin/python benchmarks/texture_lookup.py [--size 2048] [--lookups 2097152] [--rounds 7]

On a random 8-bit RGB image of ``--size`` squared texels (a gray one for the bump maps'
gradients), one kernel per variant evaluates ``--lookups`` bilinear lookups and sums them:

* ``rgb``: :meth:`drpt.render.texture.TextureSet.lookup`'s texture of a ``raw`` bitmap, as a
  float32 Dr.Jit texture (``float``, what drpt kept before :class:`~drpt.render.texture.Packed8`),
  as ``Packed8`` with the raw codes decoded by a division (``codes raw``) and with an sRGB table
  (``codes sRGB``: twelve table gathers per lookup; drpt keeps sRGB images as float textures);
* ``gradient``: a gray bump map's :meth:`~drpt.render.texture.TextureSet.gradient` texels, from
  the one-channel luminance texture (``luminance``) and from the footprints' codes
  (:class:`~drpt.render.texture.GrayFootprints`, ``footprints``), of a raw map (its codes
  decoded by a division) and of an sRGB one (``gradient sRGB``: by four table gathers).

Positions are ``random`` (uniform over the image: every fetch a cache miss) or ``rows`` (lane
``i`` at pixel ``i`` of 192-lane rows across the image, jittered: a minified map seen by a
camera, as the corpus's spheres show theirs). The variants take turns within each round; the
script prints each one's median milliseconds and its median ratio to the first of its group
(per round, so that load from other processes falls on both). Each variant's values are
checked equal to the first's (bit for bit) once.
"""

from __future__ import annotations

import argparse
import sys
import time

import drjit as dr
import numpy as np
from drjit.auto import PCG32, Array2f, Float, TensorXf, Texture2f, UInt32

from drpt.imageio import decoding_table
from drpt.render.texture import GrayFootprints, Packed8, _luminance_texture


def positions(n: int, kind: str, seed: int) -> Array2f:
    rng = PCG32(n, dr.arange(UInt32, n) + dr.opaque(UInt32, seed * 7919))
    if kind == "random":
        return Array2f(rng.next_float32(), rng.next_float32())
    i = dr.arange(UInt32, n)
    rows = (n + 191) // 192
    return Array2f(Float(i % 192) / 192.0 + rng.next_float32() * 0.005,
                   Float(i // 192) / rows + rng.next_float32() * 0.005)


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--size", type=int, default=2048)
    ap.add_argument("--lookups", type=int, default=1 << 21)
    ap.add_argument("--rounds", type=int, default=7)
    a = ap.parse_args(argv)
    rng = np.random.default_rng(1)
    codes = rng.integers(0, 256, (a.size, a.size, 3), dtype=np.uint8)
    gray = np.ascontiguousarray(codes[..., :1])
    raw, srgb = decoding_table(False), decoding_table(True)
    linear, repeat = dr.FilterMode.Linear, dr.WrapMode.Repeat
    f32 = Texture2f(TensorXf(raw[codes]), filter_mode=linear, wrap_mode=repeat)
    gray_f32 = Texture2f(TensorXf(np.repeat(raw[gray], 3, axis=2)), filter_mode=linear, wrap_mode=repeat)
    lum = _luminance_texture(gray_f32)
    foot = GrayFootprints(gray[..., 0], raw)
    foot_srgb = GrayFootprints(gray[..., 0], srgb)
    lum_srgb = _luminance_texture(Texture2f(TensorXf(np.repeat(srgb[gray], 3, axis=2)), filter_mode=linear,
                                            wrap_mode=repeat))
    groups = {
        "rgb": {"float": lambda p: f32.eval(p), "codes raw": Packed8(codes, raw).eval,
                "codes sRGB": Packed8(codes, srgb).eval},
        "gradient": {"luminance": lambda p: [c[0] for c in lum.eval_fetch(p)],
                     "footprints": lambda p: list(foot.fetch(p, True))},
        "gradient sRGB": {"luminance": lambda p: [c[0] for c in lum_srgb.eval_fetch(p)],
                          "footprints": lambda p: list(foot_srgb.fetch(p, True))},
    }
    print(f"{a.size}x{a.size} texels, {a.lookups} lookups, {a.rounds} rounds; ms (median), ratio to the first")
    for kind in ("random", "rows"):
        for group, ways in groups.items():
            names = list(ways)
            if group == "rgb":  # the float and raw-code textures agree bit for bit
                p = positions(4096, kind, 0)
                assert np.array_equal(np.array(ways["float"](p)), np.array(ways["codes raw"](p)))
            else:  # so do the luminance texture and the footprints
                p = positions(4096, kind, 0)
                assert all(np.array_equal(np.array(x), np.array(y))
                           for x, y in zip(ways["luminance"](p), ways["footprints"](p)))
            t = {k: [] for k in names}
            for r in range(a.rounds + 1):
                for k in names if r % 2 == 0 else reversed(names):
                    v = ways[k](positions(a.lookups, kind, r))
                    s = sum(v[1:], v[0])
                    t0 = time.perf_counter()
                    dr.eval(s)
                    dr.sync_thread()
                    if r > 0:  # round 0 compiles
                        t[k].append(time.perf_counter() - t0)
            base = np.array(t[names[0]])
            line = ", ".join(f"{k} {np.median(t[k]) * 1e3:.1f} ms ({np.median(np.array(t[k]) / base):.2f})"
                             for k in names)
            print(f"{kind:6s} {group:13s}: {line}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
