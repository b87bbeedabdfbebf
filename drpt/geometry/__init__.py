"""Pure Dr.Jit ray/primitive intersection tests (LLVM backend types).

Every function works on wide arrays, has no side effects and never returns
NaN: a miss is ``hit == False`` with ``t == inf``. Hits require
``0 < t < tmax`` (``tmin < t`` for spheres, default ``tmin = 0``); ``t`` is in
units of the (not necessarily normalized) ray direction.

* :func:`intersect_triangle` -- Möller–Trumbore on ``(p0, e1, e2)``.
* :func:`intersect_triangle_watertight` -- Woop et al. 2013 on vertices,
  watertight across shared edges and vertices; :class:`RayPrep` holds its
  per-ray constants.
* :func:`intersect_sphere` -- Ray Tracing Gems precision-improved quadratic.
* :func:`intersect_plane` -- two-sided infinite plane.
* :func:`intersect_parallelogram` -- two triangles forming a parallelogram as one
  (a plane and a range check); :func:`parallelogram_pairs` finds them.
"""

from .parallelogram import intersect_parallelogram, parallelogram_pairs
from .plane import intersect_plane
from .sphere import intersect_sphere
from .triangle import RayPrep, intersect_triangle, intersect_triangle_watertight

__all__ = [
    "RayPrep",
    "intersect_parallelogram",
    "intersect_plane",
    "intersect_sphere",
    "intersect_triangle",
    "intersect_triangle_watertight",
    "parallelogram_pairs",
]
