"""A modified-Phong BSDF for Mitsuba 3 (which has none), as a Python plugin.

Written against Mitsuba's own API (``mi.BSDF``, ``mi.warp``, ``mi.Frame3f``)
and deliberately *independent* of drpt's kernels in :mod:`drpt.render.bsdf`,
so that comparing the two checks drpt rather than itself. Same model and the
same sampling strategy as ``drpt.render.bsdf.phong``:

    f(wi, wo) = kd / pi + ks (n + 2) / (2 pi) max(0, cos alpha)^n

with ``alpha`` the angle between ``wo`` and the mirror direction of ``wi``
about the normal (the specular term is 0 where ``cos alpha <= 0``, also for
``n = 0``). ``eval`` returns ``f * cos(theta_o)`` as all Mitsuba BSDFs do.
Sampling picks the glossy lobe with probability
``P_s = lum(ks) / (lum(kd) + lum(ks))`` (Rec. 709 weights 0.2126, 0.7152,
0.0722; 0 when both are black), else the diffuse lobe (cosine hemisphere);
the glossy direction has density ``(n + 1) / (2 pi) cos^n alpha`` around the
mirror direction, and a direction below the surface is a failed sample
(weight 0). ``pdf`` is the mixture ``P_s pdf_s + (1 - P_s) pdf_d``. A
``BSDFContext`` that enables only one component (0 = glossy, 1 = diffuse)
restricts eval, pdf and sampling to that lobe.

Like Mitsuba's own BSDFs it is one-sided (zero unless ``cos(theta_i) > 0``
and ``cos(theta_o) > 0``); :func:`to_mitsuba` wraps it in ``twosided``.

Usage::

    from drpt.backend import mitsuba_variant
    mi.set_variant(mitsuba_variant())
    register()                     # idempotent, per variant
    bsdf = mi.load_dict(to_mitsuba(spec))

Properties: ``kd``, ``ks`` (rgb or any texture; default 0.5 and 0), ``ns``
(float, default 1).
"""

from __future__ import annotations

__all__ = ["register", "PLUGIN_NAME"]

PLUGIN_NAME = "drpt_phong"
_LUM = (0.2126, 0.7152, 0.0722)

#: variant name -> plugin class, filled by :func:`register`.
_REGISTERED: dict[str, type] = {}


