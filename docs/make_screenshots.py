"""Screenshots of the browser page for docs/service.md: ``python docs/make_screenshots.py``.

Starts ``texsynth serve`` on a fresh temporary data directory (the embedded queue, a real worker),
runs a few small real jobs on the HRTEM soot exemplar (quilting, random-phase, a solid-kopf volume, a
sweep, and one run of the tests' method asked to fail in the worker), drives Debian's Chromium through
Playwright and writes ``docs/img/service-*.png``. About a minute on two cores.
"""

from __future__ import annotations

import contextlib
import io
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx
import numpy as np
from PIL import Image

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from texsynth.app.client import Client  # noqa: E402

OUT = REPO / "docs" / "img"
CHROMIUM = "/usr/bin/chromium"
SOOT = Path(os.environ.get("TEXSYNTH_SHARED_DATA", REPO.parent / "shared" / "data")) / "hrtem-soot-128.png"


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _png_bytes(array: np.ndarray) -> bytes:
    buf = io.BytesIO()
    Image.fromarray(array).save(buf, format="PNG")
    return buf.getvalue()


def _serve(data_dir: Path) -> tuple[subprocess.Popen, str]:
    port = _free_port()
    url = f"http://127.0.0.1:{port}"
    env = {
        **os.environ,
        "PYTHONPATH": str(REPO),
        "TEXSYNTH_CONCURRENCY": "2",
        # the tests' method, whose `fail` parameter makes a run fail in the worker (every geometry error
        # of the real methods is now refused at submission with a 422)
        "TEXSYNTH_EXTRA_METHODS": "tests.service.methods_for_tests",
    }
    command = [
        sys.executable,
        "-c",
        "import sys; from texsynth.synth.cli import main; sys.exit(main())",
        "serve",
    ]
    command += ["--host", "127.0.0.1", "--port", str(port), "--data-dir", str(data_dir)]
    with open(data_dir.parent / "serve.log", "wb") as log:
        proc = subprocess.Popen(
            command, env=env, cwd=REPO, start_new_session=True, stdout=log, stderr=subprocess.STDOUT
        )
    deadline = time.monotonic() + 90
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise SystemExit(f"texsynth serve exited; see {data_dir.parent / 'serve.log'}")
        try:
            if httpx.get(url + "/api/health", timeout=2).status_code == 200:
                return proc, url
        except httpx.HTTPError:
            pass
        time.sleep(0.3)
    raise SystemExit("texsynth serve did not become healthy within 90 s")


def _stop(proc: subprocess.Popen, data_dir: Path) -> None:
    """Stop ``serve`` and the worker it started (the worker runs in its own process group)."""
    from texsynth.jobs.store import JobStore

    workers = JobStore(data_dir / "jobs.sqlite", data_dir / "jobs").workers(fresh_within=3600)
    os.killpg(proc.pid, signal.SIGTERM)
    try:
        proc.wait(timeout=20)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
    for worker in workers:
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(os.getpgid(worker["pid"]), signal.SIGTERM)


def _wait_sweep(url: str, sweep_ids: list[str], timeout: float = 300) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        states = [httpx.get(f"{url}/api/sweeps/{s}", timeout=10).json()["state"] for s in sweep_ids]
        if all(s == "done" for s in states):
            return
        time.sleep(0.5)
    raise SystemExit("the sweep did not finish")


def _wait_images(page, selector: str) -> None:
    page.wait_for_function(
        f"() => [...document.querySelectorAll({selector!r})].every((i) => i.naturalWidth > 0)"
    )


def _clip(page, first: str, last: str, pad: int = 12) -> dict:
    """The page region from the top of ``first`` to the bottom of ``last`` (document coordinates)."""
    a = page.locator(first).first.bounding_box()
    b = page.locator(last).first.bounding_box()
    scroll = page.evaluate("() => window.scrollY")
    top = min(a["y"], b["y"]) + scroll - pad
    left = min(a["x"], b["x"]) - pad
    bottom = max(a["y"] + a["height"], b["y"] + b["height"]) + scroll + pad
    right = max(a["x"] + a["width"], b["x"] + b["width"]) + pad
    return {
        "x": max(0, left),
        "y": max(0, top),
        "width": right - max(0, left),
        "height": bottom - max(0, top),
    }


