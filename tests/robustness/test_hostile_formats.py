"""Hostile input beyond drpt's own format: Mitsuba XML and its meshes, the
cluster's addresses and Ctrl-C, image output on a full device.

One test per class of the hostile-input sweep (``tests/robustness/hostile_sweep.py``
runs the same reproducers through the command line): each ends as one
located error line, or a correct image; never a crash of Mitsuba's parser
or mesh loaders, a traceback, a hang or a wrong image with exit status 0.
Checkpoints and the cluster's fake servers are fuzzed in tests/robustness/test_fuzz.py.
"""

from __future__ import annotations

import contextlib
import os
import re
import signal
import struct
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from drpt.errors import DrptError, SceneError
from drpt.scene import load_scene
from support import DATA, REPO

XML_DIR = DATA / "xml"

SCENE = """<scene version="3.0.0">
  <sensor type="perspective">
    {camera}
    <transform name="to_world"><lookat origin="0, 1, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm">{film}</film>
    <sampler type="independent"><integer name="sample_count" value="{spp}"/></sampler>
  </sensor>
  <integrator type="path">{integrator}</integrator>
  <bsdf type="diffuse" id="white">{white}</bsdf>
  <shape type="rectangle"><transform name="to_world"><rotate x="1" angle="-90"/></transform>
    <ref id="white"/></shape>
  <shape type="rectangle"><transform name="to_world"><translate y="1.5"/><rotate x="1" angle="90"/></transform>
    <emitter type="area"><rgb name="radiance" value="4"/></emitter></shape>
  {extra}
</scene>
"""
SIZE = '<integer name="width" value="8"/><integer name="height" value="8"/>'


def xml(tmp_path: Path, *, extra="", film=SIZE, spp="1", integrator="", white="",
        camera='<float name="fov" value="45"/>') -> Path:
    p = tmp_path / "scene.xml"
    p.write_text(SCENE.format(extra=extra, film=film, spp=spp, integrator=integrator, white=white,
                              camera=camera))
    return p


def line_of(path: Path, text: str) -> int:
    return next(i for i, ln in enumerate(path.read_text().splitlines(), 1) if text in ln)


