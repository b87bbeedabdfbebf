"""Materials on the device: the host layout uploaded, and the dispatch over its lobes.

:class:`drpt.materials.layout.MaterialLayout` decides everything about a scene's
materials on the host: each BSDF tree flattened into weighted, one- or two-sided
components (*rows*), the slots of the materials with several, the per-row fields
(constants or texture references), the emission. :class:`MaterialTable` uploads
it and answers the integrators' queries over wide arrays. A lane's material
(``si.material``) selects its rows; the lobes read their fields at the row through
:class:`Rows`, so a row index is never passed off as a material.

``f`` and ``pdf`` are the weighted sums over the slots, exactly Mitsuba's
``blendbsdf``/``mask`` ``eval`` and ``pdf``. Sampling picks a slot by its weight
(rescaling ``u1``), samples that component, and for a smooth sample returns the
whole mixture's ``f / pdf`` and ``pdf`` (one-sample MIS over the components: lower
variance than the chosen component's own ratio, same expectation); a Dirac sample
keeps the component's own weight (its selection probability cancels).
:meth:`MaterialTable.eval_pdf_sample` answers both at one vertex in one dispatch (each
kind's fields and textures read once), the values of the two calls bit for bit.

Model only what the scene requires: only the lobe kinds present are traced,
only their fields are uploaded, a field is looked up in a texture only when some material
gives it one, a scene where every material is one component (the usual
case) has ``K = 1`` with no weights and no slot gathers, and a kind whose
components are all two-sided (or all one-sided) flips without a per-lane
test.

Dispatch over kinds: in a table (or :meth:`MaterialTable.restricted` view) with
several lobe kinds, each kind's whole case (its fields and textures, its shading
frame, ``eval``/``pdf``/``sample``) runs inside a symbolic ``dr.if_stmt`` on the
lanes of that kind (label ``drpt_bsdf_kind``): the LLVM backend branches per SIMD
packet, so a packet pays only for the kinds its lanes have, instead of every
lane evaluating every kind under a mask. :attr:`MaterialTable.dispatch`
``"masked"`` selects the other way (every kind traced for every lane, merged
with ``select``), for A/B measurements and tests; both compute the same values
from the same random numbers, so their images are bit-identical. A table with
one kind has no branch either way (its kernel is the same).

Each lobe module (:mod:`drpt.render.bsdf`) reads its parameters through
:meth:`Rows.value`, :meth:`Rows.table_lerp` and decides trace-time choices
from :meth:`Rows.specs_of`. Emission is per material and one-sided: it radiates
only toward the side its shading normal points to, as Mitsuba's ``area`` emitter
does.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import dataclass

import drjit as dr
import numpy as np
from drjit.auto import Array2f, Array3f, Bool, Float, UInt32

from ..materials.layout import NONE, MaterialLayout
from ..materials.spec import BSDFSpec
from ..scene.model import Scene
from . import perturb
from .bsdf import BSDF, BSDFSample, lobe
from .perturb import PerturbedFrame
from .surface import Interaction
from .tables import Table, gather
from .texture import TextureSet
from .warp import Frame


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


def _among(ids) -> tuple[int, ...]:
    """The texture ids an index array references (:data:`NONE` left out), host side."""
    a = np.asarray(ids, np.int64)
    return tuple(int(i) for i in np.unique(a[a != NONE]))


def _flag(v):
    """A layout flag on the device: a Python bool stays one (decided at trace time), per-row
    flags a :class:`~drpt.render.tables.Table` of ``Bool``."""
    return v if isinstance(v, bool) else Table(Bool, v)


@dataclass
class _Slot:
    """:class:`drpt.materials.layout.Slot` on the device (tables indexed by material, read
    with :func:`drpt.render.tables.gather`)."""

    row: Table  # UInt32
    weight: Table  # Float
    texture: UInt32 | None
    complement: Table  # Bool
    kinds: list[str]
    partial: bool
    among: tuple[int, ...] | None  # the texture ids of the weights


@dataclass
class _Case:
    """One lobe kind of a slot, as :meth:`MaterialTable._cases` yields it: its lanes
    (``mask``), their rows, and ``frame()``, the lanes' local shading frame as that kind
    sees it (traced where it is called: inside the kind's branch when ``branched``)."""

    kind: str
    bsdf: BSDF
    mask: Bool
    rows: Rows
    frame: Callable[[], Frame]
    branched: bool  # the case runs in its own dr.if_stmt (MaterialTable.dispatch "kinds")

    def run(self, fn: Callable[..., tuple], state: tuple, lanes: Bool | None = None) -> tuple:
        """``fn(*state)``, the new state: ``fn`` traces the case and merges its values into
        ``state`` on its lanes itself (``dr.select``), so that the masked dispatch is ``fn``
        alone; a branched case runs it in a symbolic ``dr.if_stmt`` on ``lanes`` (default
        :attr:`mask`; the other lanes keep ``state``)."""
        if not self.branched:
            return fn(*state)
        return dr.if_stmt(state, self.mask if lanes is None else lanes, fn, lambda *old: old,
                          label="drpt_bsdf_kind")


class Rows:
    """The lanes' rows of a :class:`MaterialTable` (``row``: UInt32, a row of the
    layout per lane): the ``table`` a lobe's ``params(table, si, active)`` reads
    its fields from, at ``row``, with textures looked up at ``si``."""

    __slots__ = ("table", "row")

    def __init__(self, table: MaterialTable, row: UInt32):
        self.table, self.row = table, row

    def value(self, name: str, si: Interaction, active: Bool):
        """Field ``name`` of the lanes' rows: Array3f for ``"rgb"``, Float for
        ``"float"``; a textured value is looked up at ``si.uv`` (a float field reads
        the texture's luminance, as Mitsuba's ``bitmap`` does for a scalar parameter)."""
        t = self.table._types[name]
        cls = Array3f if t == "rgb" else Float
        v = gather(cls, self.table._data[name], self.row, active)
        tid = self.table._tex.get(name)
        if tid is not None:
            ids = gather(UInt32, tid, self.row, active)
            textured = active & (ids != NONE)
            looked = self.table.textures.lookup(ids, si.uv, textured, scalar=cls is not Array3f, si=si,
                                                among=self.table._tex_among[name])
            v = dr.select(textured, looked if cls is Array3f else _luminance(looked), v)
        return v

    def table_lerp(self, name: str, si: Interaction, x: Float, active: Bool) -> Float:
        """Linear interpolation of the ``("table", N)`` field ``name`` of the lanes'
        rows at ``x`` in [0, 1] (sample ``i`` at ``x = i / (N - 1)``; ``x`` clamped)."""
        n = int(self.table._types[name][1])
        pos = dr.clip(Float(x), 0.0, 1.0) * (n - 1)
        i0 = dr.minimum(UInt32(pos), n - 2)
        frac = pos - Float(i0)
        base = self.row * n + i0
        a = gather(Float, self.table._data[name], base, active)
        b = gather(Float, self.table._data[name], base + 1, active)
        return dr.fma(frac, b - a, a)

    def specs_of(self, kind: str) -> list[BSDFSpec]:
        """The leaf specs of ``kind`` in the scene (host side), for trace-time choices."""
        return self.table.specs_of(kind)


class MaterialTable:
    """A scene's :class:`~drpt.materials.layout.MaterialLayout` on the device, and the
    BSDF and emission queries over it."""

    def __init__(self, scene: Scene, mode: str = "auto"):
        lay = self.layout = MaterialLayout.build(scene, mode, lobe)
        self.notes = lay.notes
        self.K = lay.K
        # the lobe kinds of each material's components (host side: the wavefront
        # integrator's shading queues group materials by them)
        self.material_kinds = lay.material_kinds
        self.kinds = lay.kinds
        # interactions carry dp/du (frames follow it, as Mitsuba's) only where some BSDF
        # depends on the tangent's direction; a scene without one traces no tangent code
        self.tangents = lay.tangents
        self.lobes = {k: lobe(k) for k in self.kinds}
        # (small per-material and per-row tables: read as literals where they are few,
        # drpt.render.tables)
        self.kind = Table(UInt32, lay.kind)
        self.emission = Table(Array3f, lay.emission)
        self.has_emission = lay.has_emission
        # per material: whether it emits (Mitsuba's shape with an area emitter), for
        # hide_emitters' skipping of area emitters along camera rays
        if lay.has_emission:
            glows = lay.emission.max(axis=1) > 0.0
            if lay.emission_texture is not None:
                glows = glows | (lay.emission_texture != NONE)
            self._emissive = Table(Bool, glows)
        # sidedness, per kind: True / False when uniform, else a per-row array
        self._two = {k: _flag(v) for k, v in lay.two_sided.items()}
        # slots (only when some material has several components); slots whose weights read
        # the same textures (a mask's opacity and its pass-through's one minus it) share one
        # array, so that their lookups are one (:meth:`_slot`)
        uploaded: list[tuple[np.ndarray, UInt32]] = []

        def texture_ids(a):
            for b, ids in uploaded:
                if np.array_equal(a, b):
                    return ids
            uploaded.append((a, UInt32(a)))
            return uploaded[-1][1]

        self._slots = [_Slot(Table(UInt32, sl.row), Table(Float, sl.weight),
                             None if sl.texture is None else texture_ids(sl.texture), Table(Bool, sl.complement),
                             sl.kinds, sl.partial, None if sl.texture is None else _among(sl.texture))
                       for sl in lay.slots]
        # materials whose slots need reading (several components, or one whose weight is
        # not exactly 1): only their lanes compute the slots (:meth:`_slots_at`); None
        # where every material's do
        self._multi = None
        if lay.slots:
            n_comp = np.array([len(cs) for cs in lay.components])
            multi = (n_comp > 1) | (lay.slots[0].weight != 1.0)
            if lay.slots[0].texture is not None:
                multi |= lay.slots[0].texture != NONE
            self._multi = None if multi.all() else Table(Bool, multi)
        # per-row fields of the kinds present
        self._types = {name: f.type for name, f in lay.fields.items()}
        self._data: dict[str, object] = {}
        self._tex: dict[str, UInt32] = {}
        self._tex_among: dict[str, tuple[int, ...]] = {}  # per textured field, the ids it references
        for name, f in lay.fields.items():
            self._data[name] = Table(Array3f if f.type == "rgb" else Float, f.values)
            if f.texture is not None:
                self._tex[name] = UInt32(f.texture)
                self._tex_among[name] = _among(f.texture)
        # textured emission (Mitsuba's area radiance bitmap), by material
        self._emit_tex = None if lay.emission_texture is None else UInt32(lay.emission_texture)
        self._emit_among = None if lay.emission_texture is None else _among(lay.emission_texture)
        # Perturbed frames (normalmap, bumpmap): per row, only in scenes that have them
        self._pkinds = lay.perturbed_kinds
        if lay.perturb is not None:
            pt = lay.perturb
            self._has_normal, self._has_bump = pt.has_normal, pt.has_bump
            self._p_code, self._p_tex = Table(UInt32, pt.code), Table(UInt32, pt.texture)
            # per kind, the texture ids its rows reference (each kind traces only its own)
            codes, texs = np.asarray(pt.code), np.asarray(pt.texture)
            self._p_among_normal = _among(texs[codes == 1])
            self._p_among_bump = _among(texs[codes == 2])
            self._p_const = None if pt.constant is None else Table(Array3f, pt.constant)
            if pt.scale is not None:
                self._p_scale = Table(Float, pt.scale)
            self._p_flip, self._p_shadow, self._p_inner = _flag(pt.flip), _flag(pt.shadow), _flag(pt.inner)
        # Textures: one set for every textured field and weight.
        self.textures = None
        if lay.textures:
            bumps = lay.perturb is not None and lay.perturb.has_bump
            self.textures = TextureSet(lay.textures, scene.triangles,
                                       gradients=self._p_among_bump if bumps else ())
        # materials made only of Dirac lobes (glass, mirrors): Whitted follows them
        delta = lay.material_delta
        self._all_delta = bool(delta.all())
        self._mat_delta = None if (self._all_delta or not delta.any()) else Table(Bool, delta)
        self._any_delta = bool(delta.any())
        # the kinds of the delta-only materials (what :meth:`specular` traces), and whether
        # each of them is one component (then slot 0 holds its row, at weight 1)
        self._delta_kinds = tuple(sorted({k for ks, d in zip(lay.material_kinds, delta) if d for k in ks}))
        self._delta_single = all(len(cs) == 1 for cs, d in zip(lay.components, delta) if d)
        # materials blending two or more smooth components (blendbsdf of two lobes, ...):
        # only theirs need the whole mixture evaluated after sampling (see sample); a
        # mask's pass-through beside one smooth lobe does not
        blends = np.array([sum(not self.lobes[c.leaf.kind].DELTA for c in cs) > 1
                           for cs in lay.components], bool)
        self._blends_smooth = True if blends.all() else Table(Bool, blends) if blends.any() else False

    _only: tuple[str, ...] | None = None  # a restricted view's kinds (see restricted)

    #: how lanes reach their lobe kind's code where a table traces several kinds: ``"kinds"``,
    #: each kind's case in its own symbolic ``dr.if_stmt`` (a SIMD packet runs only the kinds
    #: its lanes have); ``"masked"``, every kind for every lane, merged with ``dr.select``.
    #: Same images; read at trace time (set it before a kernel is traced, e.g. for an A/B).
    dispatch: str = "kinds"

    def at(self, row: UInt32) -> Rows:
        """The lanes' rows ``row``: what the lobes read their fields through."""
        return Rows(self, row)

    def _perturbed(self, si: Interaction, row: UInt32, mask: Bool, outer: Frame,
                   sh_frame: Frame) -> PerturbedFrame:
        """The frame the lanes' perturbed components see (:mod:`drpt.render.perturb`);
        ``outer``: the interaction's frame as the component sees it (mirrored inside
        ``twosided`` from behind), ``sh_frame``: the interaction's own."""
        code = gather(UInt32, self._p_code, row, mask)
        tid = gather(UInt32, self._p_tex, row, mask)
        wi_l = outer.to_local(si.wi)

        def rowflag(v):
            return v if isinstance(v, bool) else gather(Bool, v, row, mask)

        flip = rowflag(self._p_flip)
        n, s = Array3f(0.0, 0.0, 1.0), Array3f(1.0, 0.0, 0.0)
        if self._has_normal:
            m = mask & (code == 1)
            if self._p_const is None:
                rgb = self.textures.lookup(tid, si.uv, m, si=si, among=self._p_among_normal)
            else:
                rgb = gather(Array3f, self._p_const, row, m)
                if self.textures is not None:
                    rgb = dr.select(tid != NONE, self.textures.lookup(tid, si.uv, m & (tid != NONE), si=si,
                                                                      among=self._p_among_normal), rgb)
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
            grad = self.textures.gradient(tid, si.uv, m, among=self._p_among_bump)
            grad = grad * gather(Float, self._p_scale, row, m)
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

    def specular(self) -> MaterialTable:
        """A :meth:`restricted` view of the kinds of the materials made only of Dirac lobes
        (see :attr:`mixes_delta`): what sampling traces for those materials' lanes alone.
        Where each of those materials is one component, the view samples slot 0's row
        without choosing a slot."""
        view = self.restricted(self._delta_kinds)
        view._one_slot = self.K > 1 and self._delta_single
        return view

    _one_slot = False  # (a specular view: the lanes' materials are one component each)

    # ------------------------------------------------------------------ parameters
    def specs_of(self, kind: str) -> list[BSDFSpec]:
        """The leaf specs of ``kind`` in the scene (host side), for trace-time choices."""
        return self.layout.specs_of(kind)

    # ------------------------------------------------------------------ emission
    @property
    def has_emission_texture(self) -> bool:
        """Whether some material's emission is a texture (Mitsuba's area radiance bitmap)."""
        return self._emit_tex is not None

    def emitted(self, si: Interaction) -> Array3f:
        """Radiance leaving ``si`` toward ``si.wi`` (zero on back faces)."""
        if not self.has_emission:
            return Array3f(0.0)
        le = gather(Array3f, self.emission, si.material, si.valid)
        if self._emit_tex is not None:
            le = self.textured_emission(si.material, si.uv, le, si.valid)
        front = si.valid & (dr.dot(si.ns, si.wi) > 0.0)
        return dr.select(front, le, 0.0)

    def is_emissive(self, si: Interaction, active: Bool) -> Bool:
        """Lanes of ``active`` whose hit's material emits, on either face (Mitsuba's
        ``shape->emitter() != nullptr``); only traced for scenes with emission."""
        if not self.has_emission:
            return Bool(False)
        hit = active & si.valid
        return hit & gather(Bool, self._emissive, si.material, hit)

    def textured_emission(self, material: UInt32, uv: Array2f, le: Array3f, active: Bool) -> Array3f:
        """``le`` where the material's emission is constant, its texture at OBJ ``uv`` where
        it has one (only traced for scenes with a textured emitter)."""
        ids = gather(UInt32, self._emit_tex, material, active)
        textured = active & (ids != NONE)
        return dr.select(textured, self.textures.lookup(ids, uv, textured, among=self._emit_among), le)

    def is_specular_only(self) -> bool:
        """Whether every lobe this table traces (a :meth:`restricted` view: its kinds') is a delta lobe."""
        return all(self.lobes[k].DELTA for k in (self.kinds if self._only is None else self._only))

    @property
    def mixes_delta(self) -> bool:
        """Whether some materials are made only of Dirac lobes and others are not (host side,
        read at trace time): then :meth:`is_delta` is a per-lane gather."""
        return self._any_delta and not self._all_delta

    def is_delta(self, si: Interaction) -> Bool:
        """Lanes whose material has only Dirac lobes (glass, mirror)."""
        if not self._any_delta:
            return Bool(False)
        if self._all_delta:
            return Bool(si.valid)
        return si.valid & gather(Bool, self._mat_delta, si.material, si.valid)

    def diffuse_color(self, si: Interaction, active: Bool) -> Array3f:
        """The diffuse color of the lanes' first component (its kind's ``COLOR``
        field, e.g. ``kd``), for the Whitted ambient term; 0 for kinds without one."""
        out = Array3f(0.0)
        for case in self._cases(si, 0):
            name = getattr(case.bsdf, "COLOR", None)
            if name is not None:
                m = case.mask & active

                def color(out, m=m, rows=case.rows, name=name):
                    return (dr.select(m, rows.value(name, si, m), out),)

                (out,) = case.run(color, (out,), m)
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
            row, w, present = self._slot(si, j)
            for case in self._cases(si, j, row, present):
                m = case.mask & active
                bsdf, rows = case.bsdf, case.rows
                name = getattr(bsdf, "COLOR", None)
                if name is None and case.kind == "null" and w is not None:
                    w_null = dr.select(m, w_null + w, w_null)
                    continue
                if name is None and bsdf.DELTA:
                    continue

                def reflectance(out, m=m, bsdf=bsdf, rows=rows, name=name, frame=case.frame, w=w):
                    if name is not None:
                        a = rows.value(name, si, m)
                    else:
                        a = bsdf.eval(bsdf.params(rows, si, m), frame().to_local(si.wi), up) * dr.pi
                    return (dr.select(m, a if w is None else dr.fma(a, w, out), out),)

                (out,) = case.run(reflectance, (out,), m)
        if "null" in self.kinds and self.K > 1:
            out = dr.select(w_null < 1.0, out / dr.maximum(1.0 - w_null, 1e-6), out)
        return out

    # ------------------------------------------------------------------ dispatch
    def _slot(self, si: Interaction, j: int):
        """(the lanes' rows, weight or None, lanes with a component) of slot ``j``."""
        if self.K == 1:  # a material's one row is its index
            return si.material, None, si.valid
        s = self._slots[j]
        row = gather(UInt32, s.row, si.material, si.valid)
        present = si.valid & (row != NONE) if s.partial else si.valid
        w = gather(Float, s.weight, si.material, present)
        if s.texture is not None:
            # looked up on every valid lane (w is 0 where the slot is absent): the same
            # expression for every slot sharing the texture array, traced once
            ids = gather(UInt32, s.texture, si.material, si.valid)
            textured = si.valid & (ids != NONE)
            t = _luminance(self.textures.lookup(ids, si.uv, textured, scalar=True, si=si, among=s.among))
            comp = gather(Bool, s.complement, si.material, present)
            w = dr.select(textured, w * dr.select(comp, 1.0 - t, t), w)
        return row, dr.select(present, w, 0.0), present

    def _cases(self, si: Interaction, j: int | None = None, row=None, present=None):
        """A :class:`_Case` for each kind of slot ``j`` (all kinds when ``j`` is None:
        ``row`` given). Cases are branched (:attr:`dispatch` ``"kinds"``) where lanes
        have several kinds; each branched case traces its frame alone, while masked
        cases share the tangent and flipped frames (computed once, for every lane)."""
        if self.dispatch not in ("kinds", "masked"):
            raise ValueError(f"MaterialTable.dispatch must be 'kinds' or 'masked', not {self.dispatch!r}")
        if row is None:
            row, _, present = self._slot(si, j)
        rows = self.at(row)
        kinds = self.kinds if (j is None or self.K == 1) else self._slots[j].kinds
        if self._only is not None:
            kinds = [k for k in kinds if k in self._only]
        if len(self.kinds) == 1 or (self._only is not None and len(self._only) == 1
                                    and (self.K == 1 or self._one_slot)):
            kind_of = None
        else:
            kind_of = gather(UInt32, self.kind, row, present)
        branched = kind_of is not None and self.dispatch == "kinds"
        flip = dr.dot(si.ns, si.wi) < 0.0
        shared: dict[str, Frame] = {}
        for kind in kinds:
            i = self.kinds.index(kind)
            mask = present if kind_of is None else present & (kind_of == i)

            def frame(kind=kind, mask=mask, base=({} if branched else shared)):
                return self._frame(si, row, mask, flip, kind, base)

            if not branched:  # traced here, as the masked dispatch always has
                f = frame()

                def frame(f=f):
                    return f

            yield _Case(kind, self.lobes[kind], mask, rows, frame, branched)

    def _frame(self, si: Interaction, row: UInt32, mask: Bool, flip: Bool, kind: str,
               base: dict) -> Frame:
        """The local shading frame of the lanes ``mask`` of ``kind`` (``flip``: the lanes
        seeing the shading normal from behind); ``base`` caches the frames that do not
        depend on the kind (the tangent frame, the flipped and plain normal frames)."""
        two = self._two[kind]
        if si.dp_du is not None:  # frames follow dp/du; twosided mirrors z
            if "tangent" not in base:
                base["tangent"] = tangent_frame(si.ns, si.dp_du)
            tangent = base["tangent"]
            if two is True:
                frame = _z_flipped(tangent, flip)
            elif two is False:
                frame = tangent
            else:
                frame = _z_flipped(tangent, gather(Bool, two, row, mask) & flip)
            if kind in self._pkinds:
                frame = self._perturbed(si, row, mask, frame, tangent)
            return frame
        if two is True:
            if "flipped" not in base:
                base["flipped"] = Frame(dr.select(flip, -si.ns, si.ns))
            return base["flipped"]
        if two is False:
            if "plain" not in base:
                base["plain"] = Frame(si.ns)
            return base["plain"]
        f2 = gather(Bool, two, row, mask) & flip
        return Frame(dr.select(f2, -si.ns, si.ns))

    # ------------------------------------------------------------------
    def eval_pdf(self, si: Interaction, wo: Array3f, importance: bool = False) -> tuple[Array3f, Float]:
        """``f * |cos|`` and the sampling density (solid angle) for world ``wo``. With
        ``importance`` (read at trace time) ``f`` is importance mode's, for a light subpath's
        vertex: a lobe whose transmission scales radiance (its module's ``importance_scale``:
        rough dielectrics, principled) has that scaling undone."""
        f, pdf = Array3f(0.0), Float(0.0)
        for j, (row, w, present) in enumerate(self._slots_at(si)):
            for case in self._cases(si, j, row, present):
                if case.bsdf.DELTA:
                    continue  # nothing to evaluate

                def evaluate(f, pdf, case=case, w=w):
                    p, frame = case.bsdf.params(case.rows, si, case.mask), case.frame()
                    return _eval_case(case, p, frame, frame.to_local(si.wi), wo, w, f, pdf, importance)

                f, pdf = case.run(evaluate, (f, pdf))
        return f, pdf

    def eval_pdf_rev(self, si: Interaction, wo: Array3f, importance: bool = False) -> tuple[Array3f, Float, Float]:
        """:meth:`eval_pdf` toward ``wo`` and the reverse density: the density of sampling
        ``si.wi`` seen from ``wo`` (what ``eval_pdf`` of ``si`` with ``wi = wo`` toward
        ``si.wi`` returns), in one dispatch over the kinds (bidirectional path tracing's MIS
        weights ask for both at every connection). Each lobe's ``pdf`` runs twice in its
        case's frame, with the directions swapped; where a two-sided frame would flip
        between the two (``wi`` and ``wo`` on opposite sides of the shading normal) the
        swapped pair is mirrored in ``z``, as :func:`_z_flipped` mirrors the frame (an
        isotropic lobe's density is the same in any frame of the flipped normal).
        Perturbed frames (normal and bump maps) depend on ``wi``: tables with them take
        the two evaluations. ``importance``: :meth:`eval_pdf`'s."""
        if self._pkinds:
            return self._two_evaluations(si, wo, importance)
        f, pdf, rev = Array3f(0.0), Float(0.0), Float(0.0)
        # the lanes whose two-sided frame would flip for the reverse direction
        across = (dr.dot(si.ns, si.wi) < 0.0) != (dr.dot(si.ns, wo) < 0.0)
        for case, w, lanes in self._smooth_cases(si):
            mirror = None if lanes is None else (across if lanes is True else across & lanes)

            def evaluate(f, pdf, rev, case=case, w=w, mirror=mirror):
                frame = case.frame()
                p = case.bsdf.params(case.rows, si, case.mask)
                return _merge(case.mask, w, (f, pdf, rev),
                                  _lobe_rev(case.bsdf, p, frame, frame.to_local(si.wi), wo, mirror, importance))

            f, pdf, rev = case.run(evaluate, (f, pdf, rev))
        return f, pdf, rev

    def _smooth_cases(self, si: Interaction):
        """Each non-Dirac case of each slot at ``si`` with its slot's weight and the lanes
        whose two-sided frame may mirror (None: a one-sided kind; True: every lane):
        ``(case, w, lanes)``, for :meth:`eval_pdf_rev` and :meth:`prepare_rev`."""
        for j in range(self.K):
            row, w, present = self._slot(si, j)
            for case in self._cases(si, j, row, present):
                if case.bsdf.DELTA:
                    continue  # nothing to evaluate
                yield case, w, self._mirror_lanes(case, row)

    def _mirror_lanes(self, case: _Case, row: UInt32):
        """The lanes of ``case`` whose two-sided frame may mirror between two directions:
        None for a one-sided kind, True where the kind is two-sided on every row."""
        two = self._two[case.kind]
        return None if two is False else (True if two is True else gather(Bool, two, row, case.mask))

    def prepare_rev(self, si: Interaction, importance: bool = False
                    ) -> Callable[[Array3f], tuple[Array3f, Float, Float]]:
        """:meth:`eval_pdf_rev` of ``si`` toward directions given later: what does not depend
        on the direction (each case's fields, its shading frame and ``si.wi`` in it) is traced
        now, once, for every lane of the case, and the returned function traces the rest per
        call, branched per kind as :meth:`eval_pdf_rev` is; each call computes the values
        :meth:`eval_pdf_rev` computes. For a vertex evaluated toward many directions in a loop
        (bdpt's camera vertex joined to each light vertex): prepared outside the loop, the
        loop's body no longer gathers the fields nor builds the frame."""
        if self._pkinds:
            return lambda wo: self._two_evaluations(si, wo, importance)
        prepared = []
        for case, w, lanes in self._smooth_cases(si):
            frame = case.frame()
            p = case.bsdf.params(case.rows, si, case.mask)
            prepared.append((case, w, lanes, frame, p, frame.to_local(si.wi)))

        def evaluate(wo: Array3f) -> tuple[Array3f, Float, Float]:
            f, pdf, rev = Array3f(0.0), Float(0.0), Float(0.0)
            across = (dr.dot(si.ns, si.wi) < 0.0) != (dr.dot(si.ns, wo) < 0.0)
            for case, w, lanes, frame, p, wi_l in prepared:
                mirror = None if lanes is None else (across if lanes is True else across & lanes)

                def one(f, pdf, rev, case=case, w=w, mirror=mirror, frame=frame, p=p, wi_l=wi_l):
                    return _merge(case.mask, w, (f, pdf, rev),
                                  _lobe_rev(case.bsdf, p, frame, wi_l, wo, mirror, importance))

                f, pdf, rev = case.run(one, (f, pdf, rev))
            return f, pdf, rev

        return evaluate

    def _two_evaluations(self, si: Interaction, wo: Array3f, importance: bool = False
                         ) -> tuple[Array3f, Float, Float]:
        """:meth:`eval_pdf_rev` by two :meth:`eval_pdf` (tables with perturbed frames)."""
        return (*self.eval_pdf(si, wo, importance), self._pdf_seen_from(si, wo))

    def _pdf_seen_from(self, si: Interaction, wo: Array3f) -> Float:
        """The density of sampling ``si.wi`` at ``si`` seen from ``wo``, by a second
        :meth:`eval_pdf` (tables with perturbed frames, which depend on ``wi``)."""
        rev_si = copy.copy(si)
        rev_si.wi = wo
        return self.eval_pdf(rev_si, si.wi)[1]

    def sample(self, si: Interaction, u1: Float, u2: Array2f, rev: bool = False):
        """Sample a world direction; returns it and the local :class:`BSDFSample`. With
        ``rev`` (read at trace time) also the reverse density of a smooth sample: the
        density of sampling ``si.wi`` seen from the sampled direction, as
        :meth:`eval_pdf_rev` gives it, from the sampled lobe in its own case (0 after a Dirac
        lobe; bidirectional path tracing's MIS weights read it)."""
        if self.K == 1:
            row, present, chosen_w = si.material, si.valid, None
        elif self._one_slot:
            row, present, chosen_w = gather(UInt32, self._slots[0].row, si.material, si.valid), si.valid, None
        else:
            slots = self._slots_at(si)
            picked, chosen_w, u1 = self._pick(slots, u1)
            row = UInt32(NONE)
            for take, (rj, _, _) in zip(picked, slots):
                row = dr.select(take, rj, row)
            present = si.valid & _any(picked)
        out = BSDFSample()
        wo = Array3f(0.0, 0.0, 1.0)
        # the reverse density in the sampled lobe's case (tables with perturbed frames, which
        # depend on wi, evaluate it after sampling)
        rev_here = rev and not self._pkinds
        pdf_rev = (Float(0.0),) if rev_here else ()
        for case in self._cases(si, None, row, present):

            def draw(out, wo, *pdf_rev, case=case, u1=u1):
                p, frame = case.bsdf.params(case.rows, si, case.mask), case.frame()
                wi_l = frame.to_local(si.wi)
                out, wo = _sample_case(case, p, frame, wi_l, u1, u2, case.mask, out, wo)
                if pdf_rev and not case.bsdf.DELTA:
                    pdf_rev = (self._sampled_rev(si, case, p, frame, wi_l, wo, out, row, pdf_rev[0]),)
                return (out, wo) + pdf_rev

            out, wo, *pdf_rev = case.run(draw, (out, wo, *pdf_rev))
        if rev and not rev_here:
            full_rev = dr.select(out.delta, 0.0, self._pdf_seen_from(si, wo))
            return (*self._mixture(si, wo, out, present, chosen_w), full_rev)
        return self._mixture(si, wo, out, present, chosen_w, *pdf_rev)

    def _sampled_rev(self, si: Interaction, case: _Case, p, frame: Frame, wi_l: Array3f,
                     wo: Array3f, out: BSDFSample, row: UInt32, pdf_rev: Float) -> Float:
        """:meth:`sample`'s reverse density on ``case``'s lanes: its lobe's density of
        sampling ``si.wi`` from the sampled ``wo``, the pair mirrored in ``z`` where a
        two-sided frame would flip between them (as :meth:`eval_pdf_rev` reads it; the
        world direction taken back into the frame gives the same bits), 0 after a Dirac
        sample."""
        lanes = self._mirror_lanes(case, row)
        across = (dr.dot(si.ns, si.wi) < 0.0) != (dr.dot(si.ns, wo) < 0.0)
        mirror = None if lanes is None else (across if lanes is True else across & lanes)
        wi_l, wo_l = _mirrored(mirror, wi_l, frame.to_local(wo))
        return dr.select(case.mask & ~out.delta, case.bsdf.pdf(p, wo_l, wi_l), pdf_rev)

    def eval_pdf_sample(self, si: Interaction, wo: Array3f, u1: Float,
                        u2: Array2f) -> tuple[Array3f, Float, Array3f, BSDFSample]:
        """:meth:`eval_pdf` toward ``wo`` and :meth:`sample` from ``(u1, u2)`` in one
        dispatch: ``(f, pdf, wo_sampled, sample)``, the same values as the two calls.
        Each kind's case reads its fields (texture lookups included), builds its frame
        and maps ``wi`` once for both (Mitsuba's ``eval_pdf_sample``); with several slots,
        slot ``j``'s cases also sample the lanes that picked slot ``j``."""
        f, pdf = Array3f(0.0), Float(0.0)
        out, wo_s = BSDFSample(), Array3f(0.0, 0.0, 1.0)
        slots = self._slots_at(si)
        if self.K == 1:
            picked, chosen_w, present = [None], None, si.valid
        else:
            picked, chosen_w, u1 = self._pick(slots, u1)
            present = si.valid & _any(picked)
        for j, (row, w, pres) in enumerate(slots):
            for case in self._cases(si, j, row, pres):
                ev = not case.bsdf.DELTA  # (a Dirac lobe adds nothing to f and pdf)
                drawn = case.mask if picked[j] is None else case.mask & picked[j]

                def both(f, pdf, out, wo_s, case=case, w=w, ev=ev, drawn=drawn):
                    p, frame = case.bsdf.params(case.rows, si, case.mask), case.frame()
                    wi_l = frame.to_local(si.wi)
                    if ev:
                        f, pdf = _eval_case(case, p, frame, wi_l, wo, w, f, pdf)
                    out, wo_s = _sample_case(case, p, frame, wi_l, u1, u2, drawn, out, wo_s)
                    return f, pdf, out, wo_s

                f, pdf, out, wo_s = case.run(both, (f, pdf, out, wo_s), case.mask if ev else drawn)
        wo_s, out = self._mixture(si, wo_s, out, present, chosen_w)
        return f, pdf, wo_s, out

    def _slots_at(self, si: Interaction) -> list[tuple]:
        """:meth:`_slot` of every slot: ``(rows, weight, present)`` each (``K == 1``: the
        material's one row, no weight). Where some materials are one component at weight 1,
        the slots are read in a symbolic ``if`` on the lanes of the others (label
        ``drpt_slots``): the lanes of the one-component materials take slot 0's row at
        weight 1 and no other slot, the values the slots hold for them, so a packet
        without a lane on a mask or a blend skips the slots' gathers and their textured
        weights' lookups."""
        if self.K == 1 or self._multi is None:
            return [self._slot(si, j) for j in range(self.K)]
        multi = si.valid & gather(Bool, self._multi, si.material, si.valid)

        def several():
            return tuple(v for j in range(self.K) for v in self._slot(si, j))

        def one():
            rest = (v for _ in range(1, self.K) for v in (UInt32(NONE), Float(0.0), Bool(False)))
            return (gather(UInt32, self._slots[0].row, si.material, si.valid), Float(1.0), Bool(si.valid),
                    *rest)

        vals = dr.if_stmt((), multi, several, one, label="drpt_slots")
        return [tuple(vals[3 * j:3 * j + 3]) for j in range(self.K)]

    def _pick(self, slots: list[tuple], u1: Float) -> tuple[list[Bool], Float, Float]:
        """Slot choice for sampling (``K > 1``; ``slots``: :meth:`_slots_at`'s): per slot
        the lanes that picked it (by its weight), the chosen slot's weight, and ``u1``
        rescaled within it for the lobe."""
        lo, chosen_w = Float(0.0), Float(1.0)
        picked, any_ = [], Bool(False)
        for j, (_, w, pres) in enumerate(slots):
            take = pres & ~any_ & ((u1 < lo + w) | Bool(j == self.K - 1)) & (w > 0.0)
            u_rest = dr.select(take, (u1 - lo) / dr.select(w > 0.0, w, 1.0), 0.0)
            chosen_w = dr.select(take, w, chosen_w)
            u1 = dr.select(take, dr.clip(u_rest, 0.0, 0.99999994), u1)
            picked.append(take)
            any_ |= take
            lo = lo + w
        return picked, chosen_w, u1

    def _mixture(self, si: Interaction, wo: Array3f, out: BSDFSample, present: Bool,
                 chosen_w: Float | None, *pdf_rev: Float) -> tuple:
        """The sampled component's ``out`` made the mixture's (``K > 1``; ``present``: the
        lanes with a component): ``(wo, out)``; given the component's reverse density
        (:meth:`sample`'s ``rev``), the mixture's too: ``(wo, out, pdf_rev)``."""
        out.valid &= present
        if self.K > 1 and not self._one_slot and not self.is_specular_only():
            smooth = out.valid & ~out.delta
            # A smooth sample weighs the whole mixture: f_mix / pdf_mix. Where the chosen
            # component is its material's only smooth one (the others Dirac: a mask's
            # pass-through), f_mix = w f_j and pdf_mix = w pdf_j (Dirac lobes add nothing
            # off their direction), so the ratio is the component's own weight and the
            # density its own times its slot's weight w: no second evaluation.
            blends = self._blends_smooth
            if blends is not True:
                single = smooth if blends is False else smooth & ~gather(Bool, blends, si.material, smooth)
                out.pdf = dr.select(single, out.pdf * chosen_w, out.pdf)
                out.valid &= ~single | (out.pdf > 0.0)
                if pdf_rev:
                    pdf_rev = (dr.select(single, pdf_rev[0] * chosen_w, pdf_rev[0]),)
            if blends is not False:
                mixed = smooth if blends is True else smooth & gather(Bool, blends, si.material, smooth)
                if pdf_rev:
                    f, pdf, mixed_rev = self.eval_pdf_rev(si, wo)
                    pdf_rev = (dr.select(mixed, mixed_rev, pdf_rev[0]),)
                else:
                    f, pdf = self.eval_pdf(si, wo)
                ok = mixed & (pdf > 0.0)
                out.weight = dr.select(mixed, dr.select(ok, f / dr.select(ok, pdf, 1.0), 0.0), out.weight)
                out.pdf = dr.select(mixed, pdf, out.pdf)
                out.valid &= ~mixed | ok
        return (wo, out, *pdf_rev)


def _lobe_rev(bsdf: BSDF, p, frame, wi_l: Array3f, wo: Array3f, mirror: Bool | None,
              importance: bool = False):
    """One lobe's ``(f, pdf, pdf_rev)`` toward world ``wo`` in ``frame`` (``wi_l``: ``si.wi`` in
    it), the swapped pair mirrored in ``z`` on the lanes ``mirror``
    (:meth:`MaterialTable.eval_pdf_rev`); ``f`` in importance mode with ``importance``."""
    wo_l = frame.to_local(wo)
    fj, pj = _value(bsdf, p, wi_l, wo_l, importance), bsdf.pdf(p, wi_l, wo_l)
    wi_l, wo_l = _mirrored(mirror, wi_l, wo_l)
    return fj, pj, bsdf.pdf(p, wo_l, wi_l)


def _mirrored(mirror: Bool | None, wi_l: Array3f, wo_l: Array3f) -> tuple[Array3f, Array3f]:
    """The local pair mirrored in ``z`` on the lanes ``mirror`` (None: as it is)."""
    if mirror is None:
        return wi_l, wo_l
    return (Array3f(wi_l.x, wi_l.y, dr.select(mirror, -wi_l.z, wi_l.z)),
            Array3f(wo_l.x, wo_l.y, dr.select(mirror, -wo_l.z, wo_l.z)))


def _merge(mask: Bool, w: Float | None, state: tuple, lobe: tuple) -> tuple:
    """``state`` (``f``, ``pdf``[, ``pdf_rev``]) with a lobe's values added on ``mask``,
    weighted by its slot weight ``w`` (None: the material's one component, the values replace)."""
    if w is None:
        return tuple(dr.select(mask, v, old) for v, old in zip(lobe, state))
    return tuple(dr.select(mask, dr.fma(v, w, old), old) for v, old in zip(lobe, state))


def _any(masks: list[Bool]) -> Bool:
    out = masks[0]
    for m in masks[1:]:
        out = out | m
    return out


def _value(bsdf: BSDF, p, wi_l: Array3f, wo_l: Array3f, importance: bool) -> Array3f:
    """The lobe's ``f * |cos|``, with ``importance`` in importance mode (its module's
    ``importance_scale``, where it has one; other lobes are the same in both modes)."""
    fj = bsdf.eval(p, wi_l, wo_l)
    scale = getattr(bsdf, "importance_scale", None) if importance else None
    return fj if scale is None else fj * scale(p, wi_l, wo_l)


def _eval_case(case: _Case, p, frame: Frame, wi_l: Array3f, wo: Array3f, w: Float | None,
               f: Array3f, pdf: Float, importance: bool = False) -> tuple[Array3f, Float]:
    """``(f, pdf)`` with ``case``'s lobe toward world ``wo`` added on its lanes (weighted
    by its slot's ``w``; ``None``: the one component), given its fields ``p``, its frame
    and ``wi`` in it; ``f`` in importance mode with ``importance``."""
    bsdf, mask = case.bsdf, case.mask
    wo_l = frame.to_local(wo)
    fj, pj = _value(bsdf, p, wi_l, wo_l, importance), bsdf.pdf(p, wi_l, wo_l)
    if isinstance(frame, PerturbedFrame):
        fac = frame.factor(wo)
        fj, pj = fj * fac, dr.select(fac > 0.0, pj, 0.0)
    return _merge(mask, w, (f, pdf), (fj, pj))


def _sample_case(case: _Case, p, frame: Frame, wi_l: Array3f, u1: Float, u2: Array2f, mask: Bool,
                 out: BSDFSample, wo: Array3f) -> tuple[BSDFSample, Array3f]:
    """``(out, wo)`` with ``case``'s lobe sampled on the lanes ``mask`` (its world
    direction in ``wo``), given its fields ``p``, its frame and ``wi`` in it."""
    bs = case.bsdf.sample(p, wi_l, u1, u2)
    wo_j = frame.to_world(bs.wo)
    if isinstance(frame, PerturbedFrame):
        fac = frame.factor(wo_j)
        ok = fac > 0.0
        bs.weight, bs.pdf, bs.valid = bs.weight * fac, dr.select(ok, bs.pdf, 0.0), bs.valid & ok
    return dr.select(mask, bs, out), dr.select(mask, wo_j, wo)
