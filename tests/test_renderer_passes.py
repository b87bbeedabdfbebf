"""Pass planning (drpt/render/renderer.py): every (pixel, sample) exactly once,
never more than the lane budget at a time."""

import numpy as np
import pytest

from drpt.render.renderer import plan_passes


@pytest.mark.parametrize("w,h,spp,budget", [(1, 1, 1, 16), (7, 5, 33, 64), (100, 37, 3, 250),
                                            (64, 64, 256, 1 << 21), (3, 1, 5, 1)])
def test_passes_cover_once_within_budget(w, h, spp, budget):
    count = np.zeros((h, spp), int)
    for s0, k, r0, rows in plan_passes(w, h, spp, budget):
        assert rows * w * k <= max(budget, w)  # one row is the smallest unit
        count[r0:r0 + rows, s0:s0 + k] += 1
    assert np.all(count == 1)
