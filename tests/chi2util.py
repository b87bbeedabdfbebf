"""Re-export of the chi-square helpers, now in :mod:`drpt.testing` (for tests that import
them from here)."""

from drpt.testing import (  # noqa: F401
    bsdf_chi2,
    export_bsdf,
    mitsuba,
    run_chi2,
    spherical_chi2,
    to_drpt,
    to_mitsuba_float,
    to_mitsuba_vec3,
)
