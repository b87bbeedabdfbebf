"""Wavefront volumetric path tracing: :mod:`~drpt.render.integrators.volpath`'s estimator,
one stage per kernel.

:class:`VolWavefrontIntegrator` runs the megakernel's bounce
(:meth:`VolPathIntegrator.bounce <drpt.render.integrators.volpath.VolPathIntegrator.bounce>`)
as the wavefront integrator's stages (:mod:`~drpt.render.integrators.wavefront`: compaction
and the coherence sort, then per bounce), each stage calling volpath's own per-event
functions on its lanes, with the same random numbers in the same order:

1. **closest hit** (``closest hit``, ``interaction``): Russian roulette and the depth limit
   (``roulette``: one random number), then the closest hit of the lanes that go on;
2. **free flight** (``free flight``): distance sampling in the ray's medium (``free_flight``)
   and what the ray reaches if it reaches a surface or escapes (``emitted``, added to the
   radiance buffer); the lanes are then sorted by event (a counting sort, as the
   wavefront's queues): a medium event (a scattering event below the depth limit) goes to
   the **medium queue**, a surface to the
   shading queue of its material's lobe kinds, and the rest (escaped, absorbed, a
   scattering event at the depth limit) end;
3. **medium queue** (``medium``): next-event estimation with the phase function and phase
   sampling (``nee_query`` and ``next_ray`` of a :class:`~drpt.render.integrators.volpath.Flight`
   with ``medium`` only: no BSDF code is traced);
4. **shading queues** (``shade``): next-event estimation with the BSDF and BSDF sampling,
   null boundaries and medium transitions (``surface`` only, on the queue's
   :meth:`~drpt.render.scene.DeviceScene.restricted` scene: only its lobes are traced);
5. **shadow rays** (``shadow rays``, ``shadow resolve``): every queue writes its shadow
   query (one per path) at its paths' positions; those that can contribute are compacted
   into one batch whose transmittance (``VolPathIntegrator.shadow``: media, null boundaries,
   thin sheets) is one kernel, and ``a * tr * b`` is added at the paths' lanes. In a scene
   with a heterogeneous medium the shadow ray's ratio tracking draws from the path's
   stream between next-event estimation and the next direction, so there each queue
   traces its shadow rays inside its own kernel (the same numbers as the megakernel).

The buffers carry volpath's state (:class:`VolWaveState`: the wavefront's, plus the ray's
medium and the last real scattering point). With ``tail`` the last paths finish in one fused
loop of ``VolPathIntegrator.bounce``.

As for the path integrator's wavefront, a path is the megakernel's ``sample`` of the same
lane stream (float rounding aside), and a seed gives the same image bit for bit; the
renderer runs it with one path per lane.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import drjit as dr
from drjit.auto import Array3f, Bool, Float, UInt32, UInt64

from ...options import PathOptions
from ...scene.model import Scene
from ..sampler import pack, unpack
from ..scene import DeviceScene
from .volpath import Flight, VolPathIntegrator, VolPathState, VolShadowQuery
from .wavefront import WavefrontIntegrator, WaveState, _take, _Timer, gather_state


@dataclass
class VolWaveState(WaveState):
    """The wavefront's buffers plus volpath's state (``ref_p``: the last real scattering
    event, always carried)."""

    medium: UInt32  # 1-based medium id of the ray, 0 in vacuum


#: the Flight arrays the free-flight stage writes for the queues
_FLIGHT = ("beta", "depth", "scatter", "scatter_live", "surf", "p_med", "in_medium", "g")
#: those a surface queue reads
_SURFACE = ("beta", "depth", "surf")
#: the shadow query's buffers
_QUERY = ("a", "b", "o", "d", "tmax", "medium", "ok")


def _vol_state(s: WaveState, active: Bool, L: Array3f | None = None) -> VolPathState:
    """The buffers ``s`` as volpath's loop state (what its per-event steps read)."""
    return VolPathState(o=s.o, d=s.d, L=L, beta=s.beta, eta=s.eta, depth=s.depth, prev_pdf=s.prev_pdf,
                        prev_delta=s.prev_delta, ref_p=s.ref_p, medium=s.medium, active=active)


