"""Regenerates the Mitsuba 3 reference images in reference/.

Each bundled scene is exported with drpt's Mitsuba exporter and rendered by
Mitsuba's ``path`` integrator at high spp; the EXR holds linear float32 RGB.
Run from the repository root:

    .venv/bin/python reference/make_references.py            # all
    .venv/bin/python reference/make_references.py cornellbox # one

The table of references, the batches and the generated scenes live in
:mod:`drpt.tools.reference` (``REFERENCES``, ``BATCHES``, ``GENERATED``);
this script renders them with :func:`drpt.tools.reference.render_committed`.
"""

import sys
from pathlib import Path

# The checkout's drpt, also when another one is installed.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from drpt.tools.reference import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
