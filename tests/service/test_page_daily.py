"""The page for daily lab use (issue 27), in headless Chromium: every registered method submits from its
defaults (both queues), the basic set stays short, a rejected field is marked, focused and explained in
one line, a sweep ranks its values and "use this value" fills the form, a cancelled job reads as
cancelled, the job list filters and deletes, and the pages fit 800 px without sideways scrolling. Every
test also fails on a console error.
"""

from __future__ import annotations

import httpx
import pytest

from tests.service.test_browser import browser  # noqa: F401  (the module-scoped Chromium fixture)

pytestmark = [pytest.mark.integration, pytest.mark.browser]

#: a small output per kind of method, so that every method's defaults run in seconds
SMALL_2D = {"width": "48", "height": "48"}
SMALL_3D = {"width": "16", "height": "16", "depth": "16"}


def _page(browser, width: int = 1200, height: int = 1000, expected: tuple[str, ...] = ()):  # noqa: F811
    """A page and the list its console errors and uncaught exceptions go to (``expected`` ones aside)."""
    page = browser.new_page(viewport={"width": width, "height": height})
    errors: list[str] = []

    def console(message) -> None:
        if message.type == "error" and not any(e in message.text for e in expected):
            errors.append(message.text)

    page.on("console", console)
    page.on("pageerror", lambda exc: errors.append(str(exc)))
    return page, errors


def _methods(url: str) -> list[dict]:
    return httpx.get(url + "/api/methods", timeout=10).json()["data"]


@pytest.fixture()
def files(tmp_path, exemplar_png) -> dict[str, str]:
    exemplar = tmp_path / "fringes.png"
    exemplar.write_bytes(exemplar_png)
    return {"exemplar": str(exemplar)}


def test_every_method_submits_with_its_defaults(browser, service, files):  # noqa: F811
    """Each registered method, from the page, with the form as built from its schema (only the size made
    small): submitted, accepted, and succeeded. A list field shown wrongly (issue 27's `planes`) or a
    default the server refuses fails here, whatever method brings it."""
    page, errors = _page(browser)
    page.goto(service.url + "/")
    page.wait_for_selector("#method option[value='wei-levoy']", state="attached")
    submitted = {}
    for method in _methods(service.url):
        name = method["name"]
        page.goto(service.url + "/#/")
        page.wait_for_selector(f"#method option[value='{name}']", state="attached")
        page.select_option("#method", name)
        page.set_input_files("#exemplar", files["exemplar"])
        if method["inputs"].get("constraint") == "required":
            page.set_input_files("#constraint", files["exemplar"])
        small = SMALL_3D if method["output_ndim"] == 3 else SMALL_2D
        for field, value in small.items():
            page.fill(f"#param-{field}", value)
        page.fill("#seed", "1")
        page.click("#submit")
        page.wait_for_url("**/#/jobs/*", timeout=20_000)
        submitted[name] = page.url.rsplit("/", 1)[1]
        assert page.is_hidden("#form-error") or not page.query_selector("#form-error")
    client = service.client()
    states = {name: client.wait(job, timeout=300) for name, job in submitted.items()}
    failed = {name: (j["state"], j["message"]) for name, j in states.items() if j["state"] != "succeeded"}
    assert not failed, failed
    # the solids' list field went as a JSON array of plane names
    for name, job in states.items():
        if "planes" in job["params"]:
            assert sorted(job["params"]["planes"]) == ["xy", "xz", "yz"], name
    assert not errors, errors
    page.close()


def test_the_basic_set_is_at_most_12_inputs_for_every_method(browser, embedded):  # noqa: F811
    page, errors = _page(browser)
    page.goto(embedded.url + "/")
    page.wait_for_selector("#method option[value='wei-levoy']", state="attached")
    counts = {}
    for method in _methods(embedded.url):
        page.select_option("#method", method["name"])
        # the fields shown before "Advanced": size, seed and the basic parameters
        counts[method["name"]] = page.locator("#basic-set > .grid .field:visible").count()
        total = len(method["params_schema"]["properties"])
        advanced = page.locator("#advanced-fields .field").count()
        assert advanced + page.locator("#basic-fields .field").count() == total, method["name"]
        assert not page.locator("#advanced-box").evaluate("(d) => d.open"), "Advanced starts closed"
        # every input has its help outside its label, tied to it by aria-describedby
        for field in page.locator("#job-form .field[data-name]").all():
            name = field.get_attribute("data-name")
            target = field.locator(f"#param-{name}, #seed").first
            described = (target.get_attribute("aria-describedby") or "").split()
            assert described and page.locator(f"[id='{described[0]}']").text_content().strip(), name
            if page.locator(f"label[for='param-{name}']").count():
                assert "help" not in page.locator(f"label[for='param-{name}']").inner_html()
    assert max(counts.values()) <= 12, counts
    assert min(counts.values()) >= 3, counts  # at least the size and the seed
    assert page.locator("h1").count() == 1
    assert not errors, errors
    page.close()


