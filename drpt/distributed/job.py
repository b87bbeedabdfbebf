"""One render job: its chunks traced here or on Dask, merged in order,
checkpointed, resumable.

:func:`run` is what ``drpt render`` calls. Chunks come from an engine: in
this process (:class:`LocalEngine`, chunk after chunk) or on Dask
(:class:`~drpt.distributed.engine.DaskEngine`, in any order), and go to a
:class:`~drpt.render.chunks.ChunkMerge`. The merged sums are written as a
checkpoint (:mod:`.checkpoint`) every ``checkpoint_seconds`` once the merged
prefix of chunks has grown since the last one, and whenever the job stops
before its end (Ctrl-C, SIGTERM, a failing chunk, a lost scheduler, any error
in this process); the caller removes it once the image is written (:func:`drpt.distributed.checkpoint.remove`).
"""

from __future__ import annotations

import contextlib
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import note
from ..options import LIGHT_TRACED, resolve_sampler
from ..render.chunks import ChunkMerge, ChunkResult, plan_chunks
from ..render.renderer import Renderer, finish, stop_estimate, stops
from . import checkpoint
from .engine import DaskEngine


class LocalEngine:
    """Chunks traced in this process, in order, by one :class:`Renderer`."""

    def __init__(self, scene, opts):
        from dataclasses import replace

        self.renderer = Renderer(scene, replace(opts, progress=False))
        self.sent_warnings = False

    def __enter__(self) -> LocalEngine:
        return self

    def __exit__(self, *exc) -> None:
        pass

    def results(self, todo: Iterable[int], into=None) -> Iterator[ChunkResult]:
        """The chunks' results in order; with ``into`` (the job's merge) the chunks that
        can are added straight into it (:meth:`Renderer.render_chunk`)."""
        for i in todo:
            r = self.renderer.render_chunk(i, into=into)
            r.worker = "this process"
            if not self.sent_warnings:
                r.warnings, self.sent_warnings = list(self.renderer.warnings), True
                r.seconds += self.renderer.build_seconds
            yield r


@contextlib.contextmanager
def _stop_requests():
    """Ctrl-C and SIGTERM ask the job to stop after the chunk in hand (a
    KeyboardInterrupt inside a Dr.Jit trace would surface as a RuntimeError);
    a second one stops at once. Yields a list that is non-empty once asked."""
    asked: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield asked
        return

    def handler(signum, frame):
        if asked:
            raise KeyboardInterrupt
        asked.append(signum)

    old = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield asked
    finally:
        for s, h in old.items():
            signal.signal(s, h)


@dataclass
class WorkerStats:
    """What one worker did: chunks and samples rendered, and their render seconds."""

    chunks: int = 0
    samples: int = 0
    seconds: float = 0.0


@dataclass
class Job:
    """What :func:`run` returns besides the image."""

    result: object  # RenderResult
    workers: dict[str, WorkerStats] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    resumed_from: int = 0  # chunks merged by the checkpoint it resumed
    stopped: str | None = None  # "target error" or "time limit" when one ended it early
    resumed_spp: int = 0  # samples per pixel those chunks hold
    requested_workers: int | None = None  # --workers N
    startup_seconds: float = 0.0  # starting the engine (a local Dask cluster), before the render


