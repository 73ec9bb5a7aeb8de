"""What stands between a request and the routes: headers, the same-origin rule, tokens.

- :class:`SecurityHeadersMiddleware` (issue 14, stored XSS): every response carries
  ``X-Content-Type-Options: nosniff`` (a browser takes the declared type, never a guess from the
  bytes) and a Content-Security-Policy that lets pages run only the service's own script and style
  files: an uploaded file, even one carrying ``<script>``, cannot execute. The API docs (``/docs``,
  served from the installed Swagger UI, no CDN) get a policy that also allows their inline start-up
  script, still from this origin only.
- :class:`AllowedHostsMiddleware` (DNS rebinding, issue 26): a page on another site can rebind its
  own name to 127.0.0.1 and then talk to the service "same-origin"; its requests still carry that
  name in ``Host``. Only the names the service serves pass (:func:`host_allowed`), else 400.
- :class:`SameOriginMiddleware` (CSRF): a state-changing request (POST, PUT, PATCH, DELETE) that a
  browser sent from another origin is refused with 403, judged from ``Sec-Fetch-Site`` and
  ``Origin``; clients that are not browsers send neither and pass.
- :class:`AuthMiddleware`: when tokens are configured (:mod:`texsynth.app.auth`), every ``/api`` request
  but ``/api/health`` needs ``Authorization: Bearer <token>`` (401 otherwise), or, for a GET of one
  job's files, a valid signed ``access`` query. The request's :class:`~texsynth.app.auth.Principal` is left
  in ``request.state.principal`` for the routes, which show each owner only their own jobs.
  One middleware for the whole prefix means no route can be forgotten.
"""

from __future__ import annotations

import ipaddress
import json
import re
import socket
from collections.abc import Iterable
from urllib.parse import parse_qs, urlsplit

from starlette.types import ASGIApp, Message, Receive, Scope, Send

from texsynth.app.auth import ANONYMOUS, Principal, Tokens

__all__ = [
    "CONTENT_SECURITY_POLICY",
    "AllowedHostsMiddleware",
    "AuthMiddleware",
    "SameOriginMiddleware",
    "SecurityHeadersMiddleware",
]

CONTENT_SECURITY_POLICY = (
    "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' blob: data:; "
    "connect-src 'self'; object-src 'none'; base-uri 'none'; form-action 'self'; frame-ancestors 'none'"
)
_DOCS_POLICY = (
    "default-src 'self'; script-src 'self' 'unsafe-inline'; style-src 'self' 'unsafe-inline'; "
    "img-src 'self' data:; connect-src 'self'; object-src 'none'; base-uri 'none'; frame-ancestors 'none'"
)
_DOCS_PATHS = ("/docs",)


async def send_json_error(
    send: Send, status: int, detail: str, kind: str, headers: list[tuple[bytes, bytes]] | None = None
) -> None:
    """The service's JSON error ``{detail, field, error}``, sent from a middleware."""
    body = json.dumps({"detail": detail, "field": None, "error": kind}).encode()
    await send(
        {
            "type": "http.response.start",
            "status": status,
            "headers": [
                (b"content-type", b"application/json"),
                (b"content-length", str(len(body)).encode()),
                *(headers or []),
            ],
        }
    )
    await send({"type": "http.response.body", "body": body})


