"""Perturbed shading frames: Mitsuba's ``normalmap`` and ``bumpmap``.

Both wrap one BSDF and show it a shading frame tilted by a texture, for
``eval``, ``pdf`` and ``sample`` alike. The math is Mitsuba's
(``src/bsdfs/normalmap.cpp``, ``bumpmap.cpp``, ``normalmap_helpers.h``), in
the coordinates of the interaction's own shading frame ``F`` (its tangent
follows ``dp/du``; inside ``twosided`` seen from behind, ``F`` is mirrored
to ``(s, t, -n)``), where the perturbed normal is ``n'`` and the perturbed
frame ``P = (s', t', n')``:

``normalmap``
    ``n' = 2 c - 1`` of the texture's RGB ``c`` (a *tangent-space* normal:
    ``x`` along ``dp/du``), ``s' = normalize((1, 0, 0) - n' n'.x)``.
``bumpmap``
    the height ``h`` (the texture's luminance) moves the surface along the
    shading normal ``N``: ``dp/du' = dp/du + N (scale dh/du - N . dp/du)``
    (likewise ``v``), ``n' = normalize(dp/du' x dp/dv')`` turned to the
    geometric normal's side, in ``F``'s coordinates;
    ``s' = normalize(dp/du - n' (n' . dp/du))`` with the *world* ``dp/du``
    (as Mitsuba computes it: only the tangent's angle about ``n'`` depends
    on it, which an isotropic BSDF does not see).

``flip_invalid_normals`` (default on) mirrors ``n'``'s ``x, y`` where the
viewer would be behind ``n'`` (``wi.z * (wi . n') <= 0``). Then the nested
BSDF sees ``wi`` and ``wo`` in ``P``; a direction counts only where it is on
the same side of ``F`` and of ``P`` (``F.z * P.z > 0``), and with
``use_shadowing_function`` (default on) ``f`` is multiplied by the
shadowing term of Estevez et al. 2019 (Ray Tracing Gems, "A Microfacet-Based
Shadowing Function to Solve the Bump Terminator Problem"):
``G = 2 / (1 + sqrt(1 + alpha2 tan^2 theta_o))``, ``alpha2 =
min(tan^2 theta_n' / 8, 1)`` (angles against ``F``'s normal).
"""

from __future__ import annotations

import drjit as dr
from drjit.auto import Array2f, Array3f, Bool, Float

from .warp import Frame


def _tan2(z: Float) -> Float:
    """``tan^2`` of the angle whose cosine is ``z`` (Mitsuba's ``Frame::tan_theta_2``)."""
    z2 = dr.square(z)
    return dr.maximum(1.0 - z2, 0.0) / z2


def shadow_terminator(n_local: Array3f, wo_local: Array3f) -> Float:
    """Estevez et al.'s shadowing term for the perturbed normal ``n_local`` and the
    direction ``wo_local``, both in the unperturbed frame (1 for an unperturbed normal)."""
    alpha2 = dr.minimum(0.125 * _tan2(n_local.z), 1.0)
    g = 2.0 / (1.0 + dr.sqrt(dr.fma(alpha2, _tan2(wo_local.z), 1.0)))
    return dr.select(alpha2 > 0.0, g, 1.0)


def flip_invalid(n: Array3f, wi_local: Array3f) -> Array3f:
    """Mitsuba's ``flip_invalid_normals``: ``n``'s ``x, y`` mirrored where the viewer
    ``wi_local`` is behind it."""
    flip = wi_local.z * dr.dot(wi_local, n) <= 0.0
    return Array3f(dr.select(flip, -n.x, n.x), dr.select(flip, -n.y, n.y), n.z)


def normalmap_normal(rgb: Array3f) -> Array3f:
    """The tangent-space normal a normal map's texel encodes (``2 c - 1``, not normalized)."""
    return dr.fma(rgb, 2.0, -1.0)


def normalmap_tangent(n: Array3f) -> Array3f:
    """``s'`` of a normal map's frame of unit normal ``n`` (local)."""
    s = Array3f(1.0, 0.0, 0.0) - n * n.x
    return _normalize_or(s, Array3f(1.0, 0.0, 0.0))


def bump_normal(grad: Array2f, n_sh: Array3f, ng: Array3f, dp_du: Array3f, dp_dv: Array3f,
                frame: Frame) -> Array3f:
    """A bump map's normal in ``frame``'s coordinates (``frame``: the interaction's
    unmirrored shading frame, normal ``n_sh``) for the height gradient ``grad`` (already
    times ``scale``) along Mitsuba's ``(u, v)``; ``(0, 0, 1)`` where the perturbed
    tangents are degenerate."""
    du = dp_du + n_sh * (grad.x - dr.dot(n_sh, dp_du))
    dv = dp_dv + n_sh * (grad.y - dr.dot(n_sh, dp_dv))
    c = dr.cross(du, dv)
    len2 = dr.squared_norm(c)
    ok = len2 > 1e-36
    n = c * dr.rsqrt(dr.select(ok, len2, 1.0))
    n = dr.select(dr.dot(ng, n) < 0.0, -n, n)
    return dr.select(ok, frame.to_local(n), Array3f(0.0, 0.0, 1.0))


def bump_tangent(n: Array3f, dp_du: Array3f) -> Array3f:
    """``s'`` of a bump map's frame of local unit normal ``n``: Mitsuba's Gram-Schmidt of
    the world ``dp/du`` against the local ``n``."""
    s = dp_du - n * dr.dot(n, dp_du)
    fallback = Frame(n).s
    return _normalize_or(s, fallback)


def _normalize_or(v: Array3f, fallback: Array3f) -> Array3f:
    len2 = dr.squared_norm(v)
    ok = len2 > 1e-30
    return dr.select(ok, v * dr.rsqrt(dr.select(ok, len2, 1.0)), fallback)


class PerturbedFrame(Frame):
    """The frame a perturbed BSDF sees (world axes ``P``), with what ``eval`` and
    ``sample`` need besides: :meth:`factor` (the side check and shadowing term of a
    world direction). ``outer``: the unperturbed frame ``F``; ``n_local``: ``n'`` in
    ``F``; ``mirror``: lanes whose ``P`` is mirrored to ``(s', t', -n')`` (a
    ``twosided`` inside the perturbation, seen from behind ``n'``), or None;
    ``shadow``: whether the shadowing term applies (a Python bool or per lane)."""

    def __init__(self, outer: Frame, n_local: Array3f, s_local: Array3f, mirror=None, shadow=True):
        t_local = dr.cross(n_local, s_local)
        s, t, n = outer.to_world(s_local), outer.to_world(t_local), outer.to_world(n_local)
        self.unmirrored = Frame.from_axes(s, t, n)
        self.s, self.t = s, t
        self.n = n if mirror is None else dr.select(mirror, -n, n)
        self.outer = outer
        self.n_local = n_local
        self.shadow = shadow

    def factor(self, wo: Array3f) -> Float:
        """For world ``wo``: 0 where it is on different sides of ``F`` and ``P``, else
        the shadowing term (or 1)."""
        z_outer = dr.dot(wo, self.outer.n)
        z_inner = dr.dot(wo, self.unmirrored.n)
        ok = z_outer * z_inner > 0.0
        if self.shadow is False:
            return dr.select(ok, 1.0, 0.0)
        wo_l = Array3f(0.0, 0.0, z_outer)  # only its angle to F's normal matters
        g = shadow_terminator(self.n_local, wo_l)
        if self.shadow is not True:
            g = dr.select(Bool(self.shadow), g, 1.0)
        return dr.select(ok, g, 0.0)
