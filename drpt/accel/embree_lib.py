"""ctypes bindings: the Embree 3 C API and Dr.Jit's hook that calls Embree from a kernel.

Dr.Jit's LLVM backend can call a packet ray query of Embree 3 (``rtcIntersectW`` /
``rtcOccludedW``, ``W`` the kernel's vector width) from inside a kernel, also inside
symbolic loops: ``jit_llvm_ray_trace(func, scene, shadow, in, out)`` of
``libdrjit-core`` adds the call to the kernel being traced. Mitsuba 3's LLVM variants
trace their rays this way. drpt reaches both libraries through ``ctypes``:

* **Embree 3**, the system library (Debian/Ubuntu ``libembree3-3``; ``.ci/setup``
  installs it with apt-get): ``libembree3.so.3``, or the path in ``DRPT_EMBREE_LIB``.
  Dr.Jit renders the call for Embree 3's calling convention (valid mask, scene,
  ``RTCIntersectContext``, ray packet), so Embree 4 does not fit. Mitsuba's wheel
  carries its own Embree, but inside a C++ namespace, not as the C API.
* **Dr.Jit's C API**, exported by ``libdrjit-core.so`` (Dr.Jit 1.5) under C++-mangled
  names: ``jit_llvm_ray_trace``, ``jit_var_pointer`` (a pointer variable for the
  function and the scene), ``jit_llvm_vector_width``, ``jit_var_ref`` and
  ``jit_var_dec_ref_impl`` (reference counts). The
  outputs of ``jit_llvm_ray_trace`` are variable indices, wrapped into Python arrays by
  ``drjit.detail.update_indices``.

:func:`load` returns the bound :class:`Lib`, or raises :class:`EmbreeUnavailable`
with the reason (no library, a symbol missing, the CUDA backend); :func:`reason`
returns that reason or ``None``. Both cache their answer.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import threading
from functools import lru_cache

import drjit as dr

from .. import backend
from ..errors import DrptError

# Embree 3 enums (rtcore_common.h, rtcore_buffer.h, rtcore_geometry.h, rtcore_scene.h)
BUFFER_INDEX = 0
BUFFER_VERTEX = 1
FORMAT_UINT3 = 0x5003
FORMAT_FLOAT3 = 0x9003
FORMAT_FLOAT4 = 0x9004
GEOMETRY_TRIANGLE = 0
GEOMETRY_SPHERE_POINT = 50
SCENE_FLAG_ROBUST = 1 << 2
BUILD_QUALITY_HIGH = 2
WIDTHS = (1, 4, 8, 16)  # packet queries Embree 3 exports


class EmbreeUnavailable(DrptError):
    """Embree 3 or Dr.Jit's ray-trace hook cannot be used here."""


