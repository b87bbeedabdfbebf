"""Materials on the device: per-material parameters and the BSDF dispatch.

Each scene material becomes one BSDF (:func:`drpt.shading.interpret_scene`
decides which, the same function the Mitsuba exporter uses), whose lobe
module comes from :data:`drpt.render.bsdf.REGISTRY`. Only the kinds the
scene has are traced: a diffuse-only scene compiles no Phong, GGX or glass
code (nor uploads their parameters); a scene without textures compiles no
texture lookups; a single kind needs no per-lane dispatch at all. With
several kinds, each present lobe is evaluated under its own mask and the
results are merged with ``select``.

Sidedness: lobes registered ``TWO_SIDED`` (diffuse, Phong, Cook-Torrance,
mirror) see their shading frame flipped to the viewer's side. The others
(the dielectric) see the unflipped frame (``+z`` = shading normal =
outside). Emission is one-sided: a material with ``emission`` radiates only
toward the side its shading normal points to, as Mitsuba's ``area`` emitter
does.
"""

from __future__ import annotations

import drjit as dr
import numpy as np
from drjit.auto import Array2f, Array3f, Bool, Float, UInt32

from ..scene.model import Scene
from ..shading import BSDFSpec, interpret_scene
from .bsdf import BSDFSample, lobe
from .surface import Interaction, _vec
from .warp import Frame

_TYPES = {"rgb": Array3f, "float": Float}


class MaterialTable:
    def __init__(self, scene: Scene, mode: str = "phong"):
        # Materials no primitive uses stay out of the kernels entirely.
        used = np.zeros(len(scene.materials), bool)
        for prims in (scene.triangles, scene.spheres, scene.planes):
            used[np.asarray(prims.material, np.int64)] = True
        self.specs: list[BSDFSpec] = [
            spec if u else BSDFSpec("diffuse", kd=(0.0, 0.0, 0.0))
            for spec, u in zip(interpret_scene(scene, mode), used)]
        self.notes = [n for s in self.specs for n in s.notes]
        self.kinds = sorted({s.kind for s, u in zip(self.specs, used) if u}) or ["diffuse"]
        self.lobes = {k: lobe(k) for k in self.kinds}
        kinds = np.array([self.kinds.index(s.kind) if s.kind in self.kinds else 0
                          for s in self.specs], np.uint32)
        self.kind = UInt32(kinds)
        self.emission = _vec(np.array([m.emission for m in scene.materials], float))
        self.has_emission = any(m.is_emissive for m in scene.materials)

        def col(name):
            return _vec(np.array([getattr(s, name) for s in self.specs], float))

        def num(name):
            return Float(np.array([getattr(s, name) for s in self.specs], np.float32))

        self.kd = col("kd")
        # the parameters of the kinds present, one array per spec field
        self._fields: dict[str, type] = {}
        for m in self.lobes.values():
            self._fields.update({name: _TYPES[t] for name, t in m.FIELDS.items()})
        for name, t in self._fields.items():
            setattr(self, name, col(name) if t is Array3f else num(name))

        # Textures (map_Kd, kept by interpret_scene only where the scene has
        # uvs); one id per material, or -1.
        self.textures = None
        paths = sorted({s.texture for s in self.specs if s.texture is not None}, key=str)
        if paths:
            from .texture import TextureSet

            self.textures = TextureSet(paths)
            tex = [paths.index(s.texture) if s.texture is not None else -1 for s in self.specs]
            self.tex_id = UInt32(np.array(tex, np.int64).astype(np.uint32))

    # ------------------------------------------------------------------
    def emitted(self, si: Interaction) -> Array3f:
        """Radiance leaving ``si`` toward ``si.wi`` (zero on back faces)."""
        if not self.has_emission:
            return Array3f(0.0)
        le = dr.gather(Array3f, self.emission, si.material, si.valid)
        front = si.valid & (dr.dot(si.ns, si.wi) > 0.0)
        return dr.select(front, le, 0.0)

    def is_specular_only(self) -> bool:
        return all(m.DELTA for m in self.lobes.values())

    def is_delta(self, si: Interaction) -> Bool:
        """Lanes whose material is a delta lobe (glass, mirror)."""
        ids = [i for i, k in enumerate(self.kinds) if self.lobes[k].DELTA]
        if not ids:
            return Bool(False)
        if len(ids) == len(self.kinds):
            return Bool(si.valid)
        kind_of = dr.gather(UInt32, self.kind, si.material, si.valid)
        mask = Bool(False)
        for i in ids:
            mask |= kind_of == i
        return si.valid & mask

    def diffuse_color(self, si: Interaction, active: Bool) -> Array3f:
        """The diffuse color (Kd or its texture), e.g. for an ambient term."""
        return self.base_color(si, active)

    def base_color(self, si: Interaction, active: Bool) -> Array3f:
        """Kd of the lanes' materials, or their texture at ``si.uv``."""
        kd = dr.gather(Array3f, self.kd, si.material, active)
        if self.textures is not None:
            tid = dr.gather(UInt32, self.tex_id, si.material, active)
            textured = active & (tid != 0xFFFFFFFF)
            kd = dr.select(textured, self.textures.lookup(tid, si.uv, textured), kd)
        return kd

    def gather(self, field: str, si: Interaction, active: Bool):
        """Spec ``field`` (one a present lobe's ``FIELDS`` names) of the lanes' materials."""
        return dr.gather(self._fields[field], getattr(self, field), si.material, active)

    def _cases(self, si: Interaction):
        """(lobe module, lane mask, local frame) for each kind present."""
        flip = dr.dot(si.ns, si.wi) < 0.0
        two_sided = Frame(dr.select(flip, -si.ns, si.ns))
        if len(self.kinds) == 1:
            kind_of = None
        else:
            kind_of = dr.gather(UInt32, self.kind, si.material, si.valid)
        for i, kind in enumerate(self.kinds):
            mask = si.valid if kind_of is None else si.valid & (kind_of == i)
            frame = two_sided if self.lobes[kind].TWO_SIDED else Frame(si.ns)
            yield self.lobes[kind], mask, frame

    # ------------------------------------------------------------------
    def eval_pdf(self, si: Interaction, wo: Array3f) -> tuple[Array3f, Float]:
        """``f * |cos|`` and the sampling density (solid angle) for world ``wo``."""
        f, pdf = Array3f(0.0), Float(0.0)
        for bsdf, mask, frame in self._cases(si):
            if bsdf.DELTA:
                continue  # nothing to evaluate
            p = bsdf.params(self, si, mask)
            wi_l, wo_l = frame.to_local(si.wi), frame.to_local(wo)
            f = dr.select(mask, bsdf.eval(p, wi_l, wo_l), f)
            pdf = dr.select(mask, bsdf.pdf(p, wi_l, wo_l), pdf)
        return f, pdf

    def sample(self, si: Interaction, u1: Float, u2: Array2f) -> tuple[Array3f, BSDFSample]:
        """Sample a world direction; returns it and the local :class:`BSDFSample`."""
        out = BSDFSample()
        wo = Array3f(0.0, 0.0, 1.0)
        for bsdf, mask, frame in self._cases(si):
            p = bsdf.params(self, si, mask)
            bs = bsdf.sample(p, frame.to_local(si.wi), u1, u2)
            out = dr.select(mask, bs, out)
            wo = dr.select(mask, frame.to_world(bs.wo), wo)
        out.valid &= si.valid
        return wo, out
