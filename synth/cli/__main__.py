"""``python -m texsynth.synth.cli``: the same as the ``texsynth`` console script."""

import sys

from texsynth.synth.cli import main

sys.exit(main())
