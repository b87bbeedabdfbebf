"""Denoising with Intel Open Image Denoise (the optional ``denoise`` extra: ``pyoidn``).

:func:`denoise` filters a rendered image with OIDN's ``RT`` filter (HDR), guided by the
albedo and shading normal of the first non-delta surface each pixel sees (the render's
``guide_albedo`` and ``guide_normal``, :mod:`drpt.aovs`), averaged over the pixel's
samples like the image. The raw image stays as rendered (unbiased); the denoised one is
written beside it (``render --denoise``: ``out.exr`` and ``out.denoised.exr``) and
``knobs`` and ``converge`` measure its error against a reference.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .errors import DrptError


def available() -> bool:
    """Whether pyoidn can be imported."""
    try:
        import pyoidn  # noqa: F401
    except ImportError:
        return False
    return True


def require() -> None:
    """Fail early (before rendering) when pyoidn is missing."""
    if not available():
        raise DrptError("--denoise needs Intel Open Image Denoise's Python binding: "
                        "pip install pyoidn (or pip install -e '.[denoise]')")


def denoise(image: np.ndarray, albedo: np.ndarray | None = None,
            normal: np.ndarray | None = None) -> np.ndarray:
    """The denoised ``(H, W, 3)`` float32 image (OIDN ``RT``, HDR, high quality), guided
    by ``albedo`` (clamped to [0, 1]) and ``normal`` (clamped to [-1, 1]) when given."""
    require()
    import pyoidn

    def prep(a, lo, hi):
        return None if a is None else np.ascontiguousarray(np.clip(a, lo, hi), np.float32)

    color = np.ascontiguousarray(np.maximum(np.nan_to_num(image, nan=0.0, posinf=0.0), 0.0),
                                 np.float32)
    alb = prep(albedo, 0.0, 1.0)
    nrm = prep(normal, -1.0, 1.0) if albedo is not None else None  # OIDN: a normal needs an albedo
    try:
        return pyoidn.denoise(color, alb, nrm, hdr=True)
    except (RuntimeError, ValueError, TypeError) as e:
        raise DrptError(f"denoising failed: {e}") from None


def denoise_result(result) -> np.ndarray:
    """:func:`denoise` of a :class:`~drpt.render.renderer.RenderResult` rendered with
    ``RenderOptions.denoise`` (its guides are the last 6 AOV channels)."""
    if result.aov is None or result.aov.shape[-1] < 6:
        raise DrptError("denoising needs a render with RenderOptions.denoise (the albedo and "
                        "normal guides)")
    return denoise(result.image, result.aov[..., -6:-3], result.aov[..., -3:])


def denoised_path(output: Path) -> Path:
    """``out.exr`` -> ``out.denoised.exr``: where ``render --denoise`` writes."""
    return output.with_name(f"{output.stem}.denoised{output.suffix}")
