"""Chunks traced on a Dask cluster: a local one or one at an address.

Dask distributed is the engine: it is pure Python (``pip install``, no
runtime of its own), starts a local cluster of worker processes in one call
(``LocalCluster(n_workers=N, threads_per_worker=1, processes=True)``),
joins a remote scheduler by address, runs a task again elsewhere when its
worker dies, and has ``as_completed`` and a dashboard.

What travels: the parsed scene (:class:`~drpt.scene.model.Scene`: geometry,
materials, lights, camera; pickled) goes to every worker once
(``client.scatter(..., broadcast=True)``; a worker that starts later copies
it from a peer). Images the scene names (textures, the sky) are read by each
worker from the same path, so across machines they must be on a shared path.
Each task then carries the scene's hash, the options and a chunk index, and
returns the chunk's float64 sums (48 bytes per pixel). A worker process keeps
its :class:`~drpt.render.renderer.Renderer` (device scene, accelerator,
compiled kernels) between chunks of the same scene and options
(:func:`trace_chunk`). Workers of a local cluster share the cores: Dr.Jit's
thread pool in each gets ``cores // N`` threads; a ``dask worker`` started by
hand keeps Dr.Jit's default, a thread per core of its machine.
"""

from __future__ import annotations

import asyncio
import json
import logging
import os
from collections.abc import Iterable, Iterator
from dataclasses import replace

from .. import backend as backends
from ..backend import ensure, name
from ..errors import DrptError
from ..render.chunks import ChunkResult
from ..render.renderer import Renderer

# Per worker process: the renderer of the last (scene hash, options) it traced.
_RENDERERS: dict[str, object] = {}


def trace_chunk(key: str, scene, opts, index: int, backend: str = "llvm") -> ChunkResult:
    """Run on a worker: chunk ``index`` of the render ``key`` (scene hash and
    options) on the coordinator's Dr.Jit ``backend``. The first chunk of a
    render on a worker builds its renderer (and returns the scene's
    warnings); later ones reuse it."""
    backends.select(backend)
    renderer = _RENDERERS.get(key)
    new = renderer is None
    if new:
        _RENDERERS.clear()
        ensure()
        renderer = Renderer(scene, replace(opts, progress=False))
        _RENDERERS[key] = renderer
    result = renderer.render_chunk(index)
    try:
        from distributed import get_worker

        result.worker = get_worker().address
    except (ImportError, ValueError):
        result.worker = f"pid {os.getpid()}"
    if new:
        result.warnings = list(renderer.warnings)
        result.seconds += renderer.build_seconds
    return result


def _share_cores(threads: int) -> None:
    """Run on a local worker: Dr.Jit's thread pool takes its share of the cores."""
    import drjit as dr

    dr.set_thread_count(threads)


# The function the workers run; tests replace it with one that fails.
TASK = trace_chunk


def _lost(e: BaseException) -> bool:
    """Whether ``e`` means the scheduler (or the connection to it) is gone."""
    import asyncio
    import concurrent.futures

    from distributed.comm.core import CommClosedError

    return isinstance(e, (CommClosedError, OSError, TimeoutError, asyncio.CancelledError,
                          concurrent.futures.CancelledError))


def check_address(address: str) -> str:
    """``address`` if drpt can join a scheduler there (``tcp://host:port`` or
    ``host:port``), else a DrptError: other protocols (``tls://`` needs
    certificates drpt does not pass, ``ucx://`` a package it does not
    install), spaces or control characters."""
    shown = repr(address)
    if not address or any(c.isspace() or not c.isprintable() for c in address):
        raise DrptError(f"--cluster {shown}: an address has no spaces or control characters "
                        "(tcp://host:8786)")
    scheme, sep, rest = address.rpartition("://")
    if sep and scheme != "tcp":
        raise DrptError(f"--cluster {shown}: drpt joins schedulers over tcp:// only, "
                        f"not {scheme}://")
    host, colon, port = rest.rpartition(":")
    import re

    if (not colon or not re.fullmatch(r"[A-Za-z0-9.-]+|\[[0-9A-Fa-f:.]+\]", host)
            or not re.fullmatch(r"[0-9]{1,5}", port) or not 0 < int(port) < 65536):
        raise DrptError(f"--cluster {shown}: give the scheduler as tcp://HOST:PORT")
    return address