def refused(path: Path, match: str) -> SceneError:
    """The SceneError loading ``path`` raises: one line at a line of that file."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(SceneError, match=match) as e:
            load_scene(path)
    err = e.value
    assert err.line is not None and len(str(err).splitlines()) == 1, str(err)
    return err


@contextlib.contextmanager
def time_limit(seconds: int):
    """Raise TimeoutError in the main thread after ``seconds``."""
    def expire(signum, frame):
        raise TimeoutError(f"still running after {seconds} s")

    old = signal.signal(signal.SIGALRM, expire)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def ply_shape(name: str) -> str:
    return f'<shape type="ply"><string name="filename" value="{name}"/></shape>'


def binary_ply(vertices, faces) -> bytes:
    head = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(vertices)}\n"
            "property float x\nproperty float y\nproperty float z\n"
            f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n").encode()
    return head + np.asarray(vertices, "<f4").tobytes() + b"".join(struct.pack("<B3i", 3, *f) for f in faces)


TRI = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]


# ------------------------------------------------------------------ XML: what would crash Mitsuba
def test_deep_nesting_is_refused_before_mitsubas_parser(tmp_path):
    nest = '<bsdf type="twosided">' * 10000 + '<bsdf type="diffuse"/>' + "</bsdf>" * 10000
    p = xml(tmp_path, extra=f'<shape type="sphere">\n{nest}</shape>')
    err = refused(p, "nested more than 100")
    assert err.line == line_of(p, "twosided")


def test_a_modest_nesting_still_loads(tmp_path):
    nest = '<bsdf type="twosided">' + '<bsdf type="mask">' * 20 + '<bsdf type="diffuse"/>' + "</bsdf>" * 21
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        load_scene(xml(tmp_path, extra=f'<shape type="sphere">{nest}</shape>'))


@pytest.mark.parametrize("bad", [3, 1000000, -1, 2**31 - 1])
def test_binary_ply_face_beyond_its_vertices(tmp_path, bad):
    (tmp_path / "m.ply").write_bytes(binary_ply(TRI, [(0, 1, 2), (0, bad, 2)]))
    p = xml(tmp_path, extra=ply_shape("m.ply"))
    err = refused(p, f"face 1 names vertex {bad}, but there are 3")
    assert err.line == line_of(p, "m.ply")


def test_ascii_ply_index_out_of_range(tmp_path):
    (tmp_path / "m.ply").write_text("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                                    "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                                    "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n")
    refused(xml(tmp_path, extra=ply_shape("m.ply")), "names vertex 7, but the mesh has 3")


@pytest.mark.parametrize("data,match", [
    (b"ply\nformat ascii 1.0\n" + bytes(range(128, 256)) * 4, "end_header"),
    (b"ply\nformat ascii 1.0\n\xff\xfe\nend_header\n", "not ASCII"),
    (b"PK\x03\x04 not a ply", "not a PLY file"),
    (binary_ply(TRI, [(0, 1, 2)])[:-5], "ends inside element 'face'"),
])
def test_garbage_ply_is_one_error(tmp_path, data, match):
    (tmp_path / "m.ply").write_bytes(data)
    refused(xml(tmp_path, extra=ply_shape("m.ply")), match)


def test_serialized_face_beyond_its_vertices(tmp_path):
    import random

    from support import fuzzformats as ff

    data = ff.mutate_serialized((XML_DIR / "shapes.serialized").read_bytes(), "index_oob", random.Random(1))
    (tmp_path / "m.serialized").write_bytes(data)
    refused(xml(tmp_path, extra='<shape type="serialized"><string name="filename" value="m.serialized"/>'
                                '<integer name="shape_index" value="0"/></shape>'
                                '<shape type="serialized"><string name="filename" value="m.serialized"/>'
                                '<integer name="shape_index" value="1"/></shape>'), "names vertex")


def test_include_of_a_fifo_or_itself(tmp_path):
    os.mkfifo(tmp_path / "fifo.xml")
    p = xml(tmp_path, extra='<include filename="fifo.xml"/>')
    with time_limit(10):  # a blocking open would hang the test
        err = refused(p, "fifo.xml: not a regular file")
    assert err.line == line_of(p, "fifo.xml")
    p = xml(tmp_path, extra='<include filename="scene.xml"/>')
    refused(p, "includes itself")


def test_a_parameter_given_twice_is_located(tmp_path):
    p = xml(tmp_path, white='<rgb name="reflectance" value="0.5"/>\n<rgb name="reflectance" value="0.2"/>')
    refused(p, "'reflectance' is given twice")


# ------------------------------------------------------------------ XML: values
def test_focal_length_zero(tmp_path):
    refused(xml(tmp_path, camera='<string name="focal_length" value="0mm"/>'), "focal_length must be positive")


@pytest.mark.parametrize("where,kw", [
    ("reflectance", {"white": '<rgb name="reflectance" value="nan, 0.5, 0.5"/>'}),
    ("color0", {"white": '<texture type="checkerboard" name="reflectance"><rgb name="color0" value="nan"/>'
                         "</texture>"}),
    ("position", {"extra": '<emitter type="point"><point name="position" x="nan" y="1" z="0"/></emitter>'}),
    ("direction", {"extra": '<emitter type="directional"><vector name="direction" x="nan" y="-1" z="0"/>'
                            "</emitter>"}),
    ("radius", {"extra": '<shape type="sphere"><float name="radius" value="nan"/></shape>'}),
])
def test_nan_values_are_errors(tmp_path, where, kw):
    refused(xml(tmp_path, **kw), f"'{where}' (must be finite|is NaN)")


def test_a_sphere_beyond_the_coordinate_limit(tmp_path):
    refused(xml(tmp_path, extra='<shape type="sphere"><transform name="to_world"><scale value="1e30"/>'
                                "</transform></shape>"), "beyond 1e\\+12")


@pytest.mark.parametrize("kw,match", [
    ({"film": '<integer name="width" value="1000000"/>'}, "width and height must be between 1 and 65536"),
    ({"spp": "4294967296"}, "sample_count must be between 1 and 4294967295"),
    ({"integrator": '<integer name="max_depth" value="4294967296"/>'}, "max_depth must be -1 or between"),
    ({"integrator": '<integer name="rr_depth" value="0"/>'}, "rr_depth must be between 1"),
])
def test_render_settings_out_of_range_name_their_line(tmp_path, kw, match):
    refused(xml(tmp_path, **kw), match)


@pytest.mark.parametrize("kind", ["texture", "envmap"])
def test_corrupt_images_name_the_xml_line(tmp_path, kind, capsys):
    from drpt.cli import main

    if kind == "texture":
        (tmp_path / "bad.png").write_bytes(b"\x89PNG\r\n\x1a\n" + b"garbage" * 10)
        p = xml(tmp_path, white='<texture type="bitmap" name="reflectance"><string name="filename" '
                                'value="bad.png"/></texture>')
    else:
        (tmp_path / "bad.exr").write_bytes(b"v/1\x01" + b"garbage" * 10)
        p = xml(tmp_path, extra='<emitter type="envmap"><string name="filename" value="bad.exr"/></emitter>')
    out = tmp_path / "out.exr"
    assert main(["render", str(p), "-q", "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    line = line_of(p, "bad.png" if kind == "texture" else "envmap")
    if kind == "texture":
        line = line_of(p, "bitmap")
    assert len(err) == 1 and err[0].startswith(f"drpt: error: {p}:{line}: bad."), err
    assert not out.exists()


# ------------------------------------------------------------------ output
@pytest.mark.parametrize("ext", [".hdr", ".pfm", ".exr", ".png"])
def test_a_full_device_is_an_error(tmp_path, ext):
    from drpt.imageio import write_image

    if not os.path.exists("/dev/full"):
        pytest.skip("no /dev/full")
    target = tmp_path / f"full{ext}"
    target.symlink_to("/dev/full")
    with pytest.raises(DrptError, match="No space left on device"):
        write_image(target, np.ones((4, 5, 3), np.float32))


def test_whitted_on_an_empty_scene_is_black(tmp_path):
    from drpt.options import RenderOptions
    from drpt.render.renderer import Renderer

    p = tmp_path / "empty.txt"
    p.write_text("PerspectiveCamera { center 0 0 5 direction 0 0 -1 up 0 1 0 angle 40 }\n")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = Renderer(load_scene(p), RenderOptions(width=8, height=4, spp=2, integrator="whitted",
                                                  progress=False))
        img = r.render().image
    assert img.shape == (4, 8, 3) and not img.any()


# ------------------------------------------------------------------ the cluster
CORNELL = REPO / "scenes" / "cornellbox" / "cornellbox.txt"


@pytest.mark.parametrize("flags,match", [
    (["--workers", "2147483648"], "--workers must be between 1 and"),
    (["--cluster", "ucx://127.0.0.1:8786"], "tcp:// only, not ucx://"),
    (["--cluster", "tls://127.0.0.1:8786"], "tcp:// only, not tls://"),
    (["--cluster", "tcp://127.0.0.1:1\nfoo"], "no spaces or control characters"),
    (["--cluster", "tcp://127.0.0.1"], "give the scheduler as tcp://HOST:PORT"),
])
def test_cluster_flags_are_one_line_at_once(tmp_path, capsys, flags, match):
    from drpt.cli import main

    t = time.monotonic()
    rc = main(["render", str(CORNELL), "--size", "8", "8", "--spp", "1", "-q", "-o", str(tmp_path / "x.exr"),
               *flags])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and re.search(match, err[0]), err
    assert time.monotonic() - t < 5


@pytest.mark.slow
def test_ctrl_c_in_a_terminal_stops_workers_quietly(tmp_path):
    """SIGINT to the whole process group (what a terminal's Ctrl-C does) during a
    --workers render: drpt's lines only, no worker tracebacks, and a checkpoint."""
    pytest.importorskip("distributed")
    out = tmp_path / "int.exr"
    meta = Path(str(out) + ".drpt-checkpoint.json")
    p = subprocess.Popen([sys.executable, "-m", "drpt", "render", str(CORNELL), "--size", "32", "32",
                          "--spp", "100000", "--chunk-spp", "1", "-q", "--workers", "2",
                          "--checkpoint-seconds", "0", "-o", str(out)],
                         cwd=REPO, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        t0 = time.monotonic()
        while not meta.exists() and p.poll() is None and time.monotonic() - t0 < 120:
            time.sleep(0.05)
        assert p.poll() is None, p.stderr.read()
        os.killpg(p.pid, signal.SIGINT)
        _, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert p.returncode == 130, err
    assert lines and all(ln.startswith("drpt: ") for ln in lines), err
    assert "continue with --resume" in err


# ------------------------------------------------------------------ XML: what Mitsuba reports without a line
@pytest.mark.parametrize("extra,match", [
    ('<shape type="sphere"><transform name="to_world"><translate value="1 2"/></transform></shape>',
     "must have 1 or 3 numbers"),
    ('<shape type="sphere"><transform name="to_world"><scale value="2" x="1"/></transform></shape>',
     "gives 'value' and x/y/z"),
    ('<shape type="rectangle"><transform name="to_world"><scale value="1e13"/></transform></shape>',
     "2 triangles have coordinates beyond 1e\\+12"),
    ('<shape type="disk"><transform name="to_world"><translate x="2e12"/></transform></shape>',
     "triangles have coordinates beyond 1e\\+12"),
])
def test_errors_mitsuba_gives_without_a_line_are_located(tmp_path, extra, match):
    p = xml(tmp_path, extra=extra)
    err = refused(p, match)
    assert err.line == line_of(p, extra[:20]) or err.line == line_of(p, extra[-30:])


def test_bytes_that_are_not_utf8_are_located(tmp_path):
    p = xml(tmp_path)
    data = p.read_bytes().replace(b'id="white"', b'id="wh\x8aite"').replace(b'<ref id="white"/>', b"")
    p.write_bytes(data)
    err = refused(p, "byte 0x8a is not UTF-8")
    assert err.line == 9


def test_a_byte_offset_becomes_a_line(tmp_path):
    """A file that ends inside an attribute: Mitsuba's parser gives the byte offset."""
    p = xml(tmp_path)
    text = p.read_text()
    p.write_text(text[:text.index('value="4"') + 8])
    err = refused(p, "malformed XML")
    assert err.line == len(p.read_text().splitlines()) and "offset" not in err.message, str(err)


def test_a_scene_without_a_sensor_names_the_scene_element(tmp_path):
    p = tmp_path / "s.xml"
    p.write_text('<scene version="3.0.0">\n<shape type="sphere"/>\n</scene>\n')
    assert refused(p, "no <sensor>").line == 1


def test_include_of_a_fifo_found_in_a_path_folder(tmp_path):
    (tmp_path / "lib").mkdir()
    os.mkfifo(tmp_path / "lib" / "fifo.xml")
    p = xml(tmp_path, extra='<path value="lib"/>\n<include filename="fifo.xml"/>')
    with time_limit(10):  # a blocking open would hang the test
        err = refused(p, "fifo.xml: not a regular file")
    assert err.line == line_of(p, "fifo.xml")


def test_unread_parameters_of_a_blendbsdf_do_not_crash_mitsuba(tmp_path):
    """drpt asks Mitsuba whether a plugin reads a parameter drpt left unread by
    loading the plugin bare; a bare blendbsdf crashes Mitsuba 3.9, so it is not asked."""
    blend = ('<shape type="sphere"><bsdf type="blendbsdf"><texture type="checkerboard" name="2.5"/>'
             '<bsdf type="diffuse"/><bsdf type="diffuse"/></bsdf></shape>')
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        load_scene(xml(tmp_path, extra=blend))
    assert any("'2.5'" in str(x.message) for x in w)


# ------------------------------------------------------------------ checkpoints
def test_a_moved_scene_folder_resumes_to_the_same_image(tmp_path):
    """The checkpoint's scene hash counts paths inside the scene's folder
    relative to it: a render interrupted in one folder resumes in a copy of it
    at a path of another length, to the uninterrupted image."""
    import contextlib
    import shutil
    from dataclasses import replace

    from drpt.distributed.job import run
    from drpt.options import RenderOptions

    opts = replace(RenderOptions(width=16, height=16, spp=4, chunk_spp=1, progress=False), max_lanes=1 << 20)
    first = tmp_path / "a"
    shutil.copytree(CORNELL.parent, first)

    def stop(merge, result, engine):
        if merge.next >= 2:
            raise KeyboardInterrupt

    with contextlib.suppress(KeyboardInterrupt):
        run(load_scene(first / "cornellbox.txt"), opts, first / "cut.exr", on_chunk=stop)
    moved = tmp_path / "moved" / "elsewhere"
    shutil.copytree(first, moved)
    job = run(load_scene(moved / "cornellbox.txt"), opts, moved / "cut.exr", resume=True)
    assert job.resumed_from == 2
    whole = run(load_scene(first / "cornellbox.txt"), opts, first / "whole.exr").result.image
    assert np.array_equal(job.result.image, whole)


def test_an_output_folder_is_refused_before_rendering(tmp_path, capsys):
    from drpt.cli import main

    out = tmp_path / "dir.exr"
    out.mkdir()
    assert main(["render", str(CORNELL), "--size", "8", "8", "--spp", "1", "-q", "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"drpt: error: {out}: is a folder; give an image file to write"]


@pytest.mark.slow
def test_a_scheduler_without_workers_is_one_line(tmp_path, capsys):
    pytest.importorskip("distributed")
    import socket

    from drpt.cli import main

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    dask = Path(sys.executable).with_name("dask")
    scheduler = subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
                                 stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        rc = main(["render", str(CORNELL), "--size", "8", "8", "--spp", "1", "-q", "-o", str(tmp_path / "x.exr"),
                   "--cluster", f"tcp://127.0.0.1:{port}"])
    finally:
        scheduler.kill()
        scheduler.wait()
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "no Dask worker took the scene" in err[0], err


def test_max_depth_zero_and_too_many_samples_name_their_line(tmp_path, capsys):
    from drpt.cli import main

    p = xml(tmp_path, integrator='<integer name="max_depth" value="0"/>')
    assert main(["render", str(p), "-q", "-o", str(tmp_path / "x.exr")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"drpt: error: {p}:{line_of(p, 'max_depth')}: max_depth 0 renders nothing "
                   "(Mitsuba gives a black image)"]
    p = xml(tmp_path, film='<integer name="width" value="65536"/><integer name="height" value="65536"/>',
            spp="4294967295")
    refused(p, "more than drpt's 2\\^60")
