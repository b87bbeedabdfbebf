"""The accelerator table (drpt.accel.registry), the Accelerator protocol and
the backend policy read at build and trace time."""

from __future__ import annotations

import dataclasses

import drjit as dr
import numpy as np
from drjit.auto import UInt32

from drpt import backend
from drpt.accel import ACCELERATORS, KINDS, Accelerator, build_accel, embree_lib, resolve_kind
from drpt.accel.device import device_array
from support.accel import make_scene, soup


def test_kinds_come_from_the_table():
    assert KINDS == ("auto", "bvh", "bvh2", "bvh4", "embree", "grid", "inline", "brute")
    assert KINDS == ("auto", *ACCELERATORS)


def test_every_kind_is_an_accelerator():
    rng = np.random.default_rng(1)
    sc = make_scene(soup(rng, 10), (rng.random((2, 3)) * 10, np.ones(2)), ([[0, 0, 1]], [0.0]))
    for kind in KINDS:
        if kind == "embree" and embree_lib.reason() is not None:
            continue  # tests/accel/test_embree.py covers the error
        a = build_accel(sc, kind)
        assert isinstance(a, Accelerator), kind
        assert a.stats["prims"] in (0, 12, 13) and a.build_seconds >= 0 and a.nbytes >= 0


def test_policy_is_read_at_call_time(monkeypatch):
    rng = np.random.default_rng(2)
    sc = make_scene(soup(rng, 10))
    assert resolve_kind(sc) == "inline"
    monkeypatch.setitem(backend.POLICIES, backend.name(),
                        dataclasses.replace(backend.policy(), inline_max_prims=5))
    assert resolve_kind(sc) == ("embree" if embree_lib.reason() is None else "bvh")
    assert resolve_kind(sc, bvh_rule=True) == "bvh"


def test_device_array_padding():
    a = np.arange(10, dtype=np.uint32)
    pad = backend.policy().align_bytes
    exact, padded = device_array(UInt32, a), device_array(UInt32, a, padded=True)
    assert dr.width(exact) == 10 and dr.width(padded) == 10 + pad // 4
    assert np.array_equal(exact.numpy(), a)
    assert np.array_equal(padded.numpy(), np.concatenate([a, np.zeros(pad // 4, np.uint32)]))
