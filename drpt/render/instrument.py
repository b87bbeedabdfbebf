"""Instrumentation hooks: what a measurement tool observes of a render's queries.

An :class:`Instrument` is attached to a device scene
(:attr:`DeviceScene.instrument <drpt.render.scene.DeviceScene.instrument>`,
None by default). The scene and the path integrator call its methods where
the queries are made, *while a kernel is traced*: each call runs once per
trace, in Python, with the lanes' arrays, and whatever the instrument does
with them (a ``dr.scatter_add`` into a counter, say) becomes part of that
kernel. A render without an instrument traces none of it, so its kernels are
the plain ones.

Calls:

* :meth:`Instrument.paths`: :meth:`PathIntegrator.sample_sequence
  <drpt.render.integrators.path.PathIntegrator.sample_sequence>` starts
  tracing a pass's paths on ``lanes`` lanes (before its loop);
* :meth:`Instrument.bounce`: :meth:`PathIntegrator.bounce
  <drpt.render.integrators.path.PathIntegrator.bounce>` (and volpath's) is
  about to trace a path vertex for the lanes of ``state.active``;
* :meth:`Instrument.occluded`: :meth:`DeviceScene.occluded
  <drpt.render.scene.DeviceScene.occluded>` traces the shadow rays of the
  lanes of ``active``;
* :meth:`Instrument.count`: the light-tracing integrators (``ptracer``,
  ``bdpt``) make a query of one of the :data:`LIGHT_KINDS` (a closest hit of a
  subpath, a shadow ray by its purpose, a splat into the film) for the lanes
  of ``active``; their :meth:`Instrument.paths` call names the kinds its kernel
  will count (every shadow ray they trace is also seen by ``occluded``).

The methods here do nothing; a tool subclasses :class:`Instrument` and
overrides those it needs (``drpt profile`` counts each lane's bounces and
shadow rays: :mod:`drpt.tools.profile`). The wavefront integrator's
per-stage timing is its own (``WavefrontIntegrator.stats``).
"""

from __future__ import annotations

#: the queries the light-tracing integrators count (:meth:`Instrument.count`)
HIT_LIGHT = "closest hit: light subpath"
HIT_CAMERA = "closest hit: camera subpath"
SHADOW_EMITTER = "shadow: emitter seen by the camera"
SHADOW_CAMERA = "shadow: light vertex to camera (t = 1)"
SHADOW_NEE = "shadow: next-event (s = 1)"
SHADOW_CONNECT = "shadow: connection (s, t >= 2)"
SPLAT = "splat into the film"
LIGHT_KINDS = (HIT_LIGHT, HIT_CAMERA, SHADOW_EMITTER, SHADOW_CAMERA, SHADOW_NEE, SHADOW_CONNECT, SPLAT)


def count(scene, kind: str, active) -> None:
    """Tell ``scene``'s instrument, if any, of a query of ``kind`` for the lanes of
    ``active`` (no code traced without one)."""
    if scene.instrument is not None:
        scene.instrument.count(kind, active)


class Instrument:
    """Observes queries while kernels are traced; every method is a no-op here."""

    def paths(self, lanes: int, kinds: tuple[str, ...] = ()) -> None:
        """A kernel of ``lanes`` lanes starts tracing paths (path regeneration); it
        will call :meth:`count` with the ``kinds`` named (light tracing; none for the
        path tracer)."""

    def bounce(self, state) -> None:
        """A path vertex is traced for the lanes of ``state.active`` (``state``: the
        integrator's loop state before the vertex)."""

    def occluded(self, o, d, tmax, active) -> None:
        """Shadow rays ``(o, d)`` up to ``tmax`` are traced for the lanes of ``active``."""

    def count(self, kind: str, active) -> None:
        """A query of ``kind`` (one of :data:`LIGHT_KINDS`) is made for the lanes of ``active``."""
