"""The wavefront integrator (drpt/render/integrators/wavefront.py) against the megakernel.

* Same estimator, path by path: with the same lane streams, the wavefront's
  ``sample`` returns the megakernel's ``sample`` radiance for every lane
  (float rounding aside: measured identical) on the Cornell box and on the
  mixed-material Cornell box (principled, rough and smooth dielectrics,
  diffuse: four shading queues).
* Same estimator, statistically: renders by the two modes at different
  seeds (the megakernel with path regeneration, 4 paths per lane) agree by
  the block z-test of drpt/testing.py (16x16 blocks at 256 spp, max |z| < 4.5);
  negative controls: the wavefront image scaled by 0.97 / 1.03 fails
  (Cornell box; 0.93 / 1.07 on the noisier mixed-material scene), and
  so does a wavefront render whose MIS weights are dropped (emitters hit
  by BSDF samples counted in full as well as by next-event estimation).
* Determinism: the same seed gives the same image bits; another seed does not.
* Compaction: after every bounce the state holds exactly the live paths,
  each once; the sort: keys come out non-decreasing (and the permutation
  is numpy's stable argsort); the queues: each runs only its kinds' lobes.
"""

from __future__ import annotations

from dataclasses import replace

import drjit as dr
import numpy as np
import pytest
from drjit.auto import PCG32, Bool, Float, UInt32

from drpt.errors import DrptError
from drpt.options import PathOptions, RenderOptions
from drpt.render.integrators import wavefront as wf
from drpt.render.integrators.path import PathIntegrator
from drpt.render.renderer import Renderer
from drpt.scene import load_scene
from drpt.testing import block_z

ZMAX = 4.5
BLOCK = 16  # 16 x 16 pixels at 256 spp: 65536 samples per block mean


@pytest.fixture(scope="module")
def scenes(tmp_path_factory, cornell):
    from drpt.tools.scenegen import envsun, materials_cornell

    out = tmp_path_factory.mktemp("wavefront_scenes")
    materials_cornell.main(out)
    loaded = {"cornell": load_scene(cornell),
              "materials": load_scene(out / "materials_cornell.txt"),
              # a sky, a sun, a point light: three estimator slots per path (area-free)
              "envsun": load_scene(envsun.main(out / "env", point=True))}
    return loaded.__getitem__


def _opts(**kw) -> RenderOptions:
    base = dict(width=16, height=16, spp=4, seed=3, progress=False, bsdf="auto")
    base.update(kw)
    return RenderOptions(**base)


