"""The browser page in real headless Chromium (Debian's package, driven by Playwright; no download).

Upload an exemplar (its preview appears), pick a method, read the generated parameter form, submit,
watch the progress bar move on the job page, and see the result image and the metrics. A screenshot
of the finished job page is saved under the test's tmp dir (and ``TEXSYNTH_SCREENSHOT`` if set).
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

pytestmark = [pytest.mark.integration, pytest.mark.browser]

CHROMIUM = "/usr/bin/chromium"
ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]


@pytest.fixture(scope="module")
def browser():
    if not Path(CHROMIUM).exists():
        pytest.skip("Debian's chromium is not installed (`apt-get install chromium`; .ci/run installs it)")
    sync_api = pytest.importorskip("playwright.sync_api")
    with sync_api.sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=CHROMIUM, args=ARGS, headless=True)
        yield b
        b.close()


def test_upload_submit_watch_progress_see_result(browser, service, exemplar_png, tmp_path):
    """On both queues (``service``: embedded and Redis): the page's whole flow does not depend on it."""
    embedded = service
    exemplar = tmp_path / "fringes.png"
    exemplar.write_bytes(exemplar_png)
    page = browser.new_page(viewport={"width": 1200, "height": 1000})
    errors: list[str] = []
    page.on("pageerror", lambda exc: errors.append(str(exc)))
    page.goto(embedded.url + "/")

    page.set_input_files("#exemplar", str(exemplar))
    page.wait_for_selector("#exemplar-preview:not([hidden])")
    page.select_option("#method", "test-blur")
    # the form is generated from the method's JSON schema, with its defaults
    assert page.input_value("#param-steps") == "10"
    assert page.input_value("#param-width") == "128"
    page.fill("#param-steps", "25")
    page.fill("#param-delay", "0.12")
    page.fill("#param-width", "96")
    page.fill("#param-height", "96")
    page.click("#submit")

    page.wait_for_url("**/#/jobs/*")
    # the progress bar moves while the job runs
    page.wait_for_function(
        "() => { const p = document.querySelector('#progress'); return p && p.value > 0 && p.value < 1; }",
        timeout=30_000,
    )
    page.wait_for_selector("#job-state.succeeded", timeout=60_000)
    result = page.wait_for_selector("img#result")
    page.wait_for_function("() => document.querySelector('img#result').naturalWidth === 96")
    assert result.is_visible()
    assert page.locator("#metrics tbody tr").count() > 0
    assert page.locator("#downloads a", has_text="output.tiff").count() == 1
    shot = tmp_path / "job-page.png"
    page.screenshot(path=str(shot), full_page=True)
    if os.environ.get("TEXSYNTH_SCREENSHOT"):
        shutil.copy(shot, os.environ["TEXSYNTH_SCREENSHOT"])
    assert not errors, errors

    # a rejected submission (past the browser's own checks) shows the service's message, marks the field
    page.goto(embedded.url + "/")
    page.set_input_files("#exemplar", str(exemplar))
    page.select_option("#method", "test-blur")
    page.fill("#param-steps", "0")
    page.evaluate("document.querySelector('.field[data-name=steps]').schema = {type: 'integer'}")
    page.click("#submit")
    page.wait_for_selector("#form-error:not([hidden])")
    assert "steps" in page.inner_text("#form-error")
    assert "invalid" in page.get_attribute(".field[data-name=steps]", "class")
    # the recent-jobs list shows the job we ran
    assert page.locator("#jobs-table tbody tr").count() >= 1
    page.close()


