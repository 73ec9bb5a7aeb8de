"""Tokens, ownership, signed file URLs and the same-origin rule (issue 14, item 3), in process.

The app runs in FastAPI's test client on a temporary data directory with its sends to the broker
replaced (no worker is needed to check who may see what); finished jobs are made through the job
store as a worker would. ``test_tokens_live.py`` runs the same against ``texsynth serve`` and the
browser page.
"""

from __future__ import annotations

import io
import os
import re
import warnings

import numpy as np
import pytest
from PIL import Image

from texsynth.app.auth import TokenError, Tokens
from texsynth.app.cli import host_notice
from texsynth.app.main import create_app
from texsynth.jobs.config import Settings

ALICE, BOB, ADMIN = "alice-token-0123456789", "bob-token-0123456789ab", "admin-token-0123456789"
A = {"Authorization": f"Bearer {ALICE}"}
B = {"Authorization": f"Bearer {BOB}"}
ROOT = {"Authorization": f"Bearer {ADMIN}"}


def _png(side: int = 32) -> bytes:
    buf = io.BytesIO()
    rng = np.random.default_rng(0)
    Image.fromarray((rng.random((side, side)) * 255).astype(np.uint8)).save(buf, "PNG")
    return buf.getvalue()


def _client(settings: Settings):
    with warnings.catch_warnings():  # starlette's test client warns about its httpx at import
        warnings.simplefilter("ignore")
        from fastapi.testclient import TestClient
    app = create_app(settings, reaper=False)
    service = app.state.service
    service.send = lambda job_id: None  # no broker traffic: these tests are about the API's answers
    service.send_group = lambda job_ids: None
    return TestClient(app, base_url="http://localhost"), service


@pytest.fixture
def api(tmp_path):
    settings = Settings(data_dir=tmp_path / "data", api_tokens=f"alice:{ALICE}, bob:{BOB}", admin_token=ADMIN)
    client, service = _client(settings)
    with client:
        yield client, service


@pytest.fixture
def open_api(tmp_path):
    client, service = _client(Settings(data_dir=tmp_path / "data"))
    with client:
        yield client, service


def submit(client, headers, **extra):
    data = {"method": "wei-levoy", "params": '{"width": 32, "height": 32}', "seed": "1"}
    return client.post(
        "/api/jobs", headers=headers, data={**data, **extra}, files={"exemplar": ("e.png", _png())}
    )


def finish(service, job_id: str) -> None:
    """Run the job as a worker would, without synthesis: claim, write an output, commit."""
    token, _ = service.store.claim(job_id, os.getpid(), 10.0)
    staging = service.store.job_dir(job_id) / f".run-{token}"
    staging.mkdir()
    (staging / "output.png").write_bytes(_png(16))
    assert service.store.commit_success(job_id, token, staging, ["output.png"], {}, {})


# -- 401 ---------------------------------------------------------------------------------------------


def test_no_token_is_401_naming_the_header(api):
    client, _ = api
    r = client.get("/api/jobs")
    assert r.status_code == 401
    assert "Authorization: Bearer <token>" in r.json()["detail"]
    assert "TEXSYNTH_TOKEN" in r.json()["detail"]
    assert r.json()["error"] == "unauthorized"
    assert r.headers["www-authenticate"].startswith("Bearer")


@pytest.mark.parametrize(
    ("header", "message"),
    [
        (f"Basic {ALICE}", "must read 'Bearer <token>'"),
        ("Bearer ", "must read 'Bearer <token>'"),
        ("Bearer not-a-known-token-at-all", "not one this service knows"),
    ],
)
def test_a_bad_authorization_header_is_401_saying_why(api, header, message):
    client, _ = api
    r = client.get("/api/methods", headers={"Authorization": header})
    assert r.status_code == 401
    assert message in r.json()["detail"]


def test_every_api_route_but_health_and_examples_needs_a_token(api):
    client, service = api
    job_id = submit(client, A).json()["id"]
    checked = 0
    for path, operations in client.app.openapi()["paths"].items():  # every route, from the schema
        if not path.startswith("/api") or path == "/api/health" or path.startswith("/api/examples"):
            continue
        concrete = re.sub(r"\{[^}]+\}", lambda m: {"{job_id}": job_id}.get(m.group(0), "x"), path)
        for method in operations:
            r = client.request(method.upper(), concrete)
            assert r.status_code == 401, (method, path, r.status_code)
            checked += 1
    assert checked >= 10
    assert service.store.count() == 1  # nothing was submitted without a token


def test_health_is_public_and_names_no_server_path(api, tmp_path):
    client, _ = api
    r = client.get("/api/health")
    assert r.status_code in (200, 503)
    assert str(tmp_path) not in r.text
    assert "/data" not in r.json()["broker_url"]


# -- ownership ----------------------------------------------------------------------------------------