def _lane_rays(r: Renderer, n: int, seed: int):
    W = r.opt.width
    lane = dr.arange(UInt32, n)
    px = lane % (W * r.opt.height)
    rng = PCG32(n, initstate=seed)
    o, d = r.camera.ray(Float(px % W) + rng.next_float32(), Float(px // W) + rng.next_float32())
    return rng, o, d


PATH_CASES = [("cornell", 0, {}), ("cornell", 512, {}), ("materials", 0, {}), ("materials", 512, {}),
              ("envsun", 0, {}), ("cornell", 0, {"max_depth": 3, "hide_emitters": True}),
              ("materials", 0, {"rr_prob": 0.7, "rr_depth": 1})]


@pytest.mark.parametrize("name,tail,path", PATH_CASES,
                         ids=[f"{n}-tail{t}-{'-'.join(p) or 'default'}" for n, t, p in PATH_CASES])
def test_same_paths_as_the_megakernel(scenes, name, tail, path):
    """With ``tail``, the last paths finish in one fused loop: still the same paths.
    Also with a depth limit, hidden emitters, a fixed roulette probability."""
    r = Renderer(scenes(name), _opts(path=PathOptions(**path)))
    r.scene.set_delta_each(False)  # (the wavefront selects delta lights with the other emitters)
    n = 4096
    rng, o, d = _lane_rays(r, n, 5)
    mk = PathIntegrator(r.scene, r.opt.path)
    mk.through_glass = False  # (the wavefront has no next-event estimation through glass)
    L_mk = mk.sample(rng, o, d, Bool(True))
    rng, o, d = _lane_rays(r, n, 5)
    integ = wf.WavefrontIntegrator(r.scene, r.opt.path, tail=tail)
    integ.stats = wf.WaveStats()
    L_wf = integ.sample(rng, o, d, Bool(True))
    a, b = (np.stack([c.numpy() for c in (v.x, v.y, v.z)], -1) for v in (L_mk, L_wf))
    assert a.max() > 0.1  # lit
    assert np.all(np.isfinite(b))
    np.testing.assert_allclose(b, a, rtol=1e-4, atol=1e-6)
    assert ("fused tail" in integ.stats.stages) == (tail > 0)
    if tail:  # the wavefront ran the first bounces, the fused loop the rest
        assert integ.stats.live[0][-1] <= tail < integ.stats.live[0][0]


def _render(scene, **kw):
    return Renderer(scene, _opts(**kw)).render()


@pytest.mark.parametrize("name", ["cornell", "materials"])
def test_same_image_where_the_megakernel_runs_one_path_per_lane(scenes, name, monkeypatch):
    """32 x 32 x 8 = 8192 samples, under the megakernel's 2^14 lanes: it traces one
    path per lane on the same streams as the wavefront (measured: bit for bit), the
    megakernel without next-event estimation through glass, which the wavefront lacks."""
    monkeypatch.setattr(PathIntegrator, "through_glass", False)
    a = _render(scenes(name), width=32, height=32, spp=8).image
    b = _render(scenes(name), width=32, height=32, spp=8, mode="wavefront").image
    assert a.mean() > 1e-2
    np.testing.assert_allclose(b, a, rtol=1e-5, atol=1e-7)


# the negative control's bias: at 32 x 32 x 256 the glass and water caustics of
# the materials scene make its block means noisier (3% reads 3.5, 7% reads ~8)
CONTROL = {"cornell": 0.03, "materials": 0.07}


@pytest.mark.parametrize("name", ["cornell", "materials"])
def test_agrees_with_megakernel_statistically(scenes, name):
    scene = scenes(name)
    W = H = 32
    spp = 256  # megakernel: 16 lanes per pixel (min_lanes 2^14), 16 regenerated paths each
    mk = _render(scene, width=W, height=H, spp=spp, seed=1)
    wv = _render(scene, width=W, height=H, spp=spp, seed=2, mode="wavefront")
    assert mk.nonfinite == 0 and wv.nonfinite == 0
    assert wv.image.mean() > 1e-2

    def zmax(img, var):
        return float(np.abs(block_z(img, var, mk.image, mk.variance, block=BLOCK)).max())

    z = zmax(wv.image, wv.variance)
    assert z < ZMAX, z
    for f in (1.0 - CONTROL[name], 1.0 + CONTROL[name]):
        assert zmax(f * wv.image, f * f * wv.variance) > ZMAX, (f, z)


def test_negative_control_without_mis_is_caught(scenes, monkeypatch):
    """Emitters hit by BSDF samples counted in full (MIS weight 1) while
    next-event estimation also counts them: the z-test must fail."""
    scene = scenes("cornell")
    mk = _render(scene, width=32, height=32, spp=64, seed=1)
    # the emission term both integrators share lives in path.py (add_emission)
    from drpt.render.integrators import path as path_module

    monkeypatch.setattr(path_module, "power_heuristic", lambda a, b: dr.select(a > 0.0, Float(1.0), 0.0))
    bad = _render(scene, width=32, height=32, spp=64, seed=2, mode="wavefront")
    z = np.abs(block_z(bad.image, bad.variance, mk.image, mk.variance, block=BLOCK)).max()
    assert z > ZMAX, z


@pytest.mark.parametrize("tail", [0, 256])
def test_deterministic_for_a_seed(scenes, tail):
    scene = scenes("materials")
    a = _render(scene, mode="wavefront", seed=9, wavefront_tail=tail)
    b = _render(scene, mode="wavefront", seed=9, wavefront_tail=tail)
    c = _render(scene, mode="wavefront", seed=10, wavefront_tail=tail)
    assert np.array_equal(a.image, b.image) and np.array_equal(a.variance, b.variance)
    assert not np.array_equal(a.image, c.image)
    mk = _render(scene, seed=9)
    assert np.array_equal(mk.image, _render(scene, seed=9).image)  # and the megakernel, for the record


def test_compaction_keeps_exactly_the_live_paths(scenes, monkeypatch):
    r = Renderer(scenes("materials"), _opts(mode="wavefront"))
    integ = r.integrator
    seen = []
    compact = integ._compact

    def checked(s, alive, timer):
        lanes, ok = s.lane.numpy(), alive.numpy()
        out, m = compact(s, alive, timer)
        if m:
            got = out.lane.numpy()
            assert dr.width(out.o) == dr.width(out.beta) == m == len(got)
            assert len(np.unique(got)) == m  # each live path once
            assert set(got) == set(lanes[ok])  # exactly the live ones: no dead lanes
        seen.append((int(ok.sum()), m))
        return out, m

    monkeypatch.setattr(integ, "_compact", checked)
    integ.stats = wf.WaveStats()
    r.render()
    assert all(alive == m for alive, m in seen)
    live = integ.stats.live[0]
    assert len(live) >= 4 and live[0] == 16 * 16 * 4
    assert all(b <= a for a, b in zip(live, live[1:])) and live[-1] < live[0] // 4


def test_sort_permutation_sorts():
    rng = np.random.default_rng(1)
    keys = rng.integers(0, 1 << wf.KEY_BITS, 50_000).astype(np.uint32)
    keys[::7] = keys[3]  # many equal keys: stability matters
    perm = wf.sort_permutation(UInt32(keys), wf.KEY_BITS).numpy()
    assert np.all(np.diff(keys[perm].astype(np.int64)) >= 0)
    assert np.array_equal(perm, np.argsort(keys, kind="stable"))


def test_rays_are_sorted_by_octant_then_morton(scenes, monkeypatch):
    r = Renderer(scenes("cornell"), _opts(mode="wavefront"))
    integ = r.integrator
    checked = []
    compact = integ._compact

    def check(s, alive, timer):
        out, m = compact(s, alive, timer)
        if m > 1:
            key = wf.ray_key(out.o, out.d, *integ._bounds).numpy().astype(np.int64)
            assert np.all(np.diff(key) >= 0)
            octant = key >> (3 * wf.MORTON_BITS)
            checked.append(len(np.unique(octant)))
        return out, m

    monkeypatch.setattr(integ, "_compact", check)
    r.render()
    assert len(checked) >= 3 and max(checked) >= 4  # bounced rays go in several octants


def test_unsorted_mode_gives_the_same_image(scenes):
    """The ray order changes which lane runs a path, not the path: the image
    without the coherence sort is the same, bit for bit."""
    scene = scenes("materials")
    r = Renderer(scene, _opts(mode="wavefront"))
    a = r.render()
    r.integrator.sort = False
    b = r.render()
    assert np.array_equal(a.image, b.image)


def test_each_queue_runs_only_its_lobes(scenes, monkeypatch):
    r = Renderer(scenes("materials"), _opts(mode="wavefront"))
    integ = r.integrator
    kinds = [q.kinds for q in integ.queues]
    assert len(kinds) >= 4 and all(len(k) == 1 for k in kinds), kinds
    ran: list[tuple[tuple, str]] = []
    current = [None]
    table = r.scene.materials
    for kind, mod in table.lobes.items():
        for fn in ("sample", "eval", "pdf"):
            orig = getattr(mod, fn)

            def wrapped(*a, _orig=orig, _kind=kind, **k):
                ran.append((current[0], _kind))
                return _orig(*a, **k)

            monkeypatch.setattr(mod, fn, wrapped)
    shade = integ._shade

    def tagged(queue, s, si):
        current[0] = queue.kinds
        # every lane of the queue has a material of the queue's kinds
        mats = si.material.numpy()
        assert all(table.material_kinds[m] == queue.kinds for m in mats)
        out = shade(queue, s, si)
        current[0] = None
        return out

    monkeypatch.setattr(integ, "_shade", tagged)
    r.render()
    assert ran and all(q is not None and k in q for q, k in ran), set(ran)
    assert {k for _, k in ran} == set(table.kinds)


def test_empty_scene(tmp_path):
    """No primitives: every camera ray escapes to the background; nothing to shade."""
    (tmp_path / "e.txt").write_text("PerspectiveCamera { center 0 0 5 direction 0 0 -1 up 0 1 0 angle 45 }\n"
                                    "Background { color 0.25 0.5 0.75 }\n")
    scene = load_scene(tmp_path / "e.txt")
    img = _render(scene, mode="wavefront").image
    np.testing.assert_allclose(img, _render(scene).image)
    np.testing.assert_allclose(img.reshape(-1, 3).mean(0), [0.25, 0.5, 0.75], rtol=1e-6)


def test_mode_options():
    with pytest.raises(DrptError, match="wavefront"):
        replace(_opts(), mode="wavefront", integrator="whitted").validate()
    with pytest.raises(DrptError, match="--mode"):
        replace(_opts(), mode="fused").validate()
    with pytest.raises(DrptError, match="--wavefront-tail"):
        replace(_opts(), mode="wavefront", wavefront_tail=-1).validate()


def test_cli_render_wavefront(tmp_path, cornell):
    from drpt.cli import main

    out = tmp_path / "wf.exr"
    assert main(["render", str(cornell), "--size", "8", "8", "--spp", "2",
                 "--mode", "wavefront", "--wavefront-tail", "16", "-q", "-o", str(out)]) == 0
    assert out.is_file()
