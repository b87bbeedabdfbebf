"""User-facing errors.

Anything a user can cause (a bad scene file, a missing texture, a bad flag,
no usable LLVM) raises :class:`DrptError` or a subclass. The command line
prints ``str(error)`` on one line and exits with status 2; it never shows a
Python traceback for these.
"""

from __future__ import annotations

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
