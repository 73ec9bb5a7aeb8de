"""Tokens, owners and signed file URLs (issue 14: "no authentication at all").

Tokens are optional. Without them the service has one anonymous owner who sees every job, and
``texsynth serve`` binds to 127.0.0.1 unless told otherwise. With them (``TEXSYNTH_API_TOKENS``,
``TEXSYNTH_API_TOKEN_FILE``, ``TEXSYNTH_ADMIN_TOKEN``) every ``/api`` request but ``/api/health``
carries ``Authorization: Bearer <token>``; a token stands for a *name*, and jobs and sweeps belong to
the name that made them (two tokens with one name share their jobs, which lets a token be replaced
without losing them). An admin entry sees and manages every job.

An entry reads ``name:token``, ``name:token:admin``, and may end with ``:quota=<bytes>`` (``10GiB``,
``500MB``; the name's own storage quota, else ``TEXSYNTH_TOKEN_QUOTA_BYTES``); ``TEXSYNTH_API_TOKENS``
holds entries separated by commas, the token file one per line (``#`` starts a comment). A token has at least
:data:`MIN_TOKEN_LENGTH` characters (``python -c "import secrets; print(secrets.token_urlsafe())"``).

Files of a job (artifacts, inputs, preview, slices) are also reachable through a **signed URL**: the
job's record, as its owner reads it, lists them with ``?access=<expiry>.<HMAC>``, a signature of the
job id and an expiry under a key kept in the data directory. ``<img src>``, download links and
"open in a new tab" cannot send an ``Authorization`` header; the signature lets them work without
ever putting the token itself in a URL (server logs, history, Referer). It grants read-only access to
one job's files until it expires (``TEXSYNTH_SIGNED_URL_SECONDS``, one hour); expiries are rounded
up to a quarter of that, so a page that polls gets the same URLs and its images stay cached.
"""

from __future__ import annotations

import hashlib
import hmac
import os
import re
import time
from dataclasses import dataclass
from pathlib import Path

from texsynth.jobs.config import Settings

__all__ = ["ANONYMOUS", "MIN_TOKEN_LENGTH", "Principal", "TokenError", "Tokens"]

MIN_TOKEN_LENGTH = 16
_NAME = re.compile(r"^[A-Za-z0-9_.@-]{1,64}$")
_TOKEN = re.compile(r"^[!-~]+$")  # printable ASCII without spaces


class TokenError(ValueError):
    """The token configuration is unusable; the message names the entry (never the token)."""


@dataclass(frozen=True)
class Principal:
    """Who makes a request: a token's ``name`` (``None`` when tokens are off), whether it is an admin,
    and ``job`` when it holds only a signed URL of that one job's files."""

    name: str | None
    admin: bool = False
    job: str | None = None
    quota: int | None = None  # bytes its jobs may keep stored; None: the service's default

    def can_see(self, owner: str | None, job_id: str | None = None) -> bool:
        if self.job is not None:
            return job_id == self.job
        return self.admin or owner == self.name

    @property
    def owner_filter(self) -> str | None:
        """The owner to filter listings by; ``None`` = every owner (admins, or no tokens)."""
        return None if self.admin else self.name


#: Everyone, when the service has no tokens: one owner, who sees every job.
ANONYMOUS = Principal(name=None, admin=True)