def probe(address: str, timeout: float) -> None:
    """Connect to ``address`` and read the handshake a Dask scheduler sends
    first, all within ``timeout`` seconds: a server that never answers, or
    answers in another protocol (HTTP, garbage), is a DrptError here, before
    Dask's client reads a frame length from it (and allocates that much) or
    waits on it without a deadline."""
    import socket
    import struct
    import time

    rest = address.rpartition("://")[2]
    host, _, port = rest.rpartition(":")
    host = host.strip("[]")
    end = time.monotonic() + timeout

    def fail(why: str) -> DrptError:
        return DrptError(f"--cluster {address}: {why}")

    def recv(sock, n: int) -> bytes:
        out = b""
        while len(out) < n:
            left = end - time.monotonic()
            if left <= 0:
                raise TimeoutError
            sock.settimeout(left)
            chunk = sock.recv(n - len(out))
            if not chunk:
                raise fail("the server closed the connection (not a Dask scheduler?)")
            out += chunk
        return out

    def connect():
        """A connection, tried again until the deadline (as Dask's client does:
        a scheduler that is starting refuses connections for a moment)."""
        while True:
            try:
                return socket.create_connection((host, int(port)), timeout=max(end - time.monotonic(), 0.001))
            except (ConnectionRefusedError, ConnectionResetError):
                if time.monotonic() + 0.1 >= end:
                    raise
                time.sleep(0.1)

    try:
        with connect() as sock:
            (nbytes,) = struct.unpack("<Q", recv(sock, 8))
            if not 16 <= nbytes <= 1 << 20:
                raise fail("the server does not speak Dask's protocol (not a Dask scheduler?)")
            frames = recv(sock, nbytes)
            (count,) = struct.unpack_from("<Q", frames)
            if not 1 <= count <= 64 or 8 * (count + 1) > nbytes:
                raise fail("the server does not speak Dask's protocol (not a Dask scheduler?)")
    except (TimeoutError, socket.timeout):
        raise fail(f"no Dask scheduler answered within {timeout:g} s") from None
    except OSError as e:
        raise fail(f"no Dask scheduler answered within {timeout:g} s "
                   f"({_one_line(e)})") from None


def _one_line(e: BaseException) -> str:
    text = " ".join(f"{type(e).__name__}: {e}".split())
    if "deserializ" in text:
        text += " (the scheduler and every worker need this drpt installed, and its dependencies)"
    return text


RESUBMITS = 3  # times a chunk cancelled under a live scheduler is submitted again


