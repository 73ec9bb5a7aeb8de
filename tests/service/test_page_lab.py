"""The job page as a lab tool, in headless Chromium (issue 15): the viewer (zoom, tiling, tensor images),
timings by stage, "run again with these settings", a 3-value sweep with its table, plot and CSV, and
the comparison of two jobs. Small images and the fast ``test-blur`` method keep it quick.
"""

from __future__ import annotations

import csv
import io

import httpx
import pytest

from tests.service.test_browser import browser  # noqa: F401  (the module-scoped Chromium fixture)

pytestmark = [pytest.mark.integration, pytest.mark.browser]


@pytest.fixture(scope="module")
def two_jobs(embedded, exemplar_png) -> tuple[dict, dict]:
    """Two finished 48x48 test-blur jobs that differ in sigma (and seed)."""
    client = embedded.client()
    a = client.submit(
        exemplar_png,
        method="test-blur",
        params={"width": 48, "height": 48, "steps": 2, "delay": 0, "sigma": 0.5},
        seed=7,
    )
    b = client.submit(
        exemplar_png,
        method="test-blur",
        params={"width": 48, "height": 48, "steps": 2, "delay": 0, "sigma": 2.0},
        seed=8,
    )
    a, b = client.wait(a["id"], timeout=60), client.wait(b["id"], timeout=60)
    assert a["state"] == b["state"] == "succeeded"
    return a, b


def _page(browser, viewport=(1200, 1000)):  # noqa: F811
    page = browser.new_page(viewport={"width": viewport[0], "height": viewport[1]})
    errors: list[str] = []
    page.on("pageerror", lambda exc: errors.append(str(exc)))
    return page, errors


def _width(page, selector: str) -> float:
    return page.evaluate(f"() => document.querySelector({selector!r}).getBoundingClientRect().width")


def test_viewer_zooms_by_keyboard_tiles_the_output_and_shows_timings(browser, embedded, two_jobs):  # noqa: F811
    job, _ = two_jobs
    page, errors = _page(browser)
    page.goto(f"{embedded.url}/#/jobs/{job['id']}")
    page.wait_for_selector("#viewer:not([hidden])")
    page.wait_for_function("() => document.querySelector('#result').naturalWidth === 48")
    page.wait_for_function("() => document.querySelector('#view-exemplar').naturalWidth === 64")
    # 1:1, then the arrow keys move through the zoom choices (native radio buttons)
    page.click("#zoom label:nth-of-type(2)")
    assert page.is_checked("input[name=zoom][value='1']")
    assert _width(page, "#result") == 48 and _width(page, "#view-exemplar") == 64
    page.keyboard.press("ArrowRight")
    assert page.is_checked("input[name=zoom][value='2']")
    assert _width(page, "#result") == 96 and _width(page, "#view-exemplar") == 128  # one pixel scale
    page.keyboard.press("ArrowRight")
    assert _width(page, "#result") == 192
    assert "one pixel = 4 screen pixels" in page.inner_text("#zoom-status")
    # pixels stay square blocks when zoomed
    assert (
        page.evaluate("() => getComputedStyle(document.querySelector('#result')).imageRendering")
        == "pixelated"
    )
    # tile 2x2, by keyboard: four copies of the output, the caption says what to look for
    assert page.locator("#tiles img:visible").count() == 1
    page.focus("#tile")
    page.keyboard.press("Space")
    assert page.locator("#tiles img:visible").count() == 4
    assert _width(page, "#tiles") >= 2 * 192
    assert "tiled 2\u00d72" in page.inner_text("#cap-output")
    # the tensor images at the output's size (their own legend cropped away), the exemplar's beside them
    # at the exemplar's, and the legends below the stage
    for kind in ("coherence", "orientation"):
        assert _width(page, f"#fig-{kind} .crop") == 192
        assert _width(page, f"#fig-ex-{kind} .crop") == 256
        page.wait_for_function(f"() => document.querySelector('#view-ex-{kind}').naturalWidth > 0")
    assert page.locator("#tensor-legends .legend").count() == 2
    assert page.locator("#tensor-legends .legend").first.is_visible()
    # fit keeps exemplar and output side by side inside the page
    page.check("input[name=zoom][value='fit']", force=True)
    assert _width(page, "#view-exemplar") + _width(page, "#tiles") < 1200
    # timings by stage: the queue, the method's own stages, the evaluation
    page.click("#timings-box summary")
    timings = page.inner_text("#timings")
    assert "waiting in the queue" in timings and "blur" in timings and "evaluation" in timings
    assert not errors, errors
    page.close()


