"""Emitters, one module per family: ``area`` (emissive triangles and spheres), ``delta``
(point and directional lights), ``envmap`` (the environment map).

The three families are sampled differently, so each has its own interface,
stated here as a :class:`~typing.Protocol` (what
:class:`drpt.render.scene.DeviceScene` asks of it):

* :class:`AreaEmitter`: one point on an emissive triangle or sphere (chosen by
  the light sampler) with its density, and that density for a point a ray hit (MIS);
* :class:`DeltaEmitter`: every light, as seen from a shading point (BSDF
  sampling never hits them: no MIS);
* :class:`EnvironmentEmitter`: a direction toward the sky with its radiance
  and solid-angle density, and both for a direction a ray escaped in (MIS).
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Protocol

from drjit.auto import Array2f, Array3f, Bool, Float, UInt32


class AreaEmitter(Protocol):
    """Emissive triangles and spheres (:class:`drpt.render.lights.area.AreaLights`)."""

    count: int  # emitters that can be sampled; 0 traces no light sampling

    def sample(self, u_select: Float, u: Array2f, active: Bool, ref: Array3f | None = None):
        """A point on an emitter: a ``LightSample`` (``p``, front normal ``n``,
        geometric normal ``ng``, radiance ``le``, ``pdf_area``, ``valid``; with
        ``ref``, a sphere's lanes in ``solid_angle`` have a solid-angle density)."""
        ...

    def pdf_area(self, prim: UInt32, active: Bool) -> Float:
        """Area density with which :meth:`sample` picks a point on triangle ``prim``."""
        ...


class DeltaEmitter(Protocol):
    """Point and directional lights (:class:`drpt.render.lights.delta.DeltaLights`)."""

    count: int

    def samples(self, p: Array3f) -> Iterator:
        """One ``DeltaSample`` (``wo``, ``dist``, ``irradiance``) per light."""
        ...


class EnvironmentEmitter(Protocol):
    """The environment map (:class:`drpt.render.lights.envmap.EnvironmentLight`,
    or :class:`~drpt.render.lights.envmap.UniformSphereSampling` of it)."""

    is_black: bool  # emits nothing: the scene then traces no environment code
    warnings: list[str]

    def eval(self, d: Array3f, active=True) -> Array3f:
        """Radiance arriving from unit world direction ``d``."""
        ...

    def eval_pdf(self, d: Array3f, active=True) -> tuple[Array3f, Float]:
        """Radiance from ``d`` and the solid-angle density of sampling ``d``."""
        ...

    def sample(self, u: Array2f, active=True) -> tuple[Array3f, Array3f, Float]:
        """A direction toward the sky, its radiance and its density."""
        ...
