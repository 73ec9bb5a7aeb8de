"""Tokens and the same-origin rule against a real ``texsynth serve``: the CLI, the Python client and
the browser page (headless Chromium) with a token; a cross-origin form post from another site's page.
"""

from __future__ import annotations

import http.server
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from tests.service.conftest import ADMIN_TOKEN, REPO, TOKENS, free_port
from tests.service.test_browser import browser  # noqa: F401  (the module's Chromium fixture)
from texsynth.app.client import Client, ServiceError

pytestmark = [pytest.mark.integration]

CLI = [sys.executable, "-c", "import sys; from texsynth.synth.cli import main; sys.exit(main())"]


def test_texsynth_submit_with_a_token(token_service, exemplar_png, tmp_path):
    exemplar = tmp_path / "e.png"
    exemplar.write_bytes(exemplar_png)
    args = [*CLI, "submit", str(exemplar), "--url", token_service.url, "--method", "test-blur"]
    args += ["--width", "32", "--height", "32", "--set", "steps=2", "--out", str(tmp_path / "out")]
    env = {**token_service.env, "TEXSYNTH_TOKEN": TOKENS["alice"]}
    done = subprocess.run(args, env=env, cwd=REPO, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    folder = Path(done.stdout.strip())
    assert (folder / "output.png").stat().st_size > 0  # downloaded through the signed URLs

    without = {k: v for k, v in token_service.env.items() if k != "TEXSYNTH_TOKEN"}
    refused = subprocess.run(args, env=without, cwd=REPO, capture_output=True, text=True, timeout=60)
    assert refused.returncode == 2
    assert refused.stderr.strip().splitlines() == [
        "texsynth submit: error: HTTP 401: this service needs a token: send the header "
        "'Authorization: Bearer <token>' (texsynth submit --token or $TEXSYNTH_TOKEN; the browser page "
        "asks for it)"
    ]
    wrong = subprocess.run(
        [*args, "--token", "not-a-token-of-this-service"],
        env=without,
        cwd=REPO,
        capture_output=True,
        text=True,
    )
    assert wrong.returncode == 2 and "not one this service knows" in wrong.stderr


def test_the_client_sees_only_its_own_jobs(token_service, exemplar_png):
    alice = Client(token_service.url, token=TOKENS["alice"])
    bob = Client(token_service.url, token=TOKENS["bob"])
    job = alice.submit(exemplar_png, method="test-blur", params={"width": 32, "height": 32, "steps": 2})
    job = alice.wait(job["id"], timeout=60)
    assert job["state"] == "succeeded" and job["owner"] == "alice"
    with pytest.raises(ServiceError) as info:
        bob.job(job["id"])
    assert info.value.status == 404
    assert job["id"] not in {j["id"] for j in bob.jobs()["data"]}
    assert job["id"] in {j["id"] for j in Client(token_service.url, token=ADMIN_TOKEN).jobs()["data"]}
    assert alice.delete(job["id"])["state"] == "deleted"
    assert not (token_service.data_dir / "jobs" / job["id"]).exists()


@pytest.mark.browser
def test_the_page_asks_for_the_token_once_and_works(browser, token_service, exemplar_png, tmp_path):  # noqa: F811
    exemplar = tmp_path / "fringes.png"
    exemplar.write_bytes(exemplar_png)
    page = browser.new_page(viewport={"width": 1200, "height": 1000})
    errors: list[str] = []
    page.on("pageerror", lambda exc: errors.append(str(exc)))
    page.goto(token_service.url + "/")
    page.wait_for_selector("#token-dialog[open]")
    assert "needs an API token" in page.inner_text("#token-message")
    page.fill("#token-input", "not-a-token-of-this-service")
    page.click("#token-form button[type=submit]")
    page.wait_for_function("() => document.querySelector('#token-message').textContent.includes('refused')")
    page.fill("#token-input", TOKENS["alice"])
    page.click("#token-form button[type=submit]")
    page.wait_for_selector("#method option[value='test-blur']", state="attached")
    assert page.evaluate("sessionStorage.getItem('texsynth-token')") == TOKENS["alice"]
    assert page.evaluate("localStorage.getItem('texsynth-token')") is None
    assert page.is_visible("#token-forget")

    page.set_input_files("#exemplar", str(exemplar))
    page.select_option("#method", "test-blur")
    page.fill("#param-steps", "3")
    page.fill("#param-width", "48")
    page.fill("#param-height", "48")
    page.click("#submit")
    page.wait_for_url("**/#/jobs/*")
    page.wait_for_selector("#job-state.succeeded", timeout=60_000)
    # images load through their signed URLs (an <img> sends no Authorization header)
    page.wait_for_function("() => document.querySelector('img#result').naturalWidth === 48")
    link = page.locator("#downloads a[download='output.png']").get_attribute("href")
    assert "access=" in link and TOKENS["alice"] not in link
    # the token is asked once: a reload of the tab keeps it
    page.reload()
    page.wait_for_selector("#job-state.succeeded")
    assert not page.is_visible("#token-dialog")
    assert not errors, errors
    page.close()


class _EvilSite(http.server.BaseHTTPRequestHandler):
    target = ""

    def do_GET(self):  # a page of another origin that posts a job to the service on load
        body = (
            f'<form id="f" method="post" enctype="multipart/form-data" action="{self.target}/api/jobs">'
            '<input name="method" value="test-blur"><input name="params" value="{}"></form>'
            "<script>document.getElementById('f').submit()</script>"
        ).encode()
        self.send_response(200)
        self.send_header("Content-Type", "text/html")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, *args):
        pass


@pytest.mark.browser
def test_a_cross_origin_form_post_from_another_site_is_refused(browser, embedded):  # noqa: F811
    handler = type("Evil", (_EvilSite,), {"target": embedded.url})
    server = http.server.ThreadingHTTPServer(("127.0.0.1", free_port()), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    before = embedded.store().count()
    page = browser.new_page()
    try:
        page.goto(f"http://127.0.0.1:{server.server_address[1]}/")  # another origin: another port
        page.wait_for_url(f"{embedded.url}/api/jobs", timeout=10_000)
        page.wait_for_function("() => document.body.innerText.includes('cross-origin request refused')")
        assert '"error":"cross_origin"' in page.inner_text("body").replace(" ", "")
    finally:
        page.close()
        server.shutdown()
        server.server_close()
    assert embedded.store().count() == before
