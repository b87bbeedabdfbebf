"""Complex indices of refraction of conductors (``eta + i k``, per RGB channel):
Mitsuba 3's named materials, as its RGB variants use them. Backend-free.

:data:`MATERIALS` maps each name Mitsuba 3's ``conductor`` and
``roughconductor`` accept for ``material`` (the ``data/ior/<name>.eta.spd``
and ``<name>.k.spd`` pairs shipped with Mitsuba 3.9: every metal and
dielectric in its preset list, including the ``_palik`` and ``-e``
(extraordinary ray) variants) to ``(eta_rgb, k_rgb)``.

How the numbers were obtained (facts measured, not re-derived): Mitsuba
reduces each measured spectrum to an RGB value in ``ior_from_file``
(``spectrum_list_to_srgb``, then an unbounded ``srgb`` texture, with
out-of-gamut negative components clamped to 0 -- hence the zeros, e.g. in
``AlSb``, ``SiC``). We read those values back from Mitsuba 3.9.x itself::

    mi.set_variant("llvm_ad_rgb")
    p = mi.traverse(mi.load_dict({"type": "conductor", "material": name}))
    eta, k = p["eta.value"], p["k.value"]

for every ``name`` in Mitsuba's ``data/ior`` directory, and wrote them here
as the shortest decimal strings that round-trip to the same float32.
``tests/render/bsdf/test_conductor.py`` re-measures them against the installed
Mitsuba.

``material = "none"`` (the default): ``eta = 0, k = 1``, for which the
conductor Fresnel term is exactly 1 (a perfect mirror tinted by
``specular_reflectance``).
"""

from __future__ import annotations

from typing import Any

RGB = tuple[float, float, float]

#: ``material="none"``: Fresnel factor 1.
NONE: tuple[RGB, RGB] = ((0.0, 0.0, 0.0), (1.0, 1.0, 1.0))

