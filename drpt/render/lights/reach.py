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

Where every emitter lies inside the receivers (a room, a box, a floor under its lights)
the estimates are the emitted powers, as before; they differ where an emitter is
outside them (the corpus's sphere grids: a point light and a rectangle light several
radii from the spheres, and the sky). Where the scene has infinite planes (which
receive from every emitter) or no bounded shape that emits nothing, :func:`receivers`
is ``None`` and the families estimate their emitted powers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...scene.model import Scene


@dataclass(frozen=True)
class Receivers:
    """The sphere that bounds the scene's lit geometry, and that geometry's cross-section."""

    center: np.ndarray
    radius: float
    #: the lit geometry's mean cross-section over all directions, at most the sphere's
    cross_section: float = 0.0
    #: the triangles' area-weighted unit normals (for a directional light's cross-section)
    normals: np.ndarray | None = None
    #: the spheres' cross-sections, summed
    spheres: float = 0.0

    def across(self, d) -> float:
        """The lit geometry's cross-section seen along ``d``, at most the sphere's."""
        d = np.asarray(d, np.float64) / max(float(np.linalg.norm(d)), 1e-30)
        tri = 0.0 if self.normals is None else float(np.abs(self.normals @ d).sum())
        return min(np.pi * self.radius ** 2, tri + self.spheres)

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
    """The bounding sphere and the cross-section of ``scene``'s triangles and spheres whose
    material emits nothing (``None``: the scene has infinite planes, or no such shape)."""
    if len(scene.planes):
        return None
    emits = np.array([m.is_emissive for m in scene.materials] or [False], bool)
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    tris, sph = scene.triangles, scene.spheres
    if len(tris):
        keep = ~emits[np.asarray(tris.material, np.int64)]
        if keep.any():
            p = tris.positions[keep].reshape(-1, 3)
            lo, hi = np.minimum(lo, p.min(0)), np.maximum(hi, p.max(0))
    if len(sph):
        keep = ~emits[np.asarray(sph.material, np.int64)]
        if keep.any():
            c, r = sph.center[keep], np.asarray(sph.radius, np.float64)[keep, None]
            lo, hi = np.minimum(lo, (c - r).min(0)), np.maximum(hi, (c + r).max(0))
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        return None
    radius = float(np.linalg.norm(hi - lo)) / 2.0
    if radius <= 0.0:
        return None
    normals, spheres = None, 0.0
    if len(tris) and (~emits[np.asarray(tris.material, np.int64)]).any():
        p = tris.positions[~emits[np.asarray(tris.material, np.int64)]]
        normals = 0.5 * np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])  # area times unit normal
    if len(sph):
        keep = ~emits[np.asarray(sph.material, np.int64)]
        spheres = float(np.pi * (np.asarray(sph.radius, np.float64)[keep] ** 2).sum())
    # a flat triangle's mean cross-section over all directions is half its area (both sides)
    tri = 0.0 if normals is None else 0.5 * float(np.linalg.norm(normals, axis=1).sum())
    cross = min(np.pi * radius ** 2, tri + spheres)
    return Receivers((lo + hi) / 2.0, radius, cross, normals, spheres)
