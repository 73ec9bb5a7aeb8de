"""Stored content cannot run as a page (issue 14): uploads are stored and served by their sniffed format,
every response says ``nosniff`` and carries a content security policy."""

from __future__ import annotations

import io
import zlib
from pathlib import Path

import httpx
import numpy as np
import pytest
from PIL import Image, PngImagePlugin

from texsynth.app.security import CONTENT_SECURITY_POLICY

pytestmark = pytest.mark.integration

SCRIPT = b"<html><script>document.title='pwned';window.pwned=1</script></html>"


def _png_with_script() -> bytes:
    info = PngImagePlugin.PngInfo()
    info.add_text("Comment", SCRIPT.decode())
    buf = io.BytesIO()
    Image.fromarray(np.full((32, 32), 128, np.uint8)).save(buf, format="PNG", pnginfo=info)
    assert zlib.crc32(buf.getvalue()) and SCRIPT in buf.getvalue()
    return buf.getvalue()


def test_an_html_named_upload_is_stored_and_served_as_png(embedded):
    files = {"exemplar": ("evil.html", _png_with_script(), "text/html")}
    r = httpx.post(
        f"{embedded.url}/api/jobs", files=files, data={"method": "test-blur", "params": "{}"}, timeout=30
    )
    assert r.status_code == 202, r.text
    job = r.json()
    assert embedded.store().get(job["id"]).inputs == {"exemplar": "exemplar.png"}
    served = httpx.get(embedded.url + job["inputs"]["exemplar"], timeout=30)
    assert served.headers["content-type"] == "image/png"
    assert served.headers["x-content-type-options"] == "nosniff"
    assert served.headers["content-security-policy"] == CONTENT_SECURITY_POLICY
    for path in ("/", "/api/health", "/static/app.js"):
        assert httpx.get(embedded.url + path, timeout=30).headers["x-content-type-options"] == "nosniff"


def test_no_script_runs_when_the_stored_input_is_opened(embedded, tmp_path: Path):
    chromium = Path("/usr/bin/chromium")
    if not chromium.exists():
        pytest.skip("Debian's chromium is not installed (`apt-get install chromium`; .ci/run installs it)")
    sync_api = pytest.importorskip("playwright.sync_api")
    files = {"exemplar": ("evil.html", _png_with_script(), "text/html")}
    job = httpx.post(
        f"{embedded.url}/api/jobs", files=files, data={"method": "test-blur", "params": "{}"}, timeout=30
    ).json()
    with sync_api.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=str(chromium), args=["--no-sandbox"], headless=True)
        page = browser.new_page()
        page.goto(embedded.url + job["inputs"]["exemplar"])
        assert page.evaluate("() => window.pwned === undefined && document.title !== 'pwned'")
        browser.close()
