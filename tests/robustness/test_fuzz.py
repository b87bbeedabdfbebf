"""Fuzzing the readers with seeded mutations of the bundled inputs.

Every case (see tests/support/fuzz.py) mutates one file of a bundled scene or
one image and reads it in-process: :func:`drpt.scene.load_scene` for scene,
OBJ and MTL files, :func:`drpt.imageio.read_image` for images. The input is
either accepted or rejected with a :class:`~drpt.errors.DrptError` whose
message is one line starting ``FILE:LINE:`` (``FILE:`` for images); any other
exception, or a case running past ``CASE_SECONDS``, fails. An accepted
scene holds only finite numbers; an accepted image has at least one pixel.
Hand-written scenes at the ends of float64 (``support.fuzz.EXTREME_SCENES``)
are held to the same rule, and the valid ones among them must load.

A few cases also run ``python -m drpt render`` at 8x8, 1 spp, which must
exit 0 with a finite image, or exit 2 with exactly one ``drpt: error:
FILE:LINE: ...`` line (``FILE: ...`` for an image) and no image written;
the other stderr lines may only be drpt's one-line warnings and notes.
Never a traceback, never a hang.

Beyond drpt's own format (tests/support/fuzzformats.py): the Mitsuba XML test scenes
of tests/data/xml with their XML (values and structure), PLY, serialized
and OBJ meshes mutated, each loaded in-process under the same contract
(``xml/FILE-MUTATION-sSEED``); a real checkpoint damaged in ten ways and read
back, refused with one line naming it or accepted consistent
(``checkpoint/MUTATION-sSEED``); generated ``--cluster`` addresses
(``cluster/address-sSEED``) and fake servers on 127.0.0.1 that speak garbage,
HTTP, nothing, hang up or announce a huge frame, each one error within
0.5 s plus a margin (``cluster/server-KIND-sSEED``).

The test id is ``FOLDER/FILE-MUTATION-sSEED`` (``extremes/NAME`` for the
hand-written scenes); ``pytest tests/robustness/test_fuzz.py -k
'cornellbox.txt-truncate-s1'`` reruns one case. Cases that fail today
because of a known defect are listed in ``KNOWN`` (in-process) and
``KNOWN_RENDER`` (command line) and expected to fail, strictly: a fix
makes them pass, and the entry must then go.
"""

from __future__ import annotations

import contextlib
import signal
import subprocess
import sys
import warnings

import numpy as np
import pytest

from drpt.imageio import read_image
from drpt.scene import load_scene
from support import fuzz as fz
from support import fuzzformats as ff

CASE_SECONDS = 5

# the defects that make cases fail today; KNOWN*: case id -> defect (a strict
# xfail each: the case turns red when the defect is fixed, and leaves the list)
KNOWN: dict[str, str] = {}
KNOWN_RENDER: dict[str, str] = {}


@pytest.fixture(scope="module")
def images(tmp_path_factory):
    folder = tmp_path_factory.mktemp("fuzz_images")
    fz.make_images(folder)
    return folder


class CaseTimeout(BaseException):
    """A case ran too long (a BaseException, so that no ``except Exception``
    or ``except OSError`` in the code under test turns it into an error message)."""


@contextlib.contextmanager
def time_limit(seconds: float):
    """Raise :class:`CaseTimeout` in the main thread after ``seconds`` (a
    blocking ``open`` of a FIFO included: Python runs the handler and does not
    retry the call when the handler raises)."""

    def expire(signum, frame):
        raise CaseTimeout(f"still running after {seconds} s")

    old = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def _params(cases, known=KNOWN):
    out = []
    for c in cases:
        marks = [pytest.mark.xfail(strict=True, reason=known[c.id])] if c.id in known else []
        out.append(pytest.param(c, id=c.id, marks=marks))
    return out


def _read(case: fz.Case, entry):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with time_limit(CASE_SECONDS):
            if case.folder == "images":
                img = read_image(entry)
                assert img.ndim == 3 and img.shape[2] in (1, 3, 4) and img.dtype == np.float32
                assert img.shape[0] >= 1 and img.shape[1] >= 1, f"accepted an empty {img.shape} image"
                return img
            scene = load_scene(entry)
    fz.assert_finite(scene)
    return scene


