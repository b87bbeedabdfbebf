"""Media no light reaches by next-event estimation (host-side scene analysis for ``volpath``).

A shadow ray from a point inside a closed surface that blocks shadow rays (any BSDF but
``null`` and ``thindielectric``: Mitsuba's volpath multiplies a shadow ray by the surface's
``eval_null_transmission``, which is 0 for every other BSDF, ``dielectric`` included) can
reach no emitter outside that surface: its transmittance is 0 whatever it crosses on the
way. Next-event estimation from such a point is pure cost. This module finds the media for
which that holds at every point, from the scene alone:

* :func:`enclosed_media`: a medium is *enclosed* when it is no shape's exterior and not the
  camera's medium, and every shape that has it as its interior is closed (every edge of its
  triangles shared by exactly two of them, with opposite directions: a consistently oriented
  closed mesh; or an analytic sphere), has outward geometric normals (a positive signed
  volume, so that its interior is the inside) and blocks shadow rays. Its lanes are then
  inside one of those shapes (the integrator's medium follows the boundaries a ray crosses).
* :func:`media_bounded`: every medium lies inside closed shapes (which may pass shadow
  rays): a ray that leaves every shape reaches the sky.
* :func:`blind_media`: an enclosed medium is *blind* when every emitter lies outside the
  bounding box of each of its boundary shapes (area emitters by their geometry's box,
  which must not overlap; point, spot and projector lights by their position; the sky,
  directional lights and a constant background are outside everything). A shadow ray from
  any of its points must then cross a blocking boundary to reach a light.

A medium that is not provably so (an open or inside-out boundary, a null or thin-dielectric
one, an emitter inside the box, a medium also outside some shape) keeps its next-event
estimation. Shapes are told apart by :attr:`~drpt.scene.model.Triangles.shape` (a Mitsuba
XML shape), else by material.
"""

from __future__ import annotations

import numpy as np

from ...scene.model import PointLight, ProjectorLight, Scene, SpotLight

#: BSDF kinds whose surfaces let shadow rays through (Mitsuba's non-zero ``eval_null_transmission``)
PASSING_KINDS = ("null", "thindielectric")

Box = tuple[np.ndarray, np.ndarray]


def _blocks_shadow_rays(material) -> bool:
    spec = material.bsdf
    return (spec.kind if spec is not None else "") not in PASSING_KINDS


def closed_outward(positions: np.ndarray) -> bool:
    """Whether the triangles ``positions`` ``(F, 3, 3)`` form closed, consistently
    oriented surfaces (each directed edge once, its reverse once, vertices matched by their
    exact coordinates) with outward geometric normals (``cross(p1 - p0, p2 - p0)``: a
    positive signed volume)."""
    if len(positions) == 0:
        return False
    _, vid = np.unique(positions.reshape(-1, 3), axis=0, return_inverse=True)
    vid = vid.reshape(-1, 3).astype(np.int64)
    n = int(vid.max()) + 1
    a = vid.reshape(-1)
    b = vid[:, [1, 2, 0]].reshape(-1)
    edges = a * n + b
    if len(np.unique(edges)) != len(edges):
        return False
    if not np.isin(b * n + a, edges).all():
        return False
    p0, p1, p2 = positions[:, 0], positions[:, 1], positions[:, 2]
    volume = float(np.einsum("ij,ij->i", p0, np.cross(p1, p2)).sum()) / 6.0
    return volume > 0.0


def _boundaries(scene: Scene, medium: int, blocking: bool = True) -> list[Box] | None:
    """The bounding boxes of the shapes whose interior is ``medium``, or None where one of
    them is open, inside-out or (``blocking``) passes shadow rays (or the medium has no such
    shape)."""
    mats = scene.materials or []
    boundary = [k for k, m in enumerate(mats) if m.interior == medium]
    if not boundary or (blocking and any(not _blocks_shadow_rays(mats[k]) for k in boundary)):
        return None
    boxes: list[Box] = []
    if len(scene.planes) and np.isin(scene.planes.material, boundary).any():
        return None
    tris = scene.triangles
    if len(tris):
        on = np.isin(tris.material, boundary)
        ids = tris.emitter_ids()
        for shape in np.unique(ids[on]):
            pos = tris.positions[on & (ids == shape)]
            if not closed_outward(pos):
                return None
            p = pos.reshape(-1, 3)
            boxes.append((p.min(0), p.max(0)))
    sph = scene.spheres
    if len(sph):
        for i in np.flatnonzero(np.isin(sph.material, boundary)):
            c, r = sph.center[i], float(sph.radius[i])
            boxes.append((c - r, c + r))
    return boxes or None


