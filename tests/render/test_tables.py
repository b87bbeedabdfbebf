"""Small constant tables read as literals (drpt/render/tables.py).

* :func:`tables.gather` of a table of a few runs (Float, UInt32, Bool, Array3f; one run, several,
  masked lanes) equals ``dr.gather`` of the uploaded array, value for value; a table of more
  than ``RUNS`` runs reads by a gather; negative control: a chain whose run ends are off by
  one row differs;
* a table's runs, expanded, give back its rows bit for bit, one run per change of row (random
  tables of long runs; Array3f rows that differ in one component only; control: the count of
  changes read from the first component alone is smaller);
* :func:`tables.search` equals ``dr.binary_search`` on a CDF (ties from zero weights, ``u`` at
  the CDF's own values); negative control: counting with ``<`` instead of ``<=`` differs;
* :func:`tables.choose` and ``SurfaceData.triangle(..., among=records)`` (an emitter's triangle
  records as literals) read the packed records' values bit for bit; negative control: the
  records of other triangles differ;
* Veach's MIS scene (emitter, sphere and material tables read as literals) renders the same
  image, bit for bit, as with every table gathered (``RUNS = 0``); Veach's path kernel reads
  no gather but its surface's per-primitive material (ten runs) and packed triangle records.
"""

from __future__ import annotations

from pathlib import Path

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Array3f, Bool, Float, UInt32

from drpt.options import RenderOptions, with_scene_settings
from drpt.render import tables
from drpt.render.renderer import Renderer
from drpt.render.surface import SurfaceData
from drpt.render.tables import Table
from drpt.scene import load_scene

VEACH = Path(__file__).resolve().parents[1] / "data" / "xml" / "veach_mis.xml"


def _lanes(n: int, size: int, seed: int = 1):
    rng = np.random.default_rng(seed)
    return UInt32(rng.integers(0, n, size).astype(np.uint32)), Bool(rng.random(size) < 0.7)


@pytest.mark.parametrize("cls, values", [
    (Float, [0.25]),
    (Float, [0.1, 0.1, 0.3, 0.3, 0.3, 0.9, 0.1]),
    (UInt32, [3, 3, 7, 1, 1, 0]),
    (Bool, [True, False, False, True]),
    (Array3f, [[0.7, 0.7, 0.7], [0.7, 0.7, 0.7], [0.2, 0.5, 0.9], [1.0, 0.0, 0.0]]),
])
def test_literal_gather_equals_dr_gather(cls, values):
    table = Table(cls, values)
    assert table.literal and len(table.runs) <= tables.RUNS
    index, active = _lanes(len(table), 4096)
    for mask in (True, active):
        got = tables.gather(cls, table, index, mask)
        want = dr.gather(cls, table.array, index, mask)
        assert np.array_equal(np.asarray(got.numpy()), np.asarray(want.numpy()))


def test_signed_zeros_are_two_runs():
    """0.0 and -0.0 are other bits: two runs, each read back with its sign (control: the
    rows compare equal as numbers)."""
    values = np.array([0.0, -0.0, -0.0, 1.0], np.float32)
    assert values[0] == values[1]
    table = Table(Float, values)
    assert len(table.runs) == 3
    got = tables.gather(Float, table, UInt32([0, 1, 2, 3])).numpy()
    assert np.array_equal(got.view(np.uint32), values.view(np.uint32))


def test_many_runs_gather():
    values = np.arange(tables.RUNS + 1, dtype=np.float32) * 0.5
    table = Table(Float, values)
    assert not table.literal
    index, active = _lanes(len(values), 1000)
    assert np.array_equal(tables.gather(Float, table, index, active).numpy(),
                          dr.gather(Float, table.array, index, active).numpy())
    # a plain array gathers
    assert np.array_equal(tables.gather(Float, table.array, index).numpy(), values[index.numpy()])


def test_shifted_runs_differ():
    """Negative control: the chain with each run's end one row early reads other values."""
    table = Table(Float, [0.1, 0.1, 0.3, 0.3, 0.3, 0.9])
    index, _ = _lanes(len(table), 1000)
    want = dr.gather(Float, table.array, index).numpy()
    table.runs = [(end - 1, row) for end, row in table.runs]
    assert not np.array_equal(tables.gather(Float, table, index).numpy(), want)


def _expand(table: Table) -> list[tuple]:
    rows, start = [], 0
    for end, row in table.runs:
        rows += [row] * (end - start)
        start = end
    return rows