@pytest.mark.parametrize("case", _params(fz.scene_cases() + fz.image_cases()))
def test_reader_accepts_or_reports(case, tmp_path, images):
    entry, _ = fz.build(case, tmp_path, images)
    try:
        _read(case, entry)
    except Exception as e:  # the contract is checked on any exception
        fz.check_error(e, tmp_path, image=case.folder == "images")


# A few cases through the command line, chosen to cover acceptance, scene
# errors, reference errors and images read only at render time.
RENDER_CASES = [
    fz.Case("cornellbox", "cornellbox.txt", "crlf", 0),
    fz.Case("cornellbox", "cornellbox.txt", "utf8_bom", 0),
    fz.Case("cornellbox", "cornellbox.txt", "extreme", 0),
    fz.Case("cornellbox", "cornellbox.txt", "extreme", 1),
    fz.Case("cornellbox", "cornellbox.txt", "truncate", 0),
    fz.Case("cornellbox", "cornellbox.txt", "utf16", 0),
    fz.Case("cornellbox", "cornellbox.txt", "group600", 0),
    fz.Case("cornellbox", "cornellbox.obj", "extreme", 0),
    fz.Case("cornellbox", "cornellbox.obj", "random_bytes", 1),
    fz.Case("cornellbox", "cornellbox.mtl", "extreme", 1),
    fz.Case("cornellbox", "cornellbox.obj", "ref_missing", 0),
    fz.Case("newscene", "newscene.txt", "token_dup", 0),
    fz.Case("newscene", "newscene.txt", "brace_drop", 1),
    fz.Case("showcase", "showcase_day.txt", "extreme", 0),
    fz.Case("showcase", "sky_day.exr", "truncate", 0),
    fz.Case("showcase", "sky_day.exr", "nonfinite", 0),
    fz.Case("showcase", "grille.png", "truncate", 0),
    fz.Case("grammar", "grammar.txt", "none", 0),
    fz.Case("grammar", "grammar.txt", "extreme", 2),
    fz.Case("extremes", "triangle_huge"),
    fz.Case("extremes", "sphere_radius_huge"),
    fz.Case("extremes", "pointlight_huge"),
    fz.Case("extremes", "camera_huge_center"),
    fz.Case("extremes", "empty_group"),
]


def _build_render_case(case: fz.Case, root, images):
    if case.folder == "extremes":
        return fz.extreme_scene(case.target, root)
    if case.target.endswith((".png", ".exr")):  # a damaged image beside an intact scene
        entry, _ = fz.build(fz.Case(case.folder, fz.ENTRY[case.folder], "none", 0), root, images)
        target = root / case.target
        target.write_bytes(fz.mutate_image(target.read_bytes(), case.target, case.mutation,
                                           fz.rng_for(case)))
        return entry
    return fz.build(case, root, images)[0]


@pytest.mark.slow
@pytest.mark.parametrize("case", _params(RENDER_CASES, KNOWN_RENDER))
def test_render_exits_cleanly(case, tmp_path, images):
    entry = _build_render_case(case, tmp_path, images)
    out = tmp_path / "out.exr"
    proc = subprocess.run([sys.executable, "-m", "drpt", "render", str(entry), "--size", "8", "8",
                           "--spp", "1", "-q", "-o", str(out)],
                          capture_output=True, text=True, timeout=120)
    err = proc.stderr.splitlines()
    assert "Traceback" not in proc.stderr, proc.stderr[-2000:]
    if proc.returncode == 0:
        img = read_image(out)
        assert img.shape[:2] == (8, 8) and np.isfinite(img).all()
        return
    assert proc.returncode == 2, proc.stderr[-2000:]
    errors = [line for line in err if line.startswith("drpt: error: ")]
    others = [line for line in err if not line.startswith(("drpt: error: ", "drpt: warning: ", "drpt: note: "))]
    assert len(errors) == 1 and not others, proc.stderr
    message = errors[0][len("drpt: error: "):]
    image = case.target.endswith((".png", ".exr"))
    fz.check_message(message, tmp_path, image=image)
    assert not out.exists()


