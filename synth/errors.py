"""The engine's errors: one small hierarchy, mapped to 4xx by the API and to exit code 2 by the CLI.

Every error says what is wrong with which input in words a person can act on; none of them is a
traceback. ``SynthError`` derives from ``ValueError`` so plain Python callers can catch either.
"""

from __future__ import annotations

from typing import Any

__all__ = [
    "Cancelled",
    "InputTooLarge",
    "InvalidInput",
    "InvalidParameter",
    "InvalidParameters",
    "StorageError",
    "SynthError",
    "UnsupportedFormat",
]


class SynthError(ValueError):
    """Base class of every error the engine raises on purpose."""


class InvalidInput(SynthError):
    """An input image or volume is unusable: unreadable, truncated, empty, NaN, absurd shape.

    ``source`` names the file (or field) so that the message points at it.
    """

    def __init__(self, source: str, problem: str) -> None:
        self.source = source
        self.problem = problem
        super().__init__(f"{source}: {problem}")


class UnsupportedFormat(InvalidInput):
    """The bytes are not an image in a format the engine reads (HTTP 415)."""


class InputTooLarge(InvalidInput):
    """The input exceeds a configured pixel or byte limit, or is a decompression bomb (HTTP 413)."""


class InvalidParameter(SynthError):
    """A parameter is out of range or inconsistent with the inputs; ``name`` is the parameter."""

    def __init__(self, name: str, value: Any, reason: str) -> None:
        self.name = name
        self.value = value
        self.reason = reason
        super().__init__(f"parameter '{name}' = {value!r}: {reason}")


class InvalidParameters(InvalidParameter):
    """Several parameters are wrong at once; ``problems`` has one :class:`InvalidParameter` per field.

    It is the first problem too (``name``, ``value``, ``reason``), so a caller that handles one
    parameter error handles this; the message names them all on one line.
    """

    def __init__(self, problems: list[InvalidParameter]) -> None:
        if not problems:
            raise ValueError("InvalidParameters needs at least one problem")
        self.problems = list(problems)
        first = problems[0]
        super().__init__(first.name, first.value, first.reason)
        if len(problems) > 1:
            self.args = ("; ".join(str(p) for p in problems),)


class Cancelled(SynthError):
    """Raised through a progress callback to stop a synthesis early (a cancelled job)."""


class StorageError(OSError):
    """A file could not be written (full disk, no permission): the machine's fault, not the input's.

    Not a :class:`SynthError`: the service reports it as an internal error (never a 4xx), the CLI
    as a failure of the machine (exit code 1). ``file`` is the file's name only, so that messages
    shown to users carry no server paths.
    """

    def __init__(self, file: str, reason: str) -> None:
        self.file = file
        self.reason = reason
        super().__init__(f"cannot write {file}: {reason}")