def test_a_rejected_field_is_highlighted_focused_and_explained(browser, embedded, files):  # noqa: F811
    page, errors = _page(browser, expected=("status of 422",))
    page.goto(embedded.url + "/")
    page.wait_for_selector("#method option[value='wei-levoy']", state="attached")
    page.set_input_files("#exemplar", files["exemplar"])
    page.select_option("#method", "wei-levoy")

    def rejected(expect: str) -> None:
        field = page.locator(".field[data-name='neighbourhood_size']")
        page.wait_for_selector("#param-neighbourhood_size-error:not([hidden])")
        assert "invalid" in field.get_attribute("class")
        assert page.get_attribute("#param-neighbourhood_size", "aria-invalid") == "true"
        assert page.evaluate("() => document.activeElement.id") == "param-neighbourhood_size"
        line = page.inner_text("#param-neighbourhood_size-error")
        assert expect in line and "\n" not in line and "{" not in line, line
        assert "{" not in page.inner_text("#form-error")  # never the whole parameter dictionary
        assert page.url.endswith("/") or page.url.endswith("#/")  # nothing was submitted

    # checked in the browser: even, and out of range
    page.fill("#param-neighbourhood_size", "12")
    page.click("#submit")
    rejected("odd")
    page.fill("#param-neighbourhood_size", "9")  # editing clears the mark
    assert "invalid" not in page.locator(".field[data-name='neighbourhood_size']").get_attribute("class")
    page.fill("#param-neighbourhood_size", "999")
    page.click("#submit")
    rejected("at most")
    # the same value past the browser's checks: the service's 422 marks the same field
    page.evaluate(
        "() => { const f = document.querySelector('.field[data-name=neighbourhood_size]');"
        " f.schema = { type: 'integer', title: 'n' }; }"
    )
    page.fill("#param-neighbourhood_size", "12")
    page.click("#submit")
    rejected("odd")
    assert not errors, errors
    page.close()


def test_a_sweep_ranks_its_values_and_use_this_value_fills_the_form(browser, embedded, files):  # noqa: F811
    page, errors = _page(browser)
    page.goto(embedded.url + "/")
    page.wait_for_selector("#method option[value='test-blur']", state="attached")
    page.set_input_files("#exemplar", files["exemplar"])
    page.select_option("#method", "test-blur")
    for name, value in (("width", "32"), ("height", "32"), ("steps", "1"), ("delay", "0")):
        page.fill(f"#param-{name}", value)
    page.click("#sweep-box summary")
    page.select_option("#sweep-param", "sigma")
    page.fill("#sweep-values", "0.5, 2, 6")
    page.fill("#sweep-seeds", "1, 2")
    page.dispatch_event("#sweep-seeds", "input")
    page.click("#sweep-submit")
    page.wait_for_url("**/#/sweeps/*")
    page.wait_for_selector("#sweep-state.succeeded", timeout=90_000)
    # the ranking: one row per value, mean ± spread over the two seeds, one best marked
    ranking = page.locator("#sweep-ranking tbody tr")
    assert ranking.count() == 3
    assert page.locator("#sweep-ranking tr.best").count() == 1
    assert "★ best" in page.inner_text("#sweep-ranking tr.best th")
    assert "±" in page.inner_text("#sweep-ranking tbody")
    assert "2 of 2" in ranking.first.inner_text()
    # the best value follows the chosen measure's direction: check it against the runs' own means
    chosen = page.input_value("#sweep-metric")
    runs = page.locator("#sweep-table tbody tr")
    assert runs.count() == 6
    # sort the runs by the chosen measure, both ways
    page.click(f"#sweep-table th[data-key='{chosen}'] button")
    assert page.get_attribute(f"#sweep-table th[data-key='{chosen}']", "aria-sort") == "ascending"
    keys = [th.get_attribute("data-key") for th in page.locator("#sweep-table thead th").all()]
    cells = f"#sweep-table tbody td:nth-child({keys.index(chosen) + 1})"
    values = [float(t) for t in page.locator(cells).all_inner_texts()]
    assert values == sorted(values)
    page.click(f"#sweep-table th[data-key='{chosen}'] button")
    values = [float(t) for t in page.locator(cells).all_inner_texts()]
    assert values == sorted(values, reverse=True)
    # "use this value" on the value 6: the form, filled, with sigma = 6 marked
    page.click("#sweep-ranking tr[data-value='6'] button.use-value")
    page.wait_for_url("**/#/new?from=*")
    page.wait_for_selector("#rerun-note:not([hidden])")
    assert page.input_value("#method") == "test-blur"
    assert page.input_value("#param-sigma") == "6"
    assert page.input_value("#param-width") == "32"
    assert "sigma = 6" in page.inner_text("#rerun-note")
    assert "chosen" in page.locator(".field[data-name='sigma']").get_attribute("class")
    assert not errors, errors
    page.close()


