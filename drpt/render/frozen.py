"""A camera pass replayed without tracing it again: ``dr.freeze`` of the pass's kernels.

Tracing a pass (the Python of the integrator's loop, the camera, the sampler and the
lane sums) costs milliseconds per render whatever its size; on a small render that is a
fifth of it (docs/performance.md, "Frozen passes"). :class:`FrozenPass` wraps the
renderer's pass body in :func:`drjit.freeze`. The renderer traces a pass shape's first pass
(samples per pixel, rows, precision) as before and calls the frozen body from its second:
that call traces and records the kernel launches, later calls launch the recorded kernels on
the current inputs (:meth:`Renderer._frozen_pass <drpt.render.renderer.Renderer._frozen_pass>`).

Contract of a body frozen here (what Dr.Jit 1.5's recording needs, and what keeps a
replay equal to a trace):

* **Inputs.** Every Dr.Jit array a kernel reads must be an input of the frozen call or
  made inside it. The body's own arguments are inputs, and so is every array reachable
  from the ``roots`` (the device scene, the integrator, the camera): :func:`device_arrays`
  walks their attributes, lists, tuples and dicts on each call (an array replaced between
  renders, as :meth:`~drpt.render.scene.DeviceScene.set_delta_each` may replace the light
  selection, is the new one at the next replay). Embree's scene and query functions are
  such inputs (:meth:`drpt.accel.embree_lib.Lib.handle`).
* **What varies per render is an array.** Python values are part of the recording's key:
  a different ``int`` argument records again, and a value the body reads from Python state
  (an ``int`` made opaque inside the body, say) would be replayed as recorded. The seed
  and the pass's first row therefore enter as opaque keys made outside
  (:func:`~drpt.render.sampler.pcg_keys`, :func:`~drpt.render.sampler.ld_stream_key`),
  and the body's ``int`` arguments (samples per pixel, rows, precision) are exactly what
  shapes its kernels.
* **Outputs are arrays**; the host reads them back after the call.
* **Nothing made outside is freed inside.** Dr.Jit 1.5 aborts the process when an array
  made before the recording is freed during it (its memory is released by a host function,
  which a recording cannot hold): the body must not drop the last reference to one (a cache
  replaced while tracing), and :meth:`FrozenPass.__call__` holds the garbage collector off
  while it runs (a collected renderer's arrays would be such frees).

The integrator's and the options' Python state that shapes the kernels (depths, the
sampler, the integrator kind) is fixed for a :class:`~drpt.render.renderer.Renderer`
(``derive`` makes a new one); the renderer also passes the options (as their ``repr``: a
dataclass argument hid the arguments after it from Dr.Jit 1.5's key) and the identities of
its objects' attributes as an argument, so a change to them records again rather than
replaying stale kernels.
"""

from __future__ import annotations

import ctypes
import gc
import os
import types
import weakref
from collections.abc import Callable
from pathlib import PurePath

import drjit as dr
import numpy as np

#: object kinds the walk does not enter (host data, paths, code, a C library's bound functions)
_LEAVES = (str, bytes, int, float, bool, complex, np.ndarray, np.generic, PurePath, types.ModuleType,
           types.FunctionType, types.BuiltinFunctionType, types.MethodType, type,
           ctypes.CDLL, ctypes._CFuncPtr)


#: packages and modules whose objects hold host data only: they import no Dr.Jit (the scene
#: model and the material specifications the device tables are made from, the render options;
#: ``tests/render/test_frozen.py`` checks that they import none), so the walk does not enter
#: their objects (a device scene keeps its host scene to rebuild its light selection, the
#: renderer's objects their options)
HOST_PACKAGES = ("drpt.scene", "drpt.materials", "drpt.options")

#: Dr.Jit's texture classes (their tensors are inputs too)
_TEXTURES = tuple(getattr(dr.auto, f"Texture{d}f{p}") for d in (1, 2, 3) for p in ("", "16", "64", "8u")
                  if hasattr(dr.auto, f"Texture{d}f{p}"))

#: ``DRPT_FREEZE=0`` traces every pass (for measuring what freezing saves)
ENABLED = os.environ.get("DRPT_FREEZE", "1") != "0"


def freezes(integrator) -> bool:
    """Whether the renderer freezes ``integrator``'s camera passes: on the LLVM backend
    (where drpt's kernels, Embree's queries included, are recorded and replayed; not tried
    on CUDA), for the megakernel integrators (one path loop per lane,
    ``sample_sequence``: the wavefront's queues have data-dependent sizes), unless
    :data:`ENABLED` is off."""
    return ENABLED and dr.backend_v(dr.auto.Float) == dr.JitBackend.LLVM and hasattr(
        integrator, "sample_sequence")


