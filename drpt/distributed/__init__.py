"""Chunked renders: on other processes or machines (Dask), and resumable.

A render is a list of chunks (:mod:`drpt.render.chunks`), each a pure
function of (scene content, render options, chunk index). :func:`.job.run`
traces them, in this process or on a Dask cluster (:mod:`.engine`), merges
them in chunk order and writes checkpoints (:mod:`.checkpoint`) from which
``--resume`` continues. The image is the same bit for bit whichever way the
chunks were traced. See ``docs/distributed.md``.

Only :mod:`.engine` imports Dask, and only when a render asks for workers.
"""
