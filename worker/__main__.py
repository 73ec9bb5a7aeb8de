import os
import sys

# OpenBLAS single-threaded, as in every ``texsynth`` command (see :mod:`synth.cli`): set before NumPy loads.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from worker.cli import main

sys.exit(main())