class Lib:
    """Embree 3's functions (``rtc*`` attributes) and Dr.Jit's hook, bound."""

    def __init__(self, emb: ctypes.CDLL, core: ctypes.CDLL):
        vp, u32, cint = ctypes.c_void_p, ctypes.c_uint32, ctypes.c_int
        sig = {
            "rtcNewDevice": (vp, [ctypes.c_char_p]),
            "rtcGetDeviceError": (cint, [vp]),
            "rtcNewScene": (vp, [vp]),
            "rtcSetSceneFlags": (None, [vp, cint]),
            "rtcSetSceneBuildQuality": (None, [vp, cint]),
            "rtcNewGeometry": (vp, [vp, cint]),
            "rtcSetSharedGeometryBuffer": (None, [vp, cint, ctypes.c_uint, cint, vp,
                                                  ctypes.c_size_t, ctypes.c_size_t,
                                                  ctypes.c_size_t]),
            "rtcCommitGeometry": (None, [vp]),
            "rtcAttachGeometryByID": (None, [vp, vp, ctypes.c_uint]),
            "rtcReleaseGeometry": (None, [vp]),
            "rtcCommitScene": (None, [vp]),
            "rtcReleaseScene": (None, [vp]),
        }
        for name, (res, args) in sig.items():
            f = getattr(emb, name)
            f.restype, f.argtypes = res, args
            setattr(self, name, f)
        self.queries = {}
        for w in WIDTHS:
            suffix = str(w)
            self.queries[w] = (ctypes.cast(getattr(emb, "rtcIntersect" + suffix), vp).value,
                               ctypes.cast(getattr(emb, "rtcOccluded" + suffix), vp).value)
        self.var_pointer = core._Z15jit_var_pointer10JitBackendPKvji
        self.var_pointer.restype, self.var_pointer.argtypes = u32, [u32, vp, u32, cint]
        self.mem_map = core._Z15jit_var_mem_map10JitBackend7VarTypePvmi
        self.mem_map.restype = u32
        self.mem_map.argtypes = [u32, u32, vp, ctypes.c_size_t, cint]
        self.ray_trace = core._Z18jit_llvm_ray_tracejjiPKjPj
        self.ray_trace.restype = None
        self.ray_trace.argtypes = [u32, u32, cint, ctypes.POINTER(u32), ctypes.POINTER(u32)]
        self.dec_ref = core._Z20jit_var_dec_ref_implj
        self.dec_ref.restype, self.dec_ref.argtypes = None, [u32]
        self.var_ref = core._Z11jit_var_refj
        self.var_ref.restype, self.var_ref.argtypes = u32, [u32]
        self.vector_width = core._Z21jit_llvm_vector_widthv
        self.vector_width.restype, self.vector_width.argtypes = u32, []
        self.device = self.rtcNewDevice(f"threads={os.cpu_count() or 1}".encode())
        if not self.device:
            raise EmbreeUnavailable("rtcNewDevice failed")
        # Embree's own allocations (its BVH), net of frees: its memory monitor callback
        self.device_bytes = 0
        lock = threading.Lock()  # Embree's build threads call the monitor

        def monitor(_user, nbytes, _post):
            with lock:
                self.device_bytes += nbytes
            return True

        self._monitor = ctypes.CFUNCTYPE(ctypes.c_bool, vp, ctypes.c_ssize_t, ctypes.c_bool)(monitor)
        emb.rtcSetDeviceMemoryMonitorFunction.restype = None
        emb.rtcSetDeviceMemoryMonitorFunction.argtypes = [vp, vp, vp]
        emb.rtcSetDeviceMemoryMonitorFunction(self.device, ctypes.cast(self._monitor, vp), None)

    def handle(self, address: int):
        """``address`` as Dr.Jit sees a buffer: a ``UInt64`` array of one element mapped at
        ``address`` (not copied, never freed by Dr.Jit), and a pointer variable that holds
        ``address`` and depends on that array; returns ``(array, pointer index)``. A kernel
        that calls Embree through the pointer names the array as the source of that
        kernel parameter, which is what ``dr.freeze`` needs: the array is an input the
        frozen function finds among its arguments (:mod:`drpt.render.frozen`), so that a
        replay passes the same address (Mitsuba 3.9 maps its Embree handles the same way).
        The caller owns the pointer variable's reference."""
        from drjit.llvm import UInt64

        index = self.mem_map(dr.JitBackend.LLVM.value, int(dr.VarType.UInt64.value), address, 1, 0)
        (array,) = dr.detail.update_indices((UInt64(),), [index])  # takes a reference
        self.dec_ref(index)
        return array, self.var_pointer(dr.JitBackend.LLVM.value, address, array.index, 0)


def _library_path() -> str | None:
    env = os.environ.get("DRPT_EMBREE_LIB")
    if env:
        return env
    for name in ("libembree3.so.3", ctypes.util.find_library("embree3")):
        if name:
            try:
                ctypes.CDLL(name)
                return name
            except OSError:
                continue
    return None


@lru_cache(maxsize=1)
def _load() -> tuple[Lib | None, str | None]:
    path = _library_path()
    if path is None:
        return None, "Embree 3 not found (apt-get install libembree3-3, or set DRPT_EMBREE_LIB)"
    try:
        emb = ctypes.CDLL(path)
        core = ctypes.CDLL(os.path.join(os.path.dirname(dr.__file__), "libdrjit-core.so"))
        return Lib(emb, core), None
    except (OSError, AttributeError, EmbreeUnavailable) as e:
        return None, f"Embree 3 at {path} or Dr.Jit's ray-trace hook unusable: {e}"


def reason() -> str | None:
    """Why the ``"embree"`` accelerator cannot run with the current backend, or ``None``."""
    if backend.policy().name != "llvm":
        return f"the embree accelerator runs on the LLVM backend, not {backend.policy().name}"
    return _load()[1]


def load() -> Lib:
    """The bound :class:`Lib`; raises :class:`EmbreeUnavailable` (:func:`reason`)."""
    why = reason()
    if why is not None:
        raise EmbreeUnavailable(why)
    return _load()[0]
