"""How often Dr.Jit records each symbolic loop's body while a render is traced.

``@dr.syntax`` turns a ``while`` on Dr.Jit values into a call of ``drjit.while_loop``
(looked up when the loop runs), whose body Dr.Jit calls once per recording: once, or twice
when it records the loop again (``OptimizeLoops`` dropping unchanged state, or a loop
variable whose width differs from the loop's). :func:`recordings` counts those calls per
loop, named by the file and line of its ``while``, and the ``while_loop`` calls that made
them (:attr:`Recordings.calls`).
"""

from __future__ import annotations

import collections
import contextlib
import os
from collections.abc import Iterator

import drjit


class Recordings(collections.Counter):
    """Body recordings per loop, ``"file.py:line" -> n``; :attr:`calls` counts the
    ``while_loop`` calls per loop (a loop traced twice, such as one loop of the film's
    for the image and for the AOVs, or a nested loop inside an outer one that is itself
    recorded twice, is called twice). Each loop recorded once per call: ``self ==
    self.calls``."""

    def __init__(self):
        super().__init__()
        self.calls: collections.Counter = collections.Counter()

    def again(self) -> dict[str, tuple[int, int]]:
        """The loops recorded more often than they were called: ``key -> (recordings,
        calls)`` (empty where each call recorded its body once)."""
        return {k: (v, self.calls[k]) for k, v in self.items() if v != self.calls[k]}


@contextlib.contextmanager
def recordings() -> Iterator[Recordings]:
    """Within the block, a counter of body recordings per loop: ``"file.py:line" -> n``
    (``file.py`` the file's base name, ``line`` its ``while``'s), and its ``calls``.
    Counts every loop that ``@dr.syntax`` code runs in the block, nested ones once per
    recording of the loop that holds them."""
    counts = Recordings()
    original = drjit.while_loop

    def counting(state, cond, body, *args, **kwargs):
        code = body.__code__
        key = f"{os.path.basename(code.co_filename)}:{code.co_firstlineno}"
        counts.calls[key] += 1

        def counted(*a):
            counts[key] += 1
            return body(*a)

        return original(state, cond, counted, *args, **kwargs)

    drjit.while_loop = counting
    try:
        yield counts
    finally:
        drjit.while_loop = original
