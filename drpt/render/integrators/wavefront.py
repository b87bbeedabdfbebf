"""Wavefront path tracing: the megakernel's estimator, one stage per kernel.

:class:`WavefrontIntegrator` traces the same paths as
:class:`~drpt.render.integrators.path.PathIntegrator` (``sample``: one path
per lane; emission with MIS, next-event estimation of one emitter chosen by
the scene's light selection, with MIS, BSDF sampling, Russian roulette, the same
seven random numbers per vertex drawn in the same order from the lane's PCG32
stream or low-discrepancy sampler, :mod:`drpt.render.sampler`, whose state the
buffers carry as two UInt64 arrays), but instead of one fused kernel with the bounce loop inside it, the
bounce loop runs in Python and every stage is its own evaluated kernel over
structure-of-arrays buffers (one Dr.Jit array per field of
:class:`WaveState`, ``n`` = the paths still alive):

1. **compaction + ray sort** (stage ``compact + sort``): the live paths of the previous
   bounce are compacted (``dr.compress`` of their mask: no dead lanes) and
   reordered by a coherence key, direction octant (3 bits, most
   significant) then the Morton code of the ray origin quantised to a
   ``2^6`` grid per axis over the origins' bounds (those of the first
   bounce's rays, which start on the surfaces, reused after: six
   reductions once, not per bounce; later origins outside are clamped to
   the grid's edge, which changes the order only) (18 bits): a stable
   least-significant-digit radix sort in Dr.Jit kernels
   (``dr.detail.block_mkperm``, the primitive under ``dr.argsort``, two
   passes of 11 and 10 bits); one gather applies compaction and order;
2. **closest hit** (``closest hit``, ``interaction``): the accelerator's
   closest-hit kernel, then the surface interaction;
3. **emission** (``emission``): what the ray hit or escaped to, MIS-weighted
   against the previous BSDF sample, added to the path's radiance (a
   scatter-add into the pass-wide radiance buffer at the path's lane);
4. **shading queues** (``partition`` + ``shade``): the paths that continue
   are grouped by the lobe kinds of their material (a counting sort by queue
   id with ``block_mkperm``; queue = the set of leaf kinds of the material's
   components, so a Cornell box of diffuse walls, principled, rough and
   smooth dielectrics runs four queues). Each queue's kernel runs only its
   BSDFs' code (a :meth:`~drpt.render.scene.DeviceScene.restricted` view of
   the scene, whose feature flags are those of its kinds): light sampling
   and BSDF evaluation for next-event estimation (queued as shadow queries),
   BSDF sampling, Russian roulette, and writes the next ray and path state;
5. **shadow rays** (``shadow rays``, ``shadow resolve``): the queues write their shadow
   queries (one per path: next-event estimation samples one emitter) into one buffer
   set at their paths' positions; those with a non-zero contribution are
   compacted (``dr.compress``) into one batch, traced by the any-hit kernel;
   unoccluded contributions are added to the radiance buffer.

With ``tail`` (``--wavefront-tail N``), once at most ``N`` paths of the pass
are alive they finish in one symbolic loop of the megakernel's own bounce
(``fused tail``): the long tail of bounces with few paths then costs one
kernel instead of a bounce's launches each.

The renderer runs this integrator with one path per lane (it has no
``sample_sequence``), so for a seed its image is in general not the
megakernel's (whose lanes regenerate paths on other streams); where the
megakernel also runs one path per lane (a pass with at most ``min_lanes``
samples), or with a low-discrepancy sampler (whose numbers depend on the
pixel, the sample and the dimension only), the images are the same.

Same estimator: every sample is the megakernel's ``sample`` function of the
same random numbers, so images agree statistically with the megakernel's
(the renderer's megakernel runs ``sample_sequence``, path regeneration, on
other random streams) and, for the same lane streams, path by path up to
float rounding (tests/render/integrators/test_wavefront.py). Determinism: every stage is a
pure function of its inputs; the sorts are stable, and a path's arithmetic
does not depend on its position in the buffer, so a seed gives the same
image bit for bit (the coherence sort changes the order, not the values).

:mod:`~drpt.render.integrators.volwavefront` runs volpath on these stages (its
subclass adds a medium queue; ``_start_state``, ``_loop_state`` and ``_stages`` are what
it replaces).

``stats`` (a :class:`WaveStats`, set by ``drpt profile``) records per stage
the wall time (``dr.sync_thread`` at every boundary), the kernels launched
(from ``dr.kernel_history`` when ``KernelHistory`` is on), lanes and rays,
and the live paths per bounce.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, fields

import drjit as dr
from drjit.auto import PCG32, Array3f, Array3u, Bool, Float, UInt32, UInt64

from ...options import PathOptions
from ..loops import loops_once
from ..sampler import light_sample, next_2d, pack, unpack
from ..scene import DeviceScene
from ..surface import Interaction
from .common import DirectLight, ShadowQuery
from .path import PathIntegrator, PathState, add_emission, continue_path, sees_from_vertex, skip_hidden_emitters

MORTON_BITS = 6  # per axis
KEY_BITS = 3 + 3 * MORTON_BITS
RADIX_BITS = 11

OUTSIDE = "accumulation + readback (outside the passes' stages)"
STAGES = ("compact + sort", "closest hit", "interaction", "emission", "free flight", "partition", "medium",
          "shade", "shadow rays", "shadow resolve", "fused tail")


@dataclass
class WaveState:
    """The live paths between kernels, one array per field (structure of arrays)."""

    lane: UInt32  # the path's lane in the pass (where its radiance goes)
    o: Array3f
    d: Array3f
    beta: Array3f
    eta: Float
    depth: UInt32
    prev_pdf: Float
    prev_delta: Bool
    rng_state: UInt64
    rng_inc: UInt64
    #: the path's last vertex (:attr:`~drpt.render.integrators.path.PathState.ref_p`; None where
    #: nothing reads it: :func:`~drpt.render.integrators.path.sees_from_vertex`)
    ref_p: Array3f | None


def _arrays(obj) -> list:
    return [getattr(obj, f.name) for f in fields(obj)] if hasattr(obj, "__dataclass_fields__") else \
        [v for v in vars(obj).values() if isinstance(v, dr.ArrayBase)]


def _take(v, idx: UInt32):
    """``v[idx]`` (a width-1 value is a broadcast constant: kept; None stays None)."""
    if v is None:
        return None
    if dr.width(v) == 1:
        return type(v)(v)
    return dr.gather(type(v), v, idx)


def gather_state(s: WaveState, idx: UInt32) -> WaveState:
    """The paths ``idx`` of ``s`` (a :class:`WaveState` or a subclass)."""
    return type(s)(*(_take(getattr(s, f.name), idx) for f in fields(s)))


def _spread(x: UInt32) -> UInt32:
    """Bits 0..9 of ``x`` moved to bits 0, 3, 6, ... (Morton interleave)."""
    x = (x | (x << 16)) & 0x030000FF
    x = (x | (x << 8)) & 0x0300F00F
    x = (x | (x << 4)) & 0x030C30C3
    return (x | (x << 2)) & 0x09249249


def ray_key(o: Array3f, d: Array3f, lo: Array3f, hi: Array3f) -> UInt32:
    """The coherence key: octant of ``d`` (high 3 bits), then the Morton code
    of ``o`` on a ``2^MORTON_BITS`` grid over ``[lo, hi]``."""
    cells = float(1 << MORTON_BITS)
    scale = cells / dr.maximum(hi - lo, 1e-30)
    q = Array3u(dr.clip((o - lo) * scale, 0.0, cells - 1.0))
    morton = _spread(q.x) | (_spread(q.y) << 1) | (_spread(q.z) << 2)
    one, zero = UInt32(1), UInt32(0)
    octant = dr.select(d.x < 0.0, one, zero) | (dr.select(d.y < 0.0, one, zero) << 1) | \
        (dr.select(d.z < 0.0, one, zero) << 2)
    return (octant << (3 * MORTON_BITS)) | morton


def sort_permutation(key: UInt32, bits: int) -> UInt32:
    """A stable permutation sorting ``key`` (values below ``2^bits``):
    least-significant-digit radix sort, one ``block_mkperm`` per digit."""
    n = dr.width(key)
    perm = dr.arange(UInt32, n)
    if n <= 1:
        return perm
    k = UInt32(key)
    shift = 0
    while shift < bits:
        b = min(RADIX_BITS, bits - shift)
        digit = (k >> shift) & ((1 << b) - 1)
        dr.eval(digit)
        p = dr.detail.block_mkperm(digit, n, 1 << b)
        k = dr.gather(UInt32, k, p)
        perm = dr.gather(UInt32, perm, p)
        dr.eval(k, perm)
        shift += b
    return perm


@dataclass
class WaveStage:
    name: str
    wall_ms: float = 0.0
    kernel_ms: float = 0.0
    launches: int = 0
    jit_kernels: int = 0
    lanes: int = 0  # sum of kernel sizes (history), else lanes entering the stage
    rays: int = 0
    codegen_ms: float = 0.0


@dataclass
class WaveStats:
    """Per-stage totals of a wavefront render and the live paths per bounce."""

    stages: dict[str, WaveStage] = field(default_factory=dict)
    live: list[list[int]] = field(default_factory=list)  # per sample(): live paths at each bounce
    history: bool = False  # read dr.kernel_history() at stage ends

    def stage(self, name: str) -> WaveStage:
        if name not in self.stages:
            self.stages[name] = WaveStage(name)
        return self.stages[name]


class _Timer:
    def __init__(self, stats: WaveStats | None):
        self.stats = stats
        if stats is not None:
            dr.sync_thread()
            self._record(stats.stage(OUTSIDE), self._drain())  # the renderer's work before sample()
            self.t = time.perf_counter()

    def _drain(self) -> list:
        return dr.kernel_history() if self.stats.history else []

    @staticmethod
    def _record(st: WaveStage, hist: list) -> None:
        for h in hist:
            st.kernel_ms += float(h.get("execution_time", 0.0))
            st.codegen_ms += float(h.get("codegen_time", 0.0))
            st.launches += 1
            st.jit_kernels += str(h["type"]).endswith("JIT")
            st.lanes += int(h.get("size", 0))

    def done(self, name: str, *outputs, lanes: int = 0, rays: int = 0) -> None:
        arrays = []
        for x in outputs:
            if isinstance(x, dr.ArrayBase):
                arrays.append(x)
            elif x is not None:
                arrays += _arrays(x)
        if arrays:
            dr.eval(*arrays)
        if self.stats is None:
            return
        dr.sync_thread()
        now = time.perf_counter()
        st = self.stats.stage(name)
        st.wall_ms += (now - self.t) * 1e3
        st.rays += rays
        self._record(st, self._drain())
        if not self.stats.history:
            st.lanes += lanes
        self.t = time.perf_counter()


class _Queue:
    """The shading code of the materials whose components are of ``kinds``."""

    def __init__(self, scene: DeviceScene, kinds: tuple[str, ...]):
        self.kinds = kinds
        self.scene = scene.restricted(kinds)
        self.direct = DirectLight(self.scene)


@loops_once
@dr.syntax
def _fused_loop(integ: PathIntegrator, scene: DeviceScene, state: PathState, rng: PCG32) -> Array3f:
    while state.active:
        state = integ.bounce(scene, state, rng)
    return state.L


class WavefrontIntegrator:
    """Path tracing as a sequence of kernels per bounce (see the module docs)."""

    def __init__(self, scene: DeviceScene, options: PathOptions, sort: bool = True, tail: int = 0):
        self.scene = scene
        self.opt = options
        self.sort = sort
        self.tail = tail  # finish in one fused loop once at most this many paths live (0: never)
        self._fused = PathIntegrator(scene, options)
        self.stats: WaveStats | None = None
        self.queues: list[_Queue] = []
        self._queue_of = None
        mats = scene.materials
        if hasattr(mats, "material_kinds"):
            sigs = sorted(set(mats.material_kinds))
            self.queues = [_Queue(scene, s) for s in sigs]
            self._queue_of = UInt32([sigs.index(s) for s in mats.material_kinds])

    # ------------------------------------------------------------------ entry
    def sample(self, rng: PCG32, o: Array3f, d: Array3f, active: Bool) -> Array3f:
        """Radiance arriving at ``o`` from ``-d``, one path per lane (as
        :meth:`PathIntegrator.sample`, the same random numbers per path)."""
        self._rng_kind = type(rng)
        rng_a, rng_b = pack(rng)
        n = max(dr.width(o), dr.width(d), dr.width(active), dr.width(rng_a))
        timer = _Timer(self.stats)
        L = dr.zeros(Array3f, n)
        s = self._start_state(o, d, n, rng_a, rng_b)
        alive = Bool(active) | dr.zeros(Bool, n)
        timer.done("compact + sort", s, alive, L)
        live = []
        self._bounds_from = 0
        while True:
            s, m = self._compact(s, alive, timer)
            if m == 0:
                break
            live.append(m)
            if m <= self.tail:
                self._finish(s, L, timer)
                break
            s, alive = self._stages(s, L, timer)
        if self.stats is not None:
            self.stats.live.append(live)
        return L

    def _start_state(self, o: Array3f, d: Array3f, n: int, rng_a: UInt64, rng_b: UInt64) -> WaveState:
        """The ``n`` camera paths' state (the megakernel's ``_start``, as buffers)."""
        return WaveState(lane=dr.arange(UInt32, n), o=Array3f(o) + dr.zeros(Array3f, n),
                         d=Array3f(d) + dr.zeros(Array3f, n),
                         beta=dr.full(Array3f, 1.0, n), eta=dr.full(Float, 1.0, n),
                         depth=dr.zeros(UInt32, n), prev_pdf=dr.full(Float, 1.0, n),
                         prev_delta=dr.full(Bool, True, n),
                         rng_state=UInt64(rng_a) + dr.zeros(UInt64, n),
                         rng_inc=UInt64(rng_b) + dr.zeros(UInt64, n),
                         ref_p=Array3f(o) + dr.zeros(Array3f, n) if sees_from_vertex(self.scene) else None)

    # ------------------------------------------------------------------ stages
    def _finish(self, s: WaveState, L: Array3f, timer: _Timer) -> None:
        """The last few paths in one fused loop of the megakernel's bounce (the
        same random numbers in the same order), their radiance added at their lanes."""
        m = dr.width(s.lane)
        rng = unpack(self._rng_kind, UInt64(s.rng_state), UInt64(s.rng_inc))
        dr.scatter_add(L, _fused_loop(self._fused, self.scene, self._loop_state(s, m), rng), s.lane)
        timer.done("fused tail", L, lanes=m)

    def _loop_state(self, s: WaveState, m: int) -> PathState:
        """The ``m`` paths of ``s`` as the fused loop's state."""
        return PathState(o=s.o, d=s.d, L=dr.zeros(Array3f, m), beta=s.beta, eta=s.eta, depth=s.depth,
                         prev_pdf=s.prev_pdf, prev_delta=s.prev_delta, active=dr.full(Bool, True, m),
                         ref_p=s.ref_p)

    def _compact(self, s: WaveState, alive: Bool, timer: _Timer) -> tuple[WaveState, int]:
        idx = dr.compress(alive)
        m = dr.width(idx)
        if m == 0:
            return s, 0
        if self.sort and m > 1:
            o, d = _take(s.o, idx), _take(s.d, idx)
            if self._bounds_from < 2:  # the camera's origins, then the first hits': reused after
                self._bounds = (Array3f(dr.min(o.x), dr.min(o.y), dr.min(o.z)),
                                Array3f(dr.max(o.x), dr.max(o.y), dr.max(o.z)))
                dr.eval(self._bounds)
                self._bounds_from += 1
            key = ray_key(o, d, *self._bounds)
            perm = sort_permutation(key, KEY_BITS)
            idx = dr.gather(UInt32, idx, perm)
        s = gather_state(s, idx)
        timer.done("compact + sort", s, lanes=m)
        return s, m

    def _stages(self, s: WaveState, L: Array3f, timer: _Timer) -> tuple[WaveState, Bool]:
        scene, opt = self.scene, self.opt
        n = dr.width(s.lane)

        # ---- closest hit
        hit = scene.intersect_preliminary(s.o, s.d, dr.full(Bool, True, n), coherent=s.depth == 0)
        timer.done("closest hit", hit, lanes=n, rays=n)
        si = skip_hidden_emitters(scene, opt, scene.interaction(s.o, s.d, hit), s, None)
        timer.done("interaction", si, lanes=n)

        # ---- emission (the megakernel's own code)
        add = add_emission(scene, opt, si, s, dr.zeros(Array3f, n), None)
        dr.scatter_add(L, add, s.lane)
        cont = Bool(si.valid)
        if opt.max_depth >= 0:
            cont &= s.depth + 1 < opt.max_depth
        timer.done("emission", L, cont, lanes=n)

        # ---- shading queues: a counting sort of the continuing paths by queue
        nq = len(self.queues)
        nxt = WaveState(lane=UInt32(s.lane), o=dr.zeros(Array3f, n), d=dr.zeros(Array3f, n),
                        beta=dr.zeros(Array3f, n), eta=dr.zeros(Float, n), depth=dr.zeros(UInt32, n),
                        prev_pdf=dr.zeros(Float, n), prev_delta=dr.zeros(Bool, n),
                        rng_state=dr.zeros(UInt64, n), rng_inc=dr.zeros(UInt64, n),
                        ref_p=None if s.ref_p is None else dr.zeros(Array3f, n))
        alive = dr.zeros(Bool, n)
        if nq == 0:
            return nxt, alive
        qid = dr.select(cont, dr.gather(UInt32, self._queue_of, si.material, cont), nq)
        ranges = self._partition(qid, nq)
        timer.done("partition", *(r[0] for r in ranges), lanes=n)

        # shadow queries, one buffer set per estimator slot (one: the sampled emitter),
        # written by every queue at its paths' positions
        queries: list[ShadowQuery] = []
        dr.eval(nxt, alive)
        for queue, (idx, count) in zip(self.queues, ranges):
            if count == 0:
                continue
            qs = gather_state(s, idx)
            qsi = dr.gather(type(si), si, idx)
            out, found, live = self._shade(queue, qs, qsi)
            for f in fields(nxt):
                if f.name != "lane" and getattr(nxt, f.name) is not None:
                    dr.scatter(getattr(nxt, f.name), getattr(out, f.name), idx)
            dr.scatter(alive, live, idx)
            for slot, q in enumerate(found):
                if slot == len(queries):
                    buf = ShadowQuery(dr.zeros(Array3f, n), dr.zeros(Array3f, n), dr.zeros(Array3f, n),
                                      dr.zeros(Float, n), dr.zeros(Bool, n))
                    dr.eval(buf.value, buf.o, buf.d, buf.tmax, buf.ok)
                    queries.append(buf)
                buf = queries[slot]
                for f in ("value", "o", "d", "tmax", "ok"):
                    dr.scatter(getattr(buf, f), getattr(q, f), idx)
            timer.done("shade", nxt, alive, *queries, lanes=count)

        # ---- shadow rays: one batch
        self._shadow(queries, s.lane, L, timer)
        return nxt, alive

    def _partition(self, qid: UInt32, nq: int) -> list[tuple[UInt32, int]]:
        """(lane indices, count) of each queue: a stable counting sort of ``qid``
        (``nq`` = the paths that end)."""
        n = dr.width(qid)
        if nq == 1:
            idx = dr.compress(qid == 0)
            return [(idx, dr.width(idx))]
        buckets = 1 << max(1, (nq).bit_length())
        counts = dr.zeros(UInt32, buckets)
        dr.scatter_reduce(dr.ReduceOp.Add, counts, UInt32(1), qid)
        dr.eval(qid)
        perm = dr.detail.block_mkperm(qid, n, buckets)
        c = counts.numpy()
        out, start = [], 0
        for q in range(nq):
            k = int(c[q])
            out.append((dr.gather(UInt32, perm, dr.arange(UInt32, k) + dr.opaque(UInt32, start))
                        if k else UInt32(), k))
            start += k
        return out

    def _shade(self, queue: _Queue, s: WaveState, si: Interaction):
        """Next-event estimation (as shadow queries), BSDF sampling and Russian
        roulette of one queue's paths (as PathIntegrator.bounce)."""
        scene, opt = queue.scene, self.opt
        rng = unpack(self._rng_kind, UInt64(s.rng_state), UInt64(s.rng_inc))
        active = dr.full(Bool, True, dr.width(s.lane))
        found: list[ShadowQuery] = []
        u_sel = rng.next_float32()
        u_light = next_2d(rng)
        if scene.has_emitters and scene.has_smooth_bsdfs:
            u_sel, u_light = light_sample(scene, rng, u_sel, u_light, active)
            found.append(queue.direct.emitter_query(si, u_sel, u_light, active, mis=True))
        for q in found:  # the path's throughput, as the megakernel's L + beta * estimate
            q.value = s.beta * q.value
            q.ok = q.ok & (dr.max(q.value) != 0.0)

        wo, bs, beta, eta, depth, live = continue_path(scene, opt, si, s, rng)
        out = WaveState(lane=s.lane, o=scene.spawn(si, wo), d=Array3f(wo), beta=beta, eta=eta,
                        depth=depth, prev_pdf=Float(bs.pdf), prev_delta=Bool(bs.delta),
                        **dict(zip(("rng_state", "rng_inc"), pack(rng))),
                        ref_p=None if s.ref_p is None else Array3f(si.p))
        return out, found, live

    def _shadow(self, queries: list[ShadowQuery], lanes: UInt32, L: Array3f, timer: _Timer) -> None:
        """Trace the bounce's shadow queries (one per estimator slot and path) as
        one batch, compacted to those that can contribute, then add the
        unoccluded contributions slot by slot."""
        if not queries:
            return
        picks = [dr.compress(q.ok) for q in queries]
        counts = [dr.width(i) for i in picks]
        total = sum(counts)
        if total == 0:
            return

        def batch(get):
            vals = [_take(get(q), i) for q, i, k in zip(queries, picks, counts) if k]
            if len(vals) == 1:
                return vals[0]
            if isinstance(vals[0], Array3f):
                return Array3f(*(dr.concat([v[c] for v in vals]) for c in range(3)))
            return dr.concat(vals)

        o, d, tmax = batch(lambda q: q.o), batch(lambda q: q.d), batch(lambda q: q.tmax)
        timer.done("shadow rays", o, d, tmax, lanes=total)
        blocked = self.scene.occluded(o, d, tmax, dr.full(Bool, True, total))
        timer.done("shadow rays", blocked, lanes=total, rays=total)
        start = 0
        for q, i, k in zip(queries, picks, counts):
            if not k:
                continue
            b = blocked if k == total else dr.gather(Bool, blocked, dr.arange(UInt32, k) + dr.opaque(UInt32, start))
            dr.scatter_add(L, dr.select(b, 0.0, _take(q.value, i)), _take(lanes, i))
            dr.eval(L)
            start += k
        timer.done("shadow resolve", L, lanes=total)
