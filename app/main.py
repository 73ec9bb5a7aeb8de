"""The FastAPI application: REST API under ``/api`` (OpenAPI at ``/docs``) and the browser page at ``/``.

``create_app(settings)`` builds it; ``uvicorn --factory texsynth.app.main:create_app`` serves it with the
environment's :class:`~texsynth.jobs.config.Settings`. The API never runs synthesis: it validates, stores,
queues and reports. Its :class:`~texsynth.jobs.reaper.Reaper` settles jobs whose worker vanished and deletes
finished jobs after the retention period.

``/docs`` is Swagger UI served from the installed ``swagger-ui-py`` package's static files (no CDN:
it works offline, and the content security policy allows nothing from another host). ReDoc has no
such package and is not served.
"""

from __future__ import annotations

import importlib.util
from contextlib import asynccontextmanager
from pathlib import Path

from fastapi import FastAPI
from fastapi.openapi.docs import get_swagger_ui_html
from fastapi.responses import FileResponse, HTMLResponse
from fastapi.staticfiles import StaticFiles

from texsynth.app.api.routes import examples, health, jobs, methods, metrics, sweeps
from texsynth.app.errors import install_error_handlers
from texsynth.app.limits import BodyLimitMiddleware
from texsynth.app.openapi import install_openapi
from texsynth.app.schemas import ErrorPublic
from texsynth.app.security import (
    AllowedHostsMiddleware,
    AuthMiddleware,
    SameOriginMiddleware,
    SecurityHeadersMiddleware,
    served_hosts,
)
from texsynth.app.service import Service
from texsynth.jobs.config import Settings
from texsynth.synth import __version__

__all__ = ["SWAGGER_UI", "create_app"]

STATIC = Path(__file__).resolve().parent / "static"


def _swagger_ui_static() -> Path | None:
    """The Swagger UI files of the installed ``swagger-ui-py`` (found without importing it)."""
    spec = importlib.util.find_spec("swagger_ui")
    for folder in (spec.submodule_search_locations or []) if spec else []:
        static = Path(folder) / "static"
        if (static / "swagger-ui-bundle.js").is_file():
            return static
    return None


SWAGGER_UI = _swagger_ui_static()


def create_app(settings: Settings | None = None, *, reaper: bool = True) -> FastAPI:
    settings = settings or Settings.from_env()
    service = Service(settings)

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        if reaper:
            service.start()
        yield
        service.stop()

    app = FastAPI(
        title="texsynth",
        version=__version__,
        description="Exemplar-based texture synthesis as a job service: submit, follow, download.",
        lifespan=lifespan,
        docs_url=None,
        redoc_url=None,
        # every error is app/errors.py's JSON body, FastAPI's own validation answers included: the
        # schema says so (instead of FastAPI's default HTTPValidationError, which no answer matches)
        responses={
            400: {"model": ErrorPublic, "description": "a malformed request (e.g. broken multipart)"},
            422: {"model": ErrorPublic, "description": "a bad parameter (the field is named)"},
        },
    )
    app.state.service = service
    # Outermost last: headers on every answer, then the Host check, the same-origin rule, tokens, then
    # the body limit (an unauthenticated upload is refused before its body is read).
    app.add_middleware(
        BodyLimitMiddleware, max_body_bytes=settings.max_body_bytes, client_timeout=settings.client_timeout
    )
    app.add_middleware(AuthMiddleware, tokens=service.tokens)
    app.add_middleware(SameOriginMiddleware, allowed=settings.allowed_origins)
    app.add_middleware(
        AllowedHostsMiddleware, allowed=served_hosts(settings.allowed_hosts, settings.allowed_origins)
    )
    app.add_middleware(SecurityHeadersMiddleware)
    install_error_handlers(app)
    for module in (jobs, methods, metrics, sweeps, examples, health):
        app.include_router(module.router)
    install_openapi(app, service.methods, tokens=service.tokens.enabled)

    if SWAGGER_UI is not None:
        app.mount("/docs/assets", StaticFiles(directory=SWAGGER_UI), name="swagger-ui")

    @app.get("/docs", include_in_schema=False)
    def docs() -> HTMLResponse:
        if SWAGGER_UI is None:
            return HTMLResponse(
                "<p>The interactive API docs need the swagger-ui-py package (pip install swagger-ui-py); "
                "the schema is at <a href='/openapi.json'>/openapi.json</a>.</p>",
                status_code=404,
            )
        return get_swagger_ui_html(
            openapi_url="/openapi.json",
            title="texsynth API",
            swagger_js_url="/docs/assets/swagger-ui-bundle.js",
            swagger_css_url="/docs/assets/swagger-ui.css",
            swagger_favicon_url="/docs/assets/favicon-32x32.png",
        )

    @app.get("/", include_in_schema=False)
    def index() -> FileResponse:
        return FileResponse(STATIC / "index.html", headers={"Cache-Control": "no-cache"})

    @app.get("/favicon.ico", include_in_schema=False)
    def favicon() -> FileResponse:
        return FileResponse(
            STATIC / "favicon.ico", media_type="image/x-icon", headers={"Cache-Control": "max-age=86400"}
        )

    app.mount("/static", StaticFiles(directory=STATIC), name="static")
    return app
