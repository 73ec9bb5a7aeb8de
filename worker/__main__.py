import sys

from texsynth.synth.threads import single_threaded_blas

single_threaded_blas()  # as in every ``texsynth`` command: before NumPy loads OpenBLAS

from texsynth.worker.cli import main  # noqa: E402

sys.exit(main())
