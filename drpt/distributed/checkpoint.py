"""Checkpoints: the merged sums of a render that has not finished.

A checkpoint of the render to ``OUT`` is two files beside it, written
atomically (a temporary file, then a rename): ``OUT.drpt-checkpoint.npz``
holds the float64 sums of the merged chunks (``sum``, ``sumsq``) and
``OUT.drpt-checkpoint.json`` says what they are (the .npz holds a copy, which
is the one read back): the scene's content hash
(:func:`scene_hash`), the render options (:func:`options_key`), the chunk
count, the chunks merged (``0..next-1``), their samples per pixel and the
NaN/Inf samples dropped. ``--resume`` accepts a checkpoint only for the
same scene content and options: its sums are then exactly those an
uninterrupted render has after the same chunks.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import pickle
import stat
from dataclasses import asdict, dataclass, replace
from pathlib import Path, PurePath

import numpy as np

from .. import backend
from ..errors import DrptError
from ..options import LIGHT_TRACED, SAMPLERS
from ..scene.model import Skybox

SUFFIX = ".drpt-checkpoint"
VERSION = 2  # 2: the description holds the sums' digest
#: the sampler of a checkpoint whose options name none (rendered when every render drew
#: independent samples)
OLD_SAMPLER = "independent"


def scene_hash(scene) -> str:
    """SHA-256 of the scene's content: the parsed model (geometry, materials,
    lights, camera; pickled) and the bytes of the images it names (textures,
    sky), which the renderer reads when it builds the device scene. The model
    holds no sets: their pickled order changes from one process to the next
    (string hashing is randomized), so the hash would too. Paths inside the
    scene's folder count relative to it, so a moved folder keeps its hash."""
    folder = _scene_folder(scene)

    def rel(p) -> str:
        p = Path(os.path.abspath(p))
        if folder is not None and p.is_relative_to(folder):
            return "<scene>/" + p.relative_to(folder).as_posix()
        return str(p)

    prefixes = []
    if folder is not None:  # the folder inside strings too (the file of each Loc: materials, lights)
        prefixes = sorted({str(folder) + os.sep, str(Path(scene.path).parent) + os.sep} - {"." + os.sep},
                          key=len, reverse=True)

    class _Pickler(pickle.Pickler):
        def persistent_id(self, obj):
            if isinstance(obj, PurePath):
                return "path", rel(obj)
            if isinstance(obj, str) and any(p in obj for p in prefixes):
                for p in prefixes:
                    obj = obj.replace(p, "<scene>/")
                return "str", obj
            return None

    buf = io.BytesIO()
    _Pickler(buf, protocol=4).dump(scene)
    data = buf.getvalue()
    h = hashlib.sha256(data)
    images = {str(m.map_kd) for m in scene.materials if m.map_kd is not None}
    images |= {str(p) for m in scene.materials for p in m.maps.values()}
    images |= {str(t.path) for m in scene.materials if m.bsdf is not None for t in m.bsdf.textures()}
    images = sorted(images | {str(light.path) for light in scene.lights if isinstance(light, Skybox)})
    for name in images:
        h.update(rel(name).encode())
        try:
            if not stat.S_ISREG(os.stat(name).st_mode):  # a FIFO would block
                raise OSError(name)
            h.update(Path(name).read_bytes())
        except OSError:
            h.update(b"<unreadable>")
    return h.hexdigest()


def _scene_folder(scene) -> Path | None:
    path = getattr(scene, "path", None)
    if path is None:
        return None
    return Path(os.path.abspath(path)).parent


def options_key(opts) -> dict:
    """The options that shape the image (all but ``progress``), with the backend. Light
    tracing's (ptracer, bdpt) record whether their squared splats are summed
    (:attr:`~drpt.options.RenderOptions.light_variance`: a checkpoint without them cannot
    go on as one with them); the other integrators always sum their squares."""
    d = asdict(replace(opts, max_lanes=opts.lanes))  # None and the default it stands for alike
    d.pop("progress", None)
    d.pop("variance", None)
    if opts.integrator in LIGHT_TRACED:
        d["variance"] = opts.light_variance
    d["backend"] = backend.name()
    return d


def paths(output: Path) -> tuple[Path, Path]:
    """The checkpoint's sums (.npz) and description (.json) for ``output``."""
    base = str(output) + SUFFIX
    return Path(base + ".npz"), Path(base + ".json")


@dataclass
class Checkpoint:
    """A render's merged prefix of chunks: what it was rendered from (``scene_hash``,
    ``options``), how far it got (``next`` of ``chunks``, at ``spp``) and its sums."""

    scene_hash: str
    options: dict
    chunks: int  # chunks of the whole render
    next: int  # chunks 0..next-1 are merged
    spp: int  # their samples per pixel
    nonfinite: int
    sum: np.ndarray
    sumsq: np.ndarray
    weight: np.ndarray | None = None  # a splatting film's sum(w), sum(w^2) ((H, W, 2))
    aov: np.ndarray | None = None  # the AOVs' sums and their weights' ((H, W, C + 1))


