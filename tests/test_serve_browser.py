#!/usr/bin/python3
"""Tests `yscene serve` in a real browser: headless Chromium, driven by
Selenium through chromedriver, opens the URL the server prints, sees the
sample count rise and the image appear, types a darker eumelanin into the
first hair material's control and sees the image darken, saves (the EXR,
PNG and json land in --output-dir), and leaves a screenshot of the page in
the build folder. Ctrl-C (SIGINT) then stops the server with exit status 0.

Usage: python3 tests/test_serve_browser.py YSCENE_PATH BUILD_DIR

Needs Debian's chromium, chromium-driver and python3-selenium
(bash scripts/setup.sh installs them); where they are missing or the
browser cannot start, prints why and exits 77 (CTest counts it as skipped).
"""

import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time

SKIP = 77
# A straight, light-brown ball: eumelanin 0.3 -> 6 takes the central pixels'
# mean to about two fifths (0.37 -> 0.15), far outside the noise of a
# few samples per pixel.
STRANDS, RESOLUTION, EUMELANIN, DARK_EUMELANIN = 2000, 160, 0.3, 6
DARKER = 0.6  # the dark frame's mean over the light one's must be below this
TIMEOUT = 60  # seconds for each wait


def step(text):
    print(f"[test_serve_browser] {text}", file=sys.stderr, flush=True)


def skip(reason):
    print(f"[test_serve_browser] skipped: {reason}", flush=True)
    sys.exit(SKIP)


def find_browser():
    """The Chromium binary and its chromedriver, or a skip saying what is missing."""
    try:
        import selenium  # noqa: F401
    except ImportError:
        skip("python3-selenium is not installed (apt-get install python3-selenium)")
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    driver = shutil.which("chromedriver") or "/usr/bin/chromedriver"
    if not browser:
        skip("no chromium on PATH (apt-get install chromium)")
    if not os.path.exists(driver):
        skip("no chromedriver (apt-get install chromium-driver)")
    return browser, driver


def start_browser(browser, driver):
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service
    options = webdriver.ChromeOptions()
    options.binary_location = browser
    for argument in ("--headless=new", "--no-sandbox", "--disable-gpu",
                     "--disable-dev-shm-usage", "--window-size=1100,700"):
        options.add_argument(argument)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    try:
        return webdriver.Chrome(service=Service(driver), options=options)
    except Exception as error:  # the browser is installed but cannot start here
        skip(f"chromium did not start: {str(error).splitlines()[0] if str(error) else error}")


def wait_for(what, condition, timeout=TIMEOUT):
    """Polls condition() until it returns a true value, which it returns."""
    deadline = time.monotonic() + timeout
    while True:
        value = condition()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(0.1)


# The mean of the displayed frame's r g b in [0, 1] over its central 40%
# square (hair, not sky), read back through a canvas (the frame comes from
# the page's own origin, so it is readable); null until an image has
# loaded. Also the frame number it shows.
FRAME_MEAN = """
const img = document.getElementById('frame');
if (!img.complete || !img.naturalWidth) return null;
const canvas = document.createElement('canvas');
canvas.width = img.naturalWidth;
canvas.height = img.naturalHeight;
const context = canvas.getContext('2d');
context.drawImage(img, 0, 0);
const x0 = Math.floor(0.3 * canvas.width), y0 = Math.floor(0.3 * canvas.height);
const data = context.getImageData(x0, y0, Math.ceil(0.4 * canvas.width),
                                  Math.ceil(0.4 * canvas.height)).data;
let sum = 0;
for (let i = 0; i < data.length; i += 4) sum += data[i] + data[i + 1] + data[i + 2];
return [sum / (3 * 255 * data.length / 4), Number(img.dataset.frame || 0)];
"""