def _make_class(mi, dr):
    """Build the plugin class for the current variant (``mi.BSDF`` is per variant)."""

    Flags = mi.BSDFFlags

    def lum(c):
        return _LUM[0] * c.x + _LUM[1] * c.y + _LUM[2] * c.z

    class DrptPhongBSDF(mi.BSDF):
        def __init__(self, props):
            mi.BSDF.__init__(self, props)
            self.kd = props.get_texture("kd", 0.5)
            self.ks = props.get_texture("ks", 0.0)
            self.ns = mi.Float(float(props.get("ns", 1.0)))
            if float(props.get("ns", 1.0)) < 0.0:
                raise ValueError("drpt_phong: ns must be >= 0")
            glossy = Flags.GlossyReflection | Flags.FrontSide
            diffuse = Flags.DiffuseReflection | Flags.FrontSide
            self.m_components = [glossy, diffuse]
            self.m_flags = glossy | diffuse

        # ------------------------------------------------------------ helpers
        def _lobes(self, ctx):
            return (ctx.is_enabled(Flags.GlossyReflection, 0),
                    ctx.is_enabled(Flags.DiffuseReflection, 1))

        def _params(self, si, active):
            return self.kd.eval(si, active), self.ks.eval(si, active)

        def _spec_prob(self, kd, ks, has_s, has_d):
            if not has_s:
                return mi.Float(0.0)
            if not has_d:
                return mi.Float(1.0)
            a = dr.maximum(lum(ks), 0.0)
            b = dr.maximum(lum(kd), 0.0)
            s = a + b
            return dr.select(s > 0.0, a / dr.select(s > 0.0, s, 1.0), 0.0)

        def _lobe_pow(self, si, wo):
            """max(0, cos alpha)^n with 0 for cos alpha <= 0."""
            refl = mi.reflect(si.wi)  # (-x, -y, z): mirror about the local normal
            c = dr.dot(refl, wo)
            pos = c > 0.0
            c_safe = dr.select(pos, dr.minimum(c, 1.0), 1.0)
            return dr.select(pos, dr.power(c_safe, self.ns), 0.0)

        def _eval_pdf(self, ctx, si, wo, active):
            has_s, has_d = self._lobes(ctx)
            cos_i = mi.Frame3f.cos_theta(si.wi)
            cos_o = mi.Frame3f.cos_theta(wo)
            ok = active & (cos_i > 0.0) & (cos_o > 0.0)
            kd, ks = self._params(si, ok)
            cn = self._lobe_pow(si, wo)
            value = mi.Color3f(0.0)
            if has_d:
                value += kd * dr.inv_pi
            if has_s:
                value += ks * ((self.ns + 2.0) * (0.5 * dr.inv_pi) * cn)
            value = dr.select(ok, value * cos_o, 0.0)
            p_s = self._spec_prob(kd, ks, has_s, has_d)
            pdf_s = (self.ns + 1.0) * (0.5 * dr.inv_pi) * cn
            pdf_d = mi.warp.square_to_cosine_hemisphere_pdf(wo)
            pdf = dr.select(ok, p_s * pdf_s + (1.0 - p_s) * pdf_d, 0.0)
            return value, pdf

        # ------------------------------------------------------ BSDF interface
        def sample(self, ctx, si, sample1, sample2, active=True):
            has_s, has_d = self._lobes(ctx)
            bs = dr.zeros(mi.BSDFSample3f)
            if not (has_s or has_d):
                return bs, mi.Color3f(0.0)
            cos_i = mi.Frame3f.cos_theta(si.wi)
            active = mi.Bool(active) & (cos_i > 0.0)
            kd, ks = self._params(si, active)
            p_s = self._spec_prob(kd, ks, has_s, has_d)
            pick_s = sample1 < p_s

            # Glossy: inverse CDF of (n+1)/(2pi) cos^n in the frame of the mirror dir.
            # cos = u^(1/(n+1)) = exp(-t); sin^2 = 1 - exp(-2t) is taken from a
            # series for small t, else float32 cancellation blurs sharp lobes.
            t = -dr.log(dr.maximum(sample2.y, 1e-38)) / (self.ns + 1.0)
            t2 = 2.0 * t
            sin2 = dr.select(t2 < 1e-2,
                             t2 * (1.0 - t2 * (0.5 - t2 * (1.0 / 6.0 - t2 * (1.0 / 24.0)))),
                             1.0 - dr.exp(-t2))
            cos_a = dr.exp(-t)
            sin_a = dr.safe_sqrt(sin2)
            sin_phi, cos_phi = dr.sincos(2.0 * dr.pi * sample2.x)
            local = mi.Vector3f(sin_a * cos_phi, sin_a * sin_phi, cos_a)
            wo_s = mi.Frame3f(mi.reflect(si.wi)).to_world(local)
            wo_d = mi.warp.square_to_cosine_hemisphere(sample2)

            bs.wo = dr.select(pick_s, wo_s, wo_d)
            bs.eta = 1.0
            bs.sampled_component = dr.select(pick_s, mi.UInt32(0), mi.UInt32(1))
            bs.sampled_type = dr.select(pick_s, mi.UInt32(+Flags.GlossyReflection),
                                        mi.UInt32(+Flags.DiffuseReflection))
            value, pdf = self._eval_pdf(ctx, si, bs.wo, active)
            ok = active & (pdf > 0.0)
            bs.pdf = dr.select(ok, pdf, 0.0)
            weight = dr.select(ok, value / dr.select(ok, pdf, 1.0), 0.0)
            return bs, weight

        def eval(self, ctx, si, wo, active=True):
            return self._eval_pdf(ctx, si, wo, active)[0]

        def pdf(self, ctx, si, wo, active=True):
            return self._eval_pdf(ctx, si, wo, active)[1]

        def eval_pdf(self, ctx, si, wo, active=True):
            return self._eval_pdf(ctx, si, wo, active)

        def eval_diffuse_reflectance(self, si, active=True):
            return self.kd.eval(si, active)

        def traverse(self, callback):
            callback.put("kd", self.kd, mi.ParamFlags.Differentiable)
            callback.put("ks", self.ks, mi.ParamFlags.Differentiable)
            callback.put("ns", self.ns, mi.ParamFlags.NonDifferentiable)

        def parameters_changed(self, keys=None):
            pass

        def to_string(self):
            return f"DrptPhongBSDF[kd={self.kd}, ks={self.ks}, ns={self.ns}]"

    return DrptPhongBSDF


def register() -> None:
    """Register ``drpt_phong`` with Mitsuba for the current variant (idempotent).

    A variant must already be set (``mi.set_variant``)."""
    import drjit as dr
    import mitsuba as mi

    variant = mi.variant()
    if variant is None:
        raise RuntimeError("set a Mitsuba variant (mi.set_variant) before register()")
    if variant in _REGISTERED:
        return
    cls = _make_class(mi, dr)
    mi.register_bsdf(PLUGIN_NAME, lambda props: cls(props))
    _REGISTERED[variant] = cls