def test_run_again_fills_the_form_and_reuses_the_inputs(browser, embedded, two_jobs):  # noqa: F811
    job, _ = two_jobs
    page, errors = _page(browser)
    page.goto(f"{embedded.url}/#/jobs/{job['id']}")
    page.wait_for_selector("#job-state.succeeded")
    page.click("#rerun")
    page.wait_for_url("**/#/new?from=*")
    page.wait_for_selector("#rerun-note:not([hidden])")
    assert "exemplar reused" in page.inner_text("#rerun-note")
    assert page.input_value("#method") == "test-blur"
    assert page.input_value("#param-width") == "48" and page.input_value("#param-steps") == "2"
    assert page.input_value("#param-sigma") == "0.5" and page.input_value("#seed") == "7"
    assert page.evaluate("() => document.querySelector('#exemplar').files.length") == 1
    page.wait_for_selector("#exemplar-preview:not([hidden])")
    page.click("#submit")
    page.wait_for_url("**/#/jobs/*")
    new_id = page.url.rsplit("/", 1)[1]
    assert new_id != job["id"]
    again = embedded.client().wait(new_id, timeout=60)
    assert again["params"] == job["params"] and again["size"] == job["size"] and again["seed"] == job["seed"]
    same_input = [httpx.get(embedded.url + j["inputs"]["exemplar"]).content for j in (job, again)]
    assert same_input[0] == same_input[1]
    assert not errors, errors
    page.close()


def test_a_three_value_sweep_its_table_plot_and_csv(browser, embedded, exemplar_png, tmp_path):  # noqa: F811
    exemplar = tmp_path / "fringes.png"
    exemplar.write_bytes(exemplar_png)
    page, errors = _page(browser)
    page.goto(embedded.url + "/")
    page.set_input_files("#exemplar", str(exemplar))
    page.select_option("#method", "test-blur")
    for name, value in (("width", "32"), ("height", "32"), ("steps", "1"), ("delay", "0")):
        page.fill(f"#param-{name}", value)
    page.click("#sweep-box summary")
    page.select_option("#sweep-param", "sigma")
    # a range of values, previewed before anything runs
    page.check("input[name=sweep-kind][value=range]", force=True)
    page.fill("#sweep-from", "0.5")
    page.fill("#sweep-to", "2")
    page.fill("#sweep-count", "3")
    page.fill("#sweep-seeds", "3")
    page.dispatch_event("#sweep-seeds", "input")
    assert page.inner_text("#sweep-preview") == "3 runs: sigma = 0.5, 1.25, 2; seed 3"
    # or a list
    page.check("input[name=sweep-kind][value=list]", force=True)
    page.fill("#sweep-values", "0.5, 1, x")
    page.dispatch_event("#sweep-values", "input")
    assert "'x' is not a valid number" in page.inner_text("#sweep-preview")
    page.fill("#sweep-values", "0.5, 1, 2")
    page.dispatch_event("#sweep-values", "input")
    page.click("#sweep-submit")
    page.wait_for_url("**/#/sweeps/*")
    page.wait_for_selector("#sweep-state.succeeded", timeout=90_000)
    # the table: one row per run, its value, seed, state, headline measures and a thumbnail
    rows = page.locator("#sweep-table tbody tr")
    assert rows.count() == 3
    header = page.inner_text("#sweep-table thead")
    assert "sigma" in header and "grey-level KL" in header and "orientation KL" in header
    table = page.inner_text("#sweep-table tbody")
    for value in ("0.5", "1", "2"):
        assert f"\t{value}\t" in table
    assert table.count("succeeded") == 3
    thumbs = "[...document.querySelectorAll('#sweep-table img.thumb')]"
    page.wait_for_function(f"() => {thumbs}.filter((i) => i.naturalWidth === 32).length === 3")
    # the plot: three points of the chosen measure against sigma; another measure redraws it
    assert page.locator("#sweep-svg circle.point").count() == 3
    assert page.text_content("#sweep-svg > title") == "grey-level KL against sigma"
    assert "sigma" in page.inner_text("#sweep-plot-caption")
    page.select_option("#sweep-metric", "summary.orientation_kl")
    assert page.text_content("#sweep-svg > title") == "orientation KL against sigma"
    assert page.locator("#sweep-svg circle.point").count() == 3
    # CSV download: a header and three runs
    href = page.get_attribute("#sweep-csv a", "href")
    text = httpx.get(embedded.url + href).text
    runs = list(csv.DictReader(io.StringIO(text)))
    assert sorted(float(r["sigma"]) for r in runs) == [0.5, 1.0, 2.0]
    assert all(r["summary.grey_kl"] for r in runs)
    assert not errors, errors
    page.close()


