"""User-facing errors, and where in an input file they are.

Anything a user can cause (a bad scene file, a missing texture, a bad flag,
no usable LLVM) raises :class:`DrptError` or a subclass. The command line
prints ``str(error)`` on one line and exits with status 2; it never shows a
Python traceback for these.

A place in an input file is a :class:`Loc` (file and 1-based line, either
possibly unknown). The readers put one on everything they build from a file
(materials, textures, skies, lights, media, Mitsuba XML nodes), and every
message about an input names one: a :class:`SceneError` for an error, a
:class:`SceneWarning` (a Python warning) or :func:`warn` for a warning.

Warnings and notes (things that do not stop a command) are printed by
:func:`warn` and :func:`note`, each on one line to stderr.
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass


@dataclass(frozen=True)
class Loc:
    """A place in an input file: ``file`` (a path, as text) and its 1-based
    ``line``; either is None when unknown.

    ``str(Loc("a.mtl", 3))`` is ``"a.mtl:3"``, ``str(Loc("a.mtl"))`` is
    ``"a.mtl"`` and a Loc without a file is ``"<input>"``: the prefix of
    every located message (``a.mtl:3: Kd: expected 1 or 3 numbers``)."""

    file: str | None = None
    line: int | None = None

    def __post_init__(self):
        if self.file is not None and not isinstance(self.file, str):
            object.__setattr__(self, "file", os.fspath(self.file))
        if self.line is not None:
            object.__setattr__(self, "line", int(self.line))

    def __str__(self) -> str:
        where = "<input>" if self.file is None else self.file
        return where if self.line is None else f"{where}:{self.line}"


def located(message: str, loc: Loc | None) -> str:
    """``"LOC: message"``, or ``message`` when ``loc`` is None: the one format of
    located messages (errors, warnings, notes)."""
    return message if loc is None else f"{loc}: {message}"


class DrptError(Exception):
    """A problem the user can fix; the message says what and where."""


class SceneError(DrptError):
    """A problem in an input file at ``loc``: ``str(error)`` is ``"LOC: message"``.

    ``path`` and ``line`` are ``loc.file`` and ``loc.line``."""

    def __init__(self, loc: Loc, message: str):
        if not isinstance(loc, Loc):
            raise TypeError(f"SceneError takes a Loc, got {type(loc).__name__}")
        self.loc = loc
        self.message = message
        super().__init__(str(self))

    @property
    def path(self) -> str | None:
        return self.loc.file

    @property
    def line(self) -> int | None:
        return self.loc.line

    def __str__(self) -> str:
        return located(self.message, self.loc)

    def __reduce__(self):  # pickles (a Dask worker's error) keep the Loc
        return (SceneError, (self.loc, self.message))


class SceneWarning(UserWarning):
    """A warning about an input file at ``loc`` (``warnings.warn(SceneWarning(loc,
    message))``): ``str(warning)`` is ``"LOC: message"`` (``message`` alone when
    ``loc`` is None: a scene built in code), and :func:`showwarning` prints it as
    :func:`warn` does."""

    def __init__(self, loc: Loc | None, message: str):
        if loc is not None and not isinstance(loc, Loc):
            raise TypeError(f"SceneWarning takes a Loc, got {type(loc).__name__}")
        self.loc = loc
        self.message = message
        super().__init__(loc, message)

    def __str__(self) -> str:
        return located(self.message, self.loc)


def _report(kind: str, message, loc: Loc | None = None) -> None:
    text = " ".join(str(message).split("\n"))
    print(f"drpt: {kind}: {located(text, loc)}", file=sys.stderr, flush=True)


def warn(message, loc: Loc | None = None) -> None:
    """Print ``drpt: warning: LOC: message`` on one line to stderr.

    ``loc`` is the input's place (a scene, an MTL file), when the warning is
    about one. A :class:`SceneWarning` as ``message`` brings its own. Every
    warning drpt prints goes through here; :func:`showwarning` routes Python
    ``warnings`` here too."""
    if isinstance(message, SceneWarning) and loc is None:
        message, loc = message.message, message.loc
    _report("warning", message, loc)


def note(message, loc: Loc | None = None) -> None:
    """Print ``drpt: note: message`` on one line to stderr (an accepted flag
    or setting that does less than it says, e.g. one that is ignored);
    ``loc`` as for :func:`warn`."""
    _report("note", message, loc)


def showwarning(message, category, filename, lineno, file=None, line=None) -> None:
    """A ``warnings.showwarning`` that prints through :func:`warn`.

    drpt's own warnings about an input are :class:`SceneWarning` and name
    its file and line; the Python source location (``filename``,
    ``lineno``) is not shown, nor is the source line Python's default
    formatter would echo."""
    warn(message)
