"""Named indices of refraction, as Mitsuba 3 knows them (backend-free).

Mitsuba's dielectric plugins (``dielectric``, ``thindielectric``,
``roughdielectric``, ``plastic``, ``roughplastic``) take ``int_ior`` and
``ext_ior`` either as a number or as the name of a medium, looked up in the
table of ``include/mitsuba/render/ior.h`` (``lookup_ior``: the name is
lower-cased, then matched exactly). :data:`NAMED` is that table, value for
value: Mitsuba's comment says the numbers are mostly from Hecht, *Optics*, 4th
edition, measured between 0 and 20 degrees Celsius at about 589 nm (the sodium
D line). Mitsuba stores them as float32; :func:`lookup_ior` returns the
decimal values below (rounding them to float32 gives Mitsuba's numbers).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

#: Medium name (lower case) -> index of refraction; Mitsuba 3's ``ior_data``.
NAMED: dict[str, float] = {
    # gases
    "vacuum": 1.0,
    "helium": 1.000036,
    "hydrogen": 1.000132,
    "air": 1.000277,
    "carbon dioxide": 1.00045,
    # liquids
    "water": 1.3330,
    "acetone": 1.36,
    "ethanol": 1.361,
    "carbon tetrachloride": 1.461,
    "glycerol": 1.4729,
    "benzene": 1.501,
    "silicone oil": 1.52045,
    "bromine": 1.661,
    # solids
    "water ice": 1.31,
    "fused quartz": 1.458,
    "pyrex": 1.470,
    "acrylic glass": 1.49,
    "polypropylene": 1.49,
    "bk7": 1.5046,
    "sodium chloride": 1.544,
    "amber": 1.55,
    "pet": 1.5750,
    "diamond": 2.419,
}


def lookup_ior(value: Any, what: str = "ior") -> float:
    """An index of refraction from a number or a medium name of :data:`NAMED`
    (any case, as Mitsuba's ``lookup_ior``).

    Raises ``ValueError`` (naming ``what``) for an unknown name, and for a
    number that is not finite and positive (Mitsuba refuses negative values;
    0 would make the relative IOR 0 or infinite).
    """
    if isinstance(value, str):
        key = value.strip().lower()
        if key not in NAMED:
            raise ValueError(f"{what}: unknown medium {value!r}; known: {', '.join(NAMED)}")
        return NAMED[key]
    if isinstance(value, bool):
        raise ValueError(f"{what}: expected a number or a medium name, got {value!r}")
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{what}: expected a number or a medium name, got {value!r}") from None
    if not (math.isfinite(x) and x > 0.0):
        raise ValueError(f"{what}: an index of refraction must be finite and > 0, got {value!r}")
    return x


def relative_ior(int_ior: Any, ext_ior: Any) -> float:
    """``int_ior / ext_ior`` (each a number or a name), computed as Mitsuba does:
    both rounded to float32, divided in float32 (the returned float is that
    float32 value exactly)."""
    i = np.float32(lookup_ior(int_ior, "int_ior"))
    e = np.float32(lookup_ior(ext_ior, "ext_ior"))
    eta = np.float32(i / e)
    if not (np.isfinite(eta) and eta > 0.0):
        raise ValueError(f"int_ior / ext_ior = {int_ior!r} / {ext_ior!r} is not a usable ratio")
    return float(eta)