@pytest.mark.parametrize("cls, dims", [(Float, 1), (UInt32, 1), (Array3f, 3)])
def test_runs_expand_to_rows(cls, dims):
    rng = np.random.default_rng(7)
    lengths = rng.integers(1, 40, 200)
    dtype = np.uint32 if cls is UInt32 else np.float32
    distinct = rng.integers(0, 3, (len(lengths), dims)).astype(dtype)
    if cls is Array3f:
        distinct[:, :2] = 0.5  # rows differ in their last component only
    values = np.repeat(distinct, lengths, axis=0)
    if dims == 1:
        values = values[:, 0]
    table = Table(cls, values)
    rows = [tuple(r) if dims == 3 else (r,) for r in values.tolist()]
    assert _expand(table) == rows
    changes = sum(1 for a, b in zip(rows, rows[1:]) if a != b)
    assert len(table.runs) == changes + 1
    if cls is Array3f:  # control: the first component alone sees no change at all
        assert changes + 1 > len({r[0] for r in rows})


def _cdf(weights) -> np.ndarray:
    cdf = np.cumsum(np.asarray(weights, np.float64)) / np.sum(weights)
    cdf[-1] = 1.0
    return cdf.astype(np.float32)


@pytest.mark.parametrize("weights", [[1.0], [0.35, 0.1625, 0.1625, 0.1625, 0.1625],
                                     [0.2, 0.0, 0.0, 0.5, 0.3, 0.0]])
def test_search_equals_binary_search(weights):
    cdf = _cdf(weights)
    table = Table(Float, cdf)
    rng = np.random.default_rng(3)
    u = Float(np.concatenate([rng.random(5000).astype(np.float32), cdf, [0.0, 0.99999994]]).astype(np.float32))
    got = tables.search(table, u).numpy()
    want = tables.search(table.array, u).numpy()  # a plain array: dr.binary_search
    assert np.array_equal(got, want)
    assert got.max() <= len(cdf) - 1


def test_search_strict_compare_differs():
    """Negative control: a count with ``<`` in place of ``<=`` differs from the binary search
    where ``u`` is one of the CDF's values (the check above would fail it)."""
    cdf = _cdf([0.2, 0.5, 0.3])
    u = Float(cdf)
    want = tables.search(Float(cdf), u).numpy()
    strict = sum((np.float32(x) < u.numpy()).astype(np.uint32) for x in cdf[:-1])
    assert not np.array_equal(strict, want)
    assert np.array_equal(tables.search(Table(Float, cdf), u).numpy(), want)


def test_triangle_records_as_literals_equal_packet_gathers():
    """The Cornell box's ceiling light (its two emissive triangles) read through
    ``SurfaceData.records``: every float of the records, masked lanes included, as the packet
    gathers read them; the records of two other triangles differ (negative control)."""
    opt = RenderOptions(width=8, height=8, spp=1, progress=False)
    cornell = Path(__file__).resolve().parents[2] / "scenes" / "cornellbox" / "cornellbox.txt"
    scene = load_scene(cornell)
    surf = SurfaceData(scene)
    lights = Renderer(scene, opt).scene.area_lights
    ids = [int(k) for k in np.asarray(lights._ids) if k < lights.n_tri]
    assert len(ids) == 2 and lights.tri_records is not None
    records = surf.records(ids)
    rng = np.random.default_rng(5)
    face = UInt32(np.asarray(ids, np.uint32)[rng.integers(0, 2, 2000)])
    active = Bool(rng.random(2000) < 0.8)
    fields = surf.tri_rows * 8
    want = np.array([v.numpy() for v in surf.tri_fields(face, active, fields)])
    got = np.array([v.numpy() for v in surf.tri_fields(face, active, fields, records)])
    assert np.array_equal(got.view(np.uint32), want.view(np.uint32))
    other = surf.records([0, 1])
    wrong = np.array([v.numpy() for v in surf.tri_fields(face, active, fields, other)])
    assert not np.array_equal(wrong, want)


def test_choose_reads_the_keyed_values():
    keys, values = [30, 7, 12], np.array([0.5, -0.0, 0.5], np.float32)
    index = UInt32([30, 7, 12, 12, 7])
    got = tables.choose(index, keys, values, Bool([True, True, True, False, True])).numpy()
    assert np.array_equal(got.view(np.uint32), np.array([0.5, -0.0, 0.5, 0.0, -0.0], np.float32).view(np.uint32))


def _veach(runs: int, monkeypatch) -> np.ndarray:
    monkeypatch.setattr(tables, "RUNS", runs)
    opt, scene = with_scene_settings(RenderOptions(progress=False), load_scene(VEACH))
    opt.width, opt.height, opt.spp, opt.seed = 48, 36, 4, 3
    return Renderer(scene, opt).render().image


def test_veach_image_bit_identical_to_gathers(monkeypatch):
    literal = _veach(tables.RUNS, monkeypatch)
    gathered = _veach(0, monkeypatch)
    assert literal.mean() > 0.0
    assert np.array_equal(literal, gathered)