def test_a_volume_from_per_plane_exemplars_and_its_slice_viewer(browser, embedded, exemplar_png, tmp_path):
    paths = {}
    for plane in ("xy", "xz", "yz"):
        paths[plane] = tmp_path / f"{plane}.png"
        paths[plane].write_bytes(exemplar_png)
    page = browser.new_page(viewport={"width": 1200, "height": 1400})
    errors: list[str] = []
    page.on("pageerror", lambda exc: errors.append(str(exc)))
    page.goto(embedded.url + "/")
    page.wait_for_selector("#method option[value='test-stack']", state="attached")
    # a 2-D method asks for one exemplar; a solid one also offers the three planes, and a depth
    assert page.is_hidden("#exemplar_xy-box")
    page.select_option("#method", "test-stack")
    for plane in ("xy", "xz", "yz"):
        assert page.is_visible(f"#exemplar_{plane}-box")
        page.set_input_files(f"#exemplar_{plane}", str(paths[plane]))
    assert page.is_visible("#inputs-hint")
    page.fill("#param-width", "40")
    page.fill("#param-height", "32")
    page.fill("#param-depth", "24")
    page.click("#submit")
    page.wait_for_url("**/#/jobs/*")
    page.wait_for_selector("#job-state.succeeded", timeout=60_000)
    page.wait_for_selector("#volume-viewer:not([hidden])")
    # three orthogonal slices through the middle of the 40 x 32 x 24 volume (yz served y right, z down)
    size = "((i) => [i.naturalWidth, i.naturalHeight])(document.querySelector('#ortho-' + p))"
    sizes = f"['xy', 'xz', 'yz'].map((p) => {size}).join()"
    page.wait_for_function(f"() => {sizes} === '40,32,40,24,32,24'")
    assert page.inner_text("#ortho-pos").startswith("x = 20, y = 16, z = 12")
    assert "xy slice at z = 12" in page.inner_text("#cap-xy")
    # a click on the xy slice moves the crosshair's x and y; the xz and yz slices follow
    scale = int(page.input_value("input[name=ortho-zoom]:checked"))
    page.click("#box-xy", position={"x": 5 * scale + 1, "y": 9 * scale + 1})
    assert page.inner_text("#ortho-pos").startswith("x = 5, y = 9, z = 12")
    assert page.get_attribute("#ortho-xz", "src").split("?")[0].endswith("/slices/xz/9.png")
    assert page.get_attribute("#ortho-yz", "src").split("?")[0].endswith("/slices/yz/5.png")
    page.wait_for_function("() => document.querySelector('#ortho-yz').complete")
    cross = page.evaluate("() => document.querySelector('#box-xy .cross-v').style.left")
    assert cross == f"{5.5 * scale:g}px"
    # a click on the (transposed) yz slice: z right, y down
    page.click("#box-yz", position={"x": 3 * scale + 1, "y": 4 * scale + 1})
    assert page.inner_text("#ortho-pos").startswith("x = 5, y = 4, z = 3")
    assert page.get_attribute("#ortho-xy", "src").split("?")[0].endswith("/slices/xy/3.png")
    # the z slider, zoom and contrast
    page.fill("#pos-z", "20")
    page.dispatch_event("#pos-z", "input")
    assert "xy slice at z = 20" in page.inner_text("#cap-xy")
    page.check("input[name=ortho-zoom][value='1']", force=True)
    assert page.evaluate("() => document.querySelector('#box-xy').getBoundingClientRect().width") == 40
    page.fill("#ortho-contrast", "2")
    page.dispatch_event("#ortho-contrast", "input")
    assert page.evaluate("() => document.querySelector('#ortho-xz').style.filter") == "contrast(2)"
    assert page.locator("#result-images figcaption", has_text="corner cut away").count() == 1
    # per-axis metrics of the volume, one column per plane
    page.wait_for_selector("#axis-metrics:not([hidden]) tbody tr")
    header = page.inner_text("#axis-metrics thead")
    assert "xy slices" in header and "xz slices" in header and "yz slices" in header
    assert "orientation KL" in page.inner_text("#axis-metrics tbody")
    page.screenshot(path=str(tmp_path / "volume-page.png"), full_page=True)
    assert not errors, errors
    page.close()


def test_job_page_explains_parameters_metrics_and_failures(browser, embedded, exemplar_png, tmp_path):
    client = embedded.client()
    done = client.wait(
        client.submit(exemplar_png, method="test-blur", params={"width": 48, "height": 48, "steps": 3})["id"],
        timeout=60,
    )
    failed = client.wait(
        client.submit(exemplar_png, method="test-blur", params={"steps": 5, "fail": "boom"})["id"], timeout=60
    )
    assert failed["state"] == "failed"
    page = browser.new_page(viewport={"width": 1200, "height": 1000})
    errors: list[str] = []
    page.on("pageerror", lambda exc: errors.append(str(exc)))
    page.goto(f"{embedded.url}/#/jobs/{done['id']}")
    page.wait_for_selector("#job-state.succeeded")
    # the parameters used, defaults marked
    page.wait_for_selector("#job-params tbody tr", state="attached")
    page.click("#job-params-box summary")
    params = page.inner_text("#job-params")
    assert "steps" in params and "default 10" in params and "sigma" in params and "default" in params
    # each headline measure with its meaning and a verdict against the documented threshold
    page.wait_for_selector("#metrics tbody tr")
    metrics = page.inner_text("#metrics")
    assert "grey-level KL" in metrics and "lower is better" in metrics
    # every headline measure with its target and a verdict
    for row in page.locator("#metrics tbody tr").all():
        cells = row.locator("td").all_inner_texts()
        assert cells[1].strip() and "target" in cells[2], cells
    assert "< 0.05" in page.inner_text("#metrics tr[data-measure='grey_kl']")
    # the exemplar's own fringe statistics beside the output's
    fringes = page.inner_text("#fringe-metrics")
    assert "exemplar" in fringes and "output" in fringes and "mean length (px)" in fringes
    page.screenshot(path=str(tmp_path / "explained.png"), full_page=True)
    # a failed job: the reason in words, and a red bar
    page.goto(f"{embedded.url}/#/jobs/{failed['id']}")
    page.wait_for_selector("#job-state.failed")
    assert "the test method was asked to fail" in page.inner_text("#job-message")
    assert page.inner_text("#progress-text").startswith("failed at")
    assert page.evaluate("() => document.querySelector('#progress').classList.contains('failed')")
    assert not errors, errors
    page.close()
