"""Whether a render's image fits in the memory this machine has, checked
before anything is traced.

A render's memory grows with its pixels, not its samples: the float64 sums
of the merged chunks (and of the sums of squares), the image and its
variance, and the copies made to write them; measured at about
:data:`BYTES_PER_PIXEL` of peak resident memory per pixel on top of
:data:`BASE_BYTES` (Python, Dr.Jit, Mitsuba and the compiled kernels; the
Cornell box from 256x256 to 2048x2048 pixels). :func:`check` compares that
with what Linux says is available (``MemAvailable`` plus free swap in
``/proc/meminfo``) and refuses, in one line, an image that cannot fit;
elsewhere it checks nothing.
"""

from __future__ import annotations

from .errors import DrptError

BYTES_PER_PIXEL = 180
BASE_BYTES = 300 << 20


def estimate(width: int, height: int) -> int:
    """Peak bytes a render of ``width`` x ``height`` pixels needs, about."""
    return BASE_BYTES + BYTES_PER_PIXEL * width * height


def available(meminfo: str = "/proc/meminfo") -> int | None:
    """Bytes this machine can still give a process (RAM and swap), or None if unknown."""
    try:
        with open(meminfo) as f:
            fields = dict(line.split(":", 1) for line in f if ":" in line)
        kb = int(fields["MemAvailable"].split()[0]) + int(fields.get("SwapFree", "0 kB").split()[0])
    except (OSError, KeyError, ValueError):
        return None
    return kb * 1024


def check(width: int, height: int, have: int | None = None) -> None:
    """Raise a DrptError when a ``width`` x ``height`` render cannot fit."""
    need = estimate(width, height)
    have = available() if have is None else have
    if have is not None and need > have:
        raise DrptError(f"a {width}x{height} image needs about {_gb(need)} of memory "
                        f"({BYTES_PER_PIXEL} bytes per pixel), and this machine has {_gb(have)} "
                        "available: render a smaller image")


def _gb(n: int) -> str:
    return f"{n / 2**30:.3g} GiB"
