"""Whether a render's image fits in the memory this machine has, checked
before anything is traced.

A render's memory grows with its pixels, not its samples. A camera render in
this process (:func:`bytes_per_pixel` with ``local``) accumulates the float64
sums of its samples and of their squares, 48 bytes per pixel, its passes
adding straight into them (:meth:`drpt.render.renderer.Renderer.render_chunk`
with ``into``); the mean and variance are then computed in those arrays,
plus the float32 image and what writing it takes: measured at
:data:`BYTES_PER_PIXEL_LOCAL` of peak resident memory per pixel on top of
:data:`BASE_BYTES` (Python, Dr.Jit, Mitsuba and the compiled kernels; the
Cornell box at 1 spp from 512x512 to 2048x2048, ``/usr/bin/time -f %M``: 66 to 74).
Renders that keep each chunk's sums apart (workers, a splatting film, light
tracing, AOVs, ``moment``) take :data:`BYTES_PER_PIXEL` (measured the same
way with the chunks' own arrays) plus their extra channels.
:func:`check` compares that with what Linux says is available
(``MemAvailable`` plus free swap in ``/proc/meminfo``) and refuses, in one
line naming a size that would fit, an image that cannot; elsewhere it checks
nothing.
"""

from __future__ import annotations

from .errors import DrptError
from .options import LIGHT_TRACED

BYTES_PER_PIXEL = 180
BYTES_PER_PIXEL_LOCAL = 80
BASE_BYTES = 300 << 20


def bytes_per_pixel(opts=None, local: bool = False) -> int:
    """Peak bytes per pixel of a render with ``opts`` (a RenderOptions; None: the most
    common), ``local``: traced in this process (not on workers)."""
    if opts is None:
        return BYTES_PER_PIXEL
    splat = not (opts.pixel_filter.is_box or opts.filter_sampling) and opts.integrator not in LIGHT_TRACED
    extra = 0
    if opts.moment:
        extra += 2 * 8 * (6 if splat else 3)  # the channel products, merged and per chunk
    if splat:
        extra += 2 * 8 * 2  # the filter weights' sums, merged and per chunk
    aovs = getattr(opts, "aovs", ()) or ()
    if aovs or getattr(opts, "denoise", False):
        extra += 2 * 8 * (3 * max(len(aovs), 2) + 1)  # AOV channels and their weight
    if opts.integrator == "bdpt":
        extra += 2 * 8 * 6  # the camera samples' squares and sums beside the splats' squares
    if getattr(opts, "bdpt_strategies", False):
        extra += 20 * 3 * (4 + 8 + 8)  # 20 strategy images: the pass's film, its sums, the total
    direct = local and not splat and opts.integrator not in LIGHT_TRACED and not opts.moment and not extra
    return (BYTES_PER_PIXEL_LOCAL if direct else BYTES_PER_PIXEL) + extra


def estimate(width: int, height: int, per_pixel: int = BYTES_PER_PIXEL) -> int:
    """Peak bytes a render of ``width`` x ``height`` pixels needs, about."""
    return BASE_BYTES + per_pixel * width * height


def available(meminfo: str = "/proc/meminfo") -> int | None:
    """Bytes this machine can still give a process (RAM and swap), or None if unknown."""
    try:
        with open(meminfo) as f:
            fields = dict(line.split(":", 1) for line in f if ":" in line)
        kb = int(fields["MemAvailable"].split()[0]) + int(fields.get("SwapFree", "0 kB").split()[0])
    except (OSError, KeyError, ValueError):
        return None
    return kb * 1024


def check(width: int, height: int, have: int | None = None, per_pixel: int = BYTES_PER_PIXEL) -> None:
    """Raise a DrptError when a ``width`` x ``height`` render cannot fit; it names the
    largest image of the same shape that would."""
    need = estimate(width, height, per_pixel)
    have = available() if have is None else have
    if have is not None and need > have:
        scale = ((have - BASE_BYTES) / per_pixel / (width * height)) ** 0.5 if have > BASE_BYTES else 0.0
        w, h = int(width * scale), int(height * scale)
        fits = f"{w}x{h} would fit" if w >= 1 and h >= 1 else "no image fits"
        raise DrptError(f"a {width}x{height} image needs about {_gb(need)} of memory "
                        f"({per_pixel} bytes per pixel), and this machine has {_gb(have)} "
                        f"available: render a smaller image ({fits})")


def _gb(n: int) -> str:
    return f"{n / 2**30:.3g} GiB"
