"""The host-side material layout: a scene's BSDF trees flattened into the arrays the
device uploads (numpy, no Dr.Jit).

Each material is a :class:`~drpt.materials.spec.BSDFSpec` tree
(:func:`drpt.materials.interpret.interpret_scene` decides it, the same function the
Mitsuba exporter uses). :func:`flatten` turns a tree into *components*: leaf lobes,
each with a weight and a sidedness.

* ``twosided(x)``: ``x``'s components see the shading frame flipped to the
  viewer's side (Mitsuba's ``twosided``); all other components see the
  unflipped frame (``+z`` = shading normal = outside) and, being one-sided,
  are black from behind unless they transmit.
* ``blendbsdf(w; a, b)``: ``a``'s components weighted by ``1 - w``, ``b``'s by ``w``.
* ``mask(o; x)``: a ``null`` component (the ray passes straight through)
  weighted ``1 - o``, ``x``'s components by ``o``.
* ``normalmap`` / ``bumpmap``: the components inside see a perturbed frame
  (:class:`Perturbations`).

Weights are constants or one texture (times a constant) per component.

:class:`MaterialLayout` is the scene's layout. Its *rows* are every component of
every used material, material by material: row ``i`` is component
``row_slot[i]`` of material ``row_material[i]``. A material's components occupy
*slots* ``0 .. K-1`` (``K`` = the most any material has); :attr:`MaterialLayout.slots`
maps each material to its row in each slot (:data:`NONE` where it has fewer
components). With ``K = 1`` (every material one component, the usual case) the row
of a material is its index and the device needs no slot tables. Per row, each
field a present kind's lobe reads (its ``FIELDS``) holds a constant and, where the
material gives one, a texture reference (an index into
:attr:`MaterialLayout.textures`); per material, the emission and its texture.

The lobes are the device's (:mod:`drpt.render.bsdf`), so :meth:`MaterialLayout.build`
takes them as an argument: anything with a kind's ``FIELDS`` (``"rgb"``,
``"float"`` or ``("table", N)``), ``DELTA`` and optionally ``derive(params) ->
dict`` (host-side values computed from the parameters). Tests pass stand-ins.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import Loc, SceneError, located
from ..scene.model import Scene
from . import bsdf_kinds
from .interpret import interpret_scene
from .spec import BSDFSpec, Checkerboard, Texture

#: "no row" / "no texture" in the index arrays (uint32).
NONE = 0xFFFFFFFF


@dataclass
class Component:
    """One leaf lobe of a material: its spec, sidedness, weight (a constant times,
    optionally, a texture or one minus it) and the frame perturbation around it."""

    leaf: BSDFSpec
    two_sided: bool
    weight: float = 1.0
    weight_texture: Texture | None = None  # weight *= tex (or 1 - tex when complement)
    complement: bool = False
    perturb: BSDFSpec | None = None  # the normalmap / bumpmap around the leaf
    two_inner: bool = False  # a twosided between the perturbation and the leaf


def flatten(spec: BSDFSpec, two_sided: bool = False, c: Component | None = None) -> list[Component]:
    """The components of ``spec`` (a complete tree), in depth-first order. ``two_sided``
    (and a component's ``two_sided``) is a ``twosided`` around the component's
    perturbation, if any (``two_inner``: one inside it). ``ValueError`` for a tree
    the layout cannot hold (a ``twosided`` with two children, nested perturbations,
    two textured weights on one path)."""
    c = c or Component(spec, False)
    if spec.kind == "twosided":
        if len(spec.children) == 2:
            raise ValueError("twosided with a different BSDF on each side is not supported")
        if c.perturb is not None:
            cc = copy.copy(c)
            cc.two_inner = True
            return flatten(spec.children[0], two_sided, cc)
        return flatten(spec.children[0], True, c)
    if spec.kind in bsdf_kinds.PERTURBING:
        if c.perturb is not None:
            raise ValueError(f"{spec.kind} inside {c.perturb.kind} is not supported")
        cc = copy.copy(c)
        v = spec.params.get(bsdf_kinds.PERTURBING[spec.kind])
        if isinstance(v, Texture) or (spec.kind == "normalmap" and isinstance(v, tuple)):
            cc.perturb = spec  # (a bump texture dropped for want of uvs perturbs nothing)
        return flatten(spec.children[0], two_sided, cc)
    if spec.kind in ("blendbsdf", "mask"):
        w = spec.params["weight" if spec.kind == "blendbsdf" else "opacity"]
        if spec.kind == "mask":
            parts = [(BSDFSpec("null"), True), (spec.children[0], False)]
        else:
            parts = [(spec.children[0], True), (spec.children[1], False)]
        out = []
        for child, complement in parts:
            cc = copy.copy(c)
            if isinstance(w, Texture):
                if cc.weight_texture is not None:
                    raise ValueError("nested blendbsdf/mask with more than one textured weight "
                                     "are not supported")
                cc.weight_texture, cc.complement = w, complement
            else:
                ww = min(max(float(w), 0.0), 1.0)
                cc.weight *= (1.0 - ww) if complement else ww
                if cc.weight == 0.0:
                    continue
            out += flatten(child, two_sided, cc)
        return out
    return [Component(spec, two_sided, c.weight, c.weight_texture, c.complement, c.perturb, c.two_inner)]


def anisotropic(leaf: BSDFSpec) -> bool:
    """Whether ``leaf``'s response depends on the tangent's direction: distinct or
    textured ``alpha_u``/``alpha_v``, principled's ``anisotropic``."""
    p = leaf.params
    if leaf.kind in ("roughconductor", "roughdielectric"):
        au, av = p.get("alpha_u"), p.get("alpha_v")
        if au is None and av is None:
            return False
        return isinstance(au, Texture) or isinstance(av, Texture) or au != av
    if leaf.kind in ("principled", "principledthin"):
        return bsdf_kinds.given(p.get("anisotropic"))
    return False


@dataclass
class Slot:
    """Slot ``j`` of every material (only when ``K > 1``): per material its row
    (:data:`NONE` where it has fewer components), constant weight, weight texture
    and whether the weight is one minus the texture."""

    row: np.ndarray  # uint32, per material
    weight: np.ndarray  # float32, per material
    texture: np.ndarray | None  # uint32 texture ids per material (NONE: constant); None when none has one
    complement: np.ndarray  # bool, per material
    kinds: list[str]  # the lobe kinds in this slot
    partial: bool  # some material has no component here


@dataclass
class Field:
    """One parameter a present kind's lobe reads, per row: ``type`` ``"rgb"`` (values
    ``(rows, 3)`` float64), ``"float"`` (``(rows,)`` float32) or ``("table", N)``
    (``rows * N`` float32, row-major); ``texture``: per row a texture id or
    :data:`NONE` (None when no row has one; tables have none). A textured row's
    constant is the texture's fallback."""

    type: Any
    values: np.ndarray
    texture: np.ndarray | None = None


@dataclass
class Perturbations:
    """The normal and bump maps, per row (only in scenes that have them): ``code``
    0 (none), 1 (normalmap), 2 (bumpmap); ``texture`` the map's texture id;
    ``constant`` a normal map's constant RGB (None when every map is a texture);
    ``scale`` the bump scale (None without bump maps). ``flip``, ``shadow`` and
    ``inner`` (``flip_invalid_normals``, ``use_shadowing_function``, a ``twosided``
    inside the perturbation) are one bool when the same for every perturbed row,
    else a per-row array."""

    code: np.ndarray
    texture: np.ndarray
    constant: np.ndarray | None
    scale: np.ndarray | None
    flip: bool | np.ndarray
    shadow: bool | np.ndarray
    inner: bool | np.ndarray
    has_normal: bool
    has_bump: bool


@dataclass
class MaterialLayout:
    """A scene's materials as the device uploads them (see the module docs)."""

    specs: list[BSDFSpec]  # per material; an unused material is black diffuse
    notes: list[str]  # messages of the used materials' specs
    components: list[list[Component]]  # per material
    rows: list[Component]  # every component, material by material
    row_material: np.ndarray  # uint32 per row: its material
    row_slot: np.ndarray  # uint32 per row: its slot in its material
    K: int  # the most components of one material
    kinds: list[str]  # the lobe kinds present, sorted
    kind: np.ndarray  # uint32 per row: index into kinds
    material_kinds: list[tuple[str, ...]]  # per material, its components' kinds
    rows_of: dict[str, list[int]]  # kind -> its rows
    two_sided: dict[str, bool | np.ndarray]  # kind -> sidedness, or per row when mixed
    tangents: int  # 0: no tangent frames; 1: dp/du; 2: also dp/dv (bump maps)
    slots: list[Slot] = field(default_factory=list)
    fields: dict[str, Field] = field(default_factory=dict)
    textures: list = field(default_factory=list)  # an image's Path, or the Texture itself
    emission: np.ndarray = field(default_factory=lambda: np.zeros((1, 3)))  # (materials, 3)
    has_emission: bool = False
    emission_texture: np.ndarray | None = None  # uint32 per material, or None
    perturbed_kinds: list[str] = field(default_factory=list)  # kinds with a perturbed row
    perturb: Perturbations | None = None
    material_delta: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))  # only Dirac lobes

    @classmethod
    def build(cls, scene: Scene, mode: str, lobe: Callable[[str], Any]) -> MaterialLayout:
        """The layout of ``scene``'s materials read in ``mode`` (``--bsdf``), with
        ``lobe(kind)`` giving each kind's ``FIELDS``, ``DELTA`` and ``derive``.
        Materials no primitive uses stay out (black diffuse, no notes). A tree the
        layout cannot hold, or a parameter ``derive`` refuses, is a
        :class:`~drpt.errors.SceneError` naming the material's place (its :class:`~drpt.errors.Loc`)."""
        used = np.zeros(len(scene.materials), bool)
        for prims in (scene.triangles, scene.spheres, scene.planes):
            used[np.asarray(prims.material, np.int64)] = True
        black = BSDFSpec("diffuse", {"kd": (0.0, 0.0, 0.0)})
        specs = interpret_scene(scene, mode)
        notes = [located(n, s.loc) for s, u in zip(specs, used) if u for n in s.notes]
        specs = [s if u else black for s, u in zip(specs, used)]
        comps: list[list[Component]] = []
        for s, m in zip(specs, scene.materials):
            try:
                comps.append(flatten(s) or [Component(black, False)])
            except ValueError as e:
                raise SceneError(m.loc or Loc(scene.path), f"material '{m.name}': {e}") from None
        if not comps:
            comps = [[Component(black, False)]]
        rows = [c for cs in comps for c in cs]
        kinds = sorted({c.leaf.kind for c in rows})
        rows_of = {k: [i for i, c in enumerate(rows) if c.leaf.kind == k] for k in kinds}
        perturbs = {c.perturb.kind for c in rows if c.perturb is not None}
        lay = cls(
            specs=specs, notes=notes, components=comps, rows=rows,
            row_material=np.array([m for m, cs in enumerate(comps) for _ in cs], np.uint32),
            row_slot=np.array([j for cs in comps for j in range(len(cs))], np.uint32),
            K=max(len(c) for c in comps), kinds=kinds,
            kind=np.array([kinds.index(c.leaf.kind) for c in rows], np.uint32),
            material_kinds=[tuple(sorted({c.leaf.kind for c in cs})) for cs in comps],
            rows_of=rows_of,
            two_sided={k: _uniform([rows[i].two_sided for i in r], [c.two_sided for c in rows])
                       for k, r in rows_of.items()},
            # dp/du (frames follow it, as Mitsuba's) only where some BSDF depends on the
            # tangent's direction; dp/dv too for bump maps
            tangents=2 if "bumpmap" in perturbs else 1 if (perturbs or any(anisotropic(c.leaf) for c in rows))
            else 0,
            emission=np.array([m.emission for m in scene.materials], float) if scene.materials
            else np.zeros((1, 3)),
            has_emission=any(m.is_emissive for m in scene.materials),
        )
        lobes = {k: lobe(k) for k in kinds}
        # texture ids: every texture the layout references, in first-use order (fields,
        # slot weights, emission, perturbations)
        if lay.K > 1:
            start = np.cumsum([0] + [len(c) for c in comps[:-1]])
            for j in range(lay.K):
                row = np.array([start[m] + j if j < len(cs) else NONE for m, cs in enumerate(comps)], np.int64)
                lay.slots.append(Slot(
                    row=row.astype(np.uint32),
                    weight=np.array([cs[j].weight if j < len(cs) else 0.0 for cs in comps], np.float32),
                    texture=None,
                    complement=np.array([cs[j].complement if j < len(cs) else False for cs in comps], bool),
                    kinds=sorted({rows[r].leaf.kind for r in row if r != NONE}),
                    partial=bool((row == NONE).any())))
        lay._fill_fields(lobes, scene)
        for j, slot in enumerate(lay.slots):
            ids = [lay.texture_id(cs[j].weight_texture) if j < len(cs) and cs[j].weight_texture is not None
                   else NONE for cs in comps]
            slot.texture = np.array(ids, np.int64).astype(np.uint32) if any(i != NONE for i in ids) else None
        etex = [lay.texture_id(m.emission_texture) if getattr(m, "emission_texture", None) is not None else NONE
                for m in scene.materials]
        lay.emission_texture = np.array(etex, np.int64).astype(np.uint32) if any(i != NONE for i in etex) else None
        lay.perturbed_kinds = sorted({c.leaf.kind for c in rows if c.perturb is not None})
        if lay.perturbed_kinds:
            lay.perturb = lay._perturbations()
        lay.material_delta = np.array([all(lobes[c.leaf.kind].DELTA for c in cs) for cs in comps], bool)
        return lay

    def texture_id(self, t: Texture) -> int:
        """The index of ``t`` in :attr:`textures`, added there on first use: an MTL-style
        image by its file (two materials' ``map_Kd`` of one file share it), a procedural
        texture or an image with options as itself."""
        key = t.path if t.is_plain and not isinstance(t, Checkerboard) else t
        if key not in self.textures:
            self.textures.append(key)
        return self.textures.index(key)

    def _fill_fields(self, lobes: dict[str, Any], scene: Scene) -> None:
        """:attr:`fields`: each present kind's ``FIELDS`` per row, from the leaf's
        parameters and the lobe's ``derive``."""
        values: list[dict] = [dict(c.leaf.params) for c in self.rows]
        for k in self.kinds:
            derive = getattr(lobes[k], "derive", None)
            if derive is None:
                continue
            for i in self.rows_of[k]:
                try:
                    values[i].update(derive(dict(values[i])))
                except ValueError as e:
                    raise SceneError(self.rows[i].leaf.loc or Loc(scene.path), str(e)) from None
        types: dict[str, Any] = {}
        for k in self.kinds:
            for name, t in lobes[k].FIELDS.items():
                if types.setdefault(name, t) != t:  # one namespace for every kind's fields
                    raise TypeError(f"BSDF field '{name}' of '{k}' is {t}, another kind's is {types[name]}")
        for name, t in types.items():
            vals = [v.get(name) for v in values]
            if isinstance(t, tuple):  # ("table", N)
                n = int(t[1])
                arr = np.zeros((len(vals), n), np.float32)
                for i, v in enumerate(vals):
                    if v is not None:
                        arr[i] = np.asarray(v, np.float32).reshape(n)
                self.fields[name] = Field(t, arr.ravel())
                continue
            width = 3 if t == "rgb" else 1
            arr = np.zeros((len(vals), width))
            tid = np.full(len(vals), NONE, np.int64)
            for i, v in enumerate(vals):
                if isinstance(v, Texture):
                    tid[i] = self.texture_id(v)
                    v = v.fallback
                if v is None or isinstance(v, (str, bool)):
                    continue
                arr[i] = np.broadcast_to(np.asarray(v, float), (width,))
            self.fields[name] = Field(t, arr if width == 3 else arr[:, 0].astype(np.float32),
                                      tid.astype(np.uint32) if (tid != NONE).any() else None)

    def _perturbations(self) -> Perturbations:
        pert = [c.perturb for c in self.rows]
        kinds = {p.kind for p in pert if p is not None}
        values = [None if p is None else p.params[bsdf_kinds.PERTURBING[p.kind]] for p in pert]
        ids = [self.texture_id(v) if isinstance(v, Texture) else NONE for v in values]
        consts = [(0.5, 0.5, 1.0) if not isinstance(v, tuple) else v for v in values]
        has_bump = "bumpmap" in kinds

        def flag(values):
            got = {v for v, p in zip(values, pert) if p is not None}
            return got.pop() if len(got) == 1 else np.array(values, bool)

        return Perturbations(
            code=np.array([0 if p is None else 1 if p.kind == "normalmap" else 2 for p in pert], np.uint32),
            texture=np.array(ids, np.int64).astype(np.uint32),
            constant=np.array(consts, float) if any(isinstance(v, tuple) for v in values) else None,
            scale=np.array([float(p.params["scale"]) if p is not None and p.kind == "bumpmap" else 0.0
                            for p in pert], np.float32) if has_bump else None,
            flip=flag([p is not None and bool(p.params["flip_invalid_normals"]) for p in pert]),
            shadow=flag([p is not None and bool(p.params["use_shadowing_function"]) for p in pert]),
            inner=flag([c.two_inner for c in self.rows]),
            has_normal="normalmap" in kinds, has_bump=has_bump)

    def specs_of(self, kind: str) -> list[BSDFSpec]:
        """The leaf specs of ``kind`` (one per row of that kind), for trace-time choices."""
        return [self.rows[i].leaf for i in self.rows_of.get(kind, [])]


def _uniform(flags: list[bool], per_row: list[bool]) -> bool | np.ndarray:
    """One bool when ``flags`` agree, else the per-row array."""
    return flags[0] if len(set(flags)) == 1 else np.array(per_row, bool)
