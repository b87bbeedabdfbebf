"""Writes the mixed-material Cornell box: runs :mod:`drpt.tools.scenegen.materials_cornell` (see there).

    python scenes/make_materials_cornell.py OUT_DIR
"""

import sys
from pathlib import Path

# The checkout's drpt, also when another one is installed.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from drpt.tools.scenegen.materials_cornell import cli  # noqa: E402

if __name__ == "__main__":
    cli()