def device_arrays(*roots, inert: dict | None = None) -> list:
    """The Dr.Jit arrays and textures reachable from ``roots`` through object attributes (``__dict__``
    and ``__slots__``), lists, tuples, sets and dict values, each once, in a fixed order; host
    values and the objects of :data:`HOST_PACKAGES` are not entered.

    ``inert`` (kept by the caller from one walk to the next) maps ``id`` to each tuple or
    frozenset found to hold only what the walk does not enter (numbers, strings, host arrays,
    or tuples so found): immutable, so they hold no array on any later walk either, which
    skips them (a scene's tables hold thousands of such tuples). The map holds the objects,
    so an ``id`` in it is never another object's."""
    out: list = []
    seen: set[int] = set()
    stack = list(reversed(roots))
    kinds = _kinds
    while stack:
        obj = stack.pop()
        i = id(obj)
        if i in seen:
            continue
        seen.add(i)
        t = type(obj)
        kind = kinds.get(t)
        if kind is None:
            kind = _kind(t)
        if kind == _LEAF or (inert is not None and i in inert):
            continue
        if kind == _ARRAY:
            out.append(obj)
            continue
        if kind == _IMMUTABLE:
            if inert is not None and all(kinds.get(type(x)) == _LEAF or id(x) in inert for x in obj):
                inert[i] = obj
                continue
            items = list(obj)
        elif kind == _SEQUENCE:
            items = list(obj)
        elif kind == _DICT:
            items = list(obj.values())
        else:
            d = getattr(obj, "__dict__", None)
            items = list(d.values()) if isinstance(d, dict) else []
            for name in _slots(t):
                if hasattr(obj, name):
                    items.append(getattr(obj, name))
        stack.extend(reversed(items))
    return out


#: what :func:`device_arrays` does with an object of a type: not entered, kept (an array or
#: texture), entered as an immutable sequence (a tuple or frozenset, which may be found
#: inert), as a list or set, as a dict's values, or as an object's attributes
_LEAF, _ARRAY, _IMMUTABLE, _SEQUENCE, _DICT, _OBJECT = range(6)
_kinds: dict[type, int] = {}
_slot_names: dict[type, tuple[str, ...]] = {}


def _kind(t: type) -> int:
    """:func:`device_arrays`' way with objects of type ``t`` (remembered by type): not entered
    for ``None``, :data:`_LEAVES` and the classes of :data:`HOST_PACKAGES`."""
    module = getattr(t, "__module__", None) or ""
    if t is type(None) or issubclass(t, _LEAVES) or any(module == p or module.startswith(p + ".")
                                                         for p in HOST_PACKAGES):
        kind = _LEAF
    elif dr.is_array_v(t) or issubclass(t, _TEXTURES):
        kind = _ARRAY
    elif issubclass(t, (tuple, frozenset)):
        kind = _IMMUTABLE
    elif issubclass(t, (list, set)):
        kind = _SEQUENCE
    elif issubclass(t, dict):
        kind = _DICT
    else:
        kind = _OBJECT
    _kinds[t] = kind
    return kind


def _slots(t: type) -> tuple[str, ...]:
    """The ``__slots__`` names of ``t`` and its bases, in method resolution order
    (remembered by type)."""
    names = _slot_names.get(t)
    if names is None:
        names = tuple(n for cls in t.__mro__ for n in getattr(cls, "__slots__", ()) if isinstance(n, str))
        _slot_names[t] = names
    return names


def _weak(f: Callable) -> Callable[[], Callable]:
    """A weak reference to bound method ``f`` (a strong one to any other callable)."""
    if hasattr(f, "__self__") and hasattr(f, "__func__"):
        return weakref.WeakMethod(f)
    return lambda: f


class FrozenPass:
    """``body(keys, *args)`` frozen with the arrays of ``roots`` as extra inputs; calls
    are ``frozen(keys, options, *args)``: ``keys`` the per-render arrays (the seed's),
    ``options`` any hashable description of the Python state the kernels depend on."""

    def __init__(self, body: Callable, roots: Callable[[], tuple]):
        # bound methods of the renderer that owns this object, held weakly: no reference
        # cycle keeps a renderer (and its recordings) alive until a garbage collection
        body_ref, roots_ref = _weak(body), _weak(roots)
        #: why recording failed (then every call returns None), or None
        self.failed: str | None = None
        inert: dict = {}  # device_arrays' immutable host tuples, from one call to the next
        self.frozen = dr.freeze(lambda keys, options, *args: body_ref()(keys, *args),
                                state_fn=lambda *a, **k: device_arrays(*roots_ref()(), inert=inert))

    def __call__(self, keys, options, *args):
        """The body's outputs, replayed or recorded now; None where Dr.Jit could not record
        it (an array the body uploads itself, say: the caller traces the body instead, and
        this pass is not frozen again)."""
        if self.failed:
            return None
        collecting = gc.isenabled()
        gc.disable()  # an array made outside and freed while recording aborts the process
        try:
            return self.frozen(keys, options, *args)
        except RuntimeError as e:
            cause = str(e.__cause__ or e)
            if not cause.startswith("record()"):
                raise
            self.failed = cause.splitlines()[0]
            return None
        finally:
            if collecting:
                gc.enable()

    @property
    def recordings(self) -> int:
        """How many times the body was traced and recorded."""
        return self.frozen.n_recordings
