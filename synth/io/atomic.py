"""The one atomic file writer: readers see the old file or the new one, never a part.

Every file the engine, the CLI and the service write goes through :func:`atomic_write_bytes` (or its
JSON form): the data goes to a temporary file beside the target, is flushed to disk, then renamed over
the target; on any failure the temporary file is removed. A failure to write (full disk, no
permission) is the machine's problem, not the input's: it raises :class:`synth.errors.StorageError`
(an ``OSError``), whose message names the file but not the server's folders.
"""

from __future__ import annotations

import contextlib
import json
import os
import uuid
from pathlib import Path
from typing import Any

from synth.errors import StorageError

__all__ = ["atomic_write_bytes", "atomic_write_json"]


def atomic_write_bytes(path: str | os.PathLike[str], data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (temporary file, ``fsync``, rename).

    Raises
    ------
    StorageError
        The file cannot be written; the message names ``path``'s file name and the system's reason.
    """
    target = Path(path)
    tmp = target.with_name(f".{target.name}.{uuid.uuid4().hex[:12]}.tmp")
    created = False
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0), 0o666)
        created = True
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, target)
    except OSError as exc:
        if created:
            with contextlib.suppress(OSError):
                tmp.unlink()
        raise StorageError(target.name, exc.strerror or str(exc)) from None


def atomic_write_json(path: str | os.PathLike[str], document: Any) -> None:
    """Write ``document`` as indented UTF-8 JSON (with a final newline) through :func:`atomic_write_bytes`."""
    atomic_write_bytes(path, (json.dumps(document, indent=2) + "\n").encode("utf-8"))
