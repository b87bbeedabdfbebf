"""Dataclass fields computed on their first read: a render's variance and moments.

A render's image is what every caller reads; its per-pixel variance and second moments are
read by some (``compare``, ``converge``'s references, ``knobs``, ``--target-error``'s
summary, the statistical tests) and not by a plain ``drpt render`` or a timing loop. On a
small render their host arithmetic is a noticeable share of the render (docs/performance.md,
"The variance on first read"), so :func:`drpt.render.renderer.finish` may hand them over as
:class:`Later` values, and :class:`DeferredField` computes such a value when the field is
first read and keeps it.

Contract:

* ``field: T = DeferredField()`` in a ``@dataclass`` body is a field without a default
  (``DeferredField(default=None)``: with that default); reads return a plain value, never a
  :class:`Later`.
* Assigning a :class:`Later` (in ``__init__`` or later) defers; assigning anything else
  stores it as is.
* A :class:`Later` computes at most once; ``pickle`` and ``copy`` of the dataclass store the
  computed value (:meth:`Later.__reduce__`), so a result crosses processes as a plain one.
* The function a :class:`Later` holds keeps its inputs alive until it runs or the result is
  freed (for the variance: the float64 mean and squares of the pixel sums).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

_NO_DEFAULT = object()


class Later:
    """A value to compute on first read: ``fn()``, called at most once."""

    __slots__ = ("_fn", "_value")

    def __init__(self, fn: Callable[[], Any]):
        self._fn = fn
        self._value = _NO_DEFAULT

    def value(self) -> Any:
        if self._value is _NO_DEFAULT:
            self._value, self._fn = self._fn(), None
        return self._value

    def __reduce__(self):
        return _plain, (self.value(),)


def _plain(value: Any) -> Any:
    """What an unpickled :class:`Later` is: its value."""
    return value


class DeferredField:
    """A dataclass field whose stored :class:`Later` is computed on first read."""

    def __init__(self, default: Any = _NO_DEFAULT):
        self.default = default

    def __set_name__(self, owner: type, name: str) -> None:
        self.name, self.slot = name, "_" + name

    def __get__(self, obj: Any, owner: type | None = None) -> Any:
        if obj is None:  # the dataclass asks for the field's default
            if self.default is _NO_DEFAULT:
                raise AttributeError(self.name)  # (a field without a default)
            return self.default
        value = obj.__dict__[self.slot]
        if isinstance(value, Later):
            value = obj.__dict__[self.slot] = value.value()
        return value

    def __set__(self, obj: Any, value: Any) -> None:
        obj.__dict__[self.slot] = value