def test_a_cancelled_job_reads_as_cancelled(browser, service, exemplar_png):  # noqa: F811
    client = service.client()
    params = {"width": 32, "height": 32, "steps": 400, "delay": 0.05}
    job = client.submit(exemplar_png, method="test-blur", params=params)
    page, errors = _page(browser)
    page.goto(f"{service.url}/#/jobs/{job['id']}")
    page.wait_for_function("() => document.querySelector('#progress').value > 0", timeout=30_000)
    page.click("#cancel")
    page.wait_for_selector("#job-state.cancelled", timeout=30_000)
    assert page.inner_text("#progress-text").startswith("cancelled")
    assert page.evaluate("() => document.querySelector('#progress').value") < 1
    assert "100%" not in page.inner_text("#progress-text")
    assert not errors, errors
    page.close()


def test_the_job_list_filters_pages_and_deletes(browser, embedded, exemplar_png):  # noqa: F811
    client = embedded.client()
    params = {"width": 24, "height": 24, "steps": 1, "delay": 0}
    jobs = [client.submit(exemplar_png, method="test-blur", params=params, seed=s)["id"] for s in range(3)]
    for job in jobs:
        client.wait(job, timeout=60)
    page, errors = _page(browser)
    page.on("dialog", lambda dialog: dialog.accept())
    page.goto(embedded.url + "/#/jobs")
    page.wait_for_selector(f"#jobs-table tr[data-job='{jobs[0]}']")
    # a thumbnail and the method per row
    row = page.locator(f"#jobs-table tr[data-job='{jobs[0]}']")
    assert "test-blur" in row.inner_text()
    page.wait_for_function(
        f"() => document.querySelector(\"tr[data-job='{jobs[0]}'] img.thumb\").naturalWidth > 0"
    )
    # filter by method (one no job used) and by state
    page.select_option("#filter-method", "test-stack")
    page.wait_for_function(f"() => !document.querySelector(\"tr[data-job='{jobs[0]}']\")")
    page.select_option("#filter-method", "test-blur")
    page.select_option("#filter-state", "succeeded")
    every = "[...document.querySelectorAll('#jobs-table tbody .state')].every"
    page.wait_for_function(f"() => {every}((s) => s.textContent === 'succeeded')")
    page.wait_for_selector(f"#jobs-table tr[data-job='{jobs[0]}']")
    methods = page.locator("#jobs-table tbody td:nth-child(3)").all_inner_texts()
    assert methods and all(m.startswith("test-blur") for m in methods)
    # delete one: gone from the list and from the service
    page.click(f"#jobs-table tr[data-job='{jobs[0]}'] button.danger")
    page.wait_for_function(f"() => !document.querySelector(\"tr[data-job='{jobs[0]}']\")")
    assert httpx.get(f"{embedded.url}/api/jobs/{jobs[0]}").status_code == 404
    # paging: 12 a page, "older" shows the next ones
    for seed in range(3, 16):
        more = client.submit(exemplar_png, method="test-blur", params=params, seed=seed)
        client.wait(more["id"], timeout=60)
    page.select_option("#filter-state", "")
    page.wait_for_function(
        "() => / of (1[3-9]|[2-9][0-9]|[0-9]{3,})$/.test(document.querySelector('#jobs-page').textContent)"
    )
    assert page.locator("#jobs-table tbody tr").count() == 12
    assert page.is_disabled("#jobs-prev")
    page.click("#jobs-next")
    page.wait_for_function("() => document.querySelector('#jobs-page').textContent.startsWith('13')")
    assert not page.is_disabled("#jobs-prev")
    assert not errors, errors
    page.close()


def _fits(page, what: str) -> None:
    width = page.evaluate("() => document.documentElement.scrollWidth")
    inner = page.evaluate("() => window.innerWidth")
    assert width <= inner, f"{what}: the page is {width} px wide in a {inner} px window"


