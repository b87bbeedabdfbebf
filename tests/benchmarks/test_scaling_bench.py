"""benchmarks/scaling.py: the scene family's triangle counts and an end-to-end run at 1k triangles."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest

from support import REPO

_PATH = REPO / "benchmarks" / "scaling.py"
_spec = importlib.util.spec_from_file_location("scaling_bench", _PATH)
scaling = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(scaling)


@pytest.mark.parametrize("n", [1_000, 10_000, 100_000, 1_000_000, 4_000_000])
def test_triangle_counts_are_what_is_asked(n):
    n_u, n_v = scaling.torus_grid(n - 14)
    total = 14 + 2 * n_u * n_v
    assert abs(total - n) <= 0.01 * n
    assert 1.5 <= n_u / n_v <= 2.5
    if n <= 10_000:
        assert len(scaling.make_scene(n).triangles) == total


def test_same_scene_only_finer():
    """The room, light and camera do not change with the size; the torus stays the same surface."""
    a, b = scaling.make_scene(1_000), scaling.make_scene(20_000)
    assert a.camera == b.camera and [m.name for m in a.materials] == [m.name for m in b.materials]
    np.testing.assert_array_equal(a.triangles.positions[:14], b.triangles.positions[:14])
    lo_a, hi_a = a.bounds()
    lo_b, hi_b = b.bounds()
    np.testing.assert_allclose(lo_a, lo_b)
    np.testing.assert_allclose(hi_a, hi_b)
    ta, tb = a.triangles.positions[14:], b.triangles.positions[14:]
    # extent of the torus itself agrees to the tessellation error
    np.testing.assert_allclose(ta.reshape(-1, 3).max(0), tb.reshape(-1, 3).max(0), atol=0.15)


def test_winding_faces_the_room():
    walls, mat = scaling.room()
    g = np.cross(walls[:, 1] - walls[:, 0], walls[:, 2] - walls[:, 0])
    inward = np.einsum("ij,ij->i", g, np.array([0.0, 2.0, 0.0]) - walls.mean(1))
    assert (inward > 0).all() and mat.tolist().count(1) == 2
    t = scaling.bumpy_torus(24, 12)
    g = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    c = t.mean(1)
    axis = c * np.array([1.0, 0.0, 1.0])
    axis = 1.3 * axis / np.linalg.norm(axis, axis=1, keepdims=True) + np.array([0.0, 1.3, 0.0])
    assert (np.einsum("ij,ij->i", g, c - axis) > 0).all()


@pytest.mark.mitsuba
def test_runs_end_to_end_at_1k(capsys):
    pytest.importorskip("mitsuba")
    rows = scaling.main(["--tris", "1e3", "--size", "16", "16", "--spp", "1", "--repeat", "1"])
    (row,) = rows
    assert row["tris"] == 1006
    for k in ("build_s", "render_s", "mi_load_s", "mi_render_s"):
        assert 0 < row[k] < 60
    assert 40 * row["tris"] < row["accel_bytes"] < 1000 * row["tris"]
    out = capsys.readouterr().out
    assert "| 1006 |" in out and "render ratio" in out and "load average at end" in out


def test_skips_a_size_that_does_not_fit(monkeypatch, capsys):
    monkeypatch.setattr(scaling, "_mem_available", lambda: 1 << 20)
    rows = scaling.main(["--tris", "1e6", "--no-mitsuba"])
    assert rows == [{"tris": 1_000_000, "skipped": rows[0]["skipped"]}]
    assert "GiB available" in rows[0]["skipped"]
    assert "| 1000000 | skipped:" in capsys.readouterr().out
