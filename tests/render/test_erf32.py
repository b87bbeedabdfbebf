"""drpt/render/erf32.py: the error bounds of its ``exp``, ``log``, ``erf`` and
``erfinv``, measured on dense grids over their whole domains against scipy's
float64 functions, float32 rounding included (the module docstring states the
same bounds). Dr.Jit's own functions meet the same bounds on the same grids
(checked here too, so a bound is not looser than what float32 allows). Negative
control of each: the same construction with its polynomial one coefficient
shorter (a cruder approximation) breaks the bound.
"""

from __future__ import annotations

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Float

from drpt.render import erf32

special = pytest.importorskip("scipy.special")


def _eval(f, x: np.ndarray) -> np.ndarray:
    return np.array(f(Float(x.astype(np.float32))), np.float64)


def _exp_grid():
    return np.linspace(-87.0, 88.0, 1_000_001).astype(np.float32)


def _log_grid():
    # every binade of the normal floats, plus a dense stretch around 1
    wide = np.exp(np.linspace(np.log(1.18e-38), np.log(3.4e38), 1_000_001)).astype(np.float32)
    near1 = np.linspace(0.5, 2.0, 500_001, dtype=np.float32)
    return np.concatenate([wide, near1])


def _erf_grid():
    return np.linspace(-6.0, 6.0, 1_000_001).astype(np.float32)


def _erfinv_grid():
    x = np.linspace(-1.0, 1.0, 1_000_001).astype(np.float32)
    # the last 2^17 floats below 1 (and above -1): the tail branch in full
    tail = (1.0 - np.arange(1, 1 << 17) * 2.0 ** -24).astype(np.float32)
    x = np.concatenate([x, tail, -tail])
    return x[np.abs(x) <= np.float32(1.0 - 2.0 ** -23)]


def _exp_err(f):
    x = _exp_grid()
    return np.max(np.abs(_eval(f, x) / np.exp(x.astype(np.float64)) - 1.0))


def _log_err(f):
    x = _log_grid()
    ref = np.log(x.astype(np.float64))
    y = _eval(f, x)
    rel = np.abs(y - ref) / np.maximum(np.abs(ref), 1e-300)
    return np.max(np.where(ref == 0.0, np.abs(y), rel))


def _erf_err(f):
    x = _erf_grid()
    return np.max(np.abs(_eval(f, x) - special.erf(x.astype(np.float64))))


def _erfinv_err(f):
    x = _erfinv_grid()
    ref = special.erfinv(x.astype(np.float64))
    y = _eval(f, x)
    return np.max(np.abs(y - ref) / np.maximum(np.abs(ref), 1e-30))


# function name, measure, bound, Dr.Jit's counterpart, polynomial the control shortens
CASES = [
    ("exp", _exp_err, 3e-7, dr.exp, "_EXP_C"),
    ("log", _log_err, 4e-7, dr.log, "_LOG_C"),
    ("erf", _erf_err, 2.5e-7, dr.erf, "_ERFC_C"),
    ("erfinv", _erfinv_err, 5e-7, dr.erfinv, "_ERFINV_C1"),
]


@pytest.mark.parametrize("name, measure, bound, drjit_fn, coeffs", CASES, ids=[c[0] for c in CASES])
def test_error_bound(name, measure, bound, drjit_fn, coeffs):
    err = measure(getattr(erf32, name))
    assert err < bound, f"erf32.{name}: max error {err:.3g} >= {bound:g}"
    # the bound is one float32 can meet: Dr.Jit's general function meets it as well
    assert measure(drjit_fn) < bound


@pytest.mark.parametrize("name, measure, bound, drjit_fn, coeffs", CASES, ids=[c[0] for c in CASES])
def test_error_bound_negative_control(monkeypatch, name, measure, bound, drjit_fn, coeffs):
    """The polynomial one coefficient shorter: the bound is broken."""
    monkeypatch.setattr(erf32, coeffs, getattr(erf32, coeffs)[:-1])
    assert measure(getattr(erf32, name)) > bound


def test_erfinv_tail_branch_control(monkeypatch):
    """Giles' second polynomial (``w >= 5``, ``|x| > 0.9966``) is checked too: shortened, it fails."""
    monkeypatch.setattr(erf32, "_ERFINV_C2", erf32._ERFINV_C2[:-1])
    assert _erfinv_err(erf32.erfinv) > 5e-7


def test_special_values():
    inf = np.float32(np.inf)
    assert list(_eval(erf32.erf, np.array([inf, -inf, 0.0, 4.0, 100.0], np.float32))) == [1, -1, 0, 1, 1]
    assert list(_eval(erf32.exp, np.array([-inf, -87.5, -1e30, 0.0], np.float32))) == [0, 0, 0, 1]
    assert _eval(erf32.log, np.array([1.0], np.float32))[0] == 0.0
    e = _eval(erf32.erfinv, np.array([0.0, 1.0 - 2.0 ** -23, -(1.0 - 2.0 ** -23)], np.float32))
    assert e[0] == 0.0 and np.isfinite(e).all() and e[1] == -e[2] > 3.5
