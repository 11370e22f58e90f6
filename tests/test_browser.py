"""The Meshcat pages in a real browser: a teleop run driven through its page, and a replay.

Headless Chromium (Debian's ``chromium`` and ``chromium-driver``; ``.ci/run`` installs them)
driven by Selenium with the system chromedriver. Skipped only when no browser is installed.
"""

from __future__ import annotations

import json
import os
import queue
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

CHROMEDRIVER = "/usr/bin/chromedriver"
# Headless on a software GL; no background networking (this machine's network is closed and
# Chromium stalls on refused connections otherwise).
CHROME_FLAGS = ("--headless=new", "--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                "--disable-background-networking", "--disable-component-update", "--disable-sync",
                "--no-first-run", "--window-size=640,480")
# Collects uncaught errors from the first script on (installed before any page script runs).
ERROR_TRAP = ("window.__errors = []; window.addEventListener('error', e => window.__errors.push("
              "String(e.message || e))); window.addEventListener('unhandledrejection', e => "
              "window.__errors.push(String(e.reason)));")
# Skips the page's WebGL rendering (the scene tree, controls and messages work as before): software
# GL draws G1's meshes at seconds per frame on 2 busy cores, which stalls the page's event loop
# and with it every Selenium command. The teleop test checks behaviour, the replay test pixels.
NO_RENDER = ("Object.defineProperty(window, 'viewer', {configurable: true, get() { return undefined; }, "
             "set(v) { v.render = () => { v.needs_render = false; }; Object.defineProperty(window, 'viewer', "
             "{value: v, writable: true, configurable: true}); }});")
WAIT_S = 90.0  # wall seconds for the slow steps (G1 simulates at ~0.2x real time on 2 busy cores)


def _chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    chromium = _chromium()
    if chromium is None or not os.path.exists(CHROMEDRIVER):
        pytest.skip("no browser: chromium and chromium-driver are not installed "
                    "(apt-get install chromium chromium-driver; .ci/run installs them)")
    webdriver = pytest.importorskip("selenium.webdriver",
                                    reason="selenium is not installed (pip install -e '.[test]')")
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = chromium
    for flag in CHROME_FLAGS:
        options.add_argument(flag)
    options.add_argument(f"--user-data-dir={tmp_path_factory.mktemp('chromium')}")
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)
    driver.execute_cdp_cmd("Page.addScriptToEvaluateOnNewDocument", {"source": ERROR_TRAP})
    yield driver
    driver.quit()


def _wait(what: str, check, timeout: float = WAIT_S, proc: subprocess.Popen | None = None):
    """Polls ``check()`` until it returns something truthy (returned), failing after ``timeout``."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        value = check()
        if value:
            return value
        if proc is not None and proc.poll() is not None:
            pytest.fail(f"the run ended (exit {proc.returncode}) while waiting for {what}")
        time.sleep(0.2)
    pytest.fail(f"timed out after {timeout:g} s waiting for {what}")


def _js_errors(driver) -> list[str]:
    logged = [e["message"] for e in driver.get_log("browser") if e["level"] == "SEVERE"]
    return logged + list(driver.execute_script("return window.__errors || []"))


def _control(driver, name: str):
    """The dat.GUI row (``li``) of the page control called ``name`` (slider or button), scrolled
    into the panel's view, or None."""
    return driver.execute_script(
        "const c = viewer.gui_controllers[arguments[0]]; if (!c) return null; "
        "c.__li.scrollIntoView({block: 'center'}); return c.__li;", name)


def _slider_value(driver, name: str) -> float | None:
    return driver.execute_script(
        "const c = viewer.gui_controllers[arguments[0]]; return c ? c.getValue() : null;", name)


def _mode_shown(driver) -> str | None:
    names = driver.execute_script("return Object.keys(viewer.gui_controllers);")
    modes = [n for n in names if n.startswith("mode: ")]
    return modes[0][len("mode: "):] if modes else None


def _scene_paths(driver, path: list[str]) -> list[str]:
    """Every node below ``path`` in the page's scene tree, as "a/b/c" paths relative to it."""
    return driver.execute_script("""
        const out = [];
        const walk = (node, prefix) => { for (const [name, child] of Object.entries(node.children)) {
            out.push(prefix + name); walk(child, prefix + name + "/"); } };
        let node = viewer.scene_tree;
        for (const name of arguments[0]) {
            if (!(name in node.children)) return out;
            node = node.children[name];
        }
        walk(node, "");
        return out;""", path)


