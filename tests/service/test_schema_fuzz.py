"""Schemathesis against the app's own OpenAPI schema, in process (issue 14: no 500, no schema violation).

The app runs on a temporary data directory through schemathesis' ASGI transport (no network, no
broker: sends are replaced, as in ``test_tokens.py``). Every operation gets at most 20 generated
requests, derandomized, so a run is bounded (well under a minute) and reproducible; each answer must
not be a 5xx and must match the status codes and bodies the schema declares.
"""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile
import time
import warnings
from pathlib import Path

import schemathesis
from hypothesis import HealthCheck, settings
from schemathesis.checks import not_a_server_error, response_schema_conformance, status_code_conformance

from texsynth.app.main import create_app
from texsynth.jobs.config import Settings

DATA = Path(tempfile.mkdtemp(prefix="texsynth-fuzz-"))
atexit.register(shutil.rmtree, DATA, True)  # also when the test is deselected


def _app():
    # schemathesis' ASGI client names the server "testserver" in its Host header
    app = create_app(Settings(data_dir=DATA / "data", allowed_hosts=("testserver",)), reaper=False)
    app.state.service.send = lambda job_id: None  # no broker: only the API's answers are checked
    app.state.service.send_group = lambda job_ids: None
    return app


with warnings.catch_warnings():  # starlette's test client warns about its httpx at import
    warnings.simplefilter("ignore")
    schema = schemathesis.openapi.from_asgi("/openapi.json", _app())


@schema.parametrize()
@settings(
    max_examples=20,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=list(HealthCheck),
)
def test_no_server_error_and_answers_match_the_schema(case):
    if case.operation.path == "/api/health":  # a worker is alive (else health answers 503, as documented)
        store = case.operation.schema.app.state.service.store
        store.worker_heartbeat("fuzz@test", os.getpid(), time.time())
    case.call_and_validate(checks=[not_a_server_error, status_code_conformance, response_schema_conformance])
