"""Chunked, distributed and resumable renders (drpt/render/chunks.py, drpt/distributed/).

The Dask tests start a local cluster of 2 worker processes (one per core of
the test machine) and render 16x16 images in many small chunks."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

FLAGS = ["--size", "16", "16", "-q"]


def _render(scene, tmp_path, name, *flags, spp=16, chunk=1):
    from drpt.cli import main
    from drpt.imageio import read_image

    out = tmp_path / f"{name}.exr"
    assert main(["render", str(scene), *FLAGS, "--spp", str(spp), "--chunk-spp", str(chunk),
                 "-o", str(out), *flags]) == 0
    return read_image(out)


def _chunks(spp=8):
    from drpt.render.chunks import plan_chunks

    return plan_chunks(4, 3, spp, 1 << 21, 1)


# ------------------------------------------------------------------ plan and merge
@pytest.mark.parametrize("w,h,spp,lanes,chunk_spp", [(16, 16, 16, 1 << 21, None), (16, 16, 16, 1 << 21, 3),
                                                    (7, 5, 33, 64, 4), (100, 37, 3, 250, 2),
                                                    (8, 8, 10, 1 << 21, 100)])
def test_chunks_cover_every_sample_once(w, h, spp, lanes, chunk_spp):
    from drpt.render.chunks import plan_chunks

    chunks = plan_chunks(w, h, spp, lanes, chunk_spp)
    count = np.zeros((h, spp), int)
    passes = []
    for c in range(chunks.count):
        got = 0
        for i in chunks.passes_of(c):
            s0, k, r0, rows = chunks.passes[i]
            count[r0:r0 + rows, s0:s0 + k] += 1
            passes.append(i)
            got = max(got, s0 + k)
        assert got - chunks.spp_before(c) == chunks.spp_of(c)
        if chunk_spp is not None:
            assert chunks.spp_of(c) <= chunk_spp
    assert passes == list(range(chunks.passes.count))
    assert np.all(count == 1)


def test_default_chunks_keep_the_pass_plan():
    """Without --chunk-spp the passes (and so the random numbers) are plan_passes' own."""
    from drpt.render.chunks import plan_chunks
    from drpt.render.renderer import plan_passes

    for args in ((16, 16, 16, 1 << 21), (512, 512, 64, 1 << 21), (2000, 2000, 4, 1 << 21)):
        assert plan_chunks(*args).passes == plan_passes(*args)


def test_merge_is_in_chunk_order_whatever_the_arrival():
    from drpt.render.chunks import ChunkResult, merge

    chunks = _chunks()
    rng = np.random.default_rng(1)
    results = [ChunkResult(c, chunks.spp_of(c), rng.random((3, 4, 3)) * 10 ** rng.uniform(-8, 8),
                           rng.random((3, 4, 3)), nonfinite=c) for c in range(chunks.count)]
    ref = merge(chunks, results)
    assert ref.done and ref.spp == 8 and ref.nonfinite == sum(range(chunks.count))
    for seed in range(5):
        order = list(np.random.default_rng(seed).permutation(len(results)))
        # arrivals in any order, some twice (a chunk traced again after a lost worker)
        arrivals = [results[i] for i in order] + [results[order[0]]]
        m = merge(chunks, arrivals)
        assert m.done and not m.pending
        assert np.array_equal(m.sum, ref.sum) and np.array_equal(m.sumsq, ref.sumsq)
        assert m.nonfinite == ref.nonfinite


def test_merge_waits_for_the_next_chunk():
    from drpt.render.chunks import ChunkMerge, ChunkResult

    chunks = _chunks()
    m = ChunkMerge(chunks)
    z = np.ones((3, 4, 3))
    assert m.push(ChunkResult(2, 1, z, z)) == []
    assert m.push(ChunkResult(0, 1, z, z)) == [0]
    assert m.push(ChunkResult(1, 1, z, z)) == [1, 2]
    assert m.next == 3 and m.spp == 3 and np.all(m.sum == 3)


@pytest.mark.slow
def test_a_chunk_is_pure(cornell):
    from drpt.options import RenderOptions
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene

    scene = load_scene(cornell)
    opts = RenderOptions(width=8, height=8, spp=8, chunk_spp=2, progress=False)
    a = Renderer(scene, opts)
    first, again = a.render_chunk(2), a.render_chunk(2)
    other = Renderer(load_scene(cornell), opts).render_chunk(2)
    for r in (again, other):
        assert np.array_equal(first.sum, r.sum) and np.array_equal(first.sumsq, r.sumsq)
    assert first.spp == 2 and first.sum.dtype == np.float64
    assert not np.array_equal(first.sum, a.render_chunk(1).sum)