def _digest(*arrays: np.ndarray | None) -> str:
    data = b"".join(np.ascontiguousarray(x).tobytes() for x in arrays if x is not None)
    return hashlib.sha256(data).hexdigest()


def check_paths(output: Path) -> None:
    """Refuse, before rendering, checkpoint paths drpt could not write or
    remove (a folder, a FIFO or a device where its files go)."""
    for p in paths(output):
        try:
            mode = os.stat(p).st_mode
        except OSError:
            continue
        if not stat.S_ISREG(mode):
            raise DrptError(f"{p}: not a regular file; drpt keeps {output.name}'s checkpoint there "
                            "(move it away)")


def save(output: Path, cp: Checkpoint) -> None:
    """Write the checkpoint. The .npz holds the description too (``meta``,
    with a digest of the sums) and is what :func:`load` trusts, so a process
    killed between the two renames leaves a consistent checkpoint; the .json
    is for people."""
    npz, meta = paths(output)
    d = {k: v for k, v in asdict(cp).items() if k not in ("sum", "sumsq", "weight", "aov")}
    d["version"] = VERSION
    d["digest"] = _digest(cp.sum, cp.sumsq, cp.weight, cp.aov)
    text = json.dumps(d, indent=1, sort_keys=True)
    tmp = npz.with_name(npz.name + ".tmp.npz")
    arrays = {"sum": cp.sum, "sumsq": cp.sumsq}
    if cp.weight is not None:
        arrays["weight"] = cp.weight
    if cp.aov is not None:
        arrays["aov"] = cp.aov
    np.savez(tmp, **arrays, meta=np.array(text))
    os.replace(tmp, npz)
    tmp = meta.with_name(meta.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, meta)


def remove(output: Path) -> None:
    """Remove the checkpoint's files (regular files only: never a folder or
    device someone put in their place)."""
    def unlink(p: Path) -> None:
        try:
            if stat.S_ISREG(os.lstat(p).st_mode) or p.is_symlink():
                p.unlink()
        except OSError:
            pass

    for p in paths(output):
        unlink(p)
    # a .tmp file left by a process killed while writing
    for p in paths(output):
        for tmp in p.parent.glob(p.name + ".tmp*"):
            unlink(tmp)


def _flat(options: dict, prefix: str = "") -> dict:
    """``options`` with the options inside others named by a dotted path (``path.max_depth``),
    so that a refused resume names the option that differs, not only its group."""
    flat = {}
    for k, v in options.items():
        if isinstance(v, dict) and v:
            flat.update(_flat(v, f"{prefix}{k}."))
        else:
            flat[f"{prefix}{k}"] = v
    return flat


# the description's fields and their types (bool is not an int here)
_FIELDS = {"version": int, "scene_hash": str, "options": dict, "chunks": int, "next": int,
           "spp": int, "nonfinite": int, "digest": str}


def recorded_sampler(output: Path) -> str | None:
    """The sampler the checkpoint of ``output`` was rendered with (``--resume``'s
    :func:`~drpt.options.resolve_sampler` resolves ``--sampler auto`` to it):
    :data:`OLD_SAMPLER` where its options name none, ``None`` where there is no
    readable checkpoint (:func:`load` then says why)."""
    try:
        with np.load(paths(output)[0], allow_pickle=False) as z:
            options = json.loads(str(z["meta"]))["options"]
        sampler = options.get("sampler", OLD_SAMPLER)
    except Exception:  # noqa: BLE001 - load() refuses a damaged checkpoint with its reason
        return None
    return sampler if sampler in SAMPLERS else None