class VolWavefrontIntegrator(WavefrontIntegrator):
    """Volumetric path tracing as a sequence of kernels per bounce (see the module docs)."""

    def __init__(self, scene: DeviceScene, options: PathOptions, model: Scene, sort: bool = True,
                 tail: int = 0):
        super().__init__(scene, options, sort=sort, tail=tail)
        self._fused = VolPathIntegrator(scene, options, model)
        #: the shadow rays draw random numbers (ratio tracking): traced inside each queue
        self.inline_shadows = self._fused.shadow_draws

    # ------------------------------------------------------------------ state
    def _start_state(self, o: Array3f, d: Array3f, n: int, rng_a: UInt64, rng_b: UInt64) -> VolWaveState:
        st = self._fused._start(Array3f(o) + dr.zeros(Array3f, n), Array3f(d) + dr.zeros(Array3f, n),
                                dr.full(Bool, True, n))
        return VolWaveState(lane=dr.arange(UInt32, n), o=st.o, d=st.d, beta=st.beta, eta=st.eta,
                            depth=st.depth, prev_pdf=st.prev_pdf, prev_delta=st.prev_delta,
                            rng_state=UInt64(rng_a) + dr.zeros(UInt64, n),
                            rng_inc=UInt64(rng_b) + dr.zeros(UInt64, n), ref_p=st.ref_p, medium=st.medium)

    def _loop_state(self, s: VolWaveState, m: int) -> VolPathState:
        return _vol_state(s, dr.full(Bool, True, m), L=dr.zeros(Array3f, m))

    def _rng(self, s: WaveState):
        return unpack(self._rng_kind, UInt64(s.rng_state), UInt64(s.rng_inc))

    # ------------------------------------------------------------------ stages
    def _stages(self, s: VolWaveState, L: Array3f, timer: _Timer) -> tuple[VolWaveState, Bool]:
        scene, integ = self.scene, self._fused
        n = dr.width(s.lane)

        # ---- Russian roulette, closest hit
        rng = self._rng(s)
        active, beta = integ.roulette(_vol_state(s, dr.full(Bool, True, n)), rng)
        draw = integ.flight_draw(_vol_state(s, active), active, rng)
        hit = scene.intersect_preliminary(s.o, s.d, active, integ.query_reach(draw[2]))
        rng_a, rng_b = pack(rng)
        timer.done("closest hit", hit, active, beta, rng_a, rng_b, *draw, lanes=n, rays=n)
        si = scene.interaction(s.o, s.d, hit)
        timer.done("interaction", si, lanes=n)

        # ---- free flight and what the ray reaches
        rng = unpack(self._rng_kind, rng_a, rng_b)
        vs = _vol_state(s, active)
        fl = integ.free_flight(vs, si, active, beta, rng, draw)
        si = integ.skip_emitters(scene, vs, si, fl)
        dr.scatter_add(L, integ.emitted(scene, vs, si, fl), s.lane)
        si = integ.past_collision(si, fl)
        on_surface = fl.surf & si.valid
        s = VolWaveState(**{**{f.name: getattr(s, f.name) for f in fields(s)},
                            **dict(zip(("rng_state", "rng_inc"), pack(rng)))})
        nq = len(self.queues)
        med_q = nq  # the medium queue after the surface queues; nq + 1: the paths that end
        qid = dr.select(fl.scatter_live, med_q, nq + 1)
        if nq:
            qid = dr.select(on_surface, dr.gather(UInt32, self._queue_of, si.material, on_surface), qid)
        timer.done("free flight", L, qid, s.rng_state, s.rng_inc,
                   *(getattr(fl, f) for f in _FLIGHT), lanes=n)
        ranges = self._partition(qid, nq + 1)
        timer.done("partition", *(r[0] for r in ranges), lanes=n)

        # ---- the queues: medium events and surfaces by lobe kinds
        nxt = VolWaveState(lane=UInt32(s.lane), o=dr.zeros(Array3f, n), d=dr.zeros(Array3f, n),
                           beta=dr.zeros(Array3f, n), eta=dr.zeros(Float, n), depth=dr.zeros(UInt32, n),
                           prev_pdf=dr.zeros(Float, n), prev_delta=dr.zeros(Bool, n),
                           rng_state=dr.zeros(UInt64, n), rng_inc=dr.zeros(UInt64, n),
                           ref_p=dr.zeros(Array3f, n), medium=dr.zeros(UInt32, n))
        alive = dr.zeros(Bool, n)
        query = None
        dr.eval(nxt, alive)
        for q, (idx, count) in enumerate(ranges):
            if count == 0:
                continue
            medium = q == med_q
            qscene = scene if medium else self.queues[q].scene
            qs = gather_state(s, idx)
            qsi = dr.gather(type(si), si, idx)
            qfl = Flight(**{f: _take(getattr(fl, f), idx) if medium or f in _SURFACE else None for f in _FLIGHT},
                         medium=medium, surface=not medium)
            out, live, found, add = self._event(qscene, qs, qsi, qfl)
            for f in fields(nxt):
                if f.name != "lane" and getattr(nxt, f.name) is not None:
                    dr.scatter(getattr(nxt, f.name), getattr(out, f.name), idx)
            dr.scatter(alive, live, idx)
            for a in add:  # (the mirrored emission, sheet_split; shadow rays traced in the queue's kernel)
                dr.scatter_add(L, a, qs.lane)
            if found is not None and not self.inline_shadows:
                if query is None:
                    query = VolShadowQuery(dr.zeros(Array3f, n), dr.zeros(Float, n), dr.zeros(Array3f, n),
                                           dr.zeros(Array3f, n), dr.zeros(Float, n), dr.zeros(UInt32, n),
                                           dr.zeros(Bool, n))
                    dr.eval(*(getattr(query, f) for f in _QUERY))
                for f in _QUERY:
                    dr.scatter(getattr(query, f), getattr(found, f), idx)
            timer.done("medium" if medium else "shade", nxt, alive, L,
                       *((getattr(query, f) for f in _QUERY) if query is not None else ()), lanes=count)

        # ---- shadow rays: one batch
        if query is not None:
            self._transmit(query, s.lane, L, timer)
        return nxt, alive

    def _event(self, scene: DeviceScene, s: VolWaveState, si, fl: Flight):
        """Next-event estimation and the next ray of one queue's paths (as
        VolPathIntegrator.bounce): ``(next state, live, shadow query or None, the radiance
        terms added here, in order)``."""
        integ = self._fused
        rng = self._rng(s)
        m = dr.width(s.lane)
        vs = _vol_state(s, dr.full(Bool, True, m))
        on_surface = Bool(fl.surf) & si.valid if fl.surface else Bool(False)
        split = integ.sheet_split(vs, si, fl, on_surface)
        add = () if split is None else (split[0],)  # (added in this order: the megakernel's)
        phase = integ.phase(vs, fl)
        q = integ.nee_query(scene, vs, si, fl, on_surface, phase, rng)
        if q is not None and self.inline_shadows:
            add += (q.resolve(integ.shadow(q.o, q.d, q.tmax, q.medium, q.ok, rng)),)
        if q is not None and not self.inline_shadows:
            q.ok = q.ok & (dr.max(q.a) != 0.0)
        nx = integ.next_ray(scene, vs, si, fl, on_surface, phase, None, rng,
                            split=None if split is None else split[1])
        out = VolWaveState(lane=s.lane, o=nx.o, d=Array3f(nx.d), beta=nx.beta, eta=Float(nx.eta),
                           depth=UInt32(nx.depth), prev_pdf=Float(nx.prev_pdf), prev_delta=Bool(nx.prev_delta),
                           **dict(zip(("rng_state", "rng_inc"), pack(rng))), ref_p=Array3f(nx.ref_p),
                           medium=UInt32(nx.medium))
        return out, nx.active, q, add

    def _transmit(self, query: VolShadowQuery, lanes: UInt32, L: Array3f, timer: _Timer) -> None:
        """The bounce's shadow queries that can contribute, compacted into one batch: their
        transmittance through media and boundaries, ``a * tr * b`` added at their lanes."""
        pick = dr.compress(query.ok)
        k = dr.width(pick)
        if k == 0:
            return
        o, d, tmax, med = (_take(getattr(query, f), pick) for f in ("o", "d", "tmax", "medium"))
        timer.done("shadow rays", o, d, tmax, med, lanes=k)
        tr = self._fused.shadow(o, d, tmax, med, dr.full(Bool, True, k))
        timer.done("shadow rays", tr, lanes=k, rays=k)
        add = _take(query.a, pick) * tr * _take(query.b, pick)
        dr.scatter_add(L, add, _take(lanes, pick))
        timer.done("shadow resolve", L, lanes=k)