def test_the_pages_fit_800_px_without_horizontal_scrolling(browser, embedded, exemplar_png):  # noqa: F811
    client = embedded.client()
    params = {"width": 96, "height": 96, "steps": 1, "delay": 0}
    a = client.wait(client.submit(exemplar_png, method="test-blur", params=params, seed=1)["id"], timeout=60)
    b = client.wait(client.submit(exemplar_png, method="test-blur", params=params, seed=2)["id"], timeout=60)
    volume = client.wait(
        client.submit(
            exemplar_png, method="test-stack", params={"width": 64, "height": 48, "depth": 40}, seed=1
        )["id"],
        timeout=60,
    )
    sweep = httpx.post(
        embedded.url + "/api/sweeps",
        files={"exemplar": ("e.png", exemplar_png, "image/png")},
        data={
            "method": "test-blur",
            "params": '{"steps": 1, "delay": 0}',
            "grid": '{"sigma": [0.5, 1.0]}',
            "width": "64",
            "height": "64",
            "seed": "1",
        },
    ).json()
    page, errors = _page(browser, width=800, height=900)
    page.goto(embedded.url + "/")
    page.wait_for_selector("#jobs-table tbody tr")
    page.select_option("#method", "tensor-constrained")
    page.click("#advanced-box summary")
    _fits(page, "home")
    page.goto(f"{embedded.url}/#/jobs/{a['id']}")
    page.wait_for_selector("#metrics tbody tr")
    page.wait_for_function("() => document.querySelector('#result').naturalWidth > 0")
    _fits(page, "job (fit)")
    # fit keeps the legends in view: no scrolling box in fit mode
    assert page.evaluate("() => getComputedStyle(document.querySelector('#stage')).maxHeight") == "none"
    assert page.locator("#tensor-legends .legend").first.is_visible()
    page.goto(f"{embedded.url}/#/jobs/{volume['id']}")
    page.wait_for_selector("#volume-viewer:not([hidden])")
    page.wait_for_function("() => document.querySelector('#ortho-xy').naturalWidth === 64")
    _fits(page, "volume")
    page.goto(f"{embedded.url}/#/compare/{a['id']}/{b['id']}")
    page.wait_for_selector("#compare-metrics tbody tr")
    _fits(page, "compare")
    page.goto(f"{embedded.url}/#/sweeps/{sweep['id']}")
    page.wait_for_selector("#sweep-state.succeeded", timeout=60_000)
    _fits(page, "sweep")
    page.goto(f"{embedded.url}/#/jobs")
    page.wait_for_selector("#jobs-table tbody tr")
    _fits(page, "job list")
    assert not errors, errors
    page.close()


def test_an_example_in_one_click_and_its_results_explained(browser, embedded):  # noqa: F811
    """The gallery lists the service's examples; a click puts the brick into the form with its method;
    the job's page shows every headline measure with a target and a verdict, the exemplar's tensor
    images beside the output's, no fringe measures (brick has none: the reason said), and the zip."""
    examples = httpx.get(embedded.url + "/api/examples", timeout=10).json()
    page, errors = _page(browser)
    page.goto(embedded.url + "/")
    page.wait_for_selector("#examples:not([hidden]) button.example")
    assert page.locator("button.example").count() == len(examples)
    assert "CC0" in page.inner_text("#example-list") and "MIT" in page.inner_text("#example-list")
    brick = next(x for x in examples if x["name"] == "brick")
    page.click("button.example[data-example='brick']")
    page.wait_for_selector("#exemplar-preview:not([hidden])")
    assert page.evaluate("() => document.querySelector('#exemplar').files[0].name") == "brick.png"
    assert page.input_value("#method") == brick["suggested_method"]
    page.fill("#param-width", "48")
    page.fill("#param-height", "48")
    page.click("#submit")
    page.wait_for_url("**/#/jobs/*")
    page.wait_for_selector("#job-state.succeeded", timeout=120_000)
    page.wait_for_selector("#metrics tbody tr")
    # a target and a verdict for every headline measure shown
    for row in page.locator("#metrics tbody tr").all():
        cells = row.locator("td").all_inner_texts()
        assert cells[1].startswith(("<", ">", "|", "1 ±")), cells
        assert "target" in cells[2], cells
    # no fringe measures for brick, and why
    assert page.locator("#metrics tr[data-measure^='fringe_']").count() == 0
    assert page.is_visible("#fringe-note") and "not shown" in page.inner_text("#fringe-note")
    assert page.is_hidden("#fringe-metrics")
    # the exemplar's tensor images beside the output's, and every artifact in one zip
    for kind in ("coherence", "orientation"):
        page.wait_for_function(f"() => document.querySelector('#view-ex-{kind}').naturalWidth > 0")
    zip_url = page.get_attribute("#zip-link", "href")
    assert httpx.get(embedded.url + zip_url).content[:2] == b"PK"
    assert not errors, errors
    page.close()