@pytest.mark.slow
def test_plain_render_does_not_import_dask(tmp_path, repo, cornell):
    code = ("import sys; from drpt.cli import main; "
            f"rc = main(['render', {str(cornell)!r}, '--size', '8', '8', '--spp', '2', '-q', "
            f"'-o', {str(tmp_path / 'a.exr')!r}]); "
            "print(rc, sorted(m for m in sys.modules if m.split('.')[0] in ('dask', 'distributed')))")
    out = subprocess.run([sys.executable, "-c", code], cwd=repo, capture_output=True, text=True,
                         timeout=120)
    assert out.stdout.split("\n")[-2] == "0 []", out.stderr


# ------------------------------------------------------------------ on Dask
@pytest.mark.slow
def test_workers_give_the_plain_image_bit_for_bit(tmp_path, cornell):
    pytest.importorskip("distributed")
    indep = ("--sampler", "independent")  # the default's (ldsampler's) image: the test below
    plain = _render(cornell, tmp_path, "plain", *indep)
    assert np.array_equal(plain, _render(cornell, tmp_path, "w1", "--workers", "1", *indep))
    assert np.array_equal(plain, _render(cornell, tmp_path, "w2", "--workers", "2", *indep))
    assert not list(tmp_path.glob("*.drpt-checkpoint*"))


@pytest.mark.slow
def test_workers_give_the_plain_image_with_the_ldsampler(tmp_path, cornell):
    pytest.importorskip("distributed")
    plain = _render(cornell, tmp_path, "plain", "--sampler", "ldsampler")
    assert np.array_equal(plain, _render(cornell, tmp_path, "w2", "--workers", "2", "--sampler", "ldsampler"))
    assert not np.array_equal(plain, _render(cornell, tmp_path, "indep", "--sampler", "independent"))


@pytest.mark.slow
def test_killed_worker_leaves_the_image_unchanged(tmp_path, cornell):
    pytest.importorskip("distributed")
    from drpt.distributed.job import run
    from drpt.options import RenderOptions
    from drpt.scene import load_scene

    opts = RenderOptions(width=16, height=16, spp=24, chunk_spp=1, progress=False)
    scene = load_scene(cornell)
    plain = run(scene, opts, tmp_path / "plain.exr").result.image
    killed = []

    def kill_one(merged, result, engine):
        if not killed and merged.next >= 2:
            pids = engine.client.run(os.getpid)
            victim = sorted(pids)[0]
            os.kill(pids[victim], signal.SIGKILL)
            killed.append(victim)

    job = run(scene, opts, tmp_path / "w2.exr", workers=2, on_chunk=kill_one)
    assert killed
    assert np.array_equal(plain, job.result.image)
    assert sum(s.chunks for s in job.workers.values()) >= 24


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow
def test_lost_scheduler_is_one_error_and_keeps_the_samples(tmp_path, repo, cornell):
    pytest.importorskip("distributed")
    from drpt.distributed.job import run
    from drpt.errors import DrptError
    from drpt.options import RenderOptions
    from drpt.scene import load_scene

    address = f"tcp://127.0.0.1:{_free_port()}"
    dask = Path(sys.executable).with_name("dask")
    env = {**os.environ, "PYTHONPATH": str(repo)}  # the scheduler unpickles the tasks too
    scheduler = subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", address.rsplit(":")[-1],
                                  "--no-dashboard"], env=env, stderr=subprocess.DEVNULL)
    worker = subprocess.Popen([dask, "worker", address, "--nthreads", "1", "--no-nanny", "--no-dashboard"], env=env,
                              stderr=subprocess.DEVNULL)
    try:
        opts = RenderOptions(width=16, height=16, spp=64, chunk_spp=1, progress=False)
        scene = load_scene(cornell)
        out = tmp_path / "lost.exr"

        def stop_scheduler(merged, result, engine):
            if merged.next >= 3 and scheduler.poll() is None:
                scheduler.kill()

        with pytest.raises(DrptError, match="scheduler went away"):
            run(scene, opts, out, cluster=address, connect_timeout=30, on_chunk=stop_scheduler)
        state = json.loads(Path(str(out) + ".drpt-checkpoint.json").read_text())
        assert state["next"] >= 3
        resumed = run(scene, opts, out, resume=True).result.image
        assert np.array_equal(resumed, run(scene, opts, tmp_path / "whole.exr").result.image)
    finally:
        for p in (worker, scheduler):
            p.kill()
            p.wait()


def _always_fails(*args):
    raise RuntimeError("this chunk always fails")


