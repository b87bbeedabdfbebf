"""Interrupted and resumed renders (:func:`drpt.distributed.job.run`), as the chunk and
checkpoint tests write them: a render stopped by ``KeyboardInterrupt`` once ``after``
chunks are merged, its checkpoint left beside ``out``, then resumed from it.

* :func:`interrupt`: run until ``after`` chunks are merged, then stop (the checkpoint is
  written after every chunk unless told otherwise); the checkpoint stays for a test to
  read, damage or resume;
* :func:`interrupted_then_resumed`: :func:`interrupt`, then resume; the resumed
  :class:`~drpt.distributed.job.Job`, whose ``result`` a test compares with a plain
  render's (bit for bit: a chunk's sums are a pure function of the scene, the options and
  the chunk).
"""

from __future__ import annotations

import pytest


def interrupt(scene, opts, out, after: int = 3, checkpoint_seconds: float | None = 0.0) -> None:
    """Render ``scene`` with ``opts`` to ``out`` and stop it with ``KeyboardInterrupt``
    once ``after`` chunks are merged (``checkpoint_seconds``: ``run``'s; ``None`` leaves
    its default). Fails the test if the render was not interrupted."""
    from drpt.distributed.job import run

    def stop(merged, result, engine):
        if merged.next >= after:
            raise KeyboardInterrupt

    kw = {} if checkpoint_seconds is None else {"checkpoint_seconds": checkpoint_seconds}
    with pytest.raises(KeyboardInterrupt):
        run(scene, opts, out, on_chunk=stop, **kw)


def interrupted_then_resumed(scene, opts, out, after: int = 3, checkpoint_seconds: float | None = 0.0):
    """:func:`interrupt`, then the same render resumed from its checkpoint: the resumed
    :class:`~drpt.distributed.job.Job`."""
    from drpt.distributed.job import run

    interrupt(scene, opts, out, after, checkpoint_seconds)
    return run(scene, opts, out, resume=True)