def enclosed_media(scene: Scene) -> dict[int, list[Box]]:
    """The enclosed media (0-based indices into ``scene.media``, see the module's docs),
    each with the bounding boxes of its boundary shapes."""
    mats = scene.materials or []
    outside = {m.exterior for m in mats if m.exterior is not None}
    out = {}
    for i in range(len(scene.media)):
        if i in outside or i == scene.camera_medium:
            continue
        boxes = _boundaries(scene, i)
        if boxes is not None:
            out[i] = boxes
    return out


def media_bounded(scene: Scene) -> bool:
    """Whether every medium lies inside closed shapes (host side, conservative): the camera
    is in none, no shape has one as its exterior, and every shape that has one as its
    interior is closed with outward normals (its boundary may pass shadow rays). A ray that
    leaves every shape is then in vacuum and reaches the sky; in a medium beyond the shapes
    it scatters first, and there only next-event estimation sees the sky (Mitsuba's
    convention), which MIS compensation of the sky must not be used with
    (:func:`drpt.render.scene.env_compensated`)."""
    mats = scene.materials or []
    if scene.camera_medium is not None or any(m.exterior is not None for m in mats):
        return False
    return all(_boundaries(scene, i, blocking=False) is not None for i in range(len(scene.media)))


def _emitter_boxes(scene: Scene, lights: bool = True) -> list[Box]:
    """Boxes around every emitter that has a place (area emitters' geometry, by material;
    with ``lights``, point, spot and projector lights' positions); infinite for an emissive
    plane."""
    boxes: list[Box] = []
    emissive = scene.emissive_materials
    tris, sph, planes = scene.triangles, scene.spheres, scene.planes
    for k in emissive:
        if len(planes) and (planes.material == k).any():
            return [(np.full(3, -np.inf), np.full(3, np.inf))]
        lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
        if len(tris) and (tris.material == k).any():
            p = tris.positions[tris.material == k].reshape(-1, 3)
            lo, hi = np.minimum(lo, p.min(0)), np.maximum(hi, p.max(0))
        if len(sph) and (sph.material == k).any():
            on = sph.material == k
            c, r = sph.center[on], sph.radius[on][:, None]
            lo, hi = np.minimum(lo, (c - r).min(0)), np.maximum(hi, (c + r).max(0))
        if np.all(lo <= hi):
            boxes.append((lo, hi))
    for light in scene.lights if lights else ():
        if isinstance(light, (PointLight, SpotLight, ProjectorLight)):
            p = np.asarray(light.position, np.float64)
            boxes.append((p, p))
    return boxes


def _overlap(a: Box, b: Box) -> bool:
    return bool(np.all(a[0] <= b[1]) and np.all(b[0] <= a[1]))


def blind_media(scene: Scene) -> frozenset[int]:
    """The blind media (0-based indices into ``scene.media``; see the module's docs): next-event
    estimation from any point in them finds transmittance 0."""
    emitters = _emitter_boxes(scene)
    return frozenset(i for i, boxes in enclosed_media(scene).items()
                     if not any(_overlap(e, b) for e in emitters for b in boxes))


def _interior_box(scene: Scene, medium: int) -> Box | None:
    """The bounding box of the shapes whose interior is ``medium`` (infinite with a plane;
    None: no such shape)."""
    mats = scene.materials or []
    inside = [k for k, m in enumerate(mats) if m.interior == medium]
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    if len(scene.planes) and np.isin(scene.planes.material, inside).any():
        return np.full(3, -np.inf), np.full(3, np.inf)
    tris, sph = scene.triangles, scene.spheres
    if len(tris) and np.isin(tris.material, inside).any():
        p = tris.positions[np.isin(tris.material, inside)].reshape(-1, 3)
        lo, hi = np.minimum(lo, p.min(0)), np.maximum(hi, p.max(0))
    if len(sph) and np.isin(sph.material, inside).any():
        on = np.isin(sph.material, inside)
        c, r = sph.center[on], sph.radius[on][:, None]
        lo, hi = np.minimum(lo, (c - r).min(0)), np.maximum(hi, (c + r).max(0))
    return (lo, hi) if np.all(lo <= hi) else None


def media_see_emitters(scene: Scene) -> bool:
    """Whether a ray in a medium can reach an emitter, the sky or the background without
    leaving the medium (host side, conservative): the camera is in a medium, or a medium is
    some shape's exterior (it may reach anything), or an emissive surface's bounding box
    overlaps the bounding box of the shapes a medium is the interior of (a ray inside them
    ends its segment within that box)."""
    if scene.camera_medium is not None or any(m.exterior is not None for m in scene.materials or []):
        return True
    emitters = _emitter_boxes(scene, lights=False)
    boxes = [b for b in (_interior_box(scene, i) for i in range(len(scene.media))) if b is not None]
    return any(_overlap(e, b) for e in emitters for b in boxes)