def run(scene, opts, output: Path, *, workers: int | None = None, cluster: str | None = None,
        resume: bool = False, checkpoint_seconds: float = 30.0, connect_timeout: float = 5.0,
        on_chunk: Callable | None = None, on_warning: Callable[[str], None] | None = None) -> Job:
    """Render ``scene`` with ``opts``; checkpoints go beside ``output``.

    Ctrl-C or SIGTERM stops the job after the chunk in hand (a second one at
    once) with a KeyboardInterrupt, after writing a checkpoint.

    ``workers`` starts a local Dask cluster of that many processes, ``cluster``
    joins the scheduler at that address, neither traces in this process.
    ``on_chunk(merge, result, engine)`` is called after each result arrives;
    ``on_warning(message)`` once for each of the scene's warnings, as soon as
    it is known (before tracing in this process, with the first chunk from
    workers)."""
    from tqdm import tqdm

    # --sampler auto: the sampler it means (a resumed render's is its checkpoint's), so that
    # the checkpoint records the sampler its sums were drawn with
    # (the checkpoint is read for it only where auto is left to resolve: cmd_render resolves first)
    opts = resolve_sampler(opts, checkpoint.recorded_sampler(output) if resume and opts.sampler == "auto" else None)
    W, H, spp = opts.width, opts.height, opts.spp
    light_tracing = opts.integrator in LIGHT_TRACED
    chunks = plan_chunks(W, H, spp, opts.lanes, opts.chunk_spp)
    key = checkpoint.scene_hash(scene)
    okey = checkpoint.options_key(opts)
    checkpoint.check_paths(output)
    if resume:
        cp = checkpoint.load(output, key, okey, chunks)
        merged = ChunkMerge(chunks, cp.next, cp.sum, cp.sumsq, cp.nonfinite, cp.weight, cp.aov)
    else:
        merged = ChunkMerge(chunks)
    job = Job(None, resumed_from=merged.next, resumed_spp=merged.spp, requested_workers=workers)
    left = chunks.count - merged.next
    if workers is not None and 0 < left < workers:
        hint = ("" if opts.chunk_spp is not None and opts.chunk_spp == 1
                else "; a smaller --chunk-spp cuts it into more")
        note(f"the render is {left} chunk{'s' if left > 1 else ''} for {workers} workers: "
             f"{workers - left} will have nothing to do{hint}")

    def save() -> None:
        checkpoint.save(output, checkpoint.Checkpoint(key, okey, chunks.count, merged.next, merged.spp,
                                                      merged.nonfinite, merged.sum, merged.sumsq,
                                                      merged.weight, merged.aov))

    def report(messages) -> None:
        for w in messages:
            if w not in job.warnings:
                job.warnings.append(w)
                if on_warning is not None:
                    on_warning(w)

    if workers is None and cluster is None:
        engine = LocalEngine(scene, opts)
        report(engine.renderer.warnings)
    else:
        engine = DaskEngine(scene, key, opts, workers=workers, address=cluster,
                            connect_timeout=connect_timeout)
    t0 = last = time.perf_counter()
    entered = t0
    saved = merged.next  # the merged prefix the last checkpoint holds
    seen = set()
    build = 0.0
    try:
        with _stop_requests() as asked, engine, tqdm(total=W * H * spp, initial=W * H * merged.spp, unit="spl",
                          unit_scale=True, disable=not opts.progress, desc="render",
                          leave=False) as bar:
            # the time to start a local cluster (seconds) is not the render's
            t0 = last = time.perf_counter()
            job.startup_seconds = t0 - entered
            # in this process, chunks are added straight into the merge where they can
            # (no full-image copy per chunk: drpt.render.renderer.Renderer.render_chunk)
            direct = {"into": merged} if isinstance(engine, LocalEngine) else {}
            for r in engine.results(range(merged.next, chunks.count), **direct):
                stats = job.workers.setdefault(r.worker, WorkerStats())
                stats.chunks += 1
                stats.samples += W * H * r.spp
                stats.seconds += r.seconds
                report(r.warnings)
                if r.index not in seen:
                    seen.add(r.index)
                    bar.update(W * H * r.spp)
                grew = merged.push(r)
                if on_chunk is not None:
                    on_chunk(merged, r, engine)
                if asked:
                    raise KeyboardInterrupt
                if grew:
                    estimate = stop_estimate(merged, opts, time.perf_counter() - t0, light_tracing)
                    if estimate is not None:
                        bar.set_postfix_str(f"relMSE ~{estimate:.3g}")
                    if stops(estimate, merged, opts, time.perf_counter() - t0):
                        job.stopped = "target error" if opts.target_error is not None and \
                            estimate is not None and estimate <= opts.target_error else "time limit"
                        break
                now = time.perf_counter()
                # a checkpoint holds the merged prefix of chunks: none is written
                # before it grows (Dask's first result need not be chunk 0)
                if not merged.done and merged.next > saved and now - last >= checkpoint_seconds:
                    try:
                        save()
                    except OSError as e:  # a full disk: the render goes on without one
                        npz, _ = checkpoint.paths(output)
                        if on_warning is not None:
                            on_warning(f"{npz}: cannot write the checkpoint: {e.strerror or e}")
                    saved, last = merged.next, now
    except BaseException:
        if merged.dirty:
            # stopped inside a chunk that was being added straight into the sums: they are
            # no merged prefix of chunks, so the checkpoint written last (if any) stays
            npz, _ = checkpoint.paths(output)
            kept = (f"checkpoint {npz.name} kept from before ({saved} of {chunks.count} chunks)"
                    if npz.is_file() else "no checkpoint written")
            note(f"stopped inside a chunk: {kept}")
            raise
        if merged.next > job.resumed_from or resume:
            npz, _ = checkpoint.paths(output)
            try:
                save()
            except OSError as e:
                note(f"no checkpoint written: {npz}: {e.strerror or e}")
                raise
            note(f"checkpoint {npz.name} kept: {merged.next} of {chunks.count} chunks "
                 f"({merged.spp} of {spp} spp); continue with --resume")
        raise
    if isinstance(engine, LocalEngine):
        build = engine.renderer.build_seconds
    job.result = finish(merged, time.perf_counter() - t0, build, light_tracing, consume=True,
                        variance=opts.light_variance)
    # the samples traced now: a resumed render's checkpoint was rendered before
    job.result.samples = W * H * (merged.spp - job.resumed_spp)
    return job


def print_workers(job: Job, file=None) -> None:
    """Per-worker figures: chunks, samples and seconds each; more workers than
    ``--workers`` asked for are explained (Dask replaces a worker that stopped)."""
    file = sys.stderr if file is None else file
    n, asked = len(job.workers), job.requested_workers
    if asked is not None and n > asked:
        print(f"  {n} workers for --workers {asked}: {n - asked} replaced "
              f"{'one' if n - asked == 1 else 'ones'} that stopped (their chunks were traced "
              "again; the image is the same)", file=file)
    for name, s in sorted(job.workers.items()):
        print(f"  {name}: {s.chunks} chunks, {s.samples / 1e6:.3g} Msamples, {s.seconds:.2f} s",
              file=file)
