"""The one atomic file writer: readers see the old file or the new one, never a part.

Every file the engine, the CLI and the service write goes through :func:`atomic_write_bytes` (or its
JSON form; :func:`atomic_writer` for a file written in pieces, e.g. a streamed download): the data
goes to a temporary file beside the target, is flushed to disk, then renamed over
the target; on any failure the temporary file is removed. A failure to write (full disk, no
permission) is the machine's problem, not the input's: it raises :class:`texsynth.synth.errors.StorageError`
(an ``OSError``), whose message names the file but not the server's folders.
"""

from __future__ import annotations

import contextlib
import json
import os
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any, BinaryIO

from texsynth.synth.errors import StorageError

__all__ = ["atomic_write_bytes", "atomic_write_json", "atomic_writer"]


def atomic_write_bytes(path: str | os.PathLike[str], data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (temporary file, ``fsync``, rename).

    Raises
    ------
    StorageError
        The file cannot be written; the message names ``path``'s file name and the system's reason.
    """
    with atomic_writer(path) as fh:
        fh.write(data)


@contextlib.contextmanager
def atomic_writer(path: str | os.PathLike[str]) -> Iterator[BinaryIO]:
    """A binary file to write ``path`` in pieces: it appears whole when the block ends, or not at all.

    The handle writes a temporary file beside ``path``; a writer that must start again (a download
    retried from its first byte) calls ``fh.seek(0); fh.truncate()``. An exception in the block
    removes the temporary file and propagates; an ``OSError`` (a failed write, in the block or here)
    becomes :class:`StorageError` naming the file.
    """
    target = Path(path)
    tmp = target.with_name(f".{target.name}.{uuid.uuid4().hex[:12]}.tmp")
    created = False
    try:
        # "x": created here or not at all (O_EXCL); opened by path, so the handle has a name (tifffile asks)
        with open(tmp, "xb") as fh:
            created = True
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, target)
        created = False
    except OSError as exc:
        raise StorageError(target.name, exc.strerror or str(exc)) from None
    finally:
        if created:
            with contextlib.suppress(OSError):
                tmp.unlink()


def atomic_write_json(path: str | os.PathLike[str], document: Any) -> None:
    """Write ``document`` as indented UTF-8 JSON (with a final newline) through :func:`atomic_write_bytes`."""
    atomic_write_bytes(path, (json.dumps(document, indent=2) + "\n").encode("utf-8"))
