"""Input files: open regular files only, and remember which line named each.

Every file drpt reads (the scene, its OBJ and MTL files, textures, the sky)
goes through :func:`check_input` before it is opened, so that a symbolic
link loop, a directory, a named pipe (FIFO), a socket or a device is a
one-line :class:`~drpt.errors.SceneError` instead of a traceback or a read
that never returns. ``/dev/null`` is the one exception: it is accepted and
reads as an empty file.

Paths are made absolute with :func:`resolve` (``os.path.realpath``), which,
unlike ``Path.resolve`` in Python 3.11, does not raise on a symbolic link
loop; the loop is then reported by :func:`check_input`.

A file named by another file is stored in the scene model as a
:class:`NamedPath`: a ``Path`` (equal to and hashing as the plain path) that
also carries the :class:`~drpt.errors.Loc` (file and line) that named it. Images are read at render or
export time, long after parsing; :func:`drpt.imageio.read_image` reports a
problem with such a file at that line, e.g. ``scene.txt:12: sky.hdr:
truncated data``.
"""

from __future__ import annotations

import errno
import os
import stat
from os import PathLike
from pathlib import Path

from ..errors import Loc, SceneError

__all__ = ["NamedPath", "named", "resolve", "is_devnull", "check_input", "read_bytes"]


class NamedPath(type(Path())):
    """An absolute path plus :attr:`named_at`, the :class:`~drpt.errors.Loc` that named it.

    Compares, hashes and behaves as the plain path; paths derived from it
    (``parent``, ``/``) have ``named_at`` None. Copies and pickles keep it."""

    named_at: Loc | None = None

    def __reduce__(self):
        return (named, (str(self), self.named_at))


def named(path: str | PathLike, ref: Loc | None) -> Path:
    """``path`` as a :class:`NamedPath` named at ``ref`` (a plain path if ``ref`` is None)."""
    if ref is None:
        return Path(path)
    p = NamedPath(path)
    p.named_at = ref
    return p


def resolve(path: str | PathLike) -> Path:
    """The absolute, symlink-free form of ``path``; never raises (a loop, or a
    name with a NUL byte, stays unresolved and :func:`check_input` reports it)."""
    try:
        return Path(os.path.realpath(os.fspath(path)))
    except ValueError:  # embedded NUL byte
        return Path(os.path.abspath(os.fspath(path)))


def _kind(mode: int) -> str | None:
    if stat.S_ISDIR(mode):
        return "a directory"
    if stat.S_ISFIFO(mode):
        return "a named pipe (FIFO)"
    if stat.S_ISSOCK(mode):
        return "a socket"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if not stat.S_ISREG(mode):
        return "not a regular file"
    return None


def is_devnull(path: str | PathLike) -> bool:
    return resolve(path) == Path(os.devnull)


def check_input(path: str | PathLike, *, ref: Loc | None = None, what: str = "file") -> None:
    """Raise :class:`SceneError` unless ``path`` is a regular file (or ``/dev/null``).

    The error is located at ``ref`` (the place that named ``path``, and the
    message names ``path``) when given, else at ``path`` itself. ``what``
    names the file's role ("OBJ file", "texture file")."""
    if ref is not None:
        where, subject = ref, f"{what} {path}"
    else:
        where, subject = Loc(path), what
    if "\0" in os.fspath(path):
        shown = os.fspath(path).replace("\0", "\\0")
        subject = f"{what} {shown}" if ref is not None else what
        raise SceneError(where if ref is not None else Loc(shown),
                         f"{subject}: a file name cannot contain a NUL byte")
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise SceneError(where, f"{subject} not found") from None
    except OSError as e:
        if e.errno == errno.ELOOP:
            raise SceneError(where, f"{subject} is a symbolic link loop") from None
        if e.errno == errno.ENOTDIR:
            raise SceneError(where, f"{subject} not found (a part of its path is not a directory)") from None
        raise SceneError(where, f"cannot read {subject}: {e.strerror or e}") from None
    kind = _kind(st.st_mode)
    if kind is None or is_devnull(path):
        return
    raise SceneError(where, f"{subject} is {kind}, not a regular file")


def read_bytes(path: str | PathLike, *, ref: Loc | None = None, what: str = "file") -> bytes:
    """The contents of ``path`` after :func:`check_input`; ``b""`` for ``/dev/null``."""
    check_input(path, ref=ref, what=what)
    try:
        with open(path, "rb") as f:
            return f.read()
    except OSError as e:
        if ref is not None:
            raise SceneError(ref, f"cannot read {what} {path}: {e.strerror or e}") from None
        raise SceneError(Loc(path), f"cannot read {what}: {e.strerror or e}") from None
