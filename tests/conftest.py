"""Shared test fixtures.

Tests take the repository's paths as fixtures (``repo``, ``scenes_dir``, ``cornell``,
``seed_dir``); module-level code that needs a path imports it from :mod:`support`
(``tests/support/``, with the other shared helpers). The statistical checks are in
:mod:`drpt.testing`. ``shared/`` beside the checkout (the seed renderer's files, Mitsuba's
corpus) may be absent: tests that read it skip cleanly.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from support import REPO, SCENES, SEED


@pytest.fixture(scope="session")
def repo() -> Path:
    """The repository checkout's root."""
    return REPO


@pytest.fixture(scope="session")
def scenes_dir() -> Path:
    """The bundled scenes, ``scenes/``."""
    return SCENES


@pytest.fixture(scope="session")
def cornell() -> Path:
    """The bundled Cornell box, ``scenes/cornellbox/cornellbox.txt``."""
    return SCENES / "cornellbox" / "cornellbox.txt"


@pytest.fixture(params=[True, False], ids=["symbolic", "evaluated"])
def loop_mode(request):
    """Run the test with Dr.Jit's loops symbolic (one kernel) and evaluated."""
    import drjit as dr

    with dr.scoped_set_flag(dr.JitFlag.SymbolicLoops, request.param):
        yield request.param


@pytest.fixture
def seed_dir() -> Path:
    if not (SEED / "scenes").is_dir():
        pytest.skip("../shared/seed is not present")
    return SEED


@pytest.fixture(scope="session")
def reference_scene(tmp_path_factory):
    """``get(scene_file)``: the loaded scene of a ``REFERENCES`` entry, loaded once
    per test session and shared (renderers do not modify scenes). A generated
    scene that scenes/ lacks (the git-ignored dining room) is generated once
    into a temporary folder (:func:`drpt.tools.reference.scene_path`)."""
    from drpt.scene import load_scene
    from drpt.tools.reference import scene_path

    out = tmp_path_factory.mktemp("generated_scenes")
    loaded = {}

    def get(scene_file: str):
        if scene_file not in loaded:
            loaded[scene_file] = load_scene(scene_path(scene_file, out))
        return loaded[scene_file]

    return get
