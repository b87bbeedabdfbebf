"""One reproducer per class of hostile input, run through the command line and
classified: traceback, hang, signal, silent wrong, error without a location,
clean error, correct image. Not a test (pytest does not collect it):

    .venv/bin/python tests/robustness/hostile_sweep.py [FAMILY ...] [-k SUBSTRING]

prints one line per case and the counts per family and outcome.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
PY = sys.executable
TIMEOUT = 45

XML = """<scene version="3.0.0">
  <default name="s" value="1"/>
  <default name="z" value="4"/>
  <sensor type="perspective">
    {camera}
    <transform name="to_world"><lookat origin="0, $s, $z" target="0, 0, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm">{film}<rfilter type="box"/></film>
    <sampler type="independent"><integer name="sample_count" value="{spp}"/></sampler>
  </sensor>
  <integrator type="path">{integrator}</integrator>
  <bsdf type="diffuse" id="white">{white}</bsdf>
  <shape type="rectangle">
    <transform name="to_world"><rotate x="1" angle="-90"/><scale value="$s"/></transform>
    <ref id="white"/>
  </shape>
  <shape type="rectangle">
    <transform name="to_world"><translate z="-1"/><scale value="$s"/></transform>
    <ref id="white"/>
  </shape>
  <shape type="rectangle">
    <transform name="to_world"><rotate x="1" angle="90"/><translate y="1.5"/><scale value="$s"/></transform>
    <emitter type="area"><rgb name="radiance" value="4"/></emitter>
  </shape>
  {extra}
