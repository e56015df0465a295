"""The live view and report.html in a real browser (issue 23, section 4): Debian's Chromium
driven by Selenium, headless, against ``fovexp monitor`` watching a dry run in progress.

Checked on the page: the trial counter advances; the gaze plot updates; a trial over an
exclusion rule's threshold shows its flag; the page goes on (and says the runner stopped) when
the runner is killed with SIGKILL; ``report.html`` renders with every figure loaded, opened from
disk and through the monitor. The screenshots are the page's documentation (docs/EXPERIMENT.md):
with ``FOVEXP_SCREENSHOTS=DIR`` they are also written there (``docs/images`` for the docs).

Without Chromium, its driver or Selenium these tests skip with the reason, unless
``FOVEXP_REQUIRE_BROWSER=1`` (``.ci/run`` installs them and sets it): then they fail.
"""

from __future__ import annotations

import os
import shutil
import signal
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from analysis_fixtures import write_study
from experiment_helpers import make_workspace, popen_cli, run_cli, xvfb_display  # noqa: F401
from monitor_helpers import MonitorProcess

pytestmark = [pytest.mark.gui, pytest.mark.slow]

CHROMIUM = os.environ.get("FOVEXP_CHROMIUM", "/usr/bin/chromium")
CHROMEDRIVER = os.environ.get("FOVEXP_CHROMEDRIVER", "/usr/bin/chromedriver")


def _missing() -> str | None:
    try:
        import selenium  # noqa: F401
    except ImportError:
        return "selenium is not installed (the test extra)"
    for path, pkg in ((CHROMIUM, "chromium"), (CHROMEDRIVER, "chromium-driver")):
        if not (Path(path).is_file() or shutil.which(path)):
            return f"{path} is missing (apt-get install chromium chromium-driver: {pkg})"
    try:
        import starlette  # noqa: F401
        import uvicorn  # noqa: F401
    except ImportError:
        return "the monitor extra is not installed"
    return None


@pytest.fixture(scope="module")
def driver() -> Iterator[Any]:
    why = _missing()
    if why is not None:
        if os.environ.get("FOVEXP_REQUIRE_BROWSER") == "1":
            pytest.fail(f"FOVEXP_REQUIRE_BROWSER=1 but {why}")
        pytest.skip(why)
    os.environ["SE_OFFLINE"] = "true"  # Selenium Manager must not look for a browser online
    from selenium import webdriver
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    opts = Options()
    opts.binary_location = CHROMIUM
    for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage",
                "--window-size=1400,1000", "--hide-scrollbars", "--force-device-scale-factor=1"):
        opts.add_argument(arg)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    d = webdriver.Chrome(service=Service(executable_path=CHROMEDRIVER), options=opts)
    d.set_page_load_timeout(30)
    try:
        yield d
    finally:
        d.quit()  # before any server it talked to stops


def shot(driver: Any, name: str, tmp_path: Path) -> Path:
    """A screenshot (PNG), kept with the test's files and, with FOVEXP_SCREENSHOTS, there."""
    path = tmp_path / name
    assert driver.save_screenshot(str(path))
    assert path.read_bytes()[:4] == b"\x89PNG"
    out = os.environ.get("FOVEXP_SCREENSHOTS")
    if out:
        Path(out).mkdir(parents=True, exist_ok=True)
        shutil.copyfile(path, Path(out) / name)
    return path


def wait_for(what: str, check: Callable[[], Any], timeout_s: float = 30.0,
             every_s: float = 0.1) -> Any:
    t_end = time.monotonic() + timeout_s
    last: Any = None
    while time.monotonic() < t_end:
        try:
            last = check()
        except Exception as exc:  # the element is being replaced: try again
            last = exc
        if last and not isinstance(last, Exception):
            return last
        time.sleep(every_s)
    raise AssertionError(f"timed out waiting for {what} (last: {last!r})")


def text(driver: Any, element_id: str) -> str:
    return str(driver.find_element("id", element_id).text)


