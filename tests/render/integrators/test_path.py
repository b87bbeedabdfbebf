"""PathIntegrator's two entry points: one path per lane (``sample``) and path
regeneration (``sample_sequence``, what the renderer runs)."""

import drjit as dr
import numpy as np
import pytest
from drjit.auto import PCG32, Bool, Float, UInt32

from drpt.options import RenderOptions
from drpt.render.renderer import Renderer
from drpt.scene import load_scene

W = H = 32


def _renderer(scene_path, bsdf):
    return Renderer(load_scene(scene_path), RenderOptions(width=W, height=H, spp=16, bsdf=bsdf,
                                                             progress=False))


def _camera_ray(r, pixel):
    """Jittered camera rays through ``pixel`` (one per lane)."""
    x, y = Float(pixel % W), Float(pixel // W)
    return lambda rng: r.camera.ray(x + rng.next_float32(), y + rng.next_float32())


def test_first_regenerated_path_is_the_single_path(scenes_dir):
    """With one path per lane and the same random stream, sample_sequence's
    sum is exactly sample()'s radiance, and its square sum the square: the
    regeneration loop adds nothing and loses nothing."""
    r = _renderer(scenes_dir / "cornellbox/cornellbox.txt", "phong")
    n = W * H
    camera_ray = _camera_ray(r, dr.arange(UInt32, n))
    rng = PCG32(n, initstate=7)
    o, d = camera_ray(rng)
    L = r.integrator.sample(rng, o, d, Bool(True))
    acc, acc2, dropped = r.integrator.sample_sequence(PCG32(n, initstate=7), camera_ray,
                                                      dr.full(UInt32, 1, n))
    dr.eval(L, acc, acc2, dropped)
    assert np.array_equal(acc.numpy(), L.numpy())
    assert np.array_equal(acc2.numpy(), (L * L).numpy())
    assert dr.sum(dropped)[0] == 0
    assert (L.numpy() > 0).mean() > 0.5  # most values are lit: a real comparison


@pytest.mark.slow
def test_sequence_mean_matches_independent_paths(scenes_dir):
    """k paths one after another in a lane estimate the same image as k lanes
    with one path each (newscene, Cook-Torrance): per color channel, the image
    sums agree within 5 standard errors (~1.8% here: a 3% loss in the
    sequence's sums fails it)."""
    r = _renderer(scenes_dir / "newscene/newscene.txt", "cook-torrance")
    n, k = W * H, 256
    acc, acc2, _ = r.integrator.sample_sequence(
        PCG32(n, initstate=1), _camera_ray(r, dr.arange(UInt32, n)), dr.full(UInt32, k, n))
    seq = acc.numpy() / k  # (3, n) pixel means
    seq_var = np.maximum(acc2.numpy() / k - seq**2, 0.0) / k  # variance of each mean

    rng = PCG32(n * k, initstate=2)
    o, d = _camera_ray(r, dr.arange(UInt32, n * k) // k)(rng)  # k adjacent lanes per pixel
    L = r.integrator.sample(rng, o, d, Bool(True))
    single = np.stack([dr.block_sum(c, k).numpy() for c in (L.x, L.y, L.z)]) / k
    sq = np.stack([dr.block_sum(c * c, k).numpy() for c in (L.x, L.y, L.z)]) / k
    single_var = np.maximum(sq - single**2, 0.0) / k
    for c in range(3):
        diff = (seq[c] - single[c]).sum()
        se = np.sqrt(seq_var[c].sum() + single_var[c].sum())
        assert se > 0 and abs(diff) < 5 * se, (c, diff, se)
