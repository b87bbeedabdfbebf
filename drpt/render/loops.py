"""How drpt's symbolic loops are recorded: once each.

Dr.Jit turns a ``while`` on Dr.Jit values in ``@dr.syntax`` code into a symbolic loop by
calling its body once with symbolic variables (a *recording*: a Python trace of the whole
body, paid by every render). By default (``dr.JitFlag.OptimizeLoops``) it records the body a
second time to drop the loop state that the body leaves unchanged, and ``@dr.syntax`` puts
every variable a loop reads into its state: the pixel position, the random streams'
increments, read-only inputs. Even with the flag off, a loop variable that the body reads
but does not change, of another width than the loop's (a width-1 opaque constant, a
sampler's step shared by all lanes, an array the body gathers from), makes it record the body
again; a width-1 variable that the body assigns a wide value (a sum started at 0) does not.

The integrators, the film, the AOV kernel and the device scene's ray queries (the
accelerators' traversal loops, also where no integrator loop holds them: the wavefront's
per-bounce kernels) trace their loops under :func:`loops_once` (the flag off), with their
loop state as wide as the loop (``dr.zeros(T, n)``, ``dr.opaque(T, v, n)``; a sampler's
fields are: :class:`~drpt.render.sampler.LDSampler` broadcasts a key, index or step given as
one value for all lanes) and read-only values of other widths out of it
(``dr.hint(cond, exclude=[...])``), so each body is recorded once (nested loops once per
recording of the loop that holds them); :func:`decorated` lists those functions. The LLVM
backend removes the loop-invariant phis itself: the kernel computes the same values, and the
images are the same bit for bit (``tests/render/test_loops.py``).
"""

from __future__ import annotations

import functools
import sys

import drjit as dr

#: every function that :func:`loops_once` returned (the wrappers)
DECORATED: list = []


def loops_once(method):
    """``method`` traced with Dr.Jit's ``OptimizeLoops`` off: its symbolic loops, and those
    of what it calls, are recorded once each where their state has the loop's width (the
    module docstring). Returns what ``method`` returns; ``__wrapped__`` is ``method``."""

    @functools.wraps(method)
    def traced(*args, **kwargs):
        with dr.scoped_set_flag(dr.JitFlag.OptimizeLoops, False):
            return method(*args, **kwargs)

    DECORATED.append(traced)
    return traced


def decorated() -> list[tuple[object, str]]:
    """``(owner, name)`` of every :func:`loops_once` function of the modules imported so far
    (the renderer imports every integrator): the class or module that holds it and its
    name there, for tools that trace them otherwise (the tests' negative control with
    ``OptimizeLoops`` on, ``benchmarks/loop_recording_ab.py``)."""
    out = []
    for module in dict.fromkeys(f.__module__ for f in DECORATED):
        owners = [sys.modules[module]]
        owners += [c for c in vars(owners[0]).values() if isinstance(c, type) and c.__module__ == module]
        out += [(owner, name) for owner in owners for name, value in vars(owner).items()
                if any(value is f for f in DECORATED)]
    return out
