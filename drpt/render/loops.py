"""How drpt's symbolic loops are recorded: once each.

Dr.Jit turns a ``while`` on Dr.Jit values in ``@dr.syntax`` code into a symbolic loop by
calling its body once with symbolic variables (a *recording*: a Python trace of the whole
body, paid by every render). By default (``dr.JitFlag.OptimizeLoops``) it records the body a
second time to drop the loop state that the body leaves unchanged, and ``@dr.syntax`` puts
every variable a loop reads into its state: the pixel position, the random streams'
increments, read-only inputs. A loop variable of another width than the loop's (a width-1
sum, a sampler's step shared by all lanes) also makes it record the body again.

The integrators and the film trace their loops under :func:`loops_once` (the flag off) with
their loop state as wide as the loop (:func:`widen`), so each body is recorded once (nested
loops once per recording of the loop that holds them). The LLVM backend removes the
loop-invariant phis itself: the kernel computes the same values, and the images are the
same bit for bit (``tests/render/test_loops.py``).
"""

from __future__ import annotations

import functools

import drjit as dr


def loops_once(method):
    """``method`` traced with Dr.Jit's ``OptimizeLoops`` off: its symbolic loops, and those
    of what it calls, are recorded once each where their state has the loop's width (the
    module docstring). Returns what ``method`` returns; ``__wrapped__`` is ``method``."""

    @functools.wraps(method)
    def traced(*args, **kwargs):
        with dr.scoped_set_flag(dr.JitFlag.OptimizeLoops, False):
            return method(*args, **kwargs)

    return traced


def widen(state, n: int) -> None:
    """Give the fields of ``state`` (a Dr.Jit struct: a sampler) that hold one value for all
    lanes ``n`` entries, in place (the same values): as loop state, a field of another width
    than the loop's makes Dr.Jit record the loop's body again."""
    for name in getattr(type(state), "DRJIT_STRUCT", {}):
        value = getattr(state, name)
        if dr.width(value) == 1 and n > 1:
            setattr(state, name, value + dr.zeros(type(value), n))
