"""``python -m synth.cli``: the same as the ``texsynth`` console script."""

import sys

from synth.cli import main

sys.exit(main())