#: name -> (eta, k), RGB, as Mitsuba 3.9's RGB variants use them (see the module docs).
MATERIALS: dict[str, tuple[RGB, RGB]] = {
    "a-C": ((2.9440458, 2.2271364, 1.9681617), (0.8874649, 0.7992985, 0.81529)),
    "Ag": ((0.1552762, 0.116727956, 0.13838764), (4.8283544, 3.1222224, 2.1469011)),
    "Al": ((1.6575009, 0.8804047, 0.52124447), (9.223811, 6.269502, 4.837004)),
    "AlAs": ((3.605296, 3.2329378, 2.2163186), (0.0006794373, 0.0, 0.007512709)),
    "AlAs_palik": ((3.605296, 3.2329378, 2.2163186), (0.0006794373, 0.0, 0.007512709)),
    "AlSb": ((0.0, 4.1393747, 4.6692543), (0.0, 0.09400908, 1.30057)),
    "AlSb_palik": ((0.0, 4.1393747, 4.6692543), (0.0, 0.09400908, 1.30057)),
    "Au": ((0.14303598, 0.37530708, 1.4420453), (3.982997, 2.3855565, 1.6033592)),
    "Be": ((4.1850123, 3.1850293, 2.7840612), (3.835466, 3.0101223, 2.868994)),
    "Be_palik": ((4.1850123, 3.1850293, 2.7840612), (3.835466, 3.0101223, 2.868994)),
    "Cr": ((4.3696675, 2.9165053, 1.6549046), (5.206547, 4.231306, 3.7546988)),
    "CsI": ((2.1448996, 1.7023189, 1.6624272), (0.0, 0.0, 0.0)),
    "CsI_palik": ((2.1448996, 1.7023189, 1.6624272), (0.0, 0.0, 0.0)),
    "Cu": ((0.20100547, 0.9237495, 1.1022154), (3.9132621, 2.4530451, 2.1420898)),
    "Cu2O": ((3.5517726, 2.9498696, 2.7518754), (0.11420702, 0.19389686, 0.6061339)),
    "Cu2O_palik": ((3.5517726, 2.9498696, 2.7518754), (0.11420702, 0.19389686, 0.6061339)),
    "Cu_palik": ((0.21322851, 0.9197154, 1.1024108), (3.9218733, 2.4573317, 2.136584)),
    "CuO": ((3.247541, 2.4478052, 2.2102196), (0.52108955, 0.57003075, 0.72217894)),
    "CuO_palik": ((3.247541, 2.4478052, 2.2102196), (0.52108955, 0.57003075, 0.72217894)),
    "d-C": ((2.7087197, 2.3188257, 2.2288976), (0.0, 0.0, 0.0)),
    "d-C_palik": ((2.7087197, 2.3188257, 2.2288976), (0.0, 0.0, 0.0)),
    "Hg": ((2.3989387, 1.440028, 0.9095704), (6.327587, 4.371925, 3.4217637)),
    "Hg_palik": ((2.3989387, 1.440028, 0.9095704), (6.327587, 4.371925, 3.4217637)),
    "HgTe": ((4.77904, 3.2311962, 2.6599011), (1.6316127, 1.5808104, 1.7292874)),
    "HgTe_palik": ((4.77904, 3.2311962, 2.6599011), (1.6316127, 1.5808104, 1.7292874)),
    "Ir": ((3.0863, 2.0821905, 1.6179146), (5.592153, 4.067088, 3.267312)),
    "Ir_palik": ((3.0863, 2.0821905, 1.6179146), (5.592153, 4.067088, 3.267312)),
    "K": ((0.06404319, 0.046409767, 0.038184915), (2.1041996, 1.34894, 0.9131259)),
    "K_palik": ((0.06404319, 0.046409767, 0.038184915), (2.1041996, 1.34894, 0.9131259)),
    "Li": ((0.26579094, 0.19561832, 0.22094862), (3.540155, 2.3111234, 1.6686072)),
    "Li_palik": ((0.26579094, 0.19561832, 0.22094862), (3.540155, 2.3111234, 1.6686072)),
    "MgO": ((2.0895839, 1.6507235, 1.594879), (4.3326952e-12, 0.0, 2.4986457e-11)),
    "MgO_palik": ((2.0895839, 1.6507235, 1.594879), (4.3326952e-12, 0.0, 2.4986457e-11)),
    "Mo": ((4.483974, 3.5251307, 2.7763104), (4.1114373, 3.420827, 3.1506073)),
    "Mo_palik": ((4.483974, 3.5251307, 2.7763104), (4.1114373, 3.420827, 3.1506073)),
    "Na_palik": ((0.060269356, 0.056140948, 0.061988432), (3.1792734, 2.1124904, 1.5790411)),
    "Nb": ((3.420074, 2.7900932, 2.3956294), (3.4413946, 2.7376661, 2.5797458)),
    "Nb_palik": ((3.420074, 2.7900932, 2.3956294), (3.4413946, 2.7376661, 2.5797458)),
    "Ni_palik": ((2.3673046, 1.6633731, 1.4670781), (4.4988117, 3.050153, 2.3454392)),
    "Rh": ((2.5857935, 1.8602164, 1.5542634), (6.7822604, 4.702987, 3.976073)),
    "Rh_palik": ((2.5857935, 1.8602164, 1.5542634), (6.7822604, 4.702987, 3.976073)),
    "Se": ((4.0583115, 2.842935, 2.8208535), (0.75404954, 0.6384435, 0.52180755)),
    "Se-e": ((5.722849, 4.165736, 4.0813384), (0.8711363, 1.1051575, 1.5653203)),
    "Se-e_palik": ((5.722849, 4.165736, 4.0813384), (0.8711363, 1.1051575, 1.5653203)),
    "Se_palik": ((4.0583115, 2.842935, 2.8208535), (0.75404954, 0.6384435, 0.52180755)),
    "SiC": ((3.1723416, 2.5259717, 2.4793706), (7.5376636e-07, 0.0, 1.0192531e-05)),
    "SiC_palik": ((3.1723416, 2.5259717, 2.4793706), (7.5376636e-07, 0.0, 1.0192531e-05)),
    "SnTe": ((4.5242496, 1.981645, 1.2815913), (0.0, 0.0, 0.0)),
    "SnTe_palik": ((4.5242496, 1.981645, 1.2815913), (0.0, 0.0, 0.0)),
    "Ta": ((2.062721, 2.3929389, 2.6279287), (2.4083598, 1.7414864, 1.9470278)),
    "Ta_palik": ((2.062721, 2.3929389, 2.6279287), (2.4083598, 1.7414864, 1.9470278)),
    "Te": ((7.3902335, 4.482105, 2.637106), (3.2560222, 3.5270588, 3.2920542)),
    "Te-e": ((7.508907, 4.2964287, 2.3699877), (5.5839286, 4.947205, 3.9975922)),
    "Te-e_palik": ((7.508907, 4.2964287, 2.3699877), (5.5839286, 4.947205, 3.9975922)),
    "Te_palik": ((7.3902335, 4.482105, 2.637106), (3.2560222, 3.5270588, 3.2920542)),
    "ThF4": ((1.8307136, 1.4422286, 1.3876476), (0.0, 0.0, 0.0)),
    "ThF4_palik": ((1.8307136, 1.4422286, 1.3876476), (0.0, 0.0, 0.0)),
    "TiC": ((3.7005284, 2.8374221, 2.582287), (3.265635, 2.3515892, 2.1727905)),
    "TiC_palik": ((3.7005284, 2.8374221, 2.582287), (3.265635, 2.3515892, 2.1727905)),
    "TiN": ((1.6484497, 1.150516, 1.3798234), (3.368328, 1.9434981, 1.1020677)),
    "TiN_palik": ((1.6484497, 1.150516, 1.3798234), (3.368328, 1.9434981, 1.1020677)),
    "TiO2": ((3.45661, 2.8017359, 2.905175), (0.00010526484, 0.0, 0.0006528865)),
    "TiO2-e": ((3.1065645, 2.5131683, 2.5824444), (2.9751605e-05, 0.0, 0.00018269809)),
    "TiO2-e_palik": ((3.1065645, 2.5131683, 2.5824444), (2.9751605e-05, 0.0, 0.00018269809)),
    "TiO2_palik": ((3.45661, 2.8017359, 2.905175), (0.00010526484, 0.0, 0.0006528865)),
    "V_palik": ((4.277582, 3.5129488, 2.7610714), (3.4913008, 2.8894548, 3.111522)),
    "VC": ((3.657566, 2.752736, 2.532672), (3.0683007, 2.1986873, 1.9631927)),
    "VC_palik": ((3.657566, 2.752736, 2.532672), (3.0683007, 2.1986873, 1.9631927)),
    "VN": ((2.8656023, 2.119189, 1.9400911), (3.0322425, 2.0561156, 1.6163063)),
    "VN_palik": ((2.8656023, 2.119189, 1.9400911), (3.0322425, 2.0561156, 1.6163063)),
    "W": ((4.3708167, 3.3002465, 2.9984074), (3.5006406, 2.604874, 2.2732332)),
}


