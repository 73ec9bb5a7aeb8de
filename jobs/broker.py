"""The embedded broker: kombu's filesystem transport, made safe against torn and malformed messages.

kombu 5.7's filesystem transport writes a message file in place (a reader can list it while it is empty
or half written) and its reader raises on whatever it cannot decode, which ends the worker's main
process: an empty ``*.msg`` in the queue folder killed the worker on every start and the job it should
have run stayed queued (issue 14). Here

- a message is written under a hidden temporary name, flushed, then renamed to its ``.msg`` name, so a
  reader sees a complete message or none;
- a message that still cannot be read (empty, not JSON, not a kombu envelope) is moved to
  ``quarantine/`` beside the queue folder with a warning, and the reader goes on to the next one.

The reaper (:mod:`jobs.reaper`) re-sends a job whose message no worker received in time, so a job
whose message was quarantined or lost still runs. Selected by the broker URL ``texsynth-fs://``
(:func:`jobs.queue.create_celery`).
"""

from __future__ import annotations

import logging
import os
import shutil
import tempfile
import uuid
from pathlib import Path
from queue import Empty
from time import monotonic
from typing import Any

from kombu.exceptions import ChannelError
from kombu.transport import TRANSPORT_ALIASES, filesystem
from kombu.utils.encoding import bytes_to_str, str_to_bytes
from kombu.utils.json import dumps, loads

from synth.errors import StorageError
from synth.io.atomic import atomic_write_bytes

__all__ = ["SCHEME", "SafeChannel", "SafeTransport", "quarantine_folder"]

log = logging.getLogger(__name__)

#: The broker URL scheme of the embedded queue.
SCHEME = "texsynth-fs"


def quarantine_folder(queue_folder: str | os.PathLike[str]) -> Path:
    """Where unreadable messages go: ``quarantine/`` beside the queue folder."""
    return Path(queue_folder).parent / "quarantine"


class SafeChannel(filesystem.Channel):
    """Atomic writes, and a reader that sets a malformed message aside instead of dying on it."""

    def _put(self, queue: str, payload: Any, **kwargs: Any) -> None:
        name = f"{round(monotonic() * 1000)}_{uuid.uuid4()}.{queue}.msg"
        final = os.path.join(self.data_folder_out, name)
        try:  # readers skip dot-files (the writer's temporary): a message is complete or absent
            atomic_write_bytes(final, str_to_bytes(dumps(payload)))
        except StorageError as exc:
            raise ChannelError(f"cannot add message {name} to the queue ({exc.reason})") from exc

    def _get(self, queue: str) -> Any:
        wanted = f"{queue}.msg"
        for filename in sorted(os.listdir(self.data_folder_in)):
            if filename.startswith(".") or filename.partition(".")[2] != wanted:
                continue
            taken = os.path.join(tempfile.gettempdir(), f"texsynth-{uuid.uuid4().hex}-{filename}")
            try:  # taking the file is the claim: another reader that lost the race skips it
                shutil.move(os.path.join(self.data_folder_in, filename), taken)
            except OSError:
                continue
            try:
                with open(taken, "rb") as fh:
                    payload = fh.read()
                message = loads(bytes_to_str(payload))
                if not isinstance(message, dict) or "body" not in message:
                    raise ValueError("not a kombu message envelope")
            except (OSError, ValueError) as exc:
                self._quarantine(taken, filename, exc)
                continue
            os.remove(taken)
            return message
        raise Empty()

    def _quarantine(self, taken: str, filename: str, exc: Exception) -> None:
        folder = quarantine_folder(self.data_folder_in)
        try:
            folder.mkdir(parents=True, exist_ok=True)
            shutil.move(taken, folder / filename)
        except OSError:
            Path(taken).unlink(missing_ok=True)
        log.warning("embedded queue: message %s set aside in %s (%s)", filename, folder.name, exc)


class SafeTransport(filesystem.Transport):
    """kombu's filesystem transport with :class:`SafeChannel`."""

    Channel = SafeChannel


TRANSPORT_ALIASES[SCHEME] = f"{__name__}:SafeTransport"
