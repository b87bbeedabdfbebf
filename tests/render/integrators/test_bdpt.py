"""Bidirectional path tracing (drpt/render/integrators/bdpt.py).

MIS weights: the recursive quantities the integrator carries along its subpaths
(``hit_update``, ``scatter_update``) and its weight functions (``connection_weight``,
``nee_weight``, ``emission_weight``) are run on random paths (random distances, cosines
and BSDF densities, some vertices Dirac, area or point lights) and must give pbrt's
weights computed from the whole path (``mis_weights_reference``, relative error < 1e-3)
and sum to 1 over the strategies of each path. Negative control: a wrong reverse density
in one update makes them disagree.

Images: 8x8-block z-tests (``drpt.testing.block_z``) of bdpt against the path tracer on the
same scene with the same ``max_depth`` (both with drpt's per-pixel variance estimates),
threshold |z| < 4.5 over every block and channel, and the z of the image means < 4: the
bundled Cornell box, a small scene of diffuse and Phong surfaces lit by a point light, a
spot light, or a directional light and a background color, one of glass, mirror, Phong and
diffuse surfaces lit by an emissive sphere (the path tracer then needs 1024 spp: its
caustics are fireflies), and envsun's sky with a sun and a point light. Negative controls: a missing cosine in the
connection of light and camera vertices, and a wrong density in the weights of next-event
estimation, must fail the same test (|z| > 6).

Each strategy alone (weight 1 for it, 0 for the others) against the path tracer's image of
the paths of that many bounces (Cornell box, 1 and 2 bounces, six strategies), with a
strategy of the wrong length as the negative control.

These render independent samples (``--sampler independent``; the thresholds were set for
them); bdpt's default, ``ldsampler``, and ``zsobol`` have z-tests and a dimension test of
their own.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Bool, Float, UInt32

from drpt.errors import DrptError
from drpt.options import PathOptions, RenderOptions
from drpt.render.integrators import bdpt as B
from drpt.render.renderer import Renderer
from drpt.render.sampler import LDSampler
from drpt.scene import load_scene
from support import bdpt_bugs

REPO = Path(__file__).resolve().parents[3]


# ------------------------------------------------------------ MIS weights
def _random_paths(rng, n, k, delta_light, infinite=False):
    """``n`` random paths of ``k`` segments: per path the geometry and densities."""
    P = {
        "d2": rng.uniform(0.05, 4.0, (n, k)),  # squared length of edge i (x_i -- x_{i+1})
        "cp": rng.uniform(0.05, 1.0, (n, k + 1)),  # |cos| at x_i of edge i
        "cm": rng.uniform(0.05, 1.0, (n, k + 1)),  # |cos| at x_i of edge i - 1
        "a": rng.uniform(0.05, 3.0, (n, k + 1)),  # BSDF density at x_i toward x_{i+1} (from x_{i-1})
        "b": rng.uniform(0.05, 3.0, (n, k + 1)),  # toward x_{i-1} (from x_{i+1})
        "e0": rng.uniform(0.05, 1.0, n),  # emission direction density at x_0
        "pL0": rng.uniform(0.1, 2.0, n),  # light subpath origin density
        "pnee": rng.uniform(0.1, 2.0, n),  # next-event estimation's density of x_0
        "cdir": rng.uniform(0.5, 3.0, n),  # camera direction density of the pixel sample
        "delta": rng.uniform(size=(n, k + 1)) < 0.25,
    }
    P["delta"][:, 0] = P["delta"][:, k] = False
    if delta_light:
        P["pnee"][:] = 1.0
    if infinite:  # x_0 is a direction: no distance, no cosine there
        P["d2"][:, 0] = 1.0
        P["cp"][:, 0] = 1.0
    # a Dirac vertex's own densities count as 1
    P["a"] = np.where(P["delta"], 1.0, P["a"])
    P["b"] = np.where(P["delta"], 1.0, P["b"])
    return P


def _pbrt_weights(P, j, k, delta_light, N, choices=1.0):
    fwd = [P["pL0"][j]] + [(P["e0"][j] if i == 1 else P["a"][j, i - 1]) * P["cm"][j, i] / P["d2"][j, i - 1]
                           for i in range(1, k + 1)]
    rev = [(P["cdir"][j] if i == k - 1 else P["b"][j, i + 1]) * P["cp"][j, i] / P["d2"][j, i]
           for i in range(k)] + [1.0]
    return B.mis_weights_reference(fwd, rev, list(P["delta"][j]), P["pnee"][j], delta_light, N, 1.0 / choices)


def _recursive(P, k, delta_light, N, wrong_rev=False, infinite=False, choices=1.0, k_weights=None,
               share=1.0, share_weights=None):
    """Each strategy's weight from the integrator's functions, per path (Dr.Jit lanes), with
    connections counted as chosen among ``choices`` (the subpaths' starting quantities times
    ``K = choices^2``, as the integrator's) and the ``t = 1`` strategy counted ``share``
    times as often as the connections (:attr:`~drpt.render.integrators.bdpt.BDPTIntegrator.share`:
    the camera's starting ``dvcm`` times ``m(share)``, the splat's weight's ``k`` too;
    ``share_weights``: the negative control's factor in the splat's weight)."""
    SW = share if share_weights is None else share_weights
    K = choices * choices
    KW = K if k_weights is None else k_weights  # (the negative control's: another one in the weights)
    F = {key: (Float(v.astype(np.float32)) if v.ndim == 1 else [Float(v[:, i].astype(np.float32))
                                                                   for i in range(v.shape[1])])
         for key, v in P.items() if key != "delta"}
    D = [Bool(P["delta"][:, i]) for i in range(k + 1)]
    emit = F["pL0"] * F["e0"]

    def light_side(s):  # dvcm, dvc at x_{s-1}
        dvcm = K * B.mis(F["pnee"] / emit)
        dvc = Float(0.0) if delta_light else K * B.mis(F["cp"][0] / emit)
        for j in range(1, s):
            # the first segment from an infinite emitter has no length (as the integrator's)
            dvcm, dvc = B.hit_update(dvcm, dvc, Float(1.0) if infinite and j == 1 else F["d2"][j - 1],
                                     F["cm"][j])
            if j < s - 1:
                rev = F["b"][j] * (1.5 if wrong_rev and j == 1 else 1.0)
                dvcm, dvc = B.scatter_update(dvcm, dvc, F["a"][j], rev, F["cp"][j], D[j])
        return dvcm, dvc

    def camera_side(s):  # dvcm, dvc at x_s
        dvcm, dvc = K * B.mis(N * share / F["cdir"]), Float(0.0)
        for i in range(k - 1, s - 1, -1):
            if i == 0 and infinite:
                break  # an escaped ray: nothing to convert
            dvcm, dvc = B.hit_update(dvcm, dvc, F["d2"][i], F["cp"][i])
            if i > s:
                dvcm, dvc = B.scatter_update(dvcm, dvc, F["b"][i], F["a"][i], F["cm"][i], D[i])
        return dvcm, dvc

    out = []
    for s in range(k + 1):
        if s == 0:
            dvcm, dvc = camera_side(0)
            w = Float(0.0) if delta_light else B.emission_weight(F["pnee"], emit, dvcm, dvc, KW)
            w = w if k > 1 else Float(0.0 if delta_light else 1.0)  # seen by the camera: weight 1
        elif s == 1:
            dvcm, dvc = camera_side(1)
            pdf_light = F["pnee"] * F["d2"][0] / F["cp"][0]
            fwd = Float(0.0) if delta_light else F["b"][1]
            w = B.nee_weight(fwd, pdf_light, emit, F["cm"][1], F["cp"][0], dvcm, dvc, F["a"][1], KW)
            w = dr.select(D[1], 0.0, w) if k > 1 else Float(0.0)
        else:
            dvcm_l, dvc_l = light_side(s)
            pdf_l = (F["cdir"] / N if s == k else F["b"][s]) * F["cp"][s - 1] / F["d2"][s - 1]
            if s == k:
                w = B.connection_weight(pdf_l, dvcm_l, dvc_l, F["b"][s - 1], Float(0.0), Float(0.0),
                                        Float(0.0), Float(0.0), KW * B.mis(SW))
            else:
                dvcm_c, dvc_c = camera_side(s)
                pdf_c = F["a"][s - 1] * F["cm"][s] / F["d2"][s - 1]
                w = B.connection_weight(pdf_l, dvcm_l, dvc_l, F["b"][s - 1], pdf_c, dvcm_c, dvc_c,
                                        F["a"][s])
            w = dr.select(D[s - 1] | (D[s] if s < k else Bool(False)), 0.0, w)
        out.append(np.broadcast_to(np.asarray(w.numpy(), np.float64), (len(P["e0"]),)))
    return np.stack(out, axis=1)


@pytest.mark.parametrize("k", [1, 2, 3, 5, 7])
@pytest.mark.parametrize("light", ["area", "point", "sky", "directional"])
@pytest.mark.parametrize("choices", [1.0, B.CONNECTION_CHOICES, 3.5])
def test_mis_weights_match_pbrts_and_sum_to_one(k, light, choices):
    """``sky``: an infinite emitter (the reference's densities of ``x_0`` and ``x_1`` are
    then solid angles and the disk's density times the cosine at ``x_1``, the integrator's
    skip the first segment's distance); ``directional``: infinite and Dirac. ``choices``:
    connections counted with their density over it (``CONNECTION_CHOICES``), in the
    reference too."""
    delta_light, infinite = light in ("point", "directional"), light in ("sky", "directional")
    rng = np.random.default_rng(10 * k + len(light))
    n, N = 300, 64.0
    P = _random_paths(rng, n, k, delta_light, infinite)
    got = _recursive(P, k, delta_light, N, infinite=infinite, choices=choices)
    ref = np.array([_pbrt_weights(P, j, k, delta_light, N, choices) for j in range(n)])
    # paths no strategy samples (a point light seen directly, or through Dirac vertices only)
    # have no weights
    possible = ref.sum(1) > 0
    assert possible.mean() > 0.5 or (delta_light and k == 1)
    assert np.allclose(ref[possible].sum(1), 1.0, atol=1e-9)
    assert np.allclose(got[possible].sum(1), 1.0, atol=2e-4), np.abs(got[possible].sum(1) - 1).max()
    assert np.allclose(got, ref, rtol=1e-3, atol=1e-5), np.abs(got - ref).max()


def test_mis_weights_negative_control():
    """A reverse density 1.5x too large at one light vertex breaks the sum."""
    k, n = 5, 300
    P = _random_paths(np.random.default_rng(3), n, k, False)
    got = _recursive(P, k, False, 64.0, wrong_rev=True)
    assert np.abs(got.sum(1) - 1.0).max() > 1e-2


def test_mis_weights_connection_factor_negative_control():
    """The connections' factor on the subpaths' starting quantities without its ``1 / k`` in
    the other strategies' weights breaks the sum."""
    k, n = 5, 300
    P = _random_paths(np.random.default_rng(4), n, k, False)
    assert np.abs(_recursive(P, k, False, 64.0, choices=2.0).sum(1) - 1.0).max() < 2e-4
    got = _recursive(P, k, False, 64.0, choices=2.0, k_weights=1.0)
    assert np.abs(got.sum(1) - 1.0).max() > 1e-2


@pytest.mark.parametrize("k", [2, 3, 5])
@pytest.mark.parametrize("light", ["area", "sky"])
def test_mis_weights_with_the_light_subpath_counted_as_a_share_match_pbrts(k, light):
    """With a low-discrepancy sampler every strategy with ``s >= 2`` is counted
    ``LD_LIGHT_SHARE`` times against ``s = 0, 1`` (the integrator's ``k = m(choices /
    share)`` on both subpaths' starting quantities, ``k m(share)`` on the camera's starting
    ``dvcm`` and in the splat's weight): the weights are pbrt's with ``N LD_LIGHT_SHARE``
    light paths and the connections counted ``LD_LIGHT_SHARE / choices`` times, and sum to 1."""
    infinite = light == "sky"
    share = B.LD_LIGHT_SHARE
    assert share != 1.0
    rng = np.random.default_rng(100 + 10 * k + len(light))
    n, N = 300, 64.0
    P = _random_paths(rng, n, k, False, infinite)
    for choices in (1.0, B.CONNECTION_CHOICES):
        got = _recursive(P, k, False, N, infinite=infinite, choices=choices / share, share=share)
        ref = np.array([_pbrt_weights(P, j, k, False, N * share, choices / share) for j in range(n)])
        possible = ref.sum(1) > 0
        assert possible.mean() > 0.5
        assert np.allclose(got[possible].sum(1), 1.0, atol=2e-4), np.abs(got[possible].sum(1) - 1).max()
        assert np.allclose(got, ref, rtol=1e-3, atol=1e-5), np.abs(got - ref).max()
        # the weights do move: light tracing's is not the one of N light paths
        plain = np.array([_pbrt_weights(P, j, k, False, N, choices) for j in range(n)])
        assert np.abs(got[:, k] - plain[:, k]).max() > 1e-2
        assert np.abs(got[:, 1] - plain[:, 1]).max() > 1e-2


def test_mis_weights_share_negative_control():
    """The share on the camera's starting ``dvcm`` without its factor in the splat's weight
    breaks the sum."""
    k, n = 4, 300
    P = _random_paths(np.random.default_rng(5), n, k, False)
    share = B.LD_LIGHT_SHARE
    got = _recursive(P, k, False, 64.0, choices=1.0 / share, share=share, share_weights=1.0)
    assert np.abs(got.sum(1) - 1.0).max() > 1e-2


@pytest.mark.parametrize("sampler", ["independent", "auto", "ldsampler", "zsobol", "stratified"])
def test_the_light_share_is_the_low_discrepancy_samplers_only(sampler):
    """Independent samples keep the power heuristic over the plain densities (their kernels and
    images unchanged); every low-discrepancy sampler (``auto`` is ``ldsampler`` for bdpt) counts
    the light subpath's strategies ``LD_LIGHT_SHARE`` times, its connections' factor with it."""
    scene = load_scene(REPO / "scenes" / "cornellbox" / "cornellbox.txt")
    r = Renderer(scene, RenderOptions(width=8, height=8, spp=4, integrator="bdpt", sampler=sampler,
                                      progress=False))
    share = 1.0 if sampler == "independent" else B.LD_LIGHT_SHARE
    assert r.integrator.share == share
    assert r.integrator.k == pytest.approx(B.mis(B.CONNECTION_CHOICES / share))


# ------------------------------------------------------------ images
POINT_SCENE = """
PerspectiveCamera { center 0 1 4.5 direction 0 -0.15 -1 up 0 1 0 angle 45 }
%s
Materials { numMaterials 6
  Material { diffuseColor 0.7 0.7 0.7 }
  Material { diffuseColor 0.2 0.6 0.2 }
  Material { transparentColor 1 1 1 indexOfRefraction 1.5 }
  Material { reflectiveColor 0.9 0.9 0.9 }
  Material { diffuseColor 0.3 0.2 0.5 specularColor 0.5 0.5 0.5 exponent 30 }
  Material { Ke 12 10 8 }
}
Group { numObjects %d
  MaterialIndex 0
  Triangle { vertex0 -2 0 -2 vertex1 2 0 2 vertex2 2 0 -2 }
  Triangle { vertex0 -2 0 -2 vertex1 -2 0 2 vertex2 2 0 2 }
  Triangle { vertex0 -2 0 -2 vertex1 2 0 -2 vertex2 2 3 -2 }
  Triangle { vertex0 -2 0 -2 vertex1 2 3 -2 vertex2 -2 3 -2 }
  MaterialIndex 1
  Triangle { vertex0 -2 0 -2 vertex1 -2 3 -2 vertex2 -2 3 2 }
  Triangle { vertex0 -2 0 -2 vertex1 -2 3 2 vertex2 -2 0 2 }
  MaterialIndex %d
  Sphere { center 0.3 0.5 0 radius 0.5 }
  MaterialIndex %d
  Sphere { center -1.0 0.4 -1.0 radius 0.4 }
  MaterialIndex 4
  Sphere { center 1.2 0.35 -0.8 radius 0.35 }
  %s
}
"""


def _scene(tmp_path_factory, name):
    """``point``: diffuse and Phong surfaces under a point light; ``specular``: glass,
    mirror, Phong and diffuse surfaces lit by a small emissive sphere (caustics that the
    path tracer finds by chance)."""
    if name == "point":
        text = POINT_SCENE % ("Lights { numLights 1 PointLight { position -0.6 2.2 0.8 color 4 4 4 } }",
                              9, 0, 4, "")
    else:
        text = POINT_SCENE % ("", 10, 2, 3, "MaterialIndex 5\n  Sphere { center 0.9 2.0 0.3 radius 0.15 }")
    path = tmp_path_factory.mktemp("bdpt") / f"{name}.txt"
    path.write_text(text)
    return load_scene(path)


def _spot_scene(point):
    """The point-light scene lit by a spot light instead (Mitsuba XML's ``spot``)."""
    from drpt.scene.model import SpotLight

    return replace(point, lights=[SpotLight((0.5, 2.5, 1.0), (-0.3, -1.0, -0.5), (6.0, 5.0, 4.0), 30.0, 20.0)])


def _render(scene, integrator, spp, depth, seed=1, size=32):
    """A renderer of independent samples: the z-tests' thresholds hold for drpt's variance
    estimate of independent samples (the low-discrepancy samplers, bdpt's default, have
    tests of their own below)."""
    opts = RenderOptions(width=size, height=size, spp=spp, seed=seed, integrator=integrator,
                         progress=False, path=PathOptions(max_depth=depth), variance=True, sampler="independent")
    return Renderer(scene, opts)


def _agree(a, b):
    """Block z and the means' z; pixels of one constant value (the background) have no
    variance but float rounding: a floor of 1e-5 relative."""
    from drpt.testing import agreement

    return agreement(a, b, floor=1e-5)


#: (scene, max_depth, bdpt spp, path spp): the path tracer's caustics need many samples
CASES = {"cornell": (8, 256, 1024), "point": (6, 128, 512), "spot": (6, 128, 512),
         "specular": (6, 128, 1024), "sky": (5, 64, 256), "directional": (5, 128, 512)}


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    import warnings

    from drpt.scene.model import DirectionalLight
    from drpt.tools.scenegen import envsun

    point = _scene(tmp_path_factory, "point")
    with warnings.catch_warnings():  # envsun's glossy material is scaled to reflect 1 (a note)
        warnings.simplefilter("ignore")
        sky = load_scene(envsun.main(tmp_path_factory.mktemp("envsun"), mtl="glossy", point=True))
    sun = replace(point, lights=[DirectionalLight((0.4, -1.0, -0.6), (1.5, 1.4, 1.2))],
                  background=replace(point.background, color=(0.3, 0.35, 0.5)))
    return {"cornell": load_scene(REPO / "scenes" / "cornellbox" / "cornellbox.txt"),
            "point": point, "spot": _spot_scene(point),
            "specular": _scene(tmp_path_factory, "specular"), "sky": sky, "directional": sun}


@pytest.fixture(scope="module")
def references(scenes):
    return {}


def _reference(scenes, references, name):
    if name not in references:
        depth, _, spp = CASES[name]
        references[name] = _render(scenes[name], "path", spp, depth, seed=7).render()
    return references[name]


@pytest.mark.slow
@pytest.mark.parametrize("name", list(CASES))
def test_bdpt_agrees_with_path_tracing(scenes, references, name):
    depth, spp, _ = CASES[name]
    r = _render(scenes[name], "bdpt", spp, depth).render()
    assert r.nonfinite == 0 and np.all(np.isfinite(r.image)) and r.image.mean() > 0.01
    zb, zm = _agree(r, _reference(scenes, references, name))
    assert zb < 4.5 and zm < 4.0, (zb, zm)


@pytest.mark.slow
@pytest.mark.parametrize("name,what", [("cornell", "no cosine at the light vertex"),
                                       ("point", "no cosine at the light vertex"),
                                       ("cornell", "a wrong density in next-event estimation's weight"),
                                       ("cornell", "the camera throughput twice in connections")])
def test_negative_controls_fail(scenes, references, monkeypatch, name, what):
    """Each must fail the test the integrator passes. The last one was a bug (a 1.3% too
    dark Cornell box at depth 8) that 64 spp against 256 did not show: hence the
    Cornell box's 256 against 1024. That control runs with ``CONNECTION_CHOICES = 1`` (the
    weights of joining every pair): the default's smaller connection weights leave its bias
    at |z| ~ 5.3."""
    bdpt_bugs.put(monkeypatch, what)
    depth, spp, _ = CASES[name]
    zb, _ = _agree(_render(scenes[name], "bdpt", spp, depth).render(), _reference(scenes, references, name))
    assert zb > 6.0, zb


def test_bdpt_variance_estimate_is_calibrated(scenes):
    """Two renders of different seeds differ by their estimated variances: the per-pixel
    z has a standard deviation near 1 (0.9-1.1 over 3072 pixel channels)."""
    a = _render(scenes["cornell"], "bdpt", 16, 5, seed=1).render()
    b = _render(scenes["cornell"], "bdpt", 16, 5, seed=2).render()
    z = (a.image - b.image) / np.sqrt(a.variance + b.variance + 1e-12)
    assert 0.9 < z.std() < 1.1, z.std()


# ------------------------------------------------------------ what it refuses
def test_bdpt_refuses_what_it_cannot_render(scenes):
    cornell = scenes["cornell"]
    lens = replace(cornell, camera=replace(cornell.camera, aperture_radius=0.1, focus_distance=3.0))
    with pytest.raises(DrptError, match="pinhole"):
        _render(lens, "bdpt", 1, 5)
    with pytest.raises(DrptError, match="at most 16 segments"):
        _render(cornell, "bdpt", 1, 40)
    r = _render(cornell, "bdpt", 1, -1)
    assert any("at most 16 segments" in w for w in r.warnings)


# ------------------------------------------------------------ chunks, workers, resume
def _cli_render(tmp_path, name, *flags, spp=16):
    from drpt.cli import main
    from drpt.imageio import read_image

    out = tmp_path / f"{name}.exr"
    scene = REPO / "scenes" / "cornellbox" / "cornellbox.txt"
    assert main(["render", str(scene), "--size", "16", "16", "-q", "--integrator", "bdpt", "--max-depth", "5",
                 "--spp", str(spp), "-o", str(out), *flags]) == 0
    return read_image(out)


@pytest.mark.slow
def test_workers_give_the_plain_image(tmp_path):
    """As light tracing's: the float32 image of a chunk layout is the same in one process
    and on Dask workers (the splats' float64 sums differ at most in their last bits), with
    the default sampler (``ldsampler``) and with ``independent``; with ``independent``
    another layout draws other random numbers (negative control: a comparison that can
    fail; ``ldsampler``'s numbers follow the sample, not the layout)."""
    plain = _cli_render(tmp_path, "plain", "--chunk-spp", "4")
    indep = _cli_render(tmp_path, "indep", "--chunk-spp", "4", "--sampler", "independent")
    assert not np.array_equal(indep, _cli_render(tmp_path, "chunks", "--chunk-spp", "1", "--sampler", "independent"))
    pytest.importorskip("distributed")
    assert np.array_equal(plain, _cli_render(tmp_path, "w2", "--chunk-spp", "4", "--workers", "2"))
    assert np.array_equal(indep, _cli_render(tmp_path, "w2i", "--chunk-spp", "4", "--workers", "2",
                                             "--sampler", "independent"))


@pytest.mark.slow
def test_resume_after_an_interrupt_gives_the_uninterrupted_image(tmp_path):
    import json
    import signal
    import subprocess
    import sys
    import time

    spp, chunk = 128, 2
    whole = _cli_render(tmp_path, "whole", "--chunk-spp", str(chunk), spp=spp)
    out = tmp_path / "cut.exr"
    meta = Path(str(out) + ".drpt-checkpoint.json")
    cmd = [sys.executable, "-m", "drpt", "render", str(REPO / "scenes" / "cornellbox" / "cornellbox.txt"),
           "--size", "16", "16", "-q", "--integrator", "bdpt", "--max-depth", "5", "--spp", str(spp),
           "--chunk-spp", str(chunk), "--checkpoint-seconds", "0", "-o", str(out)]
    p = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    t0 = time.monotonic()
    while not meta.exists() and p.poll() is None and time.monotonic() - t0 < 120:
        time.sleep(0.02)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=120)
    assert p.returncode == 130, err
    state = json.loads(meta.read_text())
    assert 0 < state["next"] < state["chunks"]
    assert np.array_equal(whole, _cli_render(tmp_path, "cut", "--chunk-spp", str(chunk), "--resume", spp=spp))


# ------------------------------------------------------------ the variance film
@pytest.mark.parametrize("integrator", ["bdpt", "ptracer"])
def test_without_variance_no_squares_are_summed_and_the_image_is_the_same(scenes, monkeypatch, integrator):
    """``RenderOptions.variance`` off (the default): the light-traced passes' films keep no
    squares and the result's variance is NaN; the image is the one a render with the
    variance gives (float32, bit for bit). On: every film sums its squares, the variance
    is finite. Negative control: the images of another seed differ."""
    from drpt.render import renderer as R

    made = []

    class Film(R.SplatFilm):
        def __init__(self, *a, **kw):
            super().__init__(*a, **kw)
            made.append(bool(self.sq))

    monkeypatch.setattr(R, "SplatFilm", Film)
    opts = RenderOptions(width=16, height=16, spp=8, seed=3, integrator=integrator, progress=False,
                         path=PathOptions(max_depth=5))
    off = Renderer(scenes["cornell"], opts).render()
    assert made and not any(made), made
    assert np.isnan(off.variance).all() and off.image.shape == off.variance.shape
    made.clear()
    on = Renderer(scenes["cornell"], replace(opts, variance=True)).render()
    assert made and all(made), made
    assert np.isfinite(on.variance).all() and on.variance.max() > 0.0
    assert np.array_equal(off.image, on.image)
    assert not np.array_equal(off.image, Renderer(scenes["cornell"], replace(opts, seed=4)).render().image)


def test_a_stop_rule_or_adaptive_sampling_sums_the_squares():
    """:attr:`RenderOptions.light_variance`: the variance option, or a target error, a time
    limit or adaptive sampling (which read the estimated variance)."""
    o = RenderOptions(integrator="bdpt")
    assert not o.light_variance
    for change in ({"variance": True}, {"target_error": 0.01}, {"time_limit": 5.0}, {"adaptive": True}):
        assert replace(o, **change).light_variance, change


def test_checkpoints_record_the_variance_flag_of_light_tracing_only():
    """The checkpoint's options key holds ``variance`` (the squares summed or not) for
    ptracer and bdpt, not for the camera integrators (whose squares are always summed:
    their checkpoints are those of before the option)."""
    from drpt.distributed.checkpoint import options_key

    for integrator in ("bdpt", "ptracer"):
        o = RenderOptions(integrator=integrator)
        assert options_key(o)["variance"] is False
        assert options_key(replace(o, variance=True))["variance"] is True
        assert options_key(replace(o, time_limit=3.0))["variance"] is True
    for integrator in ("path", "volpath", "whitted"):
        o = RenderOptions(integrator=integrator)
        assert "variance" not in options_key(o)
        assert options_key(o) == options_key(replace(o, variance=True))


@pytest.mark.parametrize("first,then", [(False, True), (True, False)])
def test_resume_refuses_another_variance_flag(tmp_path, scenes, first, then):
    """A bdpt render interrupted with one ``variance`` flag is refused when resumed with the
    other: one line naming the checkpoint and the option (the CLI exits 2 on it); resumed
    with its own flag it finishes (control)."""
    from drpt.distributed.job import run

    opts = RenderOptions(width=8, height=8, spp=4, seed=7, integrator="bdpt", progress=False, chunk_spp=1,
                         path=PathOptions(max_depth=4), variance=first)

    def interrupt(merged, result, engine):
        if merged.next >= 2:
            raise KeyboardInterrupt

    out = tmp_path / "cut.exr"
    with pytest.raises(KeyboardInterrupt):
        run(scenes["cornell"], opts, out, on_chunk=interrupt, checkpoint_seconds=0.0)
    with pytest.raises(DrptError) as e:
        run(scenes["cornell"], replace(opts, variance=then), out, resume=True)
    message = str(e.value)
    assert "\n" not in message and "cut.exr" in message, message
    assert f"rendered {'with' if first else 'without'} the squared splats" in message, message
    done = run(scenes["cornell"], opts, out, resume=True).result
    assert done.image.shape == (8, 8, 3) and np.isnan(done.variance).all() != first


# ------------------------------------------------------------ against Mitsuba
@pytest.mark.slow
@pytest.mark.mitsuba
@pytest.mark.parametrize("name", ["ptracer", "sphere_light", "projector_spot"])
def test_bdpt_of_an_xml_scene_agrees_with_mitsubas_path(name):
    """bdpt against Mitsuba's path on the same file (as light tracing's test): ptracer.xml
    (an area light, point, spot and directional lights and an environment map; Mitsuba
    renders it with path), sphere_light.xml (analytic sphere lights and a rectangle
    light), both with max_depth 4, and projector_spot.xml (a textured projector and a
    textured spot light; Mitsuba's direct) and Mitsuba's default Gaussian filter (bdpt splats its
    camera samples with normalized filter weights, as light tracing splats); Mitsuba's
    variance from 8 seeds; 8x8 blocks, |z| < 4.5, the means' z < 4."""
    from drpt.testing import block_z
    from support.xml import XML, mean_z, render_xml_both

    path = XML / f"{name}.xml"
    scene = load_scene(path, defines={"spp": "256"})
    defines = {"integrator": "path"} if name == "ptracer" else {}
    r, ref, var = render_xml_both(scene, path, 256, defines, ref_spp=512, integrator="bdpt")
    z = block_z(r.image, r.variance, ref, var)
    zm = mean_z(r, ref, var)
    assert np.abs(z).max() < 4.5 and np.abs(zm).max() < 4.0, (np.abs(z).max(), np.abs(zm).max())


@pytest.mark.slow
@pytest.mark.mitsuba
def test_a_projectors_density_apart_in_next_event_estimation_fails(monkeypatch):
    """Negative control of projector_spot.xml's row above (a textured projector, whose light
    subpaths leave it with the direction density ``1 / (A cos^3)``): next-event estimation's
    MIS weight reading the density without its ``cos^3``, while the light subpath's start
    keeps it, makes the weights of a path's strategies sum to other than 1: |z| > 6 (11.3
    over the blocks, 9.8 for the means; the test itself 2.8 and 2.0)."""
    import sys

    from drpt.testing import block_z
    from support.xml import XML, mean_z, render_xml_both

    emit = B.BDPTIntegrator._delta_emit

    def apart(self, light, d=None):
        if getattr(light, "fov_x", None) is not None and sys._getframe(1).f_code.co_name == "_nee_delta":
            t = math.tan(math.radians(light.fov_x) / 2.0)
            return self.pick / (4.0 * t * t / light.aspect)
        return emit(self, light, d)

    monkeypatch.setattr(B.BDPTIntegrator, "_delta_emit", apart)
    path = XML / "projector_spot.xml"
    r, ref, var = render_xml_both(load_scene(path, defines={"spp": "256"}), path, 256, {}, ref_spp=512,
                                  integrator="bdpt")
    assert max(np.abs(block_z(r.image, r.variance, ref, var)).max(), np.abs(mean_z(r, ref, var)).max()) > 6.0


# ------------------------------------------------------------ --bdpt-strategies
def test_strategy_images_sum_to_the_image(tmp_path, capsys):
    """``--bdpt-strategies`` at ``--max-depth 4``: the 13 used strategies of paths of 1..4
    segments (``(1, 1)`` is not used), each image non-negative, the direct view (``s = 0,
    t = 2``) and light tracing's direct light (``s = 2, t = 1``) not black (its mean here is
    about 0.006, the light subpath counted ``LD_LIGHT_SHARE`` times by the default
    ``ldsampler``), and their sum the image; refused without bdpt and with workers (one line,
    exit status 2)."""
    import glob

    from drpt.cli import main
    from drpt.imageio import read_image

    image = _cli_render(tmp_path, "c", "--max-depth", "4", "--bdpt-strategies", spp=8)
    files = sorted(glob.glob(str(tmp_path / "c.bdpt_d*_s*_t*.exr")))
    assert len(files) == 13
    parts = {Path(f).name.split(".")[1]: read_image(f) for f in files}
    assert all(p.min() >= 0.0 for p in parts.values())
    assert parts["bdpt_d0_s0_t2"].max() > 1.0 and parts["bdpt_d1_s2_t1"].mean() > 0.002
    total = sum(parts.values())
    assert np.allclose(total, image, rtol=1e-5, atol=1e-6), np.abs(total - image).max()
    scene = str(REPO / "scenes" / "cornellbox" / "cornellbox.txt")
    for flags in (["--integrator", "path"], ["--integrator", "bdpt", "--workers", "2"]):
        capsys.readouterr()
        rc = main(["render", scene, "--size", "8", "8", "-q", "--bdpt-strategies", *flags,
                   "-o", str(tmp_path / "x.exr")])
        err = capsys.readouterr().err.strip().splitlines()
        assert rc == 2 and len(err) == 1 and "--bdpt-strategies" in err[0], err


# ------------------------------------------------------------ each strategy alone
class _Image:
    def __init__(self, image, variance):
        self.image, self.variance = image, variance


@pytest.fixture(scope="module")
def bounce_references(scenes):
    """The Cornell box's paths of exactly 1 and exactly 2 bounces: the path tracer's depth 2
    minus depth 1 (what the camera sees directly), depth 3 minus depth 2, each render its own
    seed. (Not ``hide_emitters``: as in Mitsuba it lets camera rays see past the light.)"""
    cornell = scenes["cornell"]

    def path(depth, seed):
        return _render(cornell, "path", 1024, depth, seed=seed).render()

    zero, one, two, one_b = path(1, 14), path(2, 11), path(3, 12), path(2, 13)
    return {1: _Image(one.image - zero.image, one.variance + zero.variance),
            2: _Image(two.image - one_b.image, two.variance + one_b.variance)}


@pytest.mark.slow
@pytest.mark.parametrize("s,t", [(0, 3), (1, 2), (2, 1), (2, 2), (3, 1), (1, 3)])
def test_each_strategy_alone_is_unbiased(scenes, bounce_references, s, t):
    """One strategy with weight 1 (``BDPTIntegrator.only``) estimates all the paths of its
    length that it can sample: in the Cornell box (no Dirac surfaces, an area light) every
    path of ``s + t - 2`` bounces. Against the path tracer's image of that many bounces.
    512 spp: (0, 3) alone (camera paths that hit the light) expects about 2 hits per 128 spp
    in the sparsest 8x8 block's lit row, and a block without a hit has no variance estimate
    (at 128 spp 1 seed of 10 had one and failed by z = 142; at 512 none of 10 did)."""
    r = _render(scenes["cornell"], "bdpt", 512, 3)
    r.integrator.only = (s, t)
    img = r.render()
    assert img.image.mean() > 0.005
    zb, zm = _agree(img, bounce_references[s + t - 2])
    assert zb < 4.5 and zm < 4.0, (zb, zm)


@pytest.mark.slow
def test_a_strategy_alone_negative_control(scenes, bounce_references):
    """(2, 2) alone is not the image of paths of 1 bounce."""
    r = _render(scenes["cornell"], "bdpt", 128, 3)
    r.integrator.only = (2, 2)
    zb, _ = _agree(r.render(), bounce_references[1])
    assert zb > 6.0, zb


# ------------------------------------------------------------ cheaper estimators
def test_roulette_keeps_the_expectation():
    """:func:`~drpt.render.integrators.bdpt.roulette` on contributions below, at and above
    the threshold: the mean of ``value / q`` over 2^20 draws is the value (|z| < 4.5, z
    from the sample's own standard error); above the threshold nothing is dropped; the
    threshold 0 keeps everything as it is. Negative control: without the division by
    ``q`` the means are too small (|z| > 6)."""
    n = 1 << 20
    rng = np.random.default_rng(5)
    for v in (0.01, 0.3, 1.0, 4.0):
        value = dr.full(B.Array3f, [v, 0.5 * v, 0.0], n)
        u = Float(rng.random(n, dtype=np.float32))
        out, ok = B.roulette(value, dr.full(Bool, True, n), u, Float(1.0))
        x = out.x.numpy().astype(np.float64)
        z = (x.mean() - v) / max(x.std() / np.sqrt(n), 1e-12)
        assert abs(z) < 4.5, (v, z)
        if v >= 1.0:
            assert ok.numpy().all() and np.allclose(x, v)
        if v < 1.0:
            biased = np.where(ok.numpy(), v, 0.0)
            zb = (biased.mean() - v) / (biased.std() / np.sqrt(n))
            assert zb < -6.0, (v, zb)
        same, ok0 = B.roulette(value, dr.full(Bool, True, n), u, Float(0.0))
        assert ok0.numpy().all() and np.allclose(same.x.numpy(), v)


def test_choose_vertex_is_uniform_over_the_usable_vertices():
    """``choose_vertex``: index uniform in ``[0, min(stored, room))`` (chi-square-like check
    of the counts, 6 sigma), returned with that count; no vertex where none is usable."""
    n = 1 << 16
    u = Float(np.random.default_rng(2).random(n, dtype=np.float32))
    for stored, room, m_exp in ((5, 3, 3), (2, 7, 2), (4, 4, 4), (0, 5, 0), (3, 0, 0)):
        i, m = B.choose_vertex(u, dr.full(B.UInt32, stored, n), dr.full(B.UInt32, room, n))
        assert (m.numpy() == m_exp).all()
        if m_exp:
            counts = np.bincount(i.numpy(), minlength=m_exp)
            assert len(counts) == m_exp
            assert np.abs(counts - n / m_exp).max() < 6 * np.sqrt(n / m_exp)


def test_connection_room_counts_the_light_vertices_that_fit_in_the_path():
    """``connection_room(k, D)``: light vertex ``j`` (a subpath of at least ``j + 1``
    segments) can be joined to camera vertex ``k`` within ``D`` segments exactly when ``j <
    room``, for the shortest subpaths (``depth_j = j + 1``, no Dirac vertex before it): the
    vertices past the room can never be joined, and the last one inside it can."""
    for depth in range(1, 10):
        k = np.arange(0, depth + 2, dtype=np.uint32)
        room = B.connection_room(B.UInt32(k), depth).numpy()
        for kk, r in zip(k, room):
            fits = [j for j in range(B.MAX_DEPTH) if (j + 1) + kk + 1 <= depth]
            assert r == len(fits), (depth, kk, r, fits)


@pytest.mark.slow
@pytest.mark.parametrize("control", [False, True])
def test_a_connection_alone_needs_the_selection_probability(scenes, bounce_references, monkeypatch, control):
    """(2, 2) alone at depth 4 joins the first camera vertex to one of up to 2 light vertices
    (``connection_room``: depth 1 makes (2, 2), depth 2 (3, 2), which counts 0 here): with
    the contribution times the number it chose from it is the image of paths of 2 bounces;
    counted once (the selection probability ignored) it is too dark (negative control)."""
    if control:
        choose = B.choose_vertex
        monkeypatch.setattr(B, "choose_vertex", lambda u, stored, room: (
            choose(u, stored, room)[0], dr.minimum(dr.minimum(stored, room), 1)))
    r = _render(scenes["cornell"], "bdpt", 128, 4)
    r.integrator.only = (2, 2)
    zb, zm = _agree(r.render(), bounce_references[2])
    if control:
        assert zb > 6.0, zb
    else:
        assert zb < 4.5 and zm < 4.0, (zb, zm)


@pytest.mark.slow
@pytest.mark.parametrize("divide", [True, False])
def test_heavy_roulette_is_unbiased_and_its_control_fails(scenes, references, monkeypatch, divide):
    """The Cornell box with the roulette's threshold at 4x the image's mean (most
    connections and splats rouletted) agrees with the path tracer (the test above's
    thresholds); without the division by the survival probability it fails (|z| > 6)."""
    if not divide:
        monkeypatch.setattr(B, "roulette", lambda value, ok, u, threshold: (
            value, ok & (u < dr.minimum(dr.max(value) / threshold, 1.0))))
    depth, spp, _ = CASES["cornell"]
    r = _render(scenes["cornell"], "bdpt", spp, depth)
    r.render()  # calibrates
    r.integrator.threshold *= 4.0 / B.ROULETTE_FRACTION
    img = r.render()
    zb, zm = _agree(img, _reference(scenes, references, "cornell"))
    if divide:
        assert zb < 4.5 and zm < 4.0, (zb, zm)
    else:
        assert zb > 6.0, zb


def test_light_survival_reads_the_reflected_share_not_the_lights_scale():
    """:func:`~drpt.render.integrators.bdpt.light_survival` is ``min(max(beta) / power *
    eta^2, 0.95)``: the same for a light 1000 times brighter or dimmer (throughput and
    power scaled alike), 0 for no power. Negative control: the path tracer's rule on
    ``max(beta)`` alone gives a bright light's subpaths 0.95 and a dim one's almost 0."""
    beta = B.Array3f([0.3, 2.0, 40.0], [0.2, 1.0, 10.0], [0.1, 0.5, 5.0])
    power = Float([1.0, 4.0, 100.0])
    eta = Float([1.0, 1.0, 1.5])
    q = B.light_survival(beta, power, eta).numpy()
    assert np.allclose(q, [0.3, 0.5, 0.9], rtol=1e-6), q
    for scale in (1e-3, 1e3):
        scaled = B.light_survival(beta * scale, power * scale, eta).numpy()
        assert np.allclose(scaled, q, rtol=1e-5), (scale, scaled)
        plain = np.minimum(dr.max(beta * scale).numpy() * eta.numpy() ** 2, 0.95)
        assert np.abs(plain - q).max() > 0.25, (scale, plain)
    assert B.light_survival(beta, Float([0.0, 0.0, 0.0]), eta).numpy().max() == 0.0


def test_occluded_where_is_the_masked_shadow_query(scenes):
    """:func:`~drpt.render.integrators.bdpt.occluded_where` (the query inside a symbolic
    ``if``) gives ``scene.occluded`` on the active lanes and False on the others, for random
    segments inside the Cornell box with a sparse mask (1 lane in 16: whole SIMD packets
    skip it) and a full one; both answers occur."""
    rng = np.random.default_rng(3)
    r = _render(scenes["cornell"], "bdpt", 1, 5)
    n = 4096
    lo, hi = np.array([0.1, 0.1, 0.1]), np.array([5.4, 5.4, 5.5])  # inside the box (cornellbox.obj)
    a = lo + (hi - lo) * rng.random((n, 3))
    b = lo + (hi - lo) * rng.random((n, 3))
    seg = b - a
    dist = np.linalg.norm(seg, axis=1)
    o, d = B.Array3f(*a.T.astype(np.float32)), B.Array3f(*(seg / dist[:, None]).T.astype(np.float32))
    tmax = Float(dist.astype(np.float32))
    for active in (rng.random(n) < 1 / 16, np.ones(n, bool)):
        want = r.scene.occluded(o, d, tmax, Bool(active)).numpy() & active
        got = B.occluded_where(r.scene, o, d, tmax, Bool(active)).numpy()
        assert np.array_equal(got, want) and want.any() and (active & ~want).any()


@pytest.mark.slow
@pytest.mark.parametrize("control", [False, True])
def test_light_subpath_roulette_is_unbiased_and_its_control_fails(scenes, monkeypatch, control):
    """The Cornell box at ``max_depth`` 6 with ``rr_depth`` 1, so that the light subpath
    plays its roulette (:func:`~drpt.render.integrators.bdpt.light_survival`) at every
    bounce: bdpt agrees with the path tracer of the same depths (the block z-test above).
    Negative control: survival probabilities doubled and not clamped (a subpath survives
    with ``min(1, 2q)`` but is divided by ``2q``) darken the light subpaths' strategies and
    fail (|z| > 6)."""
    if control:
        survival = B.light_survival
        monkeypatch.setattr(B, "light_survival", lambda beta, power, eta: 2.0 * survival(beta, power, eta))

    def render(integrator, spp, seed):
        opts = RenderOptions(width=32, height=32, spp=spp, seed=seed, integrator=integrator, progress=False,
                             path=PathOptions(max_depth=6, rr_depth=1), variance=True)
        return Renderer(scenes["cornell"], opts).render()

    zb, zm = _agree(render("bdpt", 256, 1), render("path", 1024, 7))
    if control:
        assert zb > 6.0, zb
    else:
        assert zb < 4.5 and zm < 4.0, (zb, zm)


@pytest.mark.slow
def test_pilot_sets_a_power_of_two_threshold_near_the_mean(scenes):
    """The pilot (``Renderer._calibrate_bdpt``) sets the threshold to a power of 2 within a
    factor 2.5 of ``ROULETTE_FRACTION`` times the image's mean luminance (measured on the
    render), the same in a second renderer (another process would agree too); an image
    of nothing but black has threshold 0 (no roulette)."""
    r = _render(scenes["cornell"], "bdpt", 16, 5)
    img = r.render()
    t = r.integrator.threshold
    assert t > 0 and math.log2(t) == round(math.log2(t))
    mean = float((img.image @ np.array([0.2126, 0.7152, 0.0722])).mean())
    assert 1 / 2.5 < t / (B.ROULETTE_FRACTION * mean) < 2.5, (t, mean)
    r2 = _render(scenes["cornell"], "bdpt", 16, 5)
    r2.render()
    assert r2.integrator.threshold == t
    r.integrator.calibrate(0.0)
    assert r.integrator.threshold == 0.0


@pytest.mark.slow
@pytest.mark.parametrize("name,sampler,control", [("cornell", "ldsampler", None), ("cornell", "zsobol", None),
                                                  ("specular", "ldsampler", None),
                                                  ("cornell", "ldsampler", "diagonal"),
                                                  ("cornell", "ldsampler", "reused"),
                                                  ("cornell", "ldsampler", "share")])
def test_low_discrepancy_samplers_agree_with_path_tracing(scenes, references, monkeypatch, name, sampler, control):
    """bdpt draws from the scene's sampler: the Cornell box with ``ldsampler`` and ``zsobol``,
    and the specular scene (every light vertex joined, in a loop) with ``ldsampler``,
    agree with the path tracer (independent samples; the test above's thresholds; drpt's
    variance estimate treats the samples as independent, which overestimates an ``ldsampler``
    image's error, so the test is conservative), with no warning. Negative controls fail
    (|z| > 6): the sequence's 2-D points put on the diagonal (both coordinates the first
    one's) for the integrator's draws, and every camera vertex drawing from the same
    dimensions (``CAMERA_STRIDE = 0``: a dimension reused at each bounce), and light tracing
    counted ``LD_LIGHT_SHARE`` times in the camera subpath's weights but not in the splats'
    (their ``k`` without ``m(share)``: the weights no longer sum to 1)."""
    if control == "reused":
        monkeypatch.setattr(B, "CAMERA_STRIDE", 0)
    elif control == "share":
        weight = B.connection_weight  # (the splat's call is the one that passes its k)
        monkeypatch.setattr(B, "connection_weight",
                            lambda *a: weight(*a[:-1], a[-1] / B.mis(B.LD_LIGHT_SHARE)) if len(a) == 9 else weight(*a))
    elif control:
        from drpt.render.sampler import next_2d

        def diagonal(rng):
            u = next_2d(rng)
            return B.Array2f(u.x, u.x)

        monkeypatch.setattr(B, "next_2d", diagonal)
    depth, spp, _ = CASES[name]
    opts = RenderOptions(width=32, height=32, spp=spp, seed=1, integrator="bdpt", sampler=sampler,
                         progress=False, path=PathOptions(max_depth=depth), variance=True)
    r = Renderer(scenes[name], opts)
    assert not any("sampler" in w for w in r.warnings), r.warnings
    zb, zm = _agree(r.render(), _reference(scenes, references, name))
    if control:
        assert zb > 6.0, zb
    else:
        assert zb < 4.5 and zm < 4.0, (zb, zm)


@pytest.mark.parametrize("name,sampler", [("cornell", "independent"), ("cornell", "ldsampler"),
                                          ("cornell", "zsobol"), ("cornell", "stratified"),
                                          ("specular", "independent"), ("point", "independent"),
                                          ("sky", "independent")])
def test_the_subpath_loops_are_traced_once_and_the_image_is_the_same(scenes, monkeypatch, name, sampler):
    """``trace`` records each loop's body once (``OptimizeLoops`` off, no loop variable of
    another width than the loop's, also a low-discrepancy sampler's step): per trace one
    call of ``_splat`` (where the light loop's body is recorded) and of ``_connect`` (the
    camera loop's, or in the specular scene its inner loop over the light vertices); its
    image is, bit for bit, the one of the body traced with the flag on. Negative control:
    with ``OptimizeLoops`` on, Dr.Jit records the loops again to drop their loop-invariant
    state (two calls, or more, each)."""
    calls = {"_splat": 0, "_connect": 0}
    def counting(method):
        f = getattr(B.BDPTIntegrator, method)

        def counted(self, *a, **kw):
            calls[method] += 1
            return f(self, *a, **kw)

        return counted

    for method in calls:
        monkeypatch.setattr(B.BDPTIntegrator, method, counting(method))
    opts = RenderOptions(width=16, height=16, spp=4, seed=3, integrator="bdpt", progress=False,
                         path=PathOptions(max_depth=5), sampler=sampler)
    renderer = Renderer(scenes[name], opts)
    renderer.render()  # the pass: one trace (the pilot is the path tracer's)
    assert calls == {"_splat": 1, "_connect": 1}, calls
    image = renderer.render().image

    def optimized(self, *a):
        with dr.scoped_set_flag(dr.JitFlag.OptimizeLoops, True):
            return self._trace(*a)

    monkeypatch.setattr(B.BDPTIntegrator, "trace", optimized)
    calls.update(_splat=0, _connect=0)
    assert np.array_equal(renderer.render().image, image)
    # the pass alone, each loop recorded twice (the specular scene's inner loop twice in each
    # recording of the camera loop)
    assert calls["_splat"] == 2 and calls["_connect"] in (2, 4), calls


def test_the_smooth_view_gives_the_same_image(tmp_path):
    """Connections, splats, next-event estimation and merging evaluate the BSDF on a view of
    the non-Dirac kinds (:func:`~drpt.render.integrators.bdpt.smooth_view`): in a scene of
    glass, a mirror and one smooth kind the view traces that kind alone (no lane reads its
    kind), and the image is, bit for bit, the one of the whole table. Negative control: the
    view is right only at vertices whose material is not made of Dirac lobes; sampling with it
    too (the camera subpath then reflects diffusely off the glass and the mirror) changes the
    image."""
    text = POINT_SCENE % ("", 10, 2, 3, "MaterialIndex 5\n  Sphere { center 0.9 2.0 0.3 radius 0.15 }")
    text = text.replace("specularColor 0.5 0.5 0.5 exponent 30", "")
    path = tmp_path / "one_smooth_kind.txt"
    path.write_text(text)
    scene = load_scene(path)
    opts = RenderOptions(width=16, height=16, spp=4, seed=3, integrator="bdpt", progress=False,
                         path=PathOptions(max_depth=5))

    def image():
        return Renderer(scene, opts).render().image

    with_view = image()
    renderer = Renderer(scene, opts)
    view = B.smooth_view(renderer.scene)
    assert view is not renderer.scene and view.materials._only == ("diffuse",) and view.materials.K == 1
    whole = pytest.MonkeyPatch()
    whole.setattr(B, "smooth_view", lambda s: s)
    try:
        assert np.array_equal(image(), with_view)
    finally:
        whole.undo()
    control = pytest.MonkeyPatch()
    sample = B.sample_both
    control.setattr(B, "sample_both", lambda s, *a: sample(B.smooth_view(s), *a))
    try:
        assert not np.array_equal(image(), with_view)
    finally:
        control.undo()


#: the dimensions a lane may draw in the dimension test below (its light subpath's take fewer
#: than CAMERA_DIMENSION, its camera subpath's from there on)
_DIMS = 512


class _CountingSampler(LDSampler):
    """:class:`~drpt.render.sampler.LDSampler` that counts, per lane and dimension, the draws
    in :attr:`counts` (a flat buffer of ``lanes x _DIMS``, set by the test): a draw is a
    scatter-add, so it counts inside Dr.Jit's symbolic loops and ``if``s too."""

    DRJIT_STRUCT = {**LDSampler.DRJIT_STRUCT, "lane": UInt32}
    counts = None

    def __init__(self, key=None, index=None, step=None):
        super().__init__(key, index, step)
        self.lane = dr.arange(UInt32, dr.width(self.index))

    def _count(self, k: int) -> None:
        for j in range(k):
            dr.scatter_reduce(dr.ReduceOp.Add, type(self).counts, UInt32(1),
                              self.lane * _DIMS + dr.minimum(self.dim + j, _DIMS - 1))

    def next_float32(self):
        self._count(1)
        return super().next_float32()

    def next_2d(self):
        self._count(2)
        return super().next_2d()


@pytest.mark.parametrize("name,control", [("cornell", False),
                                          pytest.param("specular", False, marks=pytest.mark.slow),
                                          ("cornell", True),
                                          pytest.param("specular", True, marks=pytest.mark.slow)])
def test_no_decision_shares_a_low_discrepancy_dimension(scenes, monkeypatch, name, control):
    """With ``--sampler ldsampler`` every random decision of a bdpt sample (the pixel position,
    the light subpath's source, point, direction, splat roulette, lobe, direction and Russian
    roulette per vertex; the camera subpath's next-event estimation, connection choice and
    roulette, or each light vertex's connection roulette where every pair is joined, lobe,
    direction and Russian roulette per vertex) draws a dimension of its own: no lane draws one
    dimension twice (counted per lane and dimension, depth 8 in the Cornell box, whose camera
    vertices join one light vertex each, and in the specular scene, whose join every one in a
    loop; caustic merging off, its photons draw from a sampler of their own). Negative
    control: the camera subpath starting at the light subpath's first dimension
    (``CAMERA_DIMENSION = 2``) reuses dimensions."""
    from drpt.render import renderer as R

    cam = B.CAMERA_DIMENSION
    if control:
        monkeypatch.setattr(B, "CAMERA_DIMENSION", 2)
    monkeypatch.setattr(R, "LDSampler", _CountingSampler)
    opts = RenderOptions(width=16, height=16, spp=4, seed=3, integrator="bdpt", sampler="ldsampler",
                         progress=False, path=PathOptions(max_depth=8), bdpt_merge=False)
    r = Renderer(scenes[name], opts)
    lanes = 16 * 16 * 4  # one pass
    _CountingSampler.counts = dr.zeros(UInt32, lanes * _DIMS)
    r.render()  # (with the path-traced pilot, which draws from the same class)
    _CountingSampler.counts = counts = dr.zeros(UInt32, lanes * _DIMS)
    r.render()
    c = counts.numpy().reshape(lanes, _DIMS)
    assert c[:, 0:2].min() == 1  # the pixel position
    if not control:
        assert c[:, 2:cam].sum(1).min() >= 5  # every light subpath's source, point, direction
        assert c[:, cam:].sum() > lanes  # the camera subpaths' draws
    assert c[:, _DIMS - 1].max() == 0  # none beyond the counted dimensions
    if control:
        assert c.max() > 1, c.max()
    else:
        assert c.max() == 1, np.argwhere(c > 1)[:5]
