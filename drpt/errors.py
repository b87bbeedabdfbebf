"""User-facing errors.

Anything a user can cause (a bad scene file, a missing texture, a bad flag,
no usable LLVM) raises :class:`DrptError` or a subclass. The command line
prints ``str(error)`` on one line and exits with status 2; it never shows a
Python traceback for these.

Warnings and notes (things that do not stop a command) are printed by
:func:`warn` and :func:`note`, each on one line to stderr.
"""

from __future__ import annotations

import sys
from os import PathLike


class DrptError(Exception):
    """A problem the user can fix; the message says what and where."""


class SceneError(DrptError):
    """A problem in an input file, located by file and (1-based) line."""

    def __init__(self, path: str | PathLike | None, line: int | None, message: str):
        self.path = None if path is None else str(path)
        self.line = line
        self.message = message
        super().__init__(str(self))

    def __str__(self) -> str:
        where = self.path or "<input>"
        if self.line is not None:
            where += f":{self.line}"
        return f"{where}: {self.message}"


def _report(kind: str, message, file=None, line=None) -> None:
    where = ""
    if file is not None:
        where = f"{file}:{line}: " if line is not None else f"{file}: "
    text = " ".join(str(message).split("\n"))
    print(f"drpt: {kind}: {where}{text}", file=sys.stderr, flush=True)


def warn(message, file: str | PathLike | None = None, line: int | None = None) -> None:
    """Print ``drpt: warning: FILE:LINE: message`` on one line to stderr.

    ``file`` and ``line`` are the input's (a scene, an MTL file), when known.
    Every warning drpt prints goes through here; :func:`showwarning` routes
    Python ``warnings`` here too."""
    _report("warning", message, file, line)


def note(message, file: str | PathLike | None = None, line: int | None = None) -> None:
    """Print ``drpt: note: message`` on one line to stderr (an accepted flag
    or setting that does less than it says, e.g. one that is ignored)."""
    _report("note", message, file, line)


def showwarning(message, category, filename, lineno, file=None, line=None) -> None:
    """A ``warnings.showwarning`` that prints through :func:`warn`.

    drpt's own warnings name the input's file and line in their message;
    the Python source location (``filename``, ``lineno``) is not shown, nor
    is the source line Python's default formatter would echo."""
    warn(message)
