"""The console page in a real headless Chromium (Debian's chromium + chromium-driver, driven
by selenium) against the real console process and the simulated cell: load it, submit a
bundled example, confirm the tank, see progress advance and the 3D preview draw, press the
e-stop and see the state change. Screenshots of each state go to the test's tmp dir."""

from __future__ import annotations

import shutil
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from sim.render import GL_PROBLEM
from tests.mesp_cell.conftest import Console

pytestmark = pytest.mark.slow  # a cell and a browser

CUBE = Path(__file__).resolve().parents[3] / "examples" / "cube.stl"
CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
DRIVER = shutil.which("chromedriver") or "/usr/bin/chromedriver"
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--no-first-run",
         "--disable-dev-shm-usage", "--window-size=1280,1100")


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    if not (Path(CHROMIUM).is_file() and Path(DRIVER).is_file()):
        pytest.skip("Chromium is not installed: apt-get install chromium chromium-driver "
                    "(make test installs them as root)")
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for flag in FLAGS:
        opts.add_argument(flag)
    driver = webdriver.Chrome(options=opts, service=Service(DRIVER))
    driver.set_page_load_timeout(30)
    try:
        yield driver
    finally:
        driver.quit()


def until(what: str, check: Callable[[], Any], timeout: float = 30.0) -> Any:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            value = check()
        except Exception:  # an element not there yet
            value = None
        if value:
            return value
        time.sleep(0.05)
    raise AssertionError(f"the page never showed {what}")


def test_operator_runs_a_job_from_the_page(console: Console, browser: Any,
                                           tmp_path: Path) -> None:
    from selenium.webdriver.common.by import By

    def shot(name: str) -> None:
        browser.save_screenshot(str(tmp_path / f"{name}.png"))

    def text(css: str) -> str:
        return str(browser.find_element(By.CSS_SELECTOR, css).text)

    browser.get(console.url)
    until("the live link", lambda: text("#link") == "live")
    until("the nodes", lambda: "supervisor" in text("#nodes"))
    shot("1-loaded")
    # submit the bundled cube; the page asks for the token once (motion needs it here)
    browser.find_element(By.ID, "model").send_keys(str(CUBE))
    browser.find_element(By.ID, "submit").click()
    alert = until("the token prompt", lambda: browser.switch_to.alert)
    alert.send_keys(console.token)
    alert.accept()
    until("the queued job", lambda: "queued" in text("#submit-msg"))
    job_id = text("#submit-msg").split()[-1]
    ready = until("the tank-ready alert", lambda: browser.find_element(
        By.CSS_SELECTOR, "[data-alert=ready] button"))
    assert job_id in text("[data-alert=ready]")
    assert browser.title.startswith("(!)")
    until("the 3D preview", lambda: int(browser.find_element(By.ID, "plot")
                                        .get_attribute("data-points") or 0) > 30)
    shot("2-ready-check")
    assert console.job(job_id)["state"] == "ready_check"
    ready.click()
    # progress advances: the bar and the layer counter move while printing
    first = until("progress", lambda: float(text("#bar-text").split()[0] or 0) > 0 or None)
    until("progress advancing", lambda: float(text("#bar-text").split()[0]) > first + 10)
    assert "/ 3" in text("#cur-layer") and "mm³" in text("#cur-ink")
    shot("3-printing")
    if not GL_PROBLEM:  # the twin drawn at the robot's pose, as the print goes on
        browser.find_element(By.ID, "twin-on").click()
        until("a frame of the twin", lambda: (browser.execute_script(
            "return window.liveStats.twinFrames || 0") >= 1))
        assert browser.find_element(By.ID, "twin-img").size["width"] > 100
        shot("3b-twin")
    until("the job's end", lambda: console.job(job_id)["state"] == "done")
    until("the history", lambda: job_id in text("#history"))
    # colour the preview by width and show fewer layers
    browser.find_element(By.CSS_SELECTOR, "#pv-colour option[value=width]").click()
    browser.execute_script("const s = document.getElementById('pv-layer'); s.value = 1; "
                           "s.dispatchEvent(new Event('input'));")
    until("the layer slider", lambda: text("#pv-layer-n") == "2 / 3")
    shot("4-done-preview-by-width")
    stats = browser.execute_script("return window.liveStats")
    delays = sorted(stats["delays"])
    print(f"browser: {stats['progress']} progress messages, supervisor to page delay p50 "
          f"{1000 * delays[len(delays) // 2]:.1f} ms, max {1000 * delays[-1]:.1f} ms")
    assert stats["progress"] >= 5 and delays[len(delays) // 2] < 0.2
    # a second job: press the e-stop while it prints and see the state change
    browser.find_element(By.ID, "model").send_keys(str(CUBE))
    browser.find_element(By.ID, "submit").click()
    until("the second job", lambda: text("#submit-msg") != f"queued {job_id}" and
          "queued" in text("#submit-msg"))
    second = text("#submit-msg").split()[-1]
    until("the tank-ready alert", lambda: browser.find_element(
        By.CSS_SELECTOR, "[data-alert=ready] button")).click()
    until("printing", lambda: console.job(second)["state"] == "printing")
    browser.find_element(By.ID, "estop").click()
    until("the e-stop banner", lambda: "E-STOP" in text("#estop-banner"))
    until("the interrupted job", lambda: "interrupted" in text("#queue"))
    assert "robot: stopped and latched" in text("#estop-banner")
    assert console.job(second)["state"] == "interrupted"
    shot("5-estop")
    browser.find_element(By.ID, "estop-reset").click()
    until("the e-stop cleared", lambda: not browser.find_element(
        By.ID, "estop-banner").is_displayed())
    browser.set_window_size(390, 844)  # a phone
    browser.execute_script("window.scrollTo(0, 0)")
    shot("6-phone")
    for name in ("1-loaded", "2-ready-check", "3-printing", "4-done-preview-by-width",
                 "5-estop", "6-phone"):
        assert (tmp_path / f"{name}.png").stat().st_size > 5000, name
    print(f"screenshots in {tmp_path}")
    assert console.post(f"/api/jobs/{second}/abort").status_code == 200