def _start_teleop(tmp_path) -> tuple[subprocess.Popen, str, queue.Queue]:
    """``romoco run g1_walk --meshcat --teleop`` in a subprocess; its page URL and stderr lines."""
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    args = ["run", "g1_walk", "--meshcat", "--teleop", "--json", "--no-wait"]
    # Ctrl-C must reach the run even when pytest itself was started with SIGINT ignored (a
    # background job of a non-interactive shell): the child gets the default handler back.
    proc = subprocess.Popen([sys.executable, "-m", "romoco_drake.cli", *args], stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=tmp_path,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    lines: queue.Queue = queue.Queue()
    threading.Thread(target=lambda: [lines.put(line) for line in proc.stderr], daemon=True).start()
    end = time.monotonic() + WAIT_S
    while time.monotonic() < end:
        try:
            line = lines.get(timeout=1.0)
        except queue.Empty:
            if proc.poll() is not None:
                pytest.fail(f"romoco run exited with {proc.returncode} before serving Meshcat")
            continue
        if m := re.search(r"Meshcat: (http://\S+)", line):
            assert re.match(r"http://(localhost|127\.0\.0\.1):\d+", m[1]), m[1]
            return proc, m[1], lines
    proc.kill()
    pytest.fail("romoco run printed no Meshcat URL")


@pytest.mark.slow
def test_teleop_page_drives_the_robot(browser, tmp_path):
    """Through the page: the robot is there, the vx slider walks it forward (the controller's
    limited command follows it), E-stop latches damping, and the page names the mode."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys

    proc, url, lines = _start_teleop(tmp_path)
    script = browser.execute_cdp_cmd("Page.addScriptToEvaluateOnNewDocument", {"source": NO_RENDER})
    try:
        browser.get(url)
        _wait("the robot's scene tree (its pelvis)", lambda: any(
            p.endswith("/pelvis") for p in _scene_paths(browser, ["drake", "robot"])), proc=proc)
        assert _wait("the mode", lambda: _mode_shown(browser), proc=proc) in ("standing", "in_air")

        for toggle in browser.find_elements(By.XPATH, "//*[text()='Open Controls']"):
            toggle.click()  # dat.GUI starts closed in a small window
        row = _wait("the vx slider", lambda: _control(browser, "vx"), proc=proc)
        box = row.find_element(By.CSS_SELECTOR, "input")
        box.send_keys(Keys.CONTROL, "a")
        box.send_keys("0.4", Keys.ENTER)
        _wait("the controller's command to follow the slider",
              lambda: (_slider_value(browser, "commanded vx (m/s)") or 0.0) > 0.2, proc=proc)
        _wait("walking", lambda: _mode_shown(browser) == "walking", proc=proc)
        _wait("the base to move forward", lambda: (_slider_value(browser, "measured vx (m/s)") or 0.0) > 0.1,
              proc=proc)

        _control(browser, "E-stop").click()
        _wait("damping after E-stop", lambda: _mode_shown(browser) == "damping", proc=proc)
        time.sleep(1.0)
        assert _mode_shown(browser) == "damping"  # latched
        assert _js_errors(browser) == []
    finally:
        browser.get("about:blank")  # leave the page before its server goes away
        browser.execute_cdp_cmd("Page.removeScriptToEvaluateOnNewDocument",
                                {"identifier": script["identifier"]})
        proc.send_signal(signal.SIGINT)
        try:
            out, err = proc.communicate(timeout=WAIT_S)
        except subprocess.TimeoutExpired:
            proc.kill()  # never leave a real-time run behind
            proc.communicate()
            pytest.fail("romoco run --teleop did not end on Ctrl-C")
    assert proc.returncode == 0, (out, err, list(lines.queue)[-20:])
    summary = json.loads(out.strip().splitlines()[-1])
    assert summary["teleop_estop"] is True
    assert summary["mean_velocity"][0] > 0.02
    assert summary["steps"] >= 2


@pytest.mark.slow
def test_replay_loads_and_keeps_the_robot_in_frame(browser, tmp_path):
    """A --record replay opened from file:// loads without a JavaScript error and, at its end,
    the robot (which walked forward) is still in the middle of the picture."""
    from PIL import Image

    replay = tmp_path / "walk.html"
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    subprocess.run([sys.executable, "-m", "romoco_drake.cli", "run", "g1_walk", "--duration", "3",
                    "--command", "0:0.8,0,0", "--record", str(replay)], check=True, env=env,
                   stdout=subprocess.DEVNULL, cwd=tmp_path)
    browser.get_log("browser")  # drop what earlier pages logged
    browser.get(replay.as_uri())
    _wait("the replay's scene", lambda: any(
        p.endswith("/pelvis") for p in _scene_paths(browser, ["drake", "robot"])))
    duration = browser.execute_script("return viewer.animator.duration;")
    assert duration > 2.0
    browser.execute_script("viewer.animator.seek(arguments[0]); viewer.set_dirty();", duration)
    time.sleep(1.0)
    shift = browser.execute_script("return viewer.scene_tree.find(['drake']).object.position.toArray();")
    assert shift[0] < -0.1  # the robot walked forward and the view followed it
    shot = tmp_path / "end.png"
    browser.save_screenshot(str(shot))
    assert _js_errors(browser) == []
    image = np.asarray(Image.open(shot).convert("RGB"), dtype=float)
    h, w, _ = image.shape
    middle = image[h // 4:3 * h // 4, w // 3:2 * w // 3]
    background = image[h // 2, 5]
    differing = np.abs(middle - background).sum(axis=2) > 60  # the robot, not the sky's gradient
    assert differing.mean() > 0.02