def js_errors(driver: Any) -> list[str]:
    return [e["message"] for e in driver.get_log("browser")
            if e["level"] == "SEVERE" and "favicon" not in e["message"]]


def test_the_live_page_follows_a_dry_run_and_survives_its_kill(
        driver: Any, tmp_path: Path, xvfb_display: str) -> None:  # noqa: F811
    ws = make_workspace(tmp_path / "ws")
    results = ws / "results"
    # R13's threshold below any gaze-to-flip latency a frame can have (even late-latched, a
    # frame is decided at least 1 ms before its flip: LATCH_MIN_MARGIN_S): every trial of the
    # dry run breaks it, so the flag's path runs whatever the machine's load (R11 and R12 keep
    # the analysis' defaults)
    mon = MonitorProcess([str(results), "--port", "0", "--max-latency-ms", "0.5"])
    run = popen_cli(["run", "protocols/calibration-fe.yaml", "--participant", "SIM01",
                     "--dry-run", "--limit-trials", "12", "--practice", "1", "--sim-speed", "2"],
                    cwd=ws)
    try:
        js_errors(driver)  # what earlier pages logged
        driver.get(mon.url)
        # the session appears, and its trial counter
        first = wait_for("a trial on the page", lambda: text(driver, "counter").startswith(
            ("trial", "practice trial")) and text(driver, "counter"), timeout_s=90)
        assert "calibration-fe / SIM01" in text(driver, "who")
        assert text(driver, "conn") == "live" and text(driver, "status") == "running"
        assert "dry run" in text(driver, "dry").lower()
        # the gaze plot updates
        svg = driver.find_element("id", "gaze")
        before = svg.get_attribute("data-newest")
        wait_for("the gaze plot to update",
                 lambda: svg.get_attribute("data-newest") not in (before, "", None)
                 and int(svg.get_attribute("data-points") or 0) > 10, timeout_s=5)
        assert driver.find_element("id", "trail").get_attribute("d").startswith("M")
        # a flagged trial shows its flag
        # read inside the wait: the page redraws the list (4 Hz), and an element found just
        # before a redraw is stale when read (seen under load)
        flag_text, flag_shown = wait_for("R13's flag", lambda: [
            (f.text, f.is_displayed()) for f in driver.find_elements(
                "css selector", "#rules .flag") if f.get_attribute("data-rule") == "R13 latency"],
            timeout_s=20)[0]
        assert flag_text == "R13: would be excluded" and flag_shown
        latency = wait_for("R13's row", lambda: driver.find_element(
            "css selector", '#rules [data-rule="R13 latency"]').text)
        assert "limit 0.5 ms" in latency
        assert "Dry run" in text(driver, "rules-note")
        # the trial counter advances
        wait_for("the counter to advance", lambda: text(driver, "counter") not in (first, "–")
                 and text(driver, "counter"), timeout_s=60)
        shown = wait_for("trial 3 or later", lambda: (
            int(driver.find_element("id", "counter").get_attribute("data-position") or 0) >= 3
            and not text(driver, "counter").startswith("practice")), timeout_s=90)
        assert shown
        time.sleep(0.5)
        shot(driver, "monitor-running.png", tmp_path)
        assert driver.find_elements("css selector", "#trials tbody tr .flag")  # done trials too
        # the runner is killed: the page goes on and says so
        run.send_signal(signal.SIGKILL)
        run.wait(timeout=30)
        counter = text(driver, "counter")
        wait_for("the page to say the runner stopped",
                 lambda: text(driver, "status") == "not responding", timeout_s=10)
        why = text(driver, "why")
        assert "process is gone" in why or "no update" in why
        assert text(driver, "counter") == counter  # the last state it wrote is still shown
        assert text(driver, "conn") == "live"  # the page and its server are fine
        listed = driver.find_element("css selector", "#running li").text
        assert "SIM01" in listed and "not responding" in listed
        time.sleep(1.5)
        assert text(driver, "status") == "not responding"
        shot(driver, "monitor-runner-killed.png", tmp_path)
        assert js_errors(driver) == []
    finally:
        driver.get("about:blank")  # the page stops reconnecting before its server stops
        if run.poll() is None:
            run.kill()
            run.wait()
        mon.stop()


