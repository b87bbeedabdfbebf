"""drpt: a Monte Carlo path tracer on Dr.Jit, checked against Mitsuba 3."""

from . import backend as _backend

__version__ = "0.1.0"

# Kernels bind drjit.auto's types when imported: choose the backend first.
_backend.select_from_env()
