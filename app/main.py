"""The FastAPI application: REST API under ``/api`` (OpenAPI at ``/docs``) and the browser page at ``/``.

``create_app(settings)`` builds it; ``uvicorn --factory app.main:create_app`` serves it with the
environment's :class:`~jobs.config.Settings`. The API never runs synthesis: it validates, stores,
queues and reports. Its :class:`~jobs.reaper.Reaper` settles jobs whose worker vanished.
"""

from __future__ import annotations

from contextlib import asynccontextmanager
from pathlib import Path

from fastapi import FastAPI
from fastapi.responses import FileResponse
from fastapi.staticfiles import StaticFiles

from app.api.routes import health, jobs, methods, metrics, sweeps
from app.errors import install_error_handlers
from app.limits import BodyLimitMiddleware
from app.security import SecurityHeadersMiddleware
from app.service import Service
from jobs.config import Settings
from synth import __version__

__all__ = ["create_app"]

STATIC = Path(__file__).resolve().parent / "static"


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
    )
    app.state.service = service
    app.add_middleware(BodyLimitMiddleware, max_body_bytes=settings.max_body_bytes)
    app.add_middleware(SecurityHeadersMiddleware)
    install_error_handlers(app)
    for module in (jobs, methods, metrics, sweeps, health):
        app.include_router(module.router)

    @app.get("/", include_in_schema=False)
    def index() -> FileResponse:
        return FileResponse(STATIC / "index.html", headers={"Cache-Control": "no-cache"})

    app.mount("/static", StaticFiles(directory=STATIC), name="static")
    return app
