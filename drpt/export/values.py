"""The exporter's value wrappers: the scene is first described with these small typed
values (an RGB triple, a point, a vector, a 4x4 matrix), so that the Mitsuba dict
(:func:`drpt.export.mitsuba.to_mitsuba_dict`) and the XML writer render the very same
description; :mod:`drpt.export.mitsuba_bsdf` writes its transforms and vectors with them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class _RGB:
    value: tuple[float, float, float]


@dataclass(frozen=True)
class _Point:
    value: tuple[float, float, float]


@dataclass(frozen=True)
class _Vector:
    value: tuple[float, float, float]


@dataclass(frozen=True)
class _Matrix:
    value: np.ndarray  # (4, 4)