class Tokens:
    """The token table of one API process (empty = tokens off) and its URL-signing key."""

    def __init__(self, entries: dict[str, Principal], key: bytes = b"", ttl: int = 3600) -> None:
        self._entries = entries
        self._key = key
        self.ttl = max(60, int(ttl))

    @property
    def enabled(self) -> bool:
        return bool(self._entries)

    @property
    def names(self) -> list[str]:
        return sorted({p.name for p in self._entries.values() if p.name})

    @classmethod
    def from_settings(cls, settings: Settings) -> Tokens:
        """Read the configured tokens; raise :class:`TokenError` naming a bad entry."""
        entries: dict[str, Principal] = {}
        sources: list[tuple[str, str]] = []
        if settings.api_tokens:
            sources += [("TEXSYNTH_API_TOKENS", e) for e in settings.api_tokens.split(",")]
        if settings.api_token_file:
            path = Path(settings.api_token_file).expanduser()
            try:
                lines = path.read_text().splitlines()
            except OSError as exc:
                raise TokenError(
                    f"TEXSYNTH_API_TOKEN_FILE: cannot read {path} ({exc.strerror or exc})"
                ) from None
            sources += [(f"{path.name} line {i}", line.split("#", 1)[0]) for i, line in enumerate(lines, 1)]
        if settings.admin_token:
            sources.append(("TEXSYNTH_ADMIN_TOKEN", f"admin:{settings.admin_token.strip()}:admin"))
        for where, raw in sources:
            entry = raw.strip()
            if not entry:
                continue
            parts = entry.split(":")
            quota = None
            if len(parts) > 2 and parts[-1].strip().startswith("quota="):
                quota = _quota(parts.pop().strip()[len("quota=") :], where)
            if len(parts) not in (2, 3) or (len(parts) == 3 and parts[2] != "admin"):
                raise TokenError(
                    f"{where}: an entry must read name:token or name:token:admin, optionally ending "
                    "with :quota=<bytes>"
                )
            name, token = parts[0].strip(), parts[1].strip()
            if not _NAME.match(name):
                raise TokenError(f"{where}: the name {name!r} may hold only letters, digits and _.@- (1-64)")
            if len(token) < MIN_TOKEN_LENGTH or not _TOKEN.match(token):
                raise TokenError(
                    f"{where}: the token of {name!r} must be at least {MIN_TOKEN_LENGTH} printable "
                    "characters without spaces (python -c 'import secrets; print(secrets.token_urlsafe())')"
                )
            if token in entries and entries[token].name != name:
                raise TokenError(f"{where}: the token of {name!r} is already given to another name")
            entries[token] = Principal(name=name, admin=len(parts) == 3, quota=quota)
        key = _signing_key(settings.data_dir) if entries else b""
        return cls(entries, key, settings.signed_url_seconds)

    # -- bearer tokens ---------------------------------------------------------------------------

    def lookup(self, token: str) -> Principal | None:
        """The principal of ``token``, compared in constant time with every known token."""
        found = None
        for known, principal in self._entries.items():
            if hmac.compare_digest(known.encode(), token.encode()):
                found = principal
        return found

    # -- signed file URLs ------------------------------------------------------------------------

    def sign(self, job_id: str, now: float | None = None) -> str | None:
        """The ``access`` value for ``job_id``'s files (``None`` when tokens are off)."""
        if not self.enabled:
            return None
        now = time.time() if now is None else now
        step = max(1, self.ttl // 4)
        expires = (int(now + self.ttl) // step + 1) * step
        return f"{expires}.{self._mac(job_id, expires)}"

    def verify(self, job_id: str, access: str, now: float | None = None) -> bool:
        now = time.time() if now is None else now
        expires, _, mac = access.partition(".")
        if not expires.isdigit() or len(expires) > 12 or int(expires) < now:
            return False
        return hmac.compare_digest(mac, self._mac(job_id, int(expires)))

    def _mac(self, job_id: str, expires: int) -> str:
        return hmac.new(self._key, f"{job_id}:{expires}".encode(), hashlib.sha256).hexdigest()[:40]


_UNITS = {"": 1, "B": 1, "KB": 10**3, "MB": 10**6, "GB": 10**9, "TB": 10**12}
_UNITS |= {"KIB": 2**10, "MIB": 2**20, "GIB": 2**30, "TIB": 2**40}


def _quota(text: str, where: str) -> int:
    """``quota=`` of a token entry in bytes: a whole number with an optional unit (``10GiB``, ``500MB``)."""
    match = re.fullmatch(r"\s*(\d{1,15})\s*([A-Za-z]{0,3})\s*", text)
    if match is None or match.group(2).upper() not in _UNITS:
        raise TokenError(
            f"{where}: quota={text!r} must be a whole number of bytes, optionally with a unit "
            "(KB, MB, GB, TB, KiB, MiB, GiB, TiB), e.g. quota=10GiB"
        )
    return int(match.group(1)) * _UNITS[match.group(2).upper()]


def _signing_key(data_dir: Path) -> bytes:
    """32 random bytes kept in ``<data dir>/.signing-key`` (mode 0600), shared by every API process
    on the data directory and across restarts, so signed URLs survive them."""
    path = Path(data_dir) / ".signing-key"
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except FileExistsError:
        for _ in range(50):  # another process may be writing it this instant
            key = path.read_bytes()
            if len(key) == 32:
                return key
            time.sleep(0.02)
        raise TokenError(f"{path.name} in the data directory is not a 32-byte key; delete it") from None
    key = os.urandom(32)
    with os.fdopen(fd, "wb") as fh:
        fh.write(key)
    return key
