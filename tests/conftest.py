"""Shared test fixtures and helpers.

``SHARED`` is the ``shared/`` folder beside the repository checkout (the seed
renderer's files); tests that read it skip cleanly when it is absent.
"""

from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
SEED = SHARED / "seed"
SCENES = REPO / "scenes"


@pytest.fixture
def seed_dir() -> Path:
    if not (SEED / "scenes").is_dir():
        pytest.skip("../shared/seed is not present")
    return SEED