def main():
    if len(sys.argv) != 3:
        print(__doc__, file=sys.stderr)
        return 2
    yscene, build_dir = os.path.abspath(sys.argv[1]), os.path.abspath(sys.argv[2])
    browser, driver = find_browser()
    with tempfile.TemporaryDirectory(prefix="serve_browser_") as folder:
        scene = os.path.join(folder, "scene.json")
        output_dir = os.path.join(folder, "saved")
        os.mkdir(output_dir)
        subprocess.run([yscene, "hair", "--style", "straight", "-n", str(STRANDS),
                        "--eumelanin", str(EUMELANIN), "-o", scene, "-q"], check=True,
                       timeout=120)
        step("starting yscene serve")
        server = subprocess.Popen(
            [yscene, "serve", scene, "--port", "0", "-r", str(RESOLUTION), "-t", "2",
             "--output-dir", output_dir],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            line = server.stdout.readline()
            if not line.startswith("serving "):
                raise AssertionError(f"serve printed {line!r}; stderr: {server.stderr.read()}")
            url = line.split(" at ", 1)[1].strip()
            assert "token=" in url, url
            page = start_browser(browser, driver)
            try:
                run_page(page, url, output_dir, build_dir)
            finally:
                page.quit()
            step("stopping the server with SIGINT")
            server.send_signal(signal.SIGINT)
            status = server.wait(timeout=30)
            assert status == 0, f"serve exited with {status}: {server.stderr.read()}"
        finally:
            if server.poll() is None:
                server.kill()
                server.wait()
    print("[test_serve_browser] passed", flush=True)
    return 0


def run_page(page, url, output_dir, build_dir):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys
    text = lambda id: page.find_element(By.ID, id).text
    page.get(url)

    step("waiting for the sample count to rise and the image to appear")
    first = int(wait_for("a sample count", lambda: text("samples").isdigit() and text("samples")))
    wait_for("the sample count to rise", lambda: int(text("samples") or 0) > max(first, 1))
    light = wait_for("the image", lambda: page.execute_script(FRAME_MEAN))
    assert light[0] > 0.02, f"the first frame is black (mean {light[0]})"
    # The page lists the scene's material with its parameters.
    number = wait_for("the eumelanin control",
                      lambda: page.find_elements(By.ID, "m0-eumelanin-value"))[0]
    assert abs(float(number.get_attribute("value")) - EUMELANIN) < 1e-3, number.get_attribute("value")

    step(f"typing eumelanin {DARK_EUMELANIN}")
    number.send_keys(Keys.CONTROL, "a")
    number.send_keys(str(DARK_EUMELANIN), Keys.TAB)
    slider = page.find_element(By.ID, "m0-eumelanin")
    wait_for("the slider to follow", lambda: abs(float(slider.get_attribute("value")) - DARK_EUMELANIN) < 1e-3)
    dark = wait_for("a darker image", lambda: (lambda m: m and m[1] > light[1] and
                                              m[0] < DARKER * light[0] and m)(
        page.execute_script(FRAME_MEAN)))
    step(f"frame mean {light[0]:.4f} -> {dark[0]:.4f}")
    # The state the server reports has the edit too.
    wait_for("the sample count to rise again", lambda: int(text("samples") or 0) > 1)

    step("saving")
    page.find_element(By.ID, "save").click()
    saved = wait_for("the save to be reported", lambda: ".json" in text("saved") and text("saved"))
    names = sorted(os.listdir(output_dir))
    assert any(n.endswith(".exr") for n in names) and any(n.endswith(".png") for n in names) and \
        any(n.endswith(".json") for n in names), f"saved {names}; page says {saved!r}"
    scene_json = [n for n in names if n.endswith(".json")][0]
    with open(os.path.join(output_dir, scene_json)) as file:
        edited = json.load(file)
    assert f'"eumelanin": {DARK_EUMELANIN}' in json.dumps(edited) or \
        any(abs(m.get("eumelanin", -1) - DARK_EUMELANIN) < 1e-4 for m in edited.get("materials", [])
            if isinstance(m, dict)), f"the saved scene lacks the edit: {scene_json}"

    os.makedirs(build_dir, exist_ok=True)
    screenshot = os.path.join(build_dir, "serve_browser.png")
    assert page.save_screenshot(screenshot), screenshot
    step(f"screenshot: {screenshot}")
    errors = [entry for entry in page.get_log("browser") if entry.get("level") == "SEVERE"]
    assert not errors, f"the page logged errors: {errors}"


if __name__ == "__main__":
    sys.exit(main())
