"""texsynth: exemplar-based texture synthesis for virtual-material design.

The engine is a library first: :func:`texsynth.synth.api.synthesize` does everything the service and the
``texsynth`` command line do, with the same parameters and the same results.
"""

from texsynth.synth.errors import (
    Cancelled,
    InputTooLarge,
    InvalidInput,
    InvalidParameter,
    SynthError,
    UnsupportedFormat,
)

__version__ = "0.1.0"

__all__ = [
    "Cancelled",
    "InputTooLarge",
    "InvalidInput",
    "InvalidParameter",
    "SynthError",
    "UnsupportedFormat",
    "__version__",
]