def _rgb(v, name: str) -> RGB:
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        return (float(v),) * 3
    try:
        t = tuple(float(x) for x in v)
    except TypeError:
        raise ValueError(f"{name} must be a number or an RGB triple, not {v!r}") from None
    if len(t) != 3:
        raise ValueError(f"{name} must be a number or an RGB triple, not {v!r}")
    return t  # type: ignore[return-value]


def complex_ior(material: str) -> tuple[RGB, RGB]:
    """``(eta, k)`` of a named material (``"none"``: ``(0, 1)``); ``ValueError`` if unknown."""
    if material == "none":
        return NONE
    if material not in MATERIALS:
        raise ValueError(f"unknown conductor material {material!r}; valid: none, " + ", ".join(MATERIALS))
    return MATERIALS[material]


def resolve(params: dict[str, Any]) -> tuple[RGB, RGB]:
    """``(eta, k)`` of a ``conductor``/``roughconductor`` spec's parameters:
    the named ``material``'s values, with an explicit ``eta`` and/or ``k``
    replacing the material's (``material="none"``: eta 0, k 1, so ``eta``
    alone gives ``k = 1``, Mitsuba's defaults). Mitsuba refuses a
    ``material`` other than ``none`` together with ``eta``, and ignores
    ``k`` given with a named material and no ``eta``; drpt lets the explicit
    values win (the exporter writes the resolved ``eta``/``k``, see
    :func:`mitsuba_ior`)."""
    eta, k = complex_ior(str(params.get("material", "none") or "none"))
    if params.get("eta") is not None:
        eta = _rgb(params["eta"], "eta")
    if params.get("k") is not None:
        k = _rgb(params["k"], "k")
    for name, v in (("eta", eta), ("k", k)):
        if not all(x == x and abs(x) != float("inf") and x >= 0.0 for x in v):
            raise ValueError(f"{name} must be finite and >= 0, not {v}")
    return eta, k


def mitsuba_ior(params: dict[str, Any]) -> dict[str, Any]:
    """The IOR parameters to write for Mitsuba so that it sees :func:`resolve`'s
    values: ``{"material": name}`` when neither ``eta`` nor ``k`` is given,
    else ``{"eta": rgb, "k": rgb}`` (no ``material``, which Mitsuba would
    refuse next to ``eta``)."""
    if params.get("eta") is None and params.get("k") is None:
        return {"material": str(params.get("material", "none") or "none")}
    eta, k = resolve(params)
    return {"eta": eta, "k": k}