</scene>
"""


FOV = '<float name="fov" value="45"/>'
SIZE = '<integer name="width" value="16"/><integer name="height" value="16"/>'


def xml(root: Path, name="scene.xml", *, extra="", film=SIZE, spp=4, integrator="", white="",
        camera=FOV, cz="4") -> Path:
    p = root / name
    p.write_text(XML.format(extra=extra, film=film, spp=spp, integrator=integrator, white=white,
                            camera=camera, cz=cz))
    return p


def run(args, cwd=None, timeout=TIMEOUT, preexec=None):
    t = time.time()
    try:
        proc = subprocess.run([PY, "-m", "drpt", *map(str, args)], capture_output=True, text=True,
                              timeout=timeout, cwd=cwd or REPO,
                              env={**os.environ, "PYTHONPATH": str(REPO)})
    except subprocess.TimeoutExpired:
        return None, "", time.time() - t
    return proc.returncode, proc.stderr, time.time() - t


def classify(rc, err, *, check=None, located=True):
    """The outcome of one run; ``check()`` says whether an exit-0 result is right."""
    if rc is None:
        return "hang"
    if rc < 0:
        return "signal"
    if "Traceback" in err or rc not in (0, 2):
        return "traceback"
    if rc == 2:
        errors = [line for line in err.splitlines() if line.startswith("drpt: error: ")]
        others = [line for line in err.splitlines()
                  if not line.startswith(("drpt: error: ", "drpt: warning: ", "drpt: note: "))]
        if len(errors) != 1 or others:
            return "traceback"
        pat = r"drpt: error: /\S+:\d+: " if located else r"drpt: error: \S"
        return "clean error" if re.match(pat, errors[0]) else "no location"
    if check is not None and not check():
        return "silent wrong"
    return "correct image"


def mean_of(path):
    from drpt.imageio import read_image
    try:
        return float(read_image(path).mean())
    except Exception:  # noqa: BLE001
        return None


# ------------------------------------------------------------------ checkpoints
def checkpoint_cases(root: Path):
    base = root / "cp"
    shutil.copytree(REPO / "scenes" / "cornellbox", base)
    scene = base / "cornellbox.txt"
    flags = ["--size", "16", "16", "--spp", "4", "--chunk-spp", "1", "-q", "--seed", "3"]
    ref = base / "ref.exr"
    run(["render", scene, *flags, "-o", ref])
    ref_mean = mean_of(ref)
    # a real checkpoint after 2 of 4 chunks
    code = (
        "import sys; from pathlib import Path\n"
        "from drpt.cli import build_parser\n"
        "from drpt.cli.args import given_settings, options_from_args\n"
        "from drpt.options import with_scene_settings\n"
        "from drpt.scene import load_scene\nfrom drpt.distributed.job import run\n"
        "a = build_parser().parse_args(['render', sys.argv[1], *sys.argv[3:]])\n"
        "s = load_scene(sys.argv[1]); o, s = with_scene_settings(options_from_args(a), s, given_settings(a))\n"
        "def stop(m, r, e):\n    if m.next >= 2: raise KeyboardInterrupt\n"
        "try:\n    run(s, o, Path(sys.argv[2]), on_chunk=stop)\nexcept KeyboardInterrupt:\n    pass\n")
    good = base / "good.exr"
    subprocess.run([PY, "-c", code, scene, good, *flags], cwd=REPO, capture_output=True,
                   env={**os.environ, "PYTHONPATH": str(REPO)})
    npz = Path(str(good) + ".drpt-checkpoint.npz")
    raw = npz.read_bytes()
    with np.load(npz) as z:
        s, s2, meta = z["sum"], z["sumsq"], str(z["meta"])

    def resave(path, **kw):
        d = {"sum": s, "sumsq": s2, "meta": np.array(meta)}
        d.update(kw)
        np.savez(path, **d)

    def case(name, make, resume=True):
        out = base / f"{name}.exr"
        target = Path(str(out) + ".drpt-checkpoint.npz")
        make(target)
        args = ["render", scene, *flags, "-o", out] + (["--resume"] if resume else [])
        rc, err, _ = run(args)
        return name, rc, err, lambda: mean_of(out) is not None and abs(mean_of(out) - ref_mean) < 1e-6 * ref_mean

    # the scene's folder moved: the checkpoint must still be accepted
    moved = root / "moved"
    shutil.copytree(base, moved)
    (moved / 'ref.exr').unlink()
    out = moved / "good.exr"
    rc, err, _ = run(["render", moved / "cornellbox.txt", *flags, "-o", out, "--resume"])
    # a valid checkpoint: a refusal is wrong
    yield "moved_folder", rc, err, lambda: mean_of(out) is not None and abs(mean_of(out) - ref_mean) < 1e-6 * ref_mean
    import json
    m = json.loads(meta)
    yield case("empty", lambda t: t.write_bytes(b""))
    yield case("truncated", lambda t: t.write_bytes(raw[: len(raw) // 2]))
    bad = bytearray(raw)
    bad[60] ^= 0xFF
    yield case("bad_crc", lambda t: t.write_bytes(bytes(bad)))
    yield case("meta_list", lambda t: resave(t, meta=np.array("[1, 2]")))
    yield case("meta_nokey", lambda t: resave(t, meta=np.array(json.dumps({k: v for k, v in m.items() if k != "spp"}))))
    yield case("next_float", lambda t: resave(t, meta=np.array(json.dumps({**m, "next": 1.5}))))
    yield case("next_str", lambda t: resave(t, meta=np.array(json.dumps({**m, "next": "1"}))))
    yield case("sum_shape", lambda t: resave(t, sum=s[:8], sumsq=s2[:8]))
    yield case("sum_nan", lambda t: resave(t, sum=s * np.nan))
    yield case("sum_1x1", lambda t: resave(t, sum=s[:1, :1], sumsq=s2[:1, :1]))
    yield case("sum_negative", lambda t: resave(t, sum=-s))
    yield case("sum_float16", lambda t: resave(t, sum=s.astype(np.float16), sumsq=s2.astype(np.float16)))
    yield case("next_contradicts", lambda t: resave(t, meta=np.array(json.dumps({**m, "next": 3}))))
    yield case("directory", lambda t: t.mkdir())
    yield case("directory_noresume", lambda t: t.mkdir(), resume=False)

    def fifo(t):
        os.mkfifo(t)
    yield case("fifo", fifo)


# ------------------------------------------------------------------ XML
def ply_binary(vertices, faces) -> bytes:
    head = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(vertices)}\n"
            "property float x\nproperty float y\nproperty float z\n"
            f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n").encode()
    body = np.asarray(vertices, "<f4").tobytes()
    for f in faces:
        body += struct.pack("<B3i", 3, *f)
    return head + body


def ply_ascii(vertices, faces) -> bytes:
    head = (f"ply\nformat ascii 1.0\nelement vertex {len(vertices)}\n"
            "property float x\nproperty float y\nproperty float z\n"
            f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n")
    body = "".join(f"{x} {y} {z}\n" for x, y, z in vertices) + "".join(f"3 {a} {b} {c}\n" for a, b, c in faces)
    return (head + body).encode()


def ply(name: str) -> str:
    return f"<shape type='ply'><string name='filename' value='{name}'/></shape>"


def xml_cases(root: Path):
    d = root / "xml"
    d.mkdir()
    flags = ["--size", "16", "16", "--spp", "4", "-q"]

    def case(name, path, *, check=None, more=(), base=flags):
        out = d / f"{name}.exr"
        rc, err, _ = run(["render", path, *base, *more, "-o", out])
        return name, rc, err, (lambda: check(out)) if check else None

    ref = xml(d, "ref.xml")
    run(["render", ref, *flags, "-o", d / "ref.exr"])
    ref_mean = mean_of(d / "ref.exr")
    nest = "<bsdf type='twosided'>" * 10000 + "<bsdf type='diffuse'/>" + "</bsdf>" * 10000
    yield case("deep_twosided", xml(d, "deep.xml", extra=f"<shape type='sphere'>{nest}</shape>"))
    tri = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
    (d / "oob.ply").write_bytes(ply_binary(tri, [(0, 1, 1000000)]))
    yield case("ply_binary_oob", xml(d, "plyb.xml", extra=ply("oob.ply")))
    (d / "oob_ascii.ply").write_bytes(ply_ascii(tri, [(0, 1, 7)]))
    yield case("ply_ascii_oob", xml(d, "plya.xml", extra=ply("oob_ascii.ply")))
    (d / "garbage.ply").write_bytes(b"ply\nformat ascii 1.0\n" + bytes(range(128, 256)) * 4)
    yield case("ply_garbage", xml(d, "plyg.xml", extra=ply("garbage.ply")))
    yield case("focal_0mm", xml(d, "focal.xml", camera='<string name="focal_length" value="0mm"/>'))
    os.mkfifo(d / "fifo.xml")
    yield case("include_fifo", xml(d, "inc.xml", extra="<include filename='fifo.xml'/>"))

    def same(out):
        m = mean_of(out)
        return m is not None and abs(m - ref_mean) < 0.01 * ref_mean
    yield case("nan_rgb", xml(d, "nanrgb.xml", white='<rgb name="reflectance" value="nan, 0.5, 0.5"/>'),
               check=same)
    yield case("nan_checkerboard", xml(d, "nanchk.xml", white='<texture type="checkerboard" name="reflectance">'
                                        '<rgb name="color0" value="nan"/></texture>'), check=same)
    yield case("nan_point", xml(d, "nanpt.xml", extra='<emitter type="point"><point name="position" '
                                 'x="nan" y="1" z="0"/></emitter>'), check=same)
    yield case("nan_directional", xml(d, "nandir.xml", extra='<emitter type="directional"><vector '
                                       'name="direction" x="nan" y="-1" z="0"/></emitter>'), check=same)
    yield case("sphere_1e30", xml(d, "big.xml", extra='<shape type="sphere"><transform name="to_world">'
                                   '<scale value="1e30"/></transform></shape>'), check=lambda o: False)
    yield case("film_huge", xml(d, "film.xml", film='<integer name="width" value="1000000"/>'),
               base=["--spp", "1", "-q"])
    yield case("spp_huge", xml(d, "spp.xml", spp="4294967296"), base=["--size", "8", "8", "-q"])
    yield case("depth_huge", xml(d, "depth.xml", integrator='<integer name="max_depth" value="4294967296"/>'))
    (d / "corrupt.png").write_bytes(b"\x89PNG\r\n\x1a\n" + b"garbage" * 10)
    yield case("texture_corrupt", xml(d, "tex.xml", white='<texture type="bitmap" name="reflectance">'
                                      '<string name="filename" value="corrupt.png"/></texture>'))
    (d / "corrupt.exr").write_bytes(b"v/1\x01" + b"garbage" * 10)
    yield case("envmap_corrupt", xml(d, "env.xml", extra='<emitter type="envmap"><string name="filename" '
                                     'value="corrupt.exr"/></emitter>'))
    yield case("malformed", xml(d, "bad.xml", extra="<shape type='sphere'><float name='radius' value='1'></shape>"))

    # far-off scales: the same scene, scaled
    for s in ("1e9", "1e11"):
        def far(out, s=s):
            m = mean_of(out)
            return m is not None and abs(m - ref_mean) < 0.01 * ref_mean
        yield case(f"scale_{s}", ref, check=far, more=["-D", f"s={s}", "-D", f"z={4 * float(s):g}"])


# ------------------------------------------------------------------ cluster
def serve(kind: str) -> tuple[int, threading.Event]:
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(4)
    stop = threading.Event()

    def loop():
        srv.settimeout(0.2)
        conns = []
        while not stop.is_set():
            try:
                c, _ = srv.accept()
            except OSError:
                continue
            conns.append(c)
            if kind == "garbage":
                c.sendall(bytes(range(256)) * 4)
            elif kind == "http":
                c.sendall(b"HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\n\r\n")
        for c in conns:
            c.close()
        srv.close()

    threading.Thread(target=loop, daemon=True).start()
    return srv.getsockname()[1], stop


def cluster_cases(root: Path):
    scene = REPO / "scenes" / "cornellbox" / "cornellbox.txt"
    flags = ["--size", "8", "8", "--spp", "1", "-q", "-o", root / "c.exr"]

    def case(name, more, timeout=TIMEOUT):
        rc, err, dt = run(["render", scene, *flags, *more], timeout=timeout)
        return name, rc, err, None

    yield case("workers_2^31", ["--workers", "2147483648"])
    yield case("ucx", ["--cluster", "ucx://127.0.0.1:1"])
    yield case("tls", ["--cluster", "tls://127.0.0.1:1"])
    yield case("newline", ["--cluster", "tcp://127.0.0.1:1\nfoo"])
    for kind in ("garbage", "http", "silent"):
        port, stop = serve(kind)
        yield case(f"server_{kind}", ["--cluster", f"tcp://127.0.0.1:{port}"], timeout=20)
        stop.set()
    # a scheduler that has no workers
    port = socket.socket()
    port.bind(("127.0.0.1", 0))
    free = port.getsockname()[1]
    port.close()
    sched = subprocess.Popen([Path(PY).with_name("dask"), "scheduler", "--host", "127.0.0.1", "--port", str(free),
                              "--no-dashboard"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    time.sleep(4)
    yield case("no_workers", ["--cluster", f"tcp://127.0.0.1:{free}"], timeout=60)
    sched.kill()
    sched.wait()
    # Ctrl-C in a terminal: SIGINT to the process group during a --workers render
    out = root / "int.exr"
    p = subprocess.Popen([PY, "-m", "drpt", "render", scene, "--size", "64", "64", "--spp", "100000",
                          "--chunk-spp", "1", "-q", "--workers", "2", "--checkpoint-seconds", "0", "-o", out],
                         cwd=REPO, stderr=subprocess.PIPE, text=True, start_new_session=True,
                         env={**os.environ, "PYTHONPATH": str(REPO)})
    cp = Path(str(out) + ".drpt-checkpoint.json")
    t = time.time()
    while time.time() - t < 60 and p.poll() is None and not cp.exists():
        time.sleep(0.2)
    time.sleep(1)
    os.killpg(p.pid, signal.SIGINT)
    try:
        _, err = p.communicate(timeout=40)
        rc = p.returncode
    except subprocess.TimeoutExpired:
        os.killpg(p.pid, signal.SIGKILL)
        rc, err = None, ""
    del cp
    lines = [x for x in err.splitlines() if x.strip()]
    bad = "Traceback" in err or any(not x.startswith("drpt: ") for x in lines)
    yield "sigint_workers", (1 if bad else rc if rc != 130 else 2), err if bad else \
        "drpt: error: interrupted", None


# ------------------------------------------------------------------ output
def output_cases(root: Path):
    scene = REPO / "scenes" / "cornellbox" / "cornellbox.txt"
    for ext in ("hdr", "pfm", "exr", "png"):
        link = root / f"full.{ext}"
        link.symlink_to("/dev/full")
        rc, err, _ = run(["render", scene, "--size", "8", "8", "--spp", "1", "-q", "-o", link])
        yield f"dev_full_{ext}", rc, err, lambda: False
    empty = root / "empty.txt"
    empty.write_text("PerspectiveCamera { center 0 0 5 direction 0 0 -1 up 0 1 0 angle 40 }\n")
    out = root / "empty.exr"
    rc, err, _ = run(["render", empty, "--size", "8", "8", "--spp", "1", "-q", "--integrator", "whitted",
                      "-o", out])
    yield "whitted_empty", rc, err, lambda: mean_of(out) == 0.0


# ------------------------------------------------------------------ command line
def cli_cases(root: Path):
    """Bad flag values, outputs drpt cannot write, folders given as files, a missing
    scene, tools given a folder, a resume refused for a nested option, a Dask port in
    use: each one line and exit status 2 (the port in use: a correct image)."""
    scene = REPO / "scenes" / "cornellbox" / "cornellbox.txt"
    out = root / "x.exr"
    small = ["--size", "8", "8", "--spp", "1", "-q"]
    folder = root / "folder"
    folder.mkdir()
    (root / "dir.png").mkdir()
    (root / "file").write_text("not a folder\n")

    def case(name, args, check=None, timeout=TIMEOUT):
        rc, err, _ = run(args, timeout=timeout)
        return name, rc, err, check

    def render(name, *more, scene=scene, output=out):
        return case(name, ["render", scene, *small, *more, "-o", output])

    yield render("spp_negative", "--spp", "-1")
    yield render("spp_2^40", "--spp", str(1 << 40))
    yield render("spp_word", "--spp", "many")
    yield render("size_zero", "--size", "0", "0")
    yield render("size_negative", "--size", "-8", "8")
    yield render("size_2^20", "--size", str(1 << 20), "8")
    yield render("size_float", "--size", "8.5", "8")
    yield render("size_one_value", "--size", "8")
    yield render("max_depth_-5", "--max-depth", "-5")
    yield render("rr_prob_nan", "--rr-prob", "nan")
    yield render("rr_prob_0", "--rr-prob", "0")
    yield render("seed_negative", "--seed", "-1")
    yield render("seed_2^70", "--seed", str(1 << 70))
    yield render("filter_bogus", "--filter", "lanczos:taps=x")
    yield render("filter_radius_-1", "--filter", "tent:radius=-1")
    yield render("hide_emitters_yes", "--hide-emitters", "yes")
    yield render("max_lanes_0", "--max-lanes", "0")
    yield render("time_limit_-1", "--time-limit", "-1")
    yield render("target_error_nan", "--target-error", "nan")
    yield render("chunk_spp_0", "--chunk-spp", "0")
    yield render("workers_0", "--workers", "0")
    yield render("gamma_nan", "--gamma", "nan", output=root / "x.png")
    yield render("define_no_value", "-D", "novalue")
    yield render("aovs_bogus", "--aovs", "albedo:nosuchtype")
    yield render("resume_no_checkpoint", "--resume", output=root / "never.exr")
    yield render("missing_scene", scene=root / "missing.txt")
    yield render("scene_is_folder", scene=folder)
    yield render("scene_empty_file", scene=root / "file")
    yield render("output_is_folder", output=root / "dir.png")
    yield render("output_folder_missing", output=root / "no" / "x.exr")
    yield render("output_under_a_file", output=root / "file" / "x.exr")
    yield render("output_in_proc", output=Path("/proc/drpt-x.exr"))
    yield render("output_bad_type", output=root / "x.jpg")
    yield case("export_output_folder", ["export", scene, folder])
    yield case("export_output_png", ["export", scene, root / "x.png"])
    yield case("export_scene_folder", ["export", folder, root / "x.xml"])
    yield case("profile_folder", ["profile", folder, *small])
    yield case("bench_folder", ["bench", folder, "--size", "8", "8", "--spp", "1"])
    yield case("compare_folder", ["compare", folder, *small])
    yield case("converge_missing", ["converge", root / "missing.txt"])
    yield case("knobs_folder", ["knobs", folder])
    yield case("view_port_70000", ["view", scene, "--port", "70000"])

    # a resume refused for an option inside another (PathOptions' max_depth): the refusal
    # names it (path.max_depth), not only the group (path)
    cut = root / "cut.exr"
    flags = ["--size", "16", "16", "--spp", "4", "--chunk-spp", "1", "-q", "--max-depth", "3"]
    code = (
        "import sys; from pathlib import Path\n"
        "from drpt.cli import build_parser\n"
        "from drpt.cli.args import options_from_args\n"
        "from drpt.scene import load_scene\nfrom drpt.distributed.job import run\n"
        "a = build_parser().parse_args(['render', sys.argv[1], *sys.argv[3:]])\n"
        "def stop(m, r, e):\n    if m.next >= 2: raise KeyboardInterrupt\n"
        "try:\n    run(load_scene(sys.argv[1]), options_from_args(a), Path(sys.argv[2]), on_chunk=stop,"
        " checkpoint_seconds=0)\nexcept KeyboardInterrupt:\n    pass\n")
    subprocess.run([PY, "-c", code, scene, cut, *flags], cwd=REPO, capture_output=True,
                   env={**os.environ, "PYTHONPATH": str(REPO)})
    flags[-1] = "4"
    name, rc, err, _ = case("resume_nested_option", ["render", scene, *flags, "--resume", "-o", cut])
    yield name, rc, err if "path.max_depth" in err or rc != 2 else err.replace("drpt: error: ", "drpt: ", 1), None

    # Dask's default scheduler and dashboard ports in use: a local cluster picks free ones
    sys.path.insert(0, str(REPO / "tests"))
    from support.ports import taken

    ported = root / "ported.exr"
    with taken(8786, 8787):
        rc, err, _ = run(["render", scene, *small, "--workers", "2", "-o", ported], timeout=120)
    yield "dask_ports_in_use", rc, err, lambda: (mean_of(ported) is not None and mean_of(ported) > 0
                                                 and "already in use" not in err)


FAMILIES = {"checkpoint": checkpoint_cases, "xml": xml_cases, "cluster": cluster_cases,
            "output": output_cases, "cli": cli_cases}
LOCATED = {"xml"}  # families whose errors must name FILE:LINE
MUST_RENDER = {"moved_folder", "scale_1e9", "scale_1e11", "whitted_empty", "dask_ports_in_use"}  # valid input


def main(argv):
    want = [a for a in argv if not a.startswith("-") and a in FAMILIES] or list(FAMILIES)
    counts = {}
    with tempfile.TemporaryDirectory() as tmp:
        for fam in want:
            root = Path(tmp) / fam
            root.mkdir()
            for name, rc, err, check in FAMILIES[fam](root):
                outcome = classify(rc, err, check=check, located=fam in LOCATED)
                if name in MUST_RENDER and outcome in ("clean error", "no location"):
                    outcome = "wrong refusal"
                counts.setdefault(fam, {}).setdefault(outcome, 0)
                counts[fam][outcome] += 1
                last = [x for x in err.splitlines() if x.strip()][-1:] or [""]
                print(f"{fam:10s} {name:22s} {outcome:14s} rc={rc} {last[0][:150]}", flush=True)
    print()
    for fam, c in counts.items():
        print(f"{fam:10s} " + ", ".join(f"{k}: {v}" for k, v in sorted(c.items())))


if __name__ == "__main__":
    main(sys.argv[1:])
