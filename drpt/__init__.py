"""drpt: a Monte Carlo path tracer on Dr.Jit (LLVM), checked against Mitsuba 3."""

__version__ = "0.1.0"
