"""Where the tests and benchmarks find the project's shared data (real HRTEM images, peers' outputs).

``$TEXSYNTH_SHARED_DATA`` when set, else ``shared/data`` beside the checkout (the layout of CI and of
every developer machine: ``<workspace>/main`` and ``<workspace>/shared``). Tests that need it skip
with a message naming both when it is absent.
"""

from __future__ import annotations

import os
from pathlib import Path

#: The checkout's root.
REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(os.environ.get("TEXSYNTH_SHARED_DATA") or REPO.parent / "shared" / "data")