class DaskEngine:
    """Traces chunks on ``workers`` local worker processes or on the scheduler
    at ``address``; :meth:`results` yields them as they finish.

    A chunk whose task raised is tried ``retries`` more times, then stops the
    render with a DrptError; one whose worker died runs on another worker
    (Dask's own rule, up to ``distributed.scheduler.allowed-failures`` deaths)."""

    def __init__(self, scene, scene_hash: str, opts, *, workers: int | None = None,
                 address: str | None = None, connect_timeout: float = 5.0, retries: int = 2):
        try:
            import distributed  # noqa: F401
        except ImportError:
            raise DrptError("--workers/--cluster need Dask distributed: "
                            "pip install 'drpt[cluster]' (or pip install distributed)") from None
        opts = replace(opts, max_lanes=opts.lanes)  # the coordinator's, not each worker's, default
        if address is not None:
            check_address(address)
        self.scene, self.opts, self.backend = scene, opts, name()
        self.key = scene_hash + json.dumps(repr(opts))
        self.workers, self.address = workers, address
        self.connect_timeout, self.retries = connect_timeout, retries
        self.client = self.cluster = None

    def __enter__(self) -> DaskEngine:
        import signal
        import threading

        from distributed import Client, LocalCluster

        # drpt reports lost workers, failed chunks and a lost scheduler itself, in one line
        names = ["distributed"] + [n for n in logging.root.manager.loggerDict
                                   if n.startswith("distributed.")]
        self.log_levels = {n: logging.getLogger(n).level for n in names}
        for n in names:
            logging.getLogger(n).setLevel(logging.CRITICAL)
        try:
            if self.address is not None:
                probe(self.address, self.connect_timeout)
                try:
                    self.client = Client(self.address, timeout=self.connect_timeout)
                except (OSError, TimeoutError, ValueError) as e:
                    raise DrptError(f"--cluster {self.address}: no Dask scheduler answered within "
                                    f"{self.connect_timeout:g} s ({_one_line(e)})") from None
            else:
                # the worker processes start with Ctrl-C ignored (an ignored signal stays
                # ignored in a child, and Python then installs no KeyboardInterrupt handler):
                # a terminal's Ctrl-C reaches the whole process group, and only this
                # process stops the render, with its checkpoint
                main = threading.current_thread() is threading.main_thread()
                old = signal.signal(signal.SIGINT, signal.SIG_IGN) if main else None
                try:
                    # no dashboard; the scheduler's HTTP server (which it starts anyway, on
                    # 8787 unless told, with a warning when that is taken) on a free port
                    # of this machine only
                    self.cluster = LocalCluster(n_workers=self.workers, threads_per_worker=1,
                                                processes=True, dashboard_address=None,
                                                scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
                                                silence_logs=logging.ERROR)
                finally:
                    if main:
                        signal.signal(signal.SIGINT, old)
                self.client = Client(self.cluster)
                # one core per worker process (Dr.Jit would start a thread per core in each)
                self.client.run(_share_cores, max(1, (os.cpu_count() or 1) // self.workers))
            try:
                self.scene_future = self.client.scatter(self.scene, broadcast=True)
            except (TimeoutError, OSError) as e:  # Dask's scatter waits a while for a worker
                where = f"--cluster {self.address}" if self.address is not None else "--workers"
                raise DrptError(f"{where}: no Dask worker took the scene ({_one_line(e)}); start "
                                "workers with: dask worker ADDRESS") from None
        except BaseException:
            self.__exit__()
            raise
        return self

    def __exit__(self, *exc) -> None:
        for thing in (self.client, self.cluster):
            if thing is not None:
                try:
                    thing.close()
                except Exception:  # noqa: BLE001 - closing a lost connection
                    pass
        for n, level in getattr(self, "log_levels", {}).items():
            logging.getLogger(n).setLevel(level)

    @property
    def n_workers(self) -> int:
        return max(1, len(self.client.scheduler_info().get("workers", {})))

    def _scheduler_alive(self) -> bool:
        """Whether the client is still connected to its scheduler (a lost
        scheduler turns the status to connecting or closed within moments)."""
        import time

        for _ in range(5):
            if self.client.status != "running":
                return False
            time.sleep(0.1)
        return True

    def results(self, todo: Iterable[int]) -> Iterator[ChunkResult]:
        """The chunks of ``todo`` as they finish. A chunk cancelled while the
        scheduler still answers (a worker that died can take its tasks, or the
        scene's copy, with it) is submitted again, up to ``RESUBMITS`` times."""
        from distributed import as_completed

        todo = iter(todo)
        window = 4 * self.n_workers
        index_of = {}
        resubmitted: dict[int, int] = {}
        ac = as_completed()

        def submit(i: int) -> None:
            if self.scene_future.status != "finished":  # its holders died: send the scene again
                self.scene_future = self.client.scatter(self.scene, broadcast=True)
            f = self.client.submit(TASK, self.key, self.scene_future, self.opts, i, self.backend,
                                   retries=self.retries, pure=False, priority=-i)
            index_of[f] = i
            ac.add(f)

        def submit_next() -> bool:
            i = next(todo, None)
            if i is None:
                return False
            submit(i)
            return True

        def again(i: int, why: str) -> None:
            """Submit chunk ``i`` once more, or stop: the scheduler is gone."""
            if resubmitted.get(i, 0) < RESUBMITS and self._scheduler_alive():
                resubmitted[i] = resubmitted.get(i, 0) + 1
                submit(i)
                return
            raise DrptError(f"the Dask scheduler went away ({why})")

        for _ in range(window):
            if not submit_next():
                break
        try:
            for f in ac:
                i = index_of.pop(f)
                if f.status == "error":
                    e = f.exception()
                    if not _lost(e):
                        raise DrptError(f"chunk {i} failed {self.retries + 1} times on the workers: "
                                        f"{_one_line(e)}")
                    again(i, _one_line(e))
                    continue
                if f.status == "cancelled":
                    again(i, f"chunk {i} was cancelled")
                    continue
                try:
                    result = f.result()
                except (Exception, asyncio.CancelledError) as e:
                    if not _lost(e):
                        raise
                    again(i, _one_line(e))
                    continue
                f.release()
                yield result
                submit_next()
        except DrptError:
            raise
        except (Exception, asyncio.CancelledError) as e:
            if _lost(e):
                raise DrptError(f"the Dask scheduler went away ({_one_line(e)})") from None
            raise