@pytest.mark.parametrize("case", _params(fz.extreme_cases()))
def test_extreme_numbers_accepted_or_reported(case, tmp_path):
    entry = fz.extreme_scene(case.target, tmp_path)
    if case.target in fz.MUST_ACCEPT:
        _read(case, entry)
        return
    try:
        _read(case, entry)
    except Exception as e:
        fz.check_error(e, tmp_path, image=False)


# ------------------------------------------------------------------ Mitsuba XML, PLY, serialized, OBJ
# (tests/support/fuzzformats.py): the meshes scene of tests/data/xml with one file
# mutated, loaded in-process: accepted with finite data, or one located error.
@pytest.mark.parametrize("target,mutation,seed", [
    pytest.param(*c, id=ff.xml_id(*c)) for c in ff.xml_cases()])
def test_xml_and_meshes_accept_or_report(target, mutation, seed, tmp_path):
    entry = ff.build_xml(target, mutation, seed, tmp_path)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with time_limit(CASE_SECONDS):
                scene = load_scene(entry)
    except Exception as e:  # the contract is checked on any exception
        fz.check_error(e, tmp_path, image=False)
        return
    fz.assert_finite(scene)


# ------------------------------------------------------------------ checkpoints
@pytest.fixture(scope="module")
def checkpoint_render(tmp_path_factory):
    """A real checkpoint (2 of 4 chunks of a 16x16 Cornell box render) and what
    :func:`checkpoint.load` checks it against."""
    from dataclasses import replace

    from drpt.distributed import checkpoint
    from drpt.distributed.job import run
    from drpt.options import RenderOptions, resolve_sampler
    from drpt.render.chunks import plan_chunks

    root = tmp_path_factory.mktemp("fuzz_checkpoint")
    scene = load_scene(fz.SCENES / "cornellbox" / "cornellbox.txt")
    opts = replace(RenderOptions(width=16, height=16, spp=4, chunk_spp=1, progress=False), max_lanes=1 << 20)
    out = root / "cut.exr"

    def stop(merge, result, engine):
        if merge.next >= 2:
            raise KeyboardInterrupt

    with contextlib.suppress(KeyboardInterrupt):
        run(scene, opts, out, on_chunk=stop)
    npz, _ = checkpoint.paths(out)
    chunks = plan_chunks(16, 16, 4, opts.max_lanes, 1)
    args = (checkpoint.scene_hash(scene), checkpoint.options_key(resolve_sampler(opts)), chunks)
    assert checkpoint.load(out, *args).next == 2  # the intact one is accepted
    return npz.read_bytes(), args


@pytest.mark.parametrize("mutation,seed", [
    pytest.param(m, s, id=f"checkpoint/{m}-s{s}") for m in ff.CHECKPOINT_MUTATIONS for s in range(3)])
def test_damaged_checkpoints_are_refused(mutation, seed, tmp_path, checkpoint_render):
    """A damaged checkpoint is refused with one line naming it, or (a mutation
    that changed nothing the render uses) accepted with consistent sums."""
    from drpt.distributed import checkpoint

    raw, args = checkpoint_render
    out = tmp_path / "cut.exr"
    npz, _ = checkpoint.paths(out)
    npz.write_bytes(raw)
    ff.mutate_checkpoint(npz, mutation, ff.rng_for(f"checkpoint/{mutation}-s{seed}"))
    try:
        with time_limit(CASE_SECONDS):
            cp = checkpoint.load(out, *args)
    except Exception as e:  # the contract is checked on any exception
        fz.check_error(e, tmp_path, image=True)
        return
    chunks = args[2]
    assert cp.sum.dtype == np.float64 and cp.sum.shape == (16, 16, 3) and np.isfinite(cp.sum).all()
    assert cp.spp == chunks.spp_before(cp.next)


def test_special_files_as_checkpoints(tmp_path, checkpoint_render):
    """A FIFO or a folder where the checkpoint goes: refused at once, never read."""
    import os

    from drpt.distributed import checkpoint
    from drpt.errors import DrptError

    _, args = checkpoint_render
    for kind in ("fifo", "dir"):
        out = tmp_path / f"{kind}.exr"
        npz, _ = checkpoint.paths(out)
        os.mkfifo(npz) if kind == "fifo" else npz.mkdir()
        with time_limit(CASE_SECONDS), pytest.raises(DrptError, match="not a regular file"):
            checkpoint.load(out, *args)
        with pytest.raises(DrptError, match="not a regular file"):
            checkpoint.check_paths(out)
        checkpoint.remove(out)  # leaves what it did not write
        assert os.path.lexists(npz)


