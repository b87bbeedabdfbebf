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
import json
import os
import pickle
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ..errors import DrptError

SUFFIX = ".drpt-checkpoint"
VERSION = 1


def scene_hash(scene) -> str:
    """SHA-256 of the scene's content: the parsed model (geometry, materials,
    lights, camera; pickled) and the bytes of the images it names (textures,
    sky), which the renderer reads when it builds the device scene. The model
    holds no sets: their pickled order changes from one process to the next
    (string hashing is randomized), so the hash would too."""
    h = hashlib.sha256(pickle.dumps(scene, protocol=4))
    from ..scene.model import Skybox

    images = {str(m.map_kd) for m in scene.materials if m.map_kd is not None}
    images |= {str(p) for m in scene.materials for p in m.maps.values()}
    images |= {str(t.path) for m in scene.materials if m.bsdf is not None for t in m.bsdf.textures()}
    images = sorted(images | {str(light.path) for light in scene.lights if isinstance(light, Skybox)})
    for name in images:
        h.update(name.encode())
        try:
            h.update(Path(name).read_bytes())
        except OSError:
            h.update(b"<unreadable>")
    return h.hexdigest()


def options_key(opts) -> dict:
    """The options that shape the image (all but ``progress``), with the backend."""
    from ..backend import name

    d = asdict(opts)
    d.pop("progress", None)
    d["backend"] = name()
    return d


def paths(output: Path) -> tuple[Path, Path]:
    """The checkpoint's sums (.npz) and description (.json) for ``output``."""
    base = str(output) + SUFFIX
    return Path(base + ".npz"), Path(base + ".json")


@dataclass
class Checkpoint:
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


def save(output: Path, cp: Checkpoint) -> None:
    """Write the checkpoint. The .npz holds the description too (``meta``)
    and is what :func:`load` trusts, so a process killed between the two
    renames leaves a consistent checkpoint; the .json is for people."""
    npz, meta = paths(output)
    d = {k: v for k, v in asdict(cp).items() if k not in ("sum", "sumsq", "weight", "aov")}
    d["version"] = VERSION
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
    for p in paths(output):
        p.unlink(missing_ok=True)
    # a .tmp file left by a process killed while writing
    for p in paths(output):
        for tmp in p.parent.glob(p.name + ".tmp*"):
            tmp.unlink(missing_ok=True)


def load(output: Path, scene_hash: str, options: dict, chunks: int) -> Checkpoint:
    """The checkpoint of ``output``, checked against this render: a missing,
    unreadable or foreign one (other scene, options or chunks) is a DrptError."""
    npz, meta = paths(output)
    if not npz.exists():
        raise DrptError(f"--resume: no checkpoint for {output} ({npz.name} beside it)")
    try:
        with np.load(npz) as z:
            s, s2 = z["sum"], z["sumsq"]
            wts = z["weight"] if "weight" in z.files else None
            aov = z["aov"] if "aov" in z.files else None
            d = json.loads(str(z["meta"]))
    except (OSError, ValueError, KeyError) as e:
        raise DrptError(f"--resume: {npz}: unreadable checkpoint ({e})") from None
    if d.get("version") != VERSION:
        raise DrptError(f"--resume: {meta}: checkpoint version {d.get('version')}, not {VERSION}")
    if d["scene_hash"] != scene_hash:
        raise DrptError(f"--resume: {meta} is a checkpoint of another scene (its content changed)")
    if d["options"] != json.loads(json.dumps(options)):
        diff = sorted(k for k in set(d["options"]) | set(options)
                      if d["options"].get(k) != json.loads(json.dumps(options)).get(k))
        raise DrptError(f"--resume: {meta} was rendered with other options ({', '.join(diff)} "
                        "differ): give the flags of the interrupted render")
    if d["chunks"] != chunks or s.shape != s2.shape or not 0 <= d["next"] <= chunks:
        raise DrptError(f"--resume: {meta} does not match this render's chunks")
    if wts is not None and wts.shape != s.shape[:2] + (2,):
        raise DrptError(f"--resume: {meta} does not match this render's chunks")
    if aov is not None and aov.shape[:2] != s.shape[:2]:
        raise DrptError(f"--resume: {meta} does not match this render's chunks")
    return Checkpoint(d["scene_hash"], d["options"], d["chunks"], d["next"], d["spp"],
                      d["nonfinite"], s, s2, wts, aov)