def load(output: Path, scene_hash: str, options: dict, chunks) -> Checkpoint:
    """The checkpoint of ``output``, checked against this render (``chunks``:
    its :class:`~drpt.render.chunks.ChunkPlan`): a missing, unreadable,
    damaged or foreign one (other scene, options or chunks) is a DrptError
    naming the file. Nothing in it is trusted unchecked: the description's
    fields and types, the sums' dtype (float64), shape (the image's), values
    (finite, not negative, ``sum^2 <= spp sumsq`` per pixel) and digest, and
    the chunks merged against the samples per pixel they hold."""
    npz, meta = paths(output)
    try:
        mode = os.stat(npz).st_mode
    except OSError:
        raise DrptError(f"--resume: no checkpoint for {output} ({npz.name} beside it)") from None
    if not stat.S_ISREG(mode):
        raise DrptError(f"{npz}: --resume: the checkpoint is not a regular file")

    def refuse(why: str) -> DrptError:
        return DrptError(f"{npz}: --resume: {why}")

    try:
        with np.load(npz, allow_pickle=False) as z:
            s, s2 = z["sum"], z["sumsq"]
            wts = z["weight"] if "weight" in z.files else None
            aov = z["aov"] if "aov" in z.files else None
            d = json.loads(str(z["meta"]))
    except Exception as e:  # noqa: BLE001 - whatever a damaged file raises (zip, npy, json)
        raise refuse(f"unreadable checkpoint ({' '.join(f'{type(e).__name__}: {e}'.split())})") from None
    if not isinstance(d, dict):
        raise refuse("damaged checkpoint (its description is not an object)")
    if d.get("version") != VERSION:
        raise refuse(f"checkpoint version {d.get('version')!r}, not {VERSION}")
    for k, t in _FIELDS.items():
        if not isinstance(d.get(k), t) or isinstance(d.get(k), bool):
            raise refuse(f"damaged checkpoint ('{k}' is {d.get(k)!r}, not {t.__name__})")
    d["options"].setdefault("sampler", OLD_SAMPLER)
    if d["scene_hash"] != scene_hash:
        raise refuse(f"a checkpoint of another scene (its content changed): {meta.name}")
    if d["options"] != json.loads(json.dumps(options)):
        was, now = _flat(d["options"]), _flat(json.loads(json.dumps(options)))
        diff = sorted(k for k in set(was) | set(now) if was.get(k) != now.get(k))
        if diff == ["variance"]:
            had = "with" if was.get("variance") else "without"
            raise refuse(f"rendered {had} the squared splats a variance estimate needs (RenderOptions.variance, "
                         "--target-error, --time-limit, --adaptive): resume it as it was rendered")
        raise refuse(f"rendered with other options ({', '.join(diff)} differ): give the flags of "
                     "the interrupted render")
    p = chunks.passes
    shape = (p.height, p.width, 3)
    if d["chunks"] != chunks.count or not 0 <= d["next"] <= chunks.count:
        raise refuse("does not match this render's chunks")
    # sumsq: the squares, then with a moment render the channel products (6) or, splatted,
    # the weighted r^2 .. gb (9); a splatting film's weights: sum(w), sum(w^2)
    sq_shapes = [shape[:2] + (c,) for c in ((6, 9) if options.get("moment") else (3,))]
    if options.get("integrator") == "bdpt":  # the splats' squares, the camera samples' squares and sums
        sq_shapes = [shape[:2] + (9,)]
    splatted = options.get("integrator") not in LIGHT_TRACED and not options.get("filter_sampling") and \
        str(options.get("filter", "box")).split(":")[0] != "box"
    if splatted != (wts is not None):
        raise refuse("damaged checkpoint (filter weights " + ("missing)" if splatted else "where none belong)"))
    arrays = [("sum", s, [shape]), ("sumsq", s2, sq_shapes)]
    if wts is not None:
        arrays.append(("weight", wts, [shape[:2] + (2,)]))
    for name, a, shapes in arrays:
        if a.dtype != np.float64 or a.shape not in shapes:
            raise refuse(f"damaged checkpoint ('{name}' is {a.dtype} {a.shape}, not float64 {shapes[0]})")
        if not np.isfinite(a).all() or (a < 0).any():
            raise refuse(f"damaged checkpoint ('{name}' holds negative or non-finite values)")
    if aov is not None and (aov.dtype != np.float64 or aov.ndim != 3 or aov.shape[:2] != shape[:2]
                            or not np.isfinite(aov).all()):
        raise refuse(f"damaged checkpoint ('aov' is {aov.dtype} {aov.shape}, not float64 finite "
                     f"{shape[:2]} x channels)")
    if _digest(s, s2, wts, aov) != d["digest"]:
        raise refuse("damaged checkpoint (its sums do not match their digest)")
    spp = chunks.spp_before(d["next"])
    if d["spp"] != spp or not 0 <= d["nonfinite"] <= p.width * p.height * spp:
        raise refuse(f"damaged checkpoint ({d['next']} chunks merged hold {spp} spp, it says "
                     f"{d['spp']}; {d['nonfinite']} samples dropped)")
    # a pixel's own samples: sum^2 <= spp sumsq (splats of other pixels' samples may exceed it;
    # the sums of squares may be float32 sums: a pixel whose samples are all equal, e.g. one
    # that sees the light, sits on the bound within float32 rounding)
    if not splatted and options.get("integrator") not in LIGHT_TRACED and \
            (s * s > spp * s2[..., :3] * (1 + 1e-4) + 1e-300).any():
        raise refuse("damaged checkpoint (its sums of squares are too small for its sums)")
    if wts is not None and (wts[..., 1] > wts[..., 0] ** 2 * (1 + 1e-9) + 1e-300).any():
        raise refuse("damaged checkpoint (its filter weights are inconsistent)")
    return Checkpoint(d["scene_hash"], d["options"], d["chunks"], d["next"], d["spp"],
                      d["nonfinite"], s, s2, wts, aov)
