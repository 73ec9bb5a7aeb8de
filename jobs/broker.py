"""The embedded broker: kombu's filesystem transport, made safe against torn and malformed messages.

kombu 5.7's filesystem transport writes a message file in place (a reader can list it while it is empty
or half written) and its reader raises on whatever it cannot decode, which ends the worker's main
process: an empty ``*.msg`` in the queue folder killed the worker on every start and the job it should
have run stayed queued (issue 14). Here

- a message is written under a hidden temporary name, flushed, then renamed to its ``.msg`` name, so a
  reader sees a complete message or none;
- a message that still cannot be read (empty, not JSON, not a complete kombu envelope: every field
  kombu's consumer reads, with its type, and a body that decodes, :func:`check_envelope`) is moved to
  ``quarantine/`` beside the queue folder with a warning naming the file, and the reader goes on;
- :func:`prune_mailboxes` (called by the reaper) unbinds the control mailboxes of workers that died
  and deletes their messages: the filesystem transport writes every broadcast (a cancel's revoke)
  into every mailbox ever bound, and a dead worker's ``*.pidbox.msg`` files piled up for ever.

The reaper (:mod:`texsynth.jobs.reaper`) re-sends a job whose message no worker received in time, so a job
whose message was quarantined or lost still runs. Selected by the broker URL ``texsynth-fs://``
(:func:`texsynth.jobs.queue.create_celery`).
"""

from __future__ import annotations

import contextlib
import logging
import os
import shutil
import tempfile
import time
import uuid
from collections.abc import Iterable, Mapping
from pathlib import Path
from queue import Empty
from time import monotonic
from typing import Any

from kombu.exceptions import ChannelError
from kombu.transport import TRANSPORT_ALIASES, filesystem
from kombu.utils.encoding import bytes_to_str, str_to_bytes
from kombu.utils.json import dumps, loads

from texsynth.synth.errors import StorageError
from texsynth.synth.io.atomic import atomic_write_bytes

__all__ = [
    "SCHEME",
    "SafeChannel",
    "SafeTransport",
    "check_envelope",
    "prune_mailboxes",
    "quarantine_folder",
]

log = logging.getLogger(__name__)

#: The broker URL scheme of the embedded queue.
SCHEME = "texsynth-fs"


def quarantine_folder(queue_folder: str | os.PathLike[str]) -> Path:
    """Where unreadable messages go: ``quarantine/`` beside the queue folder."""
    return Path(queue_folder).parent / "quarantine"


def check_envelope(message: Any, codecs: Mapping[str, Any]) -> None:
    """Raise ``ValueError`` saying what is missing or wrong unless ``message`` is a complete kombu
    envelope: what :class:`kombu.transport.virtual.Message` and the consumer read (``properties`` with
    a ``delivery_tag`` and a ``delivery_info`` naming ``exchange`` and ``routing_key``, ``headers``,
    the content type and encoding) with their types, and a body that its ``body_encoding`` decodes."""
    if not isinstance(message, dict):
        raise ValueError(f"the message is a JSON {type(message).__name__}, not an object")
    _typed(message, "body", str)
    properties = _typed(message, "properties", dict)
    _typed(properties, "delivery_tag", str, "properties.")
    info = _typed(properties, "delivery_info", dict, "properties.")
    for key in ("exchange", "routing_key"):
        _typed(info, key, str, "properties.delivery_info.")
    headers = message.get("headers")
    if headers is not None and not isinstance(headers, dict):
        raise ValueError("'headers' is not an object")
    if headers and headers.get("compression") is not None and not isinstance(headers["compression"], str):
        raise ValueError("'headers.compression' is not a string")
    for key in ("content-type", "content-encoding"):
        if message.get(key) is not None and not isinstance(message[key], str):
            raise ValueError(f"'{key}' is not a string")
    encoding = properties.get("body_encoding")
    if encoding is not None and not isinstance(encoding, str):
        raise ValueError("'properties.body_encoding' is not a string")
    if encoding and encoding.lower() != "utf-8":
        if encoding not in codecs:
            raise ValueError(f"unknown body encoding {encoding!r}")
        try:
            codecs[encoding].decode(message["body"])
        except (ValueError, TypeError) as exc:
            raise ValueError(f"the body is not valid {encoding} ({exc})") from None


def _typed(mapping: dict, key: str, kind: type, prefix: str = "") -> Any:
    if key not in mapping:
        raise ValueError(f"no '{prefix}{key}'")
    if not isinstance(mapping[key], kind):
        raise ValueError(f"'{prefix}{key}' is a {type(mapping[key]).__name__}, not a {kind.__name__}")
    return mapping[key]


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
                check_envelope(message, self.codecs)
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
        except OSError as error:
            Path(taken).unlink(missing_ok=True)
            log.warning(
                "embedded queue: unreadable message %s deleted, it could not be set aside (%s): %s",
                filename,
                error,
                exc,
            )
            return
        log.warning("embedded queue: unreadable message set aside as %s: %s", folder / filename, exc)


#: The suffix of a Celery worker's control mailbox (queue ``<node name>.celery.pidbox``).
MAILBOX = ".celery.pidbox"


def prune_mailboxes(
    queue_folder: str | os.PathLike[str],
    control_folder: str | os.PathLike[str],
    live_nodes: Iterable[str],
    max_age: float,
    now: float | None = None,
) -> int:
    """Delete control messages nobody read for ``max_age`` seconds, and unbind the mailboxes of the
    nodes that left them unread and are not in ``live_nodes`` (workers with a fresh heartbeat): a
    live worker reads its mailbox within a second or two. Returns how many messages were deleted."""
    now = time.time() if now is None else now
    live = set(live_nodes)
    messages: dict[str, list[Path]] = {}
    for path in Path(queue_folder).glob("*.pidbox.msg"):
        messages.setdefault(path.name.partition(".")[2][: -len(".msg")], []).append(path)
    dead = set()
    for queue, paths in messages.items():
        with contextlib.suppress(OSError):
            if min(p.stat().st_mtime for p in paths) < now - max_age and queue[: -len(MAILBOX)] not in live:
                dead.add(queue)
    if dead:
        _unbind(Path(control_folder) / f"{MAILBOX[1:]}.exchange", dead)
    removed = 0
    for queue, paths in messages.items():
        for path in paths:
            with contextlib.suppress(OSError):
                if queue in dead or path.stat().st_mtime < now - max_age:
                    path.unlink()
                    removed += 1
    if dead:
        log.warning("embedded queue: mailboxes of stopped workers removed: %s", ", ".join(sorted(dead)))
    return removed


def _unbind(table: Path, queues: set[str]) -> None:
    """Remove ``queues`` from a fanout exchange's table, under the lock kombu's transport takes."""
    try:
        fh = table.open("rb+", buffering=0)
    except OSError:
        return
    with fh:
        filesystem.lock(fh, filesystem.LOCK_EX)
        try:
            entries = loads(bytes_to_str(fh.read()))
            kept = [entry for entry in entries if entry[2] not in queues]
            if len(kept) != len(entries):
                fh.seek(0)
                fh.write(str_to_bytes(dumps(kept)))
                fh.truncate()
        finally:
            filesystem.unlock(fh)


class SafeTransport(filesystem.Transport):
    """kombu's filesystem transport with :class:`SafeChannel`."""

    Channel = SafeChannel


TRANSPORT_ALIASES[SCHEME] = f"{__name__}:SafeTransport"
