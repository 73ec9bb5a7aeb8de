"""``python -m texsynth.synth.cli``: the same as the ``texsynth`` console script."""

from texsynth.synth.cli import entry

entry()