def test_report_html_renders_with_every_figure(driver: Any, tmp_path: Path) -> None:
    results = write_study(tmp_path / "results", n_participants=4, seed=5)
    out = tmp_path / "report"
    r = run_cli(["analyze", str(results), "--out", str(out)], cwd=tmp_path, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]

    figures = (out / "report.md").read_text().count("![")
    assert figures >= 3  # calibration, validation and its sampling-rate reduction

    def check_page() -> int:
        images = driver.find_elements("tag name", "img")
        assert len(images) == figures
        wait_for("every figure to load", lambda: all(driver.execute_script(
            "return arguments[0].complete && arguments[0].naturalWidth > 0", i)
            for i in images), timeout_s=10)
        banner = driver.find_element("css selector", "h1 + blockquote")
        assert "dry runs" in banner.text and banner.is_displayed()
        assert banner.location["y"] < 200  # at the top
        assert len(driver.find_elements("tag name", "table")) > 5
        return len(images)

    js_errors(driver)  # what earlier pages logged
    driver.get((out / "report.html").as_uri())  # offline, from disk
    n = check_page()
    shot(driver, "report-html.png", tmp_path)
    driver.execute_script("document.querySelector('img').scrollIntoView()")
    shot(driver, "report-html-figure.png", tmp_path)
    # and through the monitor, whose finished sessions link to it
    mon = MonitorProcess([str(results), "--port", "0", "--report", str(out)])
    try:
        driver.get(mon.url)
        link = wait_for("a report link", lambda: driver.find_elements(
            "css selector", "#finished li a.report-link"), timeout_s=15)[0]
        assert link.get_attribute("href").endswith("/report/report.html")
        driver.get(link.get_attribute("href"))
        assert check_page() == n
        assert js_errors(driver) == []
    finally:
        driver.get("about:blank")
        mon.stop()


def test_a_finished_session_says_so_and_shows_no_live_rates(driver: Any, tmp_path: Path
                                                            ) -> None:
    """Issue 32: the page of a session that ended (its status file's last write, with the rates
    it had then) says how and when it finished, not "no trial on screen yet" or "671 samples
    in the last second"."""
    from monitor_helpers import live, session_file, write_live_file

    sid = "20261124-101010"
    folder = tmp_path / "results" / "calibration-sk" / "P01"
    session_file(folder, sid, state="aborted", ended="2026-11-24T10:30:00+00:00")
    ended = time.time() - 90
    data = live(sid, state="aborted", trial=None, since=ended, ended=ended, eta_s=40.0)
    data["gaze"]["samples_last_s"] = 671
    write_live_file(folder, data)
    mon = MonitorProcess([str(tmp_path / "results"), "--port", "0"])
    try:
        js_errors(driver)  # what earlier pages logged
        driver.get(mon.url)
        state = wait_for("the end on the page", lambda: text(driver, "state").startswith(
            "the session finished: ") and text(driver, "state"), timeout_s=15)
        at = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(ended))
        assert state.startswith(f"the session finished: quit by the operator at {at} (1 min ")
        assert state.endswith(" s ago)")
        assert text(driver, "status") == "finished" and text(driver, "counter") == "finished"
        assert text(driver, "rules").startswith("no trial on screen: the session has ended")
        gaze = text(driver, "gaze-info")
        assert "samples in the last second" not in gaze and "before the end" in gaze
        assert text(driver, "eta") == "" and "yet" not in text(driver, "rules")
        assert "quit by the operator" in driver.find_element("css selector", "#finished li").text
        shot(driver, "monitor-finished.png", tmp_path)
        assert js_errors(driver) == []
    finally:
        driver.get("about:blank")
        mon.stop()
