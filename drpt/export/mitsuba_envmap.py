"""A drpt ``Skybox`` as a Mitsuba 3 ``envmap`` emitter.

drpt's environment light (:mod:`drpt.render.lights.envmap`) uses Mitsuba's
own lat-long mapping, texel placement and bilinear lookup, so the matching
emitter is ``envmap`` with an *identity* ``to_world`` (verified against
Mitsuba 3.9.1 in ``tests/render/lights/test_envmap.py``: direct evaluation of the emitter
and renders of a map with one marked texel).

Mitsuba reads the same file formats as :func:`drpt.imageio.read_image`
(``.exr``, ``.hdr``, ``.pfm``, ``.png``, ``.jpg``, ``.tga``; 8-bit images
are sRGB-decoded by both) and the same RGBE decoding. Two cases need a
rewritten copy of the map, written as a float32 ``.exr`` (with a warning):

* NaN, Inf or negative texels: Mitsuba keeps them (they poison its
  luminance-based sampling tables); drpt sets them to 0, so the copy does too;
* maps narrower than 2 or shorter than 3 texels, which Mitsuba's ``envmap``
  refuses. They are resampled so that Mitsuba's bilinear lookup gives the
  same radiance field as drpt's: a single column is doubled (drpt: constant
  in ``u``), a single row is tripled (constant in ``v``), and two rows
  ``r0, r1`` become ``r0, (r0 + r1) / 2, r1`` (drpt interpolates linearly
  in ``v`` between the poles; Mitsuba then does the same piecewise).

``to_world`` is returned as a numpy 4x4 array (wrap it, e.g. in
``mi.ScalarTransform4f``, for ``mi.load_dict``).
"""

from __future__ import annotations

import tempfile
import warnings
from os import PathLike
from pathlib import Path

import numpy as np

from drpt.errors import DrptError, SceneError, SceneWarning
from drpt.imageio import read_image, write_image
from drpt.render.lights.envmap import sanitize_image
from drpt.scene.model import Skybox

__all__ = ["to_mitsuba", "TO_WORLD", "mitsuba_compatible_image"]

#: drpt's sky frame equals Mitsuba's envmap frame.
TO_WORLD = np.eye(4)


def mitsuba_compatible_image(image) -> tuple[np.ndarray, list[str]]:
    """``(image, reasons)``: the sanitised RGB map, padded to at least 2x3 so
    Mitsuba's lookup reproduces drpt's radiance field; ``reasons`` lists why
    it differs from the input (empty: the original file can be used)."""
    raw = np.asarray(image)
    img, bad = sanitize_image(raw)
    reasons = []
    if bad:
        reasons.append(f"{bad} NaN/Inf/negative texels set to 0")
    H, W = img.shape[:2]
    if W < 2:
        img = np.concatenate([img, img], axis=1)
    if H == 1:
        img = np.concatenate([img, img, img], axis=0)
    elif H == 2:
        img = np.stack([img[0], 0.5 * (img[0] + img[1]), img[1]], axis=0).astype(np.float32)
    if (H, W) != img.shape[:2]:
        reasons.append(f"{W}x{H} map resampled to {img.shape[1]}x{img.shape[0]} "
                       "(Mitsuba needs at least 2x3)")
    return img, reasons


def to_mitsuba(skybox: Skybox, scale: float = 1.0, out_dir: str | PathLike | None = None) -> dict:
    """The ``envmap`` emitter dict for ``skybox`` (see module docs).

    Reads the map to check it; when Mitsuba cannot use the file as is, a fixed
    copy ``<stem>.mitsuba.exr`` is written to ``out_dir`` (default: a new
    temporary directory) and used instead, with a warning.
    """
    path = Path(skybox.path)
    if not path.is_file():
        loc = getattr(skybox, "loc", None)
        message = f"skybox image {path} not found"
        raise SceneError(loc, message) if loc is not None else DrptError(message)
    scale = float(scale)
    if not (np.isfinite(scale) and scale >= 0.0):
        raise DrptError(f"skybox {path}: scale must be finite and >= 0, got {scale}")
    img, reasons = mitsuba_compatible_image(read_image(skybox.path))  # errors at the Skybox line
    filename = path.resolve()
    if reasons:
        d = Path(out_dir) if out_dir is not None else Path(tempfile.mkdtemp(prefix="drpt_envmap_"))
        d.mkdir(parents=True, exist_ok=True)
        filename = (d / f"{path.stem}.mitsuba.exr").resolve()
        write_image(filename, img)
        warnings.warn(SceneWarning(getattr(skybox, "loc", None), f"skybox {path}: {'; '.join(reasons)}; "
                                   f"Mitsuba gets the fixed copy {filename}"), stacklevel=2)
    return {"type": "envmap", "filename": str(filename), "scale": scale,
            "to_world": TO_WORLD.copy()}