def test_checkpoint_hash_ignores_the_folder(tmp_path):
    import shutil

    from drpt.distributed.checkpoint import scene_hash

    hashes = set()
    for name in ("a", "moved/elsewhere"):  # paths of other lengths (pickled strings count them)
        shutil.copytree(fz.SCENES / "showcase", tmp_path / name)
        hashes.add(scene_hash(load_scene(tmp_path / name / "showcase_day.txt")))
        shutil.copytree(fz.SCENES / "cornellbox", tmp_path / name / "box")
        hashes.add(scene_hash(load_scene(tmp_path / name / "box" / "cornellbox.txt")))
    assert len(hashes) == 2
    (tmp_path / "a" / "grille.png").write_bytes(b"changed")
    assert scene_hash(load_scene(tmp_path / "a" / "showcase_day.txt")) not in hashes


# ------------------------------------------------------------------ cluster addresses
@pytest.mark.parametrize("seed", range(24), ids=lambda s: f"cluster/address-s{s}")
def test_cluster_addresses_are_checked(seed):
    from drpt.distributed.engine import check_address
    from drpt.errors import DrptError

    a = ff.address(ff.rng_for(f"cluster/address-s{seed}"))
    try:
        check_address(a)
    except DrptError as e:
        assert len(str(e).splitlines()) == 1 and str(e).startswith("--cluster "), str(e)
        return
    assert a.startswith(("tcp://", "localhost", "127.", "[")) and a.rpartition(":")[2].isdigit(), a


@pytest.mark.parametrize("kind,seed", [pytest.param(k, s, id=f"cluster/server-{k}-s{s}")
                                       for k in ff.SERVER_KINDS for s in range(2)])
def test_fake_schedulers_are_one_error_within_the_deadline(kind, seed):
    """A server on 127.0.0.1 that is not a Dask scheduler: one error line, in
    about the connect timeout (0.5 s here), never an allocation of its frame length."""
    import time

    from drpt.distributed.engine import probe
    from drpt.errors import DrptError

    with ff.FakeServer(kind, ff.rng_for(f"cluster/server-{kind}-s{seed}")) as server:
        t = time.monotonic()
        with time_limit(CASE_SECONDS), pytest.raises(DrptError) as e:
            probe(f"tcp://127.0.0.1:{server.port}", 0.5)
        assert time.monotonic() - t < 2.0
    assert len(str(e.value).splitlines()) == 1


@pytest.mark.parametrize("seed,lanes", [(0, None), (3, None), (5, 1 << 20), (7, 64)])
def test_intact_checkpoints_are_accepted(tmp_path, seed, lanes):
    """A checkpoint drpt wrote passes every check :func:`checkpoint.load` makes
    (sums of squares summed in float32 sit on the bound ``sum^2 <= spp sumsq``
    within rounding where every sample is equal, e.g. pixels that see the light)."""
    from dataclasses import replace

    from drpt.backend import policy
    from drpt.distributed import checkpoint
    from drpt.distributed.job import run
    from drpt.options import RenderOptions, resolve_sampler
    from drpt.render.chunks import plan_chunks

    scene = load_scene(fz.SCENES / "cornellbox" / "cornellbox.txt")
    opts = replace(RenderOptions(width=16, height=16, spp=4, chunk_spp=1, seed=seed, progress=False),
                   max_lanes=lanes)
    out = tmp_path / "cut.exr"

    def stop(merge, result, engine):
        if merge.next >= 2:
            raise KeyboardInterrupt

    with contextlib.suppress(KeyboardInterrupt):
        run(scene, opts, out, on_chunk=stop)
    chunks = plan_chunks(16, 16, 4, lanes or policy().max_lanes, 1)
    cp = checkpoint.load(out, checkpoint.scene_hash(scene), checkpoint.options_key(resolve_sampler(opts)), chunks)
    assert cp.next == 2
