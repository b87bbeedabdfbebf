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
* The sky and directional lights: ``pi r^2`` instead of the whole scene's ``pi R^2``.

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
    """The sphere that bounds the scene's lit geometry."""

    center: np.ndarray
    radius: float

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
    """The bounding sphere of ``scene``'s triangles and spheres whose material emits
    nothing (``None``: the scene has infinite planes, or no such shape)."""
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
    return Receivers((lo + hi) / 2.0, radius) if radius > 0.0 else None