class SecurityHeadersMiddleware:
    """Adds ``nosniff`` and the content security policy to every HTTP response."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        policy = _DOCS_POLICY if scope["path"].startswith(_DOCS_PATHS) else CONTENT_SECURITY_POLICY

        async def with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                headers = list(message.get("headers", []))
                headers.append((b"x-content-type-options", b"nosniff"))
                headers.append((b"content-security-policy", policy.encode()))
                headers.append((b"referrer-policy", b"same-origin"))
                message = {**message, "headers": headers}
            await send(message)

        await self.app(scope, receive, with_headers)


def split_host(header: str) -> str:
    """The name or address of a ``Host`` header, without port or brackets, lower case, no final dot."""
    value = header.strip().lower()
    if value.startswith("["):  # an IPv6 literal: [::1]:8000
        return value[1:].partition("]")[0]
    name, colon, port = value.rpartition(":")
    if colon and port.isdigit() and ":" not in name:
        value = name
    return value.rstrip(".")


def host_allowed(host: str, allowed: Iterable[str]) -> bool:
    """Whether ``host`` (from :func:`split_host`) is one this service serves.

    IP addresses pass: a browser sends an address as ``Host`` only when the page itself was loaded
    from that address, which no other site can arrange (rebinding needs a name the attacker owns).
    So do ``localhost`` and its subdomains (RFC 6761: they resolve to loopback) and the ``allowed``
    names: ``name``, ``.domain`` for the domain and every subdomain, ``*`` for anything.
    """
    if not host:
        return False
    try:
        ipaddress.ip_address(host)
        return True
    except ValueError:
        pass
    if host == "localhost" or host.endswith(".localhost"):
        return True
    for entry in allowed:
        entry = entry.strip().lower().rstrip(".")
        if entry in ("*", host) or (entry.startswith(".") and (host.endswith(entry) or host == entry[1:])):
            return True
    return False


def served_hosts(allowed_hosts: Iterable[str], allowed_origins: Iterable[str] = ()) -> tuple[str, ...]:
    """The names to accept besides addresses and localhost: ``TEXSYNTH_ALLOWED_HOSTS``, the hosts of
    ``TEXSYNTH_ALLOWED_ORIGINS`` (a proxy's public name) and this machine's own name."""
    names = [split_host(h) if not h.strip().startswith((".", "*")) else h.strip() for h in allowed_hosts]
    names += [urlsplit(origin).hostname or "" for origin in allowed_origins]
    machine = socket.gethostname().lower()
    names += [machine, machine.partition(".")[0]]
    return tuple(dict.fromkeys(n for n in names if n))


class AllowedHostsMiddleware:
    """Answers 400 to a request whose ``Host`` is not a name this service serves (DNS rebinding).

    A request without ``Host`` (HTTP/1.0 from a script) passes: every browser sends one.
    """

    def __init__(self, app: ASGIApp, allowed: tuple[str, ...] = ()) -> None:
        self.app = app
        self.allowed = allowed

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "http":
            header = dict(scope.get("headers") or []).get(b"host")
            if header is not None:
                host = split_host(header.decode("latin-1"))
                if not host_allowed(host, self.allowed):
                    shown = host.encode("ascii", "backslashreplace").decode()[:100]
                    await send_json_error(
                        send,
                        400,
                        f"this service does not answer to the host name {shown!r} (a page that points its "
                        "own name at this machine could otherwise use it: DNS rebinding). Use localhost "
                        "or the machine's address, or add the name to TEXSYNTH_ALLOWED_HOSTS "
                        "(comma-separated; '.example.org' allows every subdomain)",
                        "bad_host",
                    )
                    return
        await self.app(scope, receive, send)


_UNSAFE_METHODS = frozenset({"POST", "PUT", "PATCH", "DELETE"})


class SameOriginMiddleware:
    """Refuses a state-changing request that a browser sent from another origin (HTTP 403).

    ``Sec-Fetch-Site`` (every current browser) must be ``same-origin`` or ``none`` (typed by the
    user); an ``Origin`` header must name this host (``Host``), or one of ``allowed`` (a proxy's
    public origin, ``TEXSYNTH_ALLOWED_ORIGINS``). A request with neither header (curl, the Python
    client, ``texsynth submit``) is not a browser's and passes.
    """

    def __init__(self, app: ASGIApp, allowed: tuple[str, ...] = ()) -> None:
        self.app = app
        self.allowed = {origin.rstrip("/").lower() for origin in allowed}

    def _refusal(self, scope: Scope) -> str | None:
        headers = dict(scope.get("headers") or [])
        origin = headers.get(b"origin", b"").decode("latin-1").strip().lower()
        site = headers.get(b"sec-fetch-site", b"").decode("latin-1").strip().lower()
        host = headers.get(b"host", b"").decode("latin-1").strip().lower()
        if origin and origin.rstrip("/") in self.allowed:
            return None
        if site and site not in ("same-origin", "none"):
            return f"the browser says it comes from a {site} page" + (f" ({origin})" if origin else "")
        if origin and (origin == "null" or urlsplit(origin).netloc != host):
            return f"it comes from the origin {origin}, not from this service ({host})"
        return None

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "http" and scope["method"] in _UNSAFE_METHODS:
            why = self._refusal(scope)
            if why is not None:
                await send_json_error(
                    send,
                    403,
                    f"cross-origin request refused: {why}. Only this service's own page may submit, "
                    "cancel or delete (a proxy's public origin can be allowed with TEXSYNTH_ALLOWED_ORIGINS)",
                    "cross_origin",
                )
                return
        await self.app(scope, receive, send)


_PUBLIC_PATHS = frozenset({"/api/health"})
#: The bundled examples: the service's own files, the same for everyone (app/api/routes/examples.py).
_PUBLIC_PREFIXES = ("/api/examples",)
#: GETs of one job's files, which a signed ``access`` query may open instead of a bearer token.
_FILE_ROUTE = re.compile(
    r"^/api/jobs/([0-9A-Za-z_-]+)/(?:artifacts/.+|artifacts\.zip|thumbnail\.png|inputs/[^/]+|preview\.png"
    r"|slices/[^/]+/[^/]+\.png)$"
)
_MISSING = (
    "this service needs a token: send the header 'Authorization: Bearer <token>' "
    "(texsynth submit --token or $TEXSYNTH_TOKEN; the browser page asks for it)"
)


class AuthMiddleware:
    """Sets ``request.state.principal`` for every ``/api`` request, or answers 401."""

    def __init__(self, app: ASGIApp, tokens: Tokens) -> None:
        self.app = app
        self.tokens = tokens

    def _principal(self, scope: Scope) -> tuple[Principal | None, str]:
        path = scope["path"].rstrip("/") or "/"
        if path in _PUBLIC_PATHS or path.startswith(_PUBLIC_PREFIXES):
            return Principal(name=None), ""
        header = dict(scope.get("headers") or []).get(b"authorization")
        if header is not None:
            scheme, _, token = header.decode("latin-1").strip().partition(" ")
            if scheme.lower() != "bearer" or not token.strip():
                return None, "the Authorization header must read 'Bearer <token>'"
            principal = self.tokens.lookup(token.strip())
            if principal is None:
                return None, (
                    "the token is not one this service knows; check $TEXSYNTH_TOKEN (or the token "
                    "given to the page) with the service's administrator"
                )
            return principal, ""
        match = _FILE_ROUTE.match(scope["path"])
        access = parse_qs(scope.get("query_string", b"").decode("latin-1")).get("access")
        if match and access and scope["method"] in ("GET", "HEAD"):
            if self.tokens.verify(match.group(1), access[-1]):
                return Principal(name=None, job=match.group(1)), ""
            return None, (
                "this file link has expired or is not valid; open the job again (GET /api/jobs/{id} "
                "with your token) for fresh links"
            )
        return None, _MISSING

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or not (scope["path"] + "/").startswith("/api/"):
            await self.app(scope, receive, send)
            return
        if not self.tokens.enabled:
            principal, why = ANONYMOUS, ""
        else:
            principal, why = self._principal(scope)
        if principal is None:
            await send_json_error(
                send, 401, why, "unauthorized", [(b"www-authenticate", b'Bearer realm="texsynth"')]
            )
            return
        scope.setdefault("state", {})["principal"] = principal
        await self.app(scope, receive, send)
