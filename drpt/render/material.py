"""Materials on the device: per-material BSDF trees flattened into lobes, and the dispatch.

Each scene material is a :class:`~drpt.materials.spec.BSDFSpec` tree
(:func:`drpt.materials.interpret.interpret_scene` decides it, the same function the
Mitsuba exporter uses). The table flattens every tree into *components*:
leaf lobes, each with a weight and a sidedness.

* ``twosided(x)``: ``x``'s components see the shading frame flipped to the
  viewer's side (Mitsuba's ``twosided``); all other components see the
  unflipped frame (``+z`` = shading normal = outside) and, being one-sided,
  are black from behind unless they transmit.
* ``blendbsdf(w; a, b)``: ``a``'s components weighted by ``1 - w``, ``b``'s by ``w``.
* ``mask(o; x)``: a ``null`` component (the ray passes straight through)
  weighted ``1 - o``, ``x``'s components by ``o``.

Weights are constants or one texture (times a constant) per component. A
material's components occupy *slots* ``0 .. K-1`` (``K`` = the most any
material has). ``f`` and ``pdf`` are the weighted sums over the slots,
exactly Mitsuba's ``blendbsdf``/``mask`` ``eval`` and ``pdf``. Sampling
picks a slot by its weight (rescaling ``u1``), samples that component, and
for a smooth sample returns the whole mixture's ``f / pdf`` and ``pdf``
(one-sample MIS over the components: lower variance than the chosen
component's own ratio, same expectation); a Dirac sample keeps the
component's own weight (its selection probability cancels).

Model only what the scene requires: only the lobe kinds present are traced
(each under its own lane mask, merged with ``select``), only their fields
are uploaded, a field is looked up in a texture only when some material
gives it one, a scene where every material is one component (the usual
case) has ``K = 1`` with no weights and no slot gathers, and a kind whose
components are all two-sided (or all one-sided) flips without a per-lane
test.

Each lobe module (:mod:`drpt.render.bsdf`) reads its parameters through
:meth:`MaterialTable.value`, :meth:`MaterialTable.table_lerp` and decides
trace-time choices from :meth:`MaterialTable.specs_of`. Emission is
per material and one-sided: it radiates only toward the side its shading
normal points to, as Mitsuba's ``area`` emitter does.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import drjit as dr
import numpy as np
from drjit.auto import Array2f, Array3f, Bool, Float, UInt32

from ..materials import bsdf_kinds
from ..materials.interpret import interpret_scene
from ..materials.spec import BSDFSpec, Checkerboard, Texture
from ..scene.model import Scene
from . import perturb
from .bsdf import BSDFSample, lobe
from .perturb import PerturbedFrame
from .surface import Interaction, _vec
from .warp import Frame

NONE = 0xFFFFFFFF


@dataclass
class _Component:
    leaf: BSDFSpec
    two_sided: bool
    weight: float = 1.0
    weight_texture: Texture | None = None  # weight *= tex (or 1 - tex when complement)
    complement: bool = False
    perturb: BSDFSpec | None = None  # the normalmap / bumpmap around the leaf
    two_inner: bool = False  # a twosided between the perturbation and the leaf


def _flatten(spec: BSDFSpec, two_sided: bool = False, c: _Component | None = None) -> list[_Component]:
    """The components of ``spec`` (a complete tree), in depth-first order. ``two_sided``
    (and a component's ``two_sided``) is a ``twosided`` around the component's
    perturbation, if any (``two_inner``: one inside it)."""
    c = c or _Component(spec, False)
    if spec.kind == "twosided":
        if len(spec.children) == 2:
            raise ValueError("twosided with a different BSDF on each side is not supported")
        if c.perturb is not None:
            cc = copy.copy(c)
            cc.two_inner = True
            return _flatten(spec.children[0], two_sided, cc)
        return _flatten(spec.children[0], True, c)
    if spec.kind in bsdf_kinds.PERTURBING:
        if c.perturb is not None:
            raise ValueError(f"{spec.kind} inside {c.perturb.kind} is not supported")
        cc = copy.copy(c)
        v = spec.params.get(bsdf_kinds.PERTURBING[spec.kind])
        if isinstance(v, Texture) or (spec.kind == "normalmap" and isinstance(v, tuple)):
            cc.perturb = spec  # (a bump texture dropped for want of uvs perturbs nothing)
        return _flatten(spec.children[0], two_sided, cc)
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
            out += _flatten(child, two_sided, cc)
        return out
    return [_Component(spec, two_sided, c.weight, c.weight_texture, c.complement, c.perturb, c.two_inner)]


def _anisotropic(leaf: BSDFSpec) -> bool:
    """Whether ``leaf``'s response depends on the tangent's direction (host side):
    distinct or textured ``alpha_u``/``alpha_v``, principled's ``anisotropic``."""
    p = leaf.params
    if leaf.kind in ("roughconductor", "roughdielectric"):
        au, av = p.get("alpha_u"), p.get("alpha_v")
        if au is None and av is None:
            return False
        return isinstance(au, Texture) or isinstance(av, Texture) or au != av
    if leaf.kind in ("principled", "principledthin"):
        return bsdf_kinds.given(p.get("anisotropic"))
    return False


def tangent_frame(n: Array3f, dp_du: Array3f) -> Frame:
    """Mitsuba's shading frame (``SurfaceInteraction::initialize_sh_frame``): ``s`` is
    ``dp/du`` made orthogonal to ``n``, ``t = n x s``; where ``dp/du`` is 0 (or along
    ``n``), :class:`Frame`'s basis of ``n`` alone."""
    base = Frame(n)
    s = dr.fma(n, -dr.dot(n, dp_du), dp_du)
    len2 = dr.squared_norm(s)
    ok = len2 > 1e-30
    s = dr.select(ok, s * dr.rsqrt(dr.select(ok, len2, 1.0)), base.s)
    return Frame.from_axes(s, dr.cross(n, s), n)


def _z_flipped(frame: Frame, flip) -> Frame:
    """``frame`` seen from behind where ``flip``: ``(s, t, -n)``, Mitsuba's ``twosided``
    (it negates the local ``z`` and keeps the tangents)."""
    return Frame.from_axes(frame.s, frame.t, dr.select(flip, -frame.n, frame.n))


def _luminance(c: Array3f) -> Float:
    return 0.212671 * c.x + 0.715160 * c.y + 0.072169 * c.z


class MaterialTable:
    def __init__(self, scene: Scene, mode: str = "auto"):
        # Materials no primitive uses stay out of the kernels entirely.
        used = np.zeros(len(scene.materials), bool)
        for prims in (scene.triangles, scene.spheres, scene.planes):
            used[np.asarray(prims.material, np.int64)] = True
        black = BSDFSpec("diffuse", {"kd": (0.0, 0.0, 0.0)})
        specs = interpret_scene(scene, mode)
        self.specs: list[BSDFSpec] = [s if u else black for s, u in zip(specs, used)]
        self.notes = [n for s, u in zip(specs, used) if u for n in s.notes]
        comps: list[list[_Component]] = []
        for s, m in zip(self.specs, scene.materials):
            try:
                comps.append(_flatten(s) or [_Component(black, False)])
            except ValueError as e:
                from ..errors import SceneError

                raise SceneError(m.origin or scene.path, None, f"material '{m.name}': {e}") from None
        if not comps:
            comps = [[_Component(black, False)]]
        self.K = max(len(c) for c in comps)
        # the lobe kinds of each material's components (host side: the wavefront
        # integrator's shading queues group materials by them)
        self.material_kinds: list[tuple[str, ...]] = [tuple(sorted({c.leaf.kind for c in cs})) for cs in comps]
        # rows: every component of every material, material by material
        self.rows: list[_Component] = [c for cs in comps for c in cs]
        self.kinds = sorted({c.leaf.kind for c in self.rows})
        # interactions carry dp/du (frames follow it, as Mitsuba's) only where some BSDF
        # depends on the tangent's direction; a scene without one traces no tangent code
        perturbs = {c.perturb.kind for c in self.rows if c.perturb is not None}
        self.tangents = 2 if "bumpmap" in perturbs else 1 if (
            perturbs or any(_anisotropic(c.leaf) for c in self.rows)) else 0
        self.lobes = {k: lobe(k) for k in self.kinds}
        self._rows_of = {k: [i for i, c in enumerate(self.rows) if c.leaf.kind == k] for k in self.kinds}
        kind_idx = np.array([self.kinds.index(c.leaf.kind) for c in self.rows], np.uint32)
        self.kind = UInt32(kind_idx)
        self.emission = _vec(np.array([m.emission for m in scene.materials], float)) \
            if scene.materials else _vec(np.zeros((1, 3)))
        self.has_emission = any(m.is_emissive for m in scene.materials)

        # sidedness, per kind: True / False when uniform, else a per-row array
        self._two: dict[str, bool | Bool] = {}
        for k, rows in self._rows_of.items():
            flags = {self.rows[i].two_sided for i in rows}
            if len(flags) == 1:
                self._two[k] = flags.pop()
            else:
                self._two[k] = Bool(np.array([c.two_sided for c in self.rows], bool))

        # slots (only when some material has several components)
        self._slots = []
        if self.K > 1:
            start = np.cumsum([0] + [len(c) for c in comps[:-1]])
            for j in range(self.K):
                row = np.array([start[m] + j if j < len(cs) else NONE for m, cs in enumerate(comps)], np.int64)
                w = np.array([cs[j].weight if j < len(cs) else 0.0 for cs in comps], np.float32)
                texs = [cs[j].weight_texture if j < len(cs) else None for cs in comps]
                comp = np.array([cs[j].complement if j < len(cs) else False for cs in comps], bool)
                kinds = sorted({self.rows[r].leaf.kind for r in row if r != NONE})
                self._slots.append({"row": UInt32(row.astype(np.uint32)), "w": Float(w), "tex": texs,
                                    "complement": Bool(comp), "kinds": kinds,
                                    "partial": bool((row == NONE).any())})

        # per-row fields of the kinds present
        values: list[dict] = [dict(c.leaf.params) for c in self.rows]
        for k in self.kinds:
            derive = getattr(self.lobes[k], "derive", None)
            if derive is None:
                continue
            for i in self._rows_of[k]:
                try:
                    values[i].update(derive(dict(values[i])))
                except ValueError as e:
                    from ..errors import SceneError

                    raise SceneError(self.rows[i].leaf.origin or scene.path, None, str(e)) from None
        self._fields: dict[str, tuple] = {}
        for k in self.kinds:
            for name, t in self.lobes[k].FIELDS.items():
                if self._fields.setdefault(name, t) != t:  # one namespace for every kind's fields
                    raise TypeError(f"BSDF field '{name}' of '{k}' is {t}, another kind's is "
                                    f"{self._fields[name]}")
        textures: list = []

        def tex_id(t: Texture) -> int:
            # an MTL-style image by its file; a procedural texture or an image with options as itself
            key = t.path if t.is_plain and not isinstance(t, Checkerboard) else t
            if key not in textures:
                textures.append(key)
            return textures.index(key)

        self._data: dict[str, object] = {}
        self._tex: dict[str, UInt32] = {}
        for name, t in self._fields.items():
            vals = [v.get(name) for v in values]
            if isinstance(t, tuple):  # ("table", N)
                n = int(t[1])
                arr = np.zeros((len(vals), n), np.float32)
                for i, v in enumerate(vals):
                    if v is not None:
                        arr[i] = np.asarray(v, np.float32).reshape(n)
                self._data[name] = Float(arr.ravel())
                continue
            width = 3 if t == "rgb" else 1
            arr = np.zeros((len(vals), width))
            tid = np.full(len(vals), NONE, np.int64)
            for i, v in enumerate(vals):
                if isinstance(v, Texture):
                    tid[i] = tex_id(v)
                    v = v.fallback
                if v is None or isinstance(v, (str, bool)):
                    continue
                arr[i] = np.broadcast_to(np.asarray(v, float), (width,))
            self._data[name] = _vec(arr) if width == 3 else Float(arr[:, 0].astype(np.float32))
            if (tid != NONE).any():
                self._tex[name] = UInt32(tid.astype(np.uint32))
        for slot in self._slots:
            ids = [tex_id(t) if t is not None else NONE for t in slot["tex"]]
            slot["tex"] = UInt32(np.array(ids, np.int64).astype(np.uint32)) if any(
                i != NONE for i in ids) else None

        # textured emission (Mitsuba's area radiance bitmap), by material
        etex = [tex_id(m.emission_texture) if getattr(m, "emission_texture", None) is not None else NONE
                for m in scene.materials]
        self._emit_tex = UInt32(np.array(etex, np.int64).astype(np.uint32)) if any(
            i != NONE for i in etex) else None

        # Perturbed frames (normalmap, bumpmap): per row, only in scenes that have them
        self._pkinds = sorted({c.leaf.kind for c in self.rows if c.perturb is not None})
        if self._pkinds:
            self._setup_perturb(tex_id)

        # Textures: one set for every textured field and weight.
        self.textures = None
        if textures:
            from .texture import TextureSet

            self.textures = TextureSet(textures, scene.triangles)
        # materials made only of Dirac lobes (glass, mirrors): Whitted follows them
        delta = [all(self.lobes[c.leaf.kind].DELTA for c in cs) for cs in comps]
        self._all_delta = all(delta)
        self._mat_delta = None if (self._all_delta or not any(delta)) else Bool(np.array(delta, bool))
        self._any_delta = any(delta)

    _only: tuple[str, ...] | None = None  # a restricted view's kinds (see restricted)

    def _setup_perturb(self, tex_id) -> None:
        rows = self.rows
        pert = [c.perturb for c in rows]
        kinds = {p.kind for p in pert if p is not None}
        self._has_normal, self._has_bump = "normalmap" in kinds, "bumpmap" in kinds
        code = np.array([0 if p is None else 1 if p.kind == "normalmap" else 2 for p in pert], np.uint32)
        self._p_code = UInt32(code)
        values = [None if p is None else p.params[bsdf_kinds.PERTURBING[p.kind]] for p in pert]
        ids = [tex_id(v) if isinstance(v, Texture) else NONE for v in values]
        self._p_tex = UInt32(np.array(ids, np.int64).astype(np.uint32))
        # a normal map's constant value (a texture's: its lookup replaces it)
        consts = [(0.5, 0.5, 1.0) if not isinstance(v, tuple) else v for v in values]
        self._p_const = _vec(np.array(consts, float)) if any(isinstance(v, tuple) for v in values) else None
        if self._has_bump:
            self._p_scale = Float(np.array([float(p.params["scale"]) if p is not None and p.kind == "bumpmap"
                                            else 0.0 for p in pert], np.float32))

        def flag(name: str, values):
            got = {v for v, p in zip(values, pert) if p is not None}
            if len(got) == 1:
                return got.pop()
            return Bool(np.array(values, bool))

        self._p_flip = flag("flip", [p is not None and bool(p.params["flip_invalid_normals"]) for p in pert])
        self._p_shadow = flag("shadow", [p is not None and bool(p.params["use_shadowing_function"])
                                         for p in pert])
        self._p_inner = flag("inner", [c.two_inner for c in rows])

    def _perturbed(self, si: Interaction, row_si: Interaction, mask: Bool, outer: Frame,
                   sh_frame: Frame) -> PerturbedFrame:
        """The frame the lanes' perturbed components see (:mod:`drpt.render.perturb`);
        ``outer``: the interaction's frame as the component sees it (mirrored inside
        ``twosided`` from behind), ``sh_frame``: the interaction's own."""
        row = row_si.material
        code = dr.gather(UInt32, self._p_code, row, mask)
        tid = dr.gather(UInt32, self._p_tex, row, mask)
        wi_l = outer.to_local(si.wi)

        def rowflag(v):
            return v if isinstance(v, bool) else dr.gather(Bool, v, row, mask)

        flip = rowflag(self._p_flip)
        n, s = Array3f(0.0, 0.0, 1.0), Array3f(1.0, 0.0, 0.0)
        if self._has_normal:
            m = mask & (code == 1)
            if self._p_const is None:
                rgb = self.textures.lookup(tid, si.uv, m, si=si)
            else:
                rgb = dr.gather(Array3f, self._p_const, row, m)
                if self.textures is not None:
                    rgb = dr.select(tid != NONE, self.textures.lookup(tid, si.uv, m & (tid != NONE), si=si), rgb)
            nn = perturb.normalmap_normal(rgb)
            if flip is not False:
                nn = dr.select(flip, perturb.flip_invalid(nn, wi_l), nn)
            len2 = dr.squared_norm(nn)
            nn = dr.select(len2 > 1e-30, nn * dr.rsqrt(dr.select(len2 > 1e-30, len2, 1.0)),
                           Array3f(0.0, 0.0, 1.0))
            n = dr.select(m, nn, n)
            s = dr.select(m, perturb.normalmap_tangent(nn), s)
        if self._has_bump:
            m = mask & (code == 2)
            grad = self.textures.gradient(tid, si.uv, m) * dr.gather(Float, self._p_scale, row, m)
            nb = perturb.bump_normal(grad, si.ns, si.ng, si.dp_du, si.dp_dv, sh_frame)
            if flip is not False:
                nb = dr.select(flip, perturb.flip_invalid(nb, wi_l), nb)
            n = dr.select(m, nb, n)
            s = dr.select(m, perturb.bump_tangent(nb, si.dp_du), s)
        inner = rowflag(self._p_inner)
        mirror = None
        if inner is not False:
            mirror = inner & (dr.dot(wi_l, n) < 0.0)
        return PerturbedFrame(outer, n, s, mirror, rowflag(self._p_shadow))

    def restricted(self, kinds) -> MaterialTable:
        """A view of this table that traces only the lobes of ``kinds`` (same
        data, nothing uploaded again), for lanes whose materials have only
        components of those kinds: a wavefront shading queue runs only its
        BSDFs' code. With one kind and one component per material, no lane
        reads its kind."""
        view = copy.copy(self)
        view._only = tuple(k for k in self.kinds if k in set(kinds))
        return view

    # ------------------------------------------------------------------ parameters
    def specs_of(self, kind: str) -> list[BSDFSpec]:
        """The leaf specs of ``kind`` in the scene (host side), for trace-time choices."""
        return [self.rows[i].leaf for i in self._rows_of.get(kind, [])]

    def value(self, name: str, si: Interaction, active: Bool):
        """Field ``name`` of the lanes' components (``si.material`` is the row):
        Array3f for ``"rgb"``, Float for ``"float"``; a textured value is looked
        up at ``si.uv`` (a float field reads the texture's luminance, as
        Mitsuba's ``bitmap`` does for a scalar parameter)."""
        t = self._fields[name]
        cls = Array3f if t == "rgb" else Float
        v = dr.gather(cls, self._data[name], si.material, active)
        tid = self._tex.get(name)
        if tid is not None:
            ids = dr.gather(UInt32, tid, si.material, active)
            textured = active & (ids != NONE)
            looked = self.textures.lookup(ids, si.uv, textured, scalar=cls is not Array3f, si=si)
            v = dr.select(textured, looked if cls is Array3f else _luminance(looked), v)
        return v

    def table_lerp(self, name: str, si: Interaction, x: Float, active: Bool) -> Float:
        """Linear interpolation of the ``("table", N)`` field ``name`` of the lanes'
        components at ``x`` in [0, 1] (sample ``i`` at ``x = i / (N - 1)``; ``x``
        clamped)."""
        n = int(self._fields[name][1])
        pos = dr.clip(Float(x), 0.0, 1.0) * (n - 1)
        i0 = dr.minimum(UInt32(pos), n - 2)
        frac = pos - Float(i0)
        base = si.material * n + i0
        a = dr.gather(Float, self._data[name], base, active)
        b = dr.gather(Float, self._data[name], base + 1, active)
        return dr.fma(frac, b - a, a)

    # ------------------------------------------------------------------ emission
    def emitted(self, si: Interaction) -> Array3f:
        """Radiance leaving ``si`` toward ``si.wi`` (zero on back faces)."""
        if not self.has_emission:
            return Array3f(0.0)
        le = dr.gather(Array3f, self.emission, si.material, si.valid)
        if self._emit_tex is not None:
            le = self.textured_emission(si.material, si.uv, le, si.valid)
        front = si.valid & (dr.dot(si.ns, si.wi) > 0.0)
        return dr.select(front, le, 0.0)

    def textured_emission(self, material: UInt32, uv: Array2f, le: Array3f, active: Bool) -> Array3f:
        """``le`` where the material's emission is constant, its texture at OBJ ``uv`` where
        it has one (only traced for scenes with a textured emitter)."""
        ids = dr.gather(UInt32, self._emit_tex, material, active)
        textured = active & (ids != NONE)
        return dr.select(textured, self.textures.lookup(ids, uv, textured), le)

    def is_specular_only(self) -> bool:
        return all(m.DELTA for m in self.lobes.values())

    def is_delta(self, si: Interaction) -> Bool:
        """Lanes whose material has only Dirac lobes (glass, mirror)."""
        if not self._any_delta:
            return Bool(False)
        if self._all_delta:
            return Bool(si.valid)
        return si.valid & dr.gather(Bool, self._mat_delta, si.material, si.valid)

    def diffuse_color(self, si: Interaction, active: Bool) -> Array3f:
        """The diffuse color of the lanes' first component (its kind's ``COLOR``
        field, e.g. ``kd``), for the Whitted ambient term; 0 for kinds without one."""
        out = Array3f(0.0)
        for _, bsdf, mask, _, row_si in self._cases(si, 0):
            name = getattr(bsdf, "COLOR", None)
            if name is not None:
                out = dr.select(mask & active, self.value(name, row_si, mask & active), out)
        return out

    def albedo(self, si: Interaction, active: Bool) -> Array3f:
        """The diffuse reflectance (the ``albedo`` AOV, Mitsuba's
        ``eval_diffuse_reflectance``): per component, its kind's ``COLOR`` field (diffuse,
        plastic, Phong, ...), else ``pi f(wi, n)`` toward the normal on the viewer's side,
        0 for delta lobes; components weighted as the material blends them. A ``mask``'s
        pass-through is left out of the blend (Mitsuba's is its nested BSDF's)."""
        out = Array3f(0.0)
        up = Array3f(0.0, 0.0, 1.0)
        w_null = Float(0.0)
        for j in range(self.K):
            row_si, w, present = self._slot(si, j)
            for kind, bsdf, mask, frame, rsi in self._cases(si, j, row_si, present):
                m = mask & active
                name = getattr(bsdf, "COLOR", None)
                if name is not None:
                    a = self.value(name, rsi, m)
                elif kind == "null" and w is not None:
                    w_null = dr.select(m, w_null + w, w_null)
                    continue
                elif bsdf.DELTA:
                    continue
                else:
                    a = bsdf.eval(bsdf.params(self, rsi, m), frame.to_local(si.wi), up) * dr.pi
                out = dr.select(m, a if w is None else dr.fma(a, w, out), out)
        if "null" in self.kinds and self.K > 1:
            out = dr.select(w_null < 1.0, out / dr.maximum(1.0 - w_null, 1e-6), out)
        return out

    # ------------------------------------------------------------------ dispatch
    def _slot(self, si: Interaction, j: int):
        """(row-indexed interaction, weight or None, lanes with a component) of slot ``j``."""
        if self.K == 1:
            return si, None, si.valid
        s = self._slots[j]
        row = dr.gather(UInt32, s["row"], si.material, si.valid)
        present = si.valid & (row != NONE) if s["partial"] else si.valid
        w = dr.gather(Float, s["w"], si.material, present)
        if s["tex"] is not None:
            ids = dr.gather(UInt32, s["tex"], si.material, present)
            textured = present & (ids != NONE)
            t = _luminance(self.textures.lookup(ids, si.uv, textured, scalar=True, si=si))
            comp = dr.gather(Bool, s["complement"], si.material, present)
            w = dr.select(textured, w * dr.select(comp, 1.0 - t, t), w)
        row_si = copy.copy(si)
        row_si.material = row
        return row_si, dr.select(present, w, 0.0), present

    def _cases(self, si: Interaction, j: int | None = None, row_si=None, present=None):
        """(kind, lobe module, lane mask, local frame, row-indexed interaction) for each
        kind of slot ``j`` (all kinds when ``j`` is None: ``row_si`` given)."""
        if row_si is None:
            row_si, _, present = self._slot(si, j)
        kinds = self.kinds if (j is None or self.K == 1) else self._slots[j]["kinds"]
        if self._only is not None:
            kinds = [k for k in kinds if k in self._only]
        if len(self.kinds) == 1 or (self._only is not None and len(self._only) == 1 and self.K == 1):
            kind_of = None
        else:
            kind_of = dr.gather(UInt32, self.kind, row_si.material, present)
        flip = dr.dot(si.ns, si.wi) < 0.0
        flipped, plain = None, None
        tangent = None
        for kind in kinds:
            i = self.kinds.index(kind)
            mask = present if kind_of is None else present & (kind_of == i)
            two = self._two[kind]
            if si.dp_du is not None:  # frames follow dp/du; twosided mirrors z
                tangent = tangent or tangent_frame(si.ns, si.dp_du)
                if two is True:
                    frame = _z_flipped(tangent, flip)
                elif two is False:
                    frame = tangent
                else:
                    frame = _z_flipped(tangent, dr.gather(Bool, two, row_si.material, mask) & flip)
                if kind in self._pkinds:
                    frame = self._perturbed(si, row_si, mask, frame, tangent)
            elif two is True:
                flipped = flipped or Frame(dr.select(flip, -si.ns, si.ns))
                frame = flipped
            elif two is False:
                plain = plain or Frame(si.ns)
                frame = plain
            else:
                f2 = dr.gather(Bool, two, row_si.material, mask) & flip
                frame = Frame(dr.select(f2, -si.ns, si.ns))
            yield kind, self.lobes[kind], mask, frame, row_si

    # ------------------------------------------------------------------
    def eval_pdf(self, si: Interaction, wo: Array3f) -> tuple[Array3f, Float]:
        """``f * |cos|`` and the sampling density (solid angle) for world ``wo``."""
        f, pdf = Array3f(0.0), Float(0.0)
        for j in range(self.K):
            row_si, w, present = self._slot(si, j)
            for _, bsdf, mask, frame, rsi in self._cases(si, j, row_si, present):
                if bsdf.DELTA:
                    continue  # nothing to evaluate
                p = bsdf.params(self, rsi, mask)
                wi_l, wo_l = frame.to_local(si.wi), frame.to_local(wo)
                fj, pj = bsdf.eval(p, wi_l, wo_l), bsdf.pdf(p, wi_l, wo_l)
                if isinstance(frame, PerturbedFrame):
                    fac = frame.factor(wo)
                    fj, pj = fj * fac, dr.select(fac > 0.0, pj, 0.0)
                if w is None:
                    f = dr.select(mask, fj, f)
                    pdf = dr.select(mask, pj, pdf)
                else:
                    f = dr.select(mask, dr.fma(fj, w, f), f)
                    pdf = dr.select(mask, dr.fma(pj, w, pdf), pdf)
        return f, pdf

    def sample(self, si: Interaction, u1: Float, u2: Array2f) -> tuple[Array3f, BSDFSample]:
        """Sample a world direction; returns it and the local :class:`BSDFSample`."""
        if self.K == 1:
            row_si, present = si, si.valid
        else:
            # pick a slot by its weight, reuse u1 rescaled within it
            row = UInt32(NONE)
            lo, chosen_w = Float(0.0), Float(1.0)
            picked = Bool(False)
            for j in range(self.K):
                rsi, w, pres = self._slot(si, j)
                take = pres & ~picked & ((u1 < lo + w) | Bool(j == self.K - 1)) & (w > 0.0)
                row = dr.select(take, rsi.material, row)
                u_rest = dr.select(take, (u1 - lo) / dr.select(w > 0.0, w, 1.0), 0.0)
                chosen_w = dr.select(take, w, chosen_w)
                u1 = dr.select(take, dr.clip(u_rest, 0.0, 0.99999994), u1)
                picked |= take
                lo = lo + w
            row_si = copy.copy(si)
            row_si.material = row
            present = si.valid & picked
        out = BSDFSample()
        wo = Array3f(0.0, 0.0, 1.0)
        for _, bsdf, mask, frame, rsi in self._cases(si, None, row_si, present):
            p = bsdf.params(self, rsi, mask)
            bs = bsdf.sample(p, frame.to_local(si.wi), u1, u2)
            wo_j = frame.to_world(bs.wo)
            if isinstance(frame, PerturbedFrame):
                fac = frame.factor(wo_j)
                ok = fac > 0.0
                bs.weight, bs.pdf, bs.valid = bs.weight * fac, dr.select(ok, bs.pdf, 0.0), bs.valid & ok
            out = dr.select(mask, bs, out)
            wo = dr.select(mask, wo_j, wo)
        out.valid &= present
        if self.K > 1 and not self.is_specular_only():
            # a smooth sample weighs the whole mixture: f_mix / pdf_mix
            smooth = out.valid & ~out.delta
            f, pdf = self.eval_pdf(si, wo)
            ok = smooth & (pdf > 0.0)
            out.weight = dr.select(smooth, dr.select(ok, f / dr.select(ok, pdf, 1.0), 0.0), out.weight)
            out.pdf = dr.select(smooth, pdf, out.pdf)
            out.valid &= ~smooth | ok
        return wo, out
