"""Test support: helpers and paths that several test files share (not tests themselves).

Test files import it as a package, ``from support import REPO`` or ``from support.corpus
import check_scene``: pytest puts ``tests/`` on ``sys.path`` (``pythonpath`` in
pyproject.toml). Test files never import each other (tests/docs/test_tests_layout.py checks
it): a helper that a second test file needs moves here. Statistical checks that users can
run on their own BSDFs and images are in :mod:`drpt.testing`, not here.

* :mod:`support.corpus`: Mitsuba 3's render-test scenes in ``../shared``, rendered as
  authored and z-tested against their references;
* :mod:`support.xml`: the Mitsuba XML corpus of ``tests/data/xml``, rendered by drpt and by
  Mitsuba from the same file;
* :mod:`support.materials`: the material test box that BSDFs are rendered in against Mitsuba;
* :mod:`support.scenes`: small scenes written for the tests (``edge_scene``);
* :mod:`support.dielectric`: a stand-in for the material table, to test lobes alone;
* :mod:`support.accel`: random triangle soups, rays and the brute-force hits the
  accelerator tests compare against;
* :mod:`support.fuzz` and :mod:`support.fuzzformats`: seeded mutations of input files;
* :mod:`support.resume`: renders interrupted after some chunks and resumed from their
  checkpoint;
* :mod:`support.ports`: ports of this machine held in use;
* :mod:`support.loops`: how often Dr.Jit records each symbolic loop while a render is traced.
* :mod:`support.beckmann`: the exact CDF of Beckmann's visible slopes, against which a slope
  sampler's inversion error is measured (also by ``benchmarks/beckmann_sampler_ab.py``).
"""

from __future__ import annotations

from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
"""The repository checkout's root."""
SCENES = REPO / "scenes"
"""The bundled scenes."""
DATA = REPO / "tests" / "data"
"""Input files written for the tests (``tests/data/xml``: the Mitsuba XML corpus)."""
SHARED = REPO.parent / "shared"
"""``shared/`` beside the checkout (Mitsuba's render-test corpus, the seed renderer); tests
that read it skip cleanly when it is absent."""
SEED = SHARED / "seed"
"""The seed renderer's files in ``shared/``."""
