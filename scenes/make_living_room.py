"""Writes the living room: runs :mod:`drpt.tools.scenegen.living_room` (see there).

    python scenes/make_living_room.py OUT_DIR
"""

import sys
from pathlib import Path

# The checkout's drpt, also when another one is installed.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from drpt.tools.scenegen.living_room import cli  # noqa: E402

if __name__ == "__main__":
    cli()