@pytest.mark.slow
def test_a_chunk_that_keeps_failing_is_one_error(tmp_path, monkeypatch, capsys, cornell):
    pytest.importorskip("distributed")
    import cloudpickle

    from drpt.cli import main
    from drpt.distributed import engine

    cloudpickle.register_pickle_by_value(sys.modules[__name__])
    monkeypatch.setattr(engine, "TASK", _always_fails)
    rc = main(["render", str(cornell), *FLAGS, "--spp", "4", "--chunk-spp", "1", "--workers", "1",
               "-o", str(tmp_path / "x.exr")])
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("drpt")]
    assert rc == 2
    assert len(err) == 1 and err[0].startswith("drpt: error: chunk ") and "always fails" in err[0]


@pytest.mark.slow
def test_bad_cluster_address_is_one_error_quickly(tmp_path, capsys, cornell):
    pytest.importorskip("distributed")
    from drpt.cli import main

    t0 = time.perf_counter()
    rc = main(["render", str(cornell), *FLAGS, "--cluster", "tcp://127.0.0.1:9",
               "-o", str(tmp_path / "x.exr")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and err[0].startswith("drpt: error: --cluster tcp://127.0.0.1:9")
    assert time.perf_counter() - t0 < 30


# ------------------------------------------------------------------ checkpoints
SPP, CHUNK = 256, 4  # 64 chunks: the render is still running when the signal comes


def _interrupt(scene, repo, out, *flags, sig=signal.SIGINT):
    """Start a render in a subprocess, signal it once it wrote a checkpoint."""
    meta = Path(str(out) + ".drpt-checkpoint.json")
    cmd = [sys.executable, "-m", "drpt", "render", str(scene), *FLAGS, "--spp", str(SPP),
           "--chunk-spp", str(CHUNK),
           "--checkpoint-seconds", "0", "-o", str(out), *flags]
    p = subprocess.Popen(cmd, cwd=repo, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    t0 = time.monotonic()
    while not meta.exists() and p.poll() is None and time.monotonic() - t0 < 120:
        time.sleep(0.02)
    p.send_signal(sig)
    _, err = p.communicate(timeout=120)
    if sig == signal.SIGKILL:  # the periodic checkpoint is all there is
        assert p.returncode == -signal.SIGKILL
    else:
        assert p.returncode == 130, err
        assert "continue with --resume" in err
    state = json.loads(meta.read_text())
    assert 0 < state["next"] < state["chunks"]
    return state


@pytest.mark.slow
@pytest.mark.parametrize("sig,first,then", [(signal.SIGINT, (), ("--workers", "2")),
                                           (signal.SIGTERM, ("--workers", "2"), ()),
                                           (signal.SIGKILL, (), ())],
                         ids=["ctrl-c-plain-then-workers", "sigterm-workers-then-plain", "sigkill-plain"])
def test_resume_after_an_interrupt_gives_the_uninterrupted_image(tmp_path, sig, first, then, repo, cornell):
    if "--workers" in first + then:
        pytest.importorskip("distributed")
    whole = _render(cornell, tmp_path, "whole", spp=SPP, chunk=CHUNK)
    out = tmp_path / "cut.exr"
    _interrupt(cornell, repo, out, *first, sig=sig)
    assert np.array_equal(whole, _render(cornell, tmp_path, "cut", "--resume", *then, spp=SPP, chunk=CHUNK))
    assert not list(tmp_path.glob("*.drpt-checkpoint*"))


@pytest.mark.slow
def test_resume_refuses_a_checkpoint_of_other_options(tmp_path, capsys, repo, cornell):
    from drpt.cli import main

    out = tmp_path / "cut.exr"
    _interrupt(cornell, repo, out)
    rc = main(["render", str(cornell), *FLAGS, "--spp", str(SPP), "--chunk-spp", str(CHUNK), "--seed", "7",
               "--resume", "-o", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "other options (seed differ)" in err[0]
    # an option inside another is named by its path
    rc = main(["render", str(cornell), *FLAGS, "--spp", str(SPP), "--chunk-spp", str(CHUNK), "--hide-emitters",
               "on", "--resume", "-o", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "other options (path.hide_emitters differ)" in err[0], err
    rc = main(["render", str(cornell), *FLAGS, "--spp", "8", "--resume", "-o", str(tmp_path / "none.exr")])
    assert rc == 2 and "no checkpoint" in capsys.readouterr().err


def _cut_after_two_chunks(monkeypatch):
    """Make the CLI's render stop (as by Ctrl-C) after its second chunk, keeping a checkpoint."""
    import drpt.cli.commands as commands
    from drpt.distributed.job import run

    def cut(*a, **kw):
        def on_chunk(merged, result, engine):
            if merged.next >= 2:
                raise KeyboardInterrupt
        return run(*a, **kw, on_chunk=on_chunk)

    monkeypatch.setattr(commands, "run", cut)


def test_resume_of_a_checkpoint_without_a_sampler_keeps_independent(tmp_path, monkeypatch, capsys, cornell):
    """A checkpoint whose options name no sampler (written when every render drew
    independent samples) resumes, with ``--sampler`` left at ``auto``, as ``independent``:
    the image is the uninterrupted ``--sampler independent`` render's bit for bit, and the
    summary line names the sampler. Negative control: without the checkpoint's sampler
    ``auto`` resolves to ``ldsampler`` and the resume is refused."""
    import drpt.cli.commands as commands
    from drpt.cli import main
    from drpt.imageio import read_image

    whole = _render(cornell, tmp_path, "whole", "--sampler", "independent", spp=8)
    out = tmp_path / "cut.exr"
    args = ["render", str(cornell), *FLAGS, "--spp", "8", "--chunk-spp", "1", "-o", str(out)]
    with monkeypatch.context() as m:
        _cut_after_two_chunks(m)
        assert main([*args, "--sampler", "independent"]) == 130
    npz = Path(str(out) + ".drpt-checkpoint.npz")
    with np.load(npz) as z:  # the checkpoint as an older drpt wrote it: no sampler in its options
        arrays = {k: z[k] for k in z.files}
    meta = json.loads(str(arrays["meta"]))
    assert meta["options"].pop("sampler") == "independent"
    arrays["meta"] = np.array(json.dumps(meta))
    np.savez(npz, **arrays)
    capsys.readouterr()
    with monkeypatch.context() as m:  # negative control: auto without the checkpoint's sampler
        m.setattr(commands.checkpoint, "recorded_sampler", lambda output: None)
        assert main([*args, "--resume"]) == 2
        assert "other options (sampler differ)" in capsys.readouterr().err
    assert main([*args, "--resume"]) == 0
    assert ", independent, " in capsys.readouterr().out
    assert np.array_equal(read_image(out), whole)


@pytest.mark.parametrize("flags,message", [(["--workers", "0"], "--workers must be between 1 and"),
                                           (["--workers", "2", "--cluster", "tcp://127.0.0.1:9"], "not both"),
                                           (["--chunk-spp", "0"], "--chunk-spp must be between"),
                                           (["--checkpoint-seconds", "-1"], "--checkpoint-seconds must be")])
def test_distributed_flag_errors_are_one_line(tmp_path, capsys, flags, message, cornell):
    from drpt.cli import main

    rc = main(["render", str(cornell), *FLAGS, "--spp", "1", "-o", str(tmp_path / "x.exr"), *flags])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and message in err[0]
    assert not (tmp_path / "x.exr").exists()


def test_scene_hash_is_the_same_in_every_process(cornell):
    """String hashing is randomized per process: a set in the scene model would
    pickle in another order in the worker that resumes a render."""
    import subprocess
    import sys

    code = ("from drpt.scene import load_scene; from drpt.distributed.checkpoint import scene_hash; "
            f"print(scene_hash(load_scene({str(cornell)!r})))")
    env = dict(os.environ)
    hashes = set()
    for seed in ("1", "2", "3", "4", "5", "6", "7"):  # a 2-element set: both orders among 7 runs w.p. 98%
        env["PYTHONHASHSEED"] = seed
        hashes.add(subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                                  check=True).stdout.strip())
    assert len(hashes) == 1, hashes


@pytest.mark.slow
def test_workers_with_dasks_default_ports_taken(tmp_path, capsys, cornell):
    """With Dask's default scheduler and dashboard ports (8786, 8787) in use, a --workers
    render takes free ports silently: the image, and no Dask warning. Negative control:
    the same cluster with the scheduler's HTTP server left on 8787 warns."""
    pytest.importorskip("distributed")
    import warnings

    from support.ports import taken

    with taken(8786, 8787):
        capsys.readouterr()
        _render(cornell, tmp_path, "w2", "--workers", "2", spp=2)
        err = capsys.readouterr().err
        assert "already in use" not in err and "Traceback" not in err, err
        from distributed import LocalCluster

        with warnings.catch_warnings(record=True) as seen:
            warnings.simplefilter("always")
            LocalCluster(n_workers=0, processes=False, dashboard_address=None).close()
        assert any("already in use" in str(w.message) for w in seen), [str(w.message) for w in seen]