def test_compare_two_jobs_swipe_blink_and_metrics(browser, embedded, two_jobs):  # noqa: F811
    a, b = two_jobs
    page, errors = _page(browser)
    page.goto(f"{embedded.url}/#/jobs/{a['id']}")
    page.wait_for_selector(f"#compare-with option[value='{b['id']}']", state="attached")
    page.select_option("#compare-with", b["id"])
    page.click("#compare-go")
    page.wait_for_url(f"**/#/compare/{a['id']}/{b['id']}")
    page.wait_for_selector("#compare-metrics tbody tr")
    page.wait_for_function("() => document.querySelector('#compare-img-b').naturalWidth === 48")
    # metrics side by side, with the better one named
    metrics = page.inner_text("#compare-metrics")
    assert "grey-level KL" in metrics and "lower is better" in metrics
    # the settings that differ are marked
    sigma_row = page.locator("#compare-params tr", has_text="sigma")
    assert "differs" in sigma_row.get_attribute("class") and "(differs)" in sigma_row.inner_text()
    # swipe: B is cut at the slider's position
    page.check("input[name=compare-zoom][value='2']", force=True)
    page.fill("#swipe", "25")
    page.dispatch_event("#swipe", "input")
    assert (
        page.evaluate("() => document.querySelector('#compare-img-b').style.clipPath")
        == "inset(0px 0px 0px 24px)"
    )
    # blink, chosen by keyboard: the two outputs alternate until paused
    page.focus("input[name=compare-mode][value=swipe]")
    page.keyboard.press("ArrowRight")
    assert page.is_checked("input[name=compare-mode][value=blink]")
    page.wait_for_selector("#blink-box:not([hidden])")
    seen = {page.inner_text("#blink-label")[:1]}
    first = next(iter(seen))
    page.wait_for_function(
        f"() => !document.querySelector('#blink-label').textContent.startsWith({first!r})", timeout=3000
    )
    seen.add(page.inner_text("#blink-label")[:1])
    assert seen == {"A", "B"}
    page.click("#blink-play")
    assert page.get_attribute("#blink-play", "aria-pressed") == "false"
    assert not errors, errors
    page.close()


def test_recent_jobs_say_why_a_job_failed(browser, embedded, exemplar_png):  # noqa: F811
    client = embedded.client()
    params = {"steps": 1, "delay": 0, "fail": "no good"}
    failed = client.wait(client.submit(exemplar_png, method="test-blur", params=params)["id"], timeout=60)
    assert failed["state"] == "failed"
    page, errors = _page(browser)
    page.goto(embedded.url + "/")
    row = page.locator("#jobs-table tbody tr", has=page.locator(f"a[href='#/jobs/{failed['id']}']"))
    row.wait_for()
    assert "the test method was asked to fail" in row.inner_text()
    assert not errors, errors
    page.close()
