"""What of an emitter's power reaches the lit geometry: the light selection's power estimates.

``--light-sampler power`` and ``mixed`` (:mod:`drpt.render.lights.selection`) weigh each
emitter by its :meth:`Emitter.power <drpt.render.lights.Emitter.power>`. What a shadow ray
toward an emitter can bring is the light that reaches the surfaces it lights, not what it
emits into empty space: a point light far below a small object sends almost all of its
``4 pi I`` past it, and the sky's power counted over the bounding sphere of every shape,
emitters included, grows with a distant area light's offset. So the families count the
part of their power that reaches the *receivers*: the bounding sphere (center ``c``,
radius ``r``) of the scene's bounded shapes that emit nothing (:func:`receivers`).

* An isotropic source at distance ``d > r`` from ``c`` (a point light, an emissive
  sphere): the share of its directions toward the sphere, ``(1 - sqrt(1 - r^2 / d^2)) /
  2`` (:meth:`Receivers.isotropic`); 1 inside it.
* A flat one (an emissive triangle, emitting toward its normal's side: its shading
  normals' mean, else its winding's) at ``d > r``: the sphere's form factor seen from it,
  ``(r / d)^2 cos`` (``cos`` between its normal and the direction to ``c``) where the
  sphere is above its horizon (``cos >= r / d``), falling linearly in ``cos`` to 0 where it
  is below (``cos <= -r / d``) (:meth:`Receivers.flat`); 1 inside.
* A spot or a projector: the isotropic share over its cone's share of all directions,
  at most 1.
* The sky and directional lights: the lit geometry's cross-section instead of the whole
  scene's ``pi R^2``: seen along a directional light, the triangles' ``sum A |n . d|``
  (both sides) plus the spheres' ``pi s^2``; for the sky its mean over all directions,
  ``sum A / 2`` plus the spheres' (Cauchy's: a convex body's mean cross-section is a
  quarter of its surface; a flat triangle's surface is both of its sides); each at most
  ``pi r^2``, the sphere's (a closed mesh counts both sides of its triangles, twice its
  cross-section, and shapes hide each other: the sphere's is the bound).

Emitters inside the receivers (a room's, a box's, a floor's lights) count all of their
power; those outside them (the corpus's sphere grids: a point light and a rectangle light
several radii from the spheres) their share, and the sky and directional lights the
cross-section wherever the geometry is. Where the scene has infinite planes (which
receive from every emitter) or no bounded shape that emits nothing, :func:`receivers`
is ``None`` and the families estimate their emitted powers (the sky and directional
lights over the whole scene's bounding sphere).

:class:`~drpt.render.scene.DeviceScene` computes the receivers once and hands them to the
families; the triangles' normals are computed only where a sky or a directional light
asks for a cross-section.
"""

from __future__ import annotations

from functools import cached_property

import numpy as np

from ...scene.model import Scene


