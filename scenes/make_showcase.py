"""Writes scenes/showcase/: runs :mod:`drpt.tools.scenegen.showcase` (see there).

    python scenes/make_showcase.py --help
"""

import sys
from pathlib import Path

# The checkout's drpt, also when another one is installed.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from drpt.tools.scenegen.showcase import cli  # noqa: E402

if __name__ == "__main__":
    cli()
