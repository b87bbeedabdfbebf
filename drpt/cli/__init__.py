"""Command line: ``python -m drpt <command> ...``.

``render`` accepts modern options and, unchanged, the seed renderer's own
flags (``-input scene.txt -size 800 800 -output x.tga -spp 64 -MonteCarlo
-cook_torrance -RR_cutdown 0.6 -Gamma 2.2 -SpatialTree -resolution 5
-SAHeuristic 2000 -gui``; ``-gui`` opens the viewer of ``drpt view`` first and
renders with the camera the user left it at). With ``-input`` the seed's defaults apply (Whitted
ray tracing, Phong shading, uniform grid; with ``-SpatialTree`` its BVH rule,
SAH only in nodes of at most ``2 * 2000`` primitives); otherwise drpt's (MIS
path tracing, the ``auto`` accelerator). A flag whose feature is not built yet
says so in one line.

The package: :mod:`.args` (the render flags shared with every tool, the seed's
spellings, and the :class:`~drpt.options.RenderOptions` they give),
:mod:`.commands` (``render``, ``view``, ``export``), :mod:`.parser` (the
parser and drpt's one-line argparse errors). The tools' commands are
:mod:`drpt.tools`.

``--backend llvm|cuda`` (or ``$DRPT_BACKEND``) chooses the Dr.Jit backend
before any kernel module is imported: :func:`main` applies it
(:func:`drpt.backend.select_from_argv`) before it imports the parser, so this
module imports nothing that binds array types.

User mistakes print one line and exit with status 2; no traceback. Warnings
print one line each (:func:`drpt.errors.warn`).
"""

from __future__ import annotations

import argparse
import sys
import warnings

from .. import backend
from ..errors import DrptError, showwarning


def build_parser() -> argparse.ArgumentParser:
    """The ``drpt`` parser (:func:`drpt.cli.parser.build_parser`)."""
    from .parser import build_parser as build  # kernels: imported once the backend is chosen

    return build()


def main(argv: list[str] | None = None) -> int:
    """Run ``drpt`` with ``argv`` (default ``sys.argv[1:]``); the exit status."""
    argv = sys.argv[1:] if argv is None else list(argv)
    with warnings.catch_warnings():
        # Python warnings (scene and export notices) print on one line, as drpt's own.
        warnings.showwarning = showwarning
        try:
            backend.select_from_argv(argv)
            from .parser import run  # kernels: imported once the backend is chosen

            return run(argv)
        except DrptError as e:
            print(f"drpt: error: {e}", file=sys.stderr)
            return 2
        except KeyboardInterrupt:
            print("drpt: interrupted", file=sys.stderr)
            return 130
