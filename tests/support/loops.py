"""How often Dr.Jit records each symbolic loop's body while a render is traced.

``@dr.syntax`` turns a ``while`` on Dr.Jit values into a call of ``drjit.while_loop``
(looked up when the loop runs), whose body Dr.Jit calls once per recording: once, or twice
when it records the loop again (``OptimizeLoops`` dropping unchanged state, or a loop
variable whose width differs from the loop's). :func:`recordings` counts those calls per
loop, named by the file and line of its ``while``.
"""

from __future__ import annotations

import collections
import contextlib
import os
from collections.abc import Iterator

import drjit


@contextlib.contextmanager
def recordings() -> Iterator[collections.Counter]:
    """Within the block, a counter of body recordings per loop: ``"file.py:line" -> n``
    (``file.py`` the file's base name, ``line`` its ``while``'s). Counts every loop that
    ``@dr.syntax`` code runs in the block, nested ones once per recording of the loop that
    holds them."""
    counts: collections.Counter = collections.Counter()
    original = drjit.while_loop

    def counting(state, cond, body, *args, **kwargs):
        code = body.__code__
        key = f"{os.path.basename(code.co_filename)}:{code.co_firstlineno}"

        def counted(*a):
            counts[key] += 1
            return body(*a)

        return original(state, cond, counted, *args, **kwargs)

    drjit.while_loop = counting
    try:
        yield counts
    finally:
        drjit.while_loop = original