def test_jobs_belong_to_their_token(api):
    client, service = api
    job = submit(client, A).json()
    assert job["owner"] == "alice"
    finish(service, job["id"])
    bobs = submit(client, B).json()
    base = f"/api/jobs/{job['id']}"

    for path in (base, f"{base}/artifacts/output.png", f"{base}/inputs/exemplar", f"{base}/preview.png"):
        r = client.get(path, headers=B)
        assert r.status_code == 404, path
        assert job["id"] in r.json()["detail"]  # the same answer as for a job that does not exist
    r = client.delete(base, headers=B)
    assert r.status_code == 404
    assert service.store.get(job["id"]).state == "succeeded"  # bob could not delete it

    assert [j["id"] for j in client.get("/api/jobs", headers=A).json()["data"]] == [job["id"]]
    assert [j["id"] for j in client.get("/api/jobs", headers=B).json()["data"]] == [bobs["id"]]
    everyone = client.get("/api/jobs", headers=ROOT).json()
    assert everyone["count"] == 2
    assert client.get(base, headers=ROOT).status_code == 200
    assert client.get(f"{base}/artifacts/output.png", headers=A).status_code == 200


def test_sweeps_belong_to_their_token(api):
    client, service = api
    r = client.post(
        "/api/sweeps",
        headers=A,
        data={"method": "wei-levoy", "grid": '{"levels": [1, 2]}', "params": '{"width": 32, "height": 32}'},
        files={"exemplar": ("e.png", _png())},
    )
    assert r.status_code == 202, r.text
    sweep_id = r.json()["id"]
    assert client.get(f"/api/sweeps/{sweep_id}", headers=B).status_code == 404
    assert client.get(f"/api/sweeps/{sweep_id}", headers=A).status_code == 200
    assert client.get(f"/api/sweeps/{sweep_id}", headers=ROOT).status_code == 200
    assert {j.owner for j in service.store.list(limit=10)[0]} == {"alice"}


def test_admin_can_delete_anyones_job(api):
    client, service = api
    job = submit(client, A).json()
    finish(service, job["id"])
    r = client.delete(f"/api/jobs/{job['id']}", headers=ROOT)
    assert r.status_code == 200
    assert r.json()["state"] == "deleted"


# -- signed file URLs ------------------------------------------------------------------------------------


def test_file_urls_are_signed_and_open_without_a_header(api):
    client, service = api
    job = submit(client, A).json()
    finish(service, job["id"])
    job = client.get(f"/api/jobs/{job['id']}", headers=A).json()
    output = job["artifacts"]["output.png"]
    assert "?access=" in output and ALICE not in output
    r = client.get(output)  # an <img src>: no Authorization header
    assert r.status_code == 200
    assert r.headers["content-type"] == "image/png"
    assert client.get(job["inputs"]["exemplar"]).status_code == 200
    # the URLs are stable between polls (the page's images stay cached)
    assert client.get(f"/api/jobs/{job['id']}", headers=A).json()["artifacts"] == job["artifacts"]


def test_a_signature_opens_only_its_own_jobs_files(api):
    client, service = api
    mine = submit(client, A).json()
    theirs = submit(client, B).json()
    finish(service, theirs["id"])
    access = mine["access"]
    r = client.get(f"/api/jobs/{theirs['id']}/artifacts/output.png?access={access}")
    assert r.status_code == 401
    assert "expired or is not valid" in r.json()["detail"]
    # nor the job's record, the list, or a change
    assert client.get(f"/api/jobs/{mine['id']}?access={access}").status_code == 401
    assert client.get(f"/api/jobs?access={access}").status_code == 401
    assert client.delete(f"/api/jobs/{mine['id']}/inputs/exemplar?access={access}").status_code == 401


def test_an_expired_signature_is_refused(api):
    client, service = api
    job = submit(client, A).json()
    tokens: Tokens = service.tokens
    old = tokens.sign(job["id"], now=0)
    assert tokens.verify(job["id"], old, now=1)
    assert not tokens.verify(job["id"], old)
    r = client.get(f"/api/jobs/{job['id']}/inputs/exemplar?access={old}")
    assert r.status_code == 401
    assert "expired" in r.json()["detail"]


def test_the_signing_key_survives_a_restart(tmp_path):
    settings = Settings(data_dir=tmp_path, api_tokens=f"alice:{ALICE}")
    access = Tokens.from_settings(settings).sign("job1")
    assert Tokens.from_settings(settings).verify("job1", access)
    assert (tmp_path / ".signing-key").stat().st_mode & 0o077 == 0


def test_without_tokens_urls_are_plain_and_everyone_sees_everything(open_api):
    client, _ = open_api
    job = submit(client, {}).json()
    assert job["owner"] is None and job["access"] is None
    assert "?" not in job["inputs"]["exemplar"]
    assert client.get("/api/jobs").json()["count"] == 1


# -- token configuration --------------------------------------------------------------------------------


def test_a_token_file_with_comments_and_an_admin_entry(tmp_path):
    path = tmp_path / "tokens"
    path.write_text(f"# lab tokens\nalice:{ALICE}\n\nroot:{ADMIN}:admin  # the operator\n")
    tokens = Tokens.from_settings(Settings(data_dir=tmp_path, api_token_file=path))
    assert tokens.lookup(ALICE).name == "alice" and not tokens.lookup(ALICE).admin
    assert tokens.lookup(ADMIN).admin
    assert tokens.lookup("x" * 22) is None