def main() -> None:
    from playwright.sync_api import sync_playwright

    OUT.mkdir(parents=True, exist_ok=True)
    soot = SOOT.read_bytes()
    small = _png_bytes(np.asarray(Image.open(io.BytesIO(soot)).convert("L"))[:24, :24])
    crop64 = _png_bytes(np.asarray(Image.open(io.BytesIO(soot)).convert("L"))[:64, :64])
    with tempfile.TemporaryDirectory(prefix="texsynth-shots-") as tmp:
        data_dir = Path(tmp) / "data"
        data_dir.mkdir()
        proc, url = _serve(data_dir)
        try:
            client = Client(url, timeout=60)
            size = {"width": 96, "height": 96}
            quilt = client.submit(soot, method="quilting", params={**size, "patch_size": 32}, seed=1)
            phase = client.submit(soot, method="random-phase", params=size, seed=1)
            volume = client.submit(
                crop64, method="solid-kopf", params={"width": 32, "height": 32, "depth": 32}, seed=1
            )
            failed = client.submit(
                small,
                method="test-blur",
                params={"width": 48, "height": 48, "fail": "the worker ran out of memory"},
                seed=1,
            )
            for job in (quilt, phase, volume, failed):
                client.wait(job["id"], timeout=300)
            with sync_playwright() as pw:
                browser = pw.chromium.launch(
                    executable_path=CHROMIUM,
                    headless=True,
                    args=["--no-sandbox", "--disable-gpu", "--hide-scrollbars"],
                )
                page = browser.new_page(viewport={"width": 1200, "height": 900}, device_scale_factor=1)
                errors: list[str] = []
                page.on("pageerror", lambda exc: errors.append(str(exc)))

                # the job page: summary, parameters used, timings by stage
                page.goto(f"{url}/#/jobs/{quilt['id']}")
                page.wait_for_selector("#job-state.succeeded")
                page.wait_for_selector("#job-params tbody tr", state="attached")
                page.click("#job-params-box summary")
                page.click("#timings-box summary")
                page.wait_for_function("() => document.querySelector('#result').naturalWidth > 0")
                page.screenshot(
                    path=str(OUT / "service-job.png"), clip=_clip(page, "#view h2", "#inputs"), full_page=True
                )

                # the metrics panel
                page.wait_for_selector("#metrics tbody tr")
                page.screenshot(
                    path=str(OUT / "service-metrics.png"),
                    clip=_clip(page, "#metrics-title", "#metrics", pad=6),
                    full_page=True,
                )

                # the viewer at 2x, the output tiled 2x2
                page.check("input[name=zoom][value='2']", force=True)
                page.check("#tile")
                page.wait_for_timeout(300)
                page.locator("#viewer").screenshot(path=str(OUT / "service-viewer.png"))

                # compare two jobs: swipe at 40 %
                page.goto(f"{url}/#/compare/{quilt['id']}/{phase['id']}")
                page.wait_for_selector("#compare-metrics tbody tr")
                page.wait_for_function("() => document.querySelector('#compare-img-b').naturalWidth > 0")
                page.fill("#swipe", "40")
                page.dispatch_event("#swipe", "input")
                page.wait_for_timeout(300)
                page.screenshot(
                    path=str(OUT / "service-compare.png"),
                    clip=_clip(page, "#view h2", "#compare-params"),
                    full_page=True,
                )

                # a sweep from the form: quilting's patch size over 3 values, 2 seeds
                page.goto(f"{url}/")
                soot_file = Path(tmp) / "hrtem-soot-128.png"
                soot_file.write_bytes(soot)
                page.set_input_files("#exemplar", str(soot_file))
                page.select_option("#method", "quilting")
                page.fill("#param-width", "96")
                page.fill("#param-height", "96")
                page.click("#sweep-box summary")
                page.select_option("#sweep-param", "patch_size")
                page.fill("#sweep-values", "16, 24, 40")
                page.fill("#sweep-seeds", "1, 2")
                page.dispatch_event("#sweep-seeds", "input")
                page.screenshot(
                    path=str(OUT / "service-sweep-form.png"),
                    clip=_clip(page, "#submit-card h2", "#sweep-submit"),
                    full_page=True,
                )
                page.click("#sweep-submit")
                page.wait_for_url("**/#/sweeps/*")
                _wait_sweep(url, page.url.split("/sweeps/")[1].split(","))
                page.wait_for_selector("#sweep-state.succeeded", timeout=60_000)
                _wait_images(page, "#sweep-table img")
                page.screenshot(
                    path=str(OUT / "service-sweep.png"),
                    clip=_clip(page, "#view h2", "#sweep-table"),
                    full_page=True,
                )

                # run again: the form filled from a job
                page.goto(f"{url}/#/new?from={quilt['id']}")
                page.wait_for_selector("#rerun-note:not([hidden])")
                page.wait_for_selector("#exemplar-preview:not([hidden])")
                page.screenshot(
                    path=str(OUT / "service-rerun.png"),
                    clip=_clip(page, "#submit-card h2", "#submit"),
                    full_page=True,
                )

                # a volume: the slice viewer, the cube, per-axis metrics
                page.goto(f"{url}/#/jobs/{volume['id']}")
                page.wait_for_selector("#job-state.succeeded")
                page.wait_for_selector("#axis-metrics:not([hidden]) tbody tr")
                _wait_images(page, "#volume-viewer img")
                # the crosshair moved off the middle by a click on the xy slice
                scale = int(page.input_value("input[name=ortho-zoom]:checked"))
                page.click("#box-xy", position={"x": 10 * scale, "y": 22 * scale})
                page.wait_for_timeout(300)
                _wait_images(page, "#volume-viewer img")
                _wait_images(page, "#result-images img")
                page.screenshot(
                    path=str(OUT / "service-volume.png"),
                    clip=_clip(page, "#results h3", "#axis-metrics"),
                    full_page=True,
                )

                # a failed job: its reason in words and a red bar
                page.goto(f"{url}/#/jobs/{failed['id']}")
                page.wait_for_selector("#job-state.failed")
                page.click("#timings-box summary")
                page.screenshot(
                    path=str(OUT / "service-failed.png"),
                    clip=_clip(page, "#view h2", "#inputs"),
                    full_page=True,
                )

                # the home page: the examples, the short form, and the jobs (failed ones with their reason)
                page.goto(f"{url}/")
                page.wait_for_selector("#jobs-table tbody tr")
                page.wait_for_selector("#examples:not([hidden]) button.example")
                _wait_images(page, "#example-list img")
                _wait_images(page, "#jobs-table img")
                page.click("button.example[data-example='soot-fringes']")
                page.wait_for_selector("#exemplar-preview:not([hidden])")
                page.screenshot(path=str(OUT / "service-home.png"), full_page=True)
                browser.close()
                if errors:
                    raise SystemExit(f"errors on the page: {errors}")
        finally:
            _stop(proc, data_dir)
    for path in sorted(OUT.glob("service-*.png")):
        print(path.relative_to(REPO))


if __name__ == "__main__":
    main()
