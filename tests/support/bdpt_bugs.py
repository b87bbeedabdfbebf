"""Bugs put into bdpt for negative controls (tests/render/integrators/test_bdpt.py and
test_light_tracers_bundled.py): each must make bdpt's image fail the z-test it passes."""

from __future__ import annotations

import drjit as dr

from drpt.render.integrators import bdpt as B

#: the controls by name
BUGS = ("no cosine at the light vertex", "a wrong density in next-event estimation's weight",
        "the camera throughput twice in connections")


def put(monkeypatch, what: str) -> None:
    """Put the bug ``what`` (one of :data:`BUGS`) into bdpt for the test's duration. The camera
    throughput counted twice runs with ``CONNECTION_CHOICES = 1`` (every pair joined)."""
    if what == BUGS[2]:
        connect = B.BDPTIntegrator._connect

        def twice(self, si, beta, *a):
            return beta * connect(self, si, beta, *a)

        monkeypatch.setattr(B.BDPTIntegrator, "_connect", twice)
        monkeypatch.setattr(B, "CONNECTION_CHOICES", 1.0)
    elif what == BUGS[0]:
        correction = B.correction

        def no_cosine(si, w):  # importance leaving a light vertex without |cos(ns, w)|
            corr, ok = correction(si, w)
            return corr / dr.maximum(dr.abs(dr.dot(si.ns, w)), 1e-3), ok

        monkeypatch.setattr(B, "correction", no_cosine)
    elif what == BUGS[1]:
        nee_weight = B.nee_weight
        monkeypatch.setattr(B, "nee_weight", lambda fwd, pdf, *a: nee_weight(fwd, pdf * 2.0, *a))
    else:
        raise ValueError(what)