def test_two_tokens_of_one_name_share_its_jobs(tmp_path):
    tokens = Tokens.from_settings(Settings(data_dir=tmp_path, api_tokens=f"alice:{ALICE},alice:{BOB}"))
    assert tokens.lookup(ALICE) == tokens.lookup(BOB)


@pytest.mark.parametrize(
    ("entries", "message"),
    [
        ("alice", "must read name:token or name:token:admin"),
        (f"alice:{ALICE}:root", "must read name:token or name:token:admin"),
        ("alice:short", "at least 16 printable characters"),
        (f"al ice:{ALICE}", "may hold only letters"),
        (f"alice:{ALICE},bob:{ALICE}", "already given to another name"),
    ],
)
def test_a_bad_token_entry_is_refused_at_start_naming_it(tmp_path, entries, message):
    with pytest.raises(TokenError, match=message) as info:
        Tokens.from_settings(Settings(data_dir=tmp_path, api_tokens=entries))
    assert "TEXSYNTH_API_TOKENS" in str(info.value)
    assert ALICE not in str(info.value)  # a message never shows a token


def test_a_missing_token_file_is_named(tmp_path):
    with pytest.raises(TokenError, match="TEXSYNTH_API_TOKEN_FILE: cannot read"):
        Tokens.from_settings(Settings(data_dir=tmp_path, api_token_file=tmp_path / "nope"))


def test_settings_never_show_a_token():
    settings = Settings(api_tokens=f"alice:{ALICE}", admin_token=ADMIN)
    assert ALICE not in repr(settings) and ADMIN not in repr(settings)


# -- serve's interface -----------------------------------------------------------------------------------


def test_serve_binds_loopback_without_tokens_and_says_so():
    host, notice = host_notice(None, tokens=False)
    assert host == "127.0.0.1"
    assert "listens on 127.0.0.1 only" in notice and "TEXSYNTH_API_TOKENS" in notice


def test_serve_warns_on_every_interface_without_tokens():
    host, notice = host_notice("0.0.0.0", tokens=False)
    assert host == "0.0.0.0"
    assert notice.startswith("texsynth serve: WARNING") and "without API tokens" in notice


def test_serve_is_quiet_with_tokens_or_on_loopback():
    assert host_notice("0.0.0.0", tokens=True) == ("0.0.0.0", None)
    assert host_notice("127.0.0.1", tokens=False) == ("127.0.0.1", None)


# -- same origin (CSRF) -----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "headers",
    [
        {"Origin": "http://evil.example", "Sec-Fetch-Site": "cross-site"},  # a browser's form post
        {"Origin": "http://evil.example"},  # an older browser: no Sec-Fetch-Site
        {"Sec-Fetch-Site": "same-site"},  # a sibling subdomain
        {"Origin": "null"},  # a sandboxed frame or a file:// page
    ],
)
def test_a_cross_origin_submission_is_refused(open_api, headers):
    client, service = open_api
    r = submit(client, headers)
    assert r.status_code == 403
    assert r.json()["error"] == "cross_origin"
    assert "cross-origin request refused" in r.json()["detail"]
    assert service.store.count() == 0
    assert list(service.settings.jobs_dir.iterdir()) == []


def test_a_cross_origin_delete_is_refused(open_api):
    client, service = open_api
    job = submit(client, {}).json()
    r = client.delete(f"/api/jobs/{job['id']}", headers={"Origin": "https://evil.example"})
    assert r.status_code == 403
    assert "https://evil.example" in r.json()["detail"]
    assert service.store.get(job["id"]).state == "queued"


def test_the_pages_own_requests_and_non_browsers_pass(open_api):
    client, _ = open_api
    own = {"Origin": "http://localhost", "Sec-Fetch-Site": "same-origin"}
    assert submit(client, own).status_code == 202
    assert submit(client, {"Sec-Fetch-Site": "none"}).status_code == 202
    assert submit(client, {}).status_code == 202  # curl, the Python client


def test_an_allowed_origin_passes(tmp_path):
    settings = Settings(data_dir=tmp_path / "data", allowed_origins=("https://texsynth.lab.example",))
    client, _ = _client(settings)
    with client:
        headers = {"Origin": "https://texsynth.lab.example", "Sec-Fetch-Site": "cross-site"}
        assert submit(client, headers).status_code == 202


def test_allowed_origins_come_from_the_environment(tmp_path):
    settings = Settings.from_env(
        {
            "TEXSYNTH_ALLOWED_ORIGINS": "https://a.example, https://b.example",
            "TEXSYNTH_DATA_DIR": str(tmp_path),
        }
    )
    assert settings.allowed_origins == ("https://a.example", "https://b.example")
    assert settings.to_env()["TEXSYNTH_ALLOWED_ORIGINS"] == "https://a.example,https://b.example"
    assert "TEXSYNTH_API_TOKENS" not in settings.to_env()  # unset values are not passed as "None"