class Receivers:
    """The sphere (``center``, ``radius``) that bounds the scene's lit geometry, and that
    geometry's cross-sections: ``triangles`` the scene's triangle corners ``(F, 3, 3)`` and
    ``keep`` those of the lit ones (a mask; neither copied), ``spheres`` the lit spheres'
    summed cross-section. The triangles' normals are computed on first use (a directional
    light's or the sky's cross-section), once."""

    def __init__(self, center, radius: float, triangles: np.ndarray | None = None, keep: np.ndarray | None = None,
                 spheres: float = 0.0):
        self.center = np.asarray(center, np.float64)
        self.radius = float(radius)
        self._triangles, self._keep = triangles, keep
        self.spheres = float(spheres)

    @cached_property
    def _area_normals(self) -> np.ndarray:
        """The lit triangles' unit normals times their areas ``(F, 3)``."""
        if self._triangles is None:
            return np.zeros((0, 3))
        p = self._triangles if self._keep is None else self._triangles[self._keep]
        return 0.5 * np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])

    @cached_property
    def cross_section(self) -> float:
        """The lit geometry's mean cross-section over all directions (a flat triangle's:
        half its area, both sides), at most the sphere's."""
        tri = 0.5 * float(np.linalg.norm(self._area_normals, axis=1).sum())
        return min(np.pi * self.radius ** 2, tri + self.spheres)

    def across(self, d) -> float:
        """The lit geometry's cross-section seen along ``d``, at most the sphere's."""
        d = np.asarray(d, np.float64) / max(float(np.linalg.norm(d)), 1e-30)
        return min(np.pi * self.radius ** 2, float(np.abs(self._area_normals @ d).sum()) + self.spheres)

    def bare(self) -> "Receivers":
        """The sphere alone (for a family that keeps it: no reference to the triangles)."""
        return Receivers(self.center, self.radius)

    def _distance(self, p) -> np.ndarray:
        return np.linalg.norm(np.asarray(p, np.float64).reshape(-1, 3) - self.center, axis=1)

    def isotropic(self, p) -> np.ndarray:
        """The share of an isotropic source's power at each point ``p`` (``(N, 3)``) that
        heads into the sphere."""
        d = self._distance(p)
        x = np.clip(self.radius / np.maximum(d, 1e-30), 0.0, 1.0)
        return np.where(d > self.radius, 0.5 * (1.0 - np.sqrt(1.0 - x * x)), 1.0)

    def flat(self, p, n) -> np.ndarray:
        """The share of the power of a flat Lambertian source at each point ``p`` (``(N,
        3)``), emitting toward the side of its normal ``n`` (need not be unit), that reaches
        the sphere."""
        p = np.asarray(p, np.float64).reshape(-1, 3)
        n = np.asarray(n, np.float64).reshape(-1, 3)
        v = self.center - p
        d = np.linalg.norm(v, axis=1)
        x = self.radius / np.maximum(d, 1e-30)
        cos = np.einsum("ij,ij->i", v, n) / np.maximum(d * np.linalg.norm(n, axis=1), 1e-30)
        # above the horizon: the form factor x^2 cos; across it, down to 0 where the sphere is below
        above = np.where(cos >= x, cos, np.maximum(0.0, (cos + x) / 2.0))
        return np.where(d > self.radius, np.minimum(1.0, x * x * above), 1.0)

    def cone(self, p, share: float) -> float:
        """The share of a spot's or projector's power that reaches the sphere, from ``p``,
        its cone holding ``share`` of all directions."""
        return float(min(1.0, self.isotropic(p)[0] / max(share, 1e-30)))


def receivers(scene: Scene) -> Receivers | None:
    """The bounding sphere and the cross-sections of ``scene``'s triangles and spheres
    whose material emits nothing (``None``: the scene has infinite planes, or no such
    shape)."""
    if len(scene.planes):
        return None
    emits = np.array([m.is_emissive for m in scene.materials] or [False], bool)
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    tris, sph = scene.triangles, scene.spheres
    keep, spheres = None, 0.0
    if len(tris):
        keep = ~emits[np.asarray(tris.material, np.int64)]
        if keep.all():
            keep = None  # (every triangle: no mask, no copy)
        if keep is None or keep.any():  # coordinate by coordinate (numpy's fastest reduction here)
            axes = [tris.positions[:, :, k] if keep is None else tris.positions[:, :, k][keep] for k in range(3)]
            lo, hi = np.array([a.min() for a in axes]), np.array([a.max() for a in axes])
    if len(sph):
        lit = ~emits[np.asarray(sph.material, np.int64)]
        if lit.any():
            c, r = sph.center[lit], np.asarray(sph.radius, np.float64)[lit, None]
            lo, hi = np.minimum(lo, (c - r).min(0)), np.maximum(hi, (c + r).max(0))
            spheres = float(np.pi * (r ** 2).sum())
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        return None
    radius = float(np.linalg.norm(hi - lo)) / 2.0
    if radius <= 0.0:
        return None
    has_tris = len(tris) and (keep is None or keep.any())
    return Receivers((lo + hi) / 2.0, radius, tris.positions if has_tris else None, keep, spheres)
