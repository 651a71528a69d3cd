#!/usr/bin/python3
"""yscene serve's benchmark (issue 37): how long a hair edit takes to show,
and how fast the serve loop renders against `yscene render`.

  python3 scripts/bench/serve_latency.py [--yscene build/apps/yscene]
      [--scene scenes/curly-hair/curly-hair.json] [--resolution 512] [--threads 2]
      [--edits 20] [--runs 3] [--samples 16] [--output docs/benchmark/serve.md]

Latency, over --edits edits that alternate the first hair material's
eumelanin between two values, each sent at a different point of a pass:
- http: a client POSTs the edit, long-polls /api/state until a frame of the
  edit's generation is published, then has that frame's PNG in hand;
- browser (where headless Chromium and Selenium are installed): the page's
  own slider gets an input event; the time until the page has loaded the
  first frame of the edit's generation (taken from the page's own requests
  and its image's load events), and until the first full-resolution frame.
Throughput: pixel samples per second of the serve loop (no client but a
once-a-second poll) and of `yscene render` at the same scene, resolution,
samples and threads, alternating, --runs each; medians.

Writes the report (markdown) to --output and prints it.
"""

import argparse
import json
import os
import platform
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
import urllib.request

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
LIGHT, DARK = 0.3, 1.3  # the eumelanin values the edits alternate between


def log(text):
    print(f"[serve_latency] {text}", file=sys.stderr, flush=True)


class Server:
    """A `yscene serve` child process and a client of its API."""

    def __init__(self, yscene, scene, resolution, threads, samples, output_dir):
        command = [yscene, "serve", scene, "--port", "0", "-r", str(resolution),
                   "-t", str(threads), "-s", str(samples), "--output-dir", output_dir]
        self.process = subprocess.Popen(command, stdout=subprocess.PIPE, text=True)
        line = self.process.stdout.readline()
        match = re.search(r"(http://[^/]+)/\?token=([0-9a-f]+)", line)
        if not match:
            self.process.kill()
            raise RuntimeError(f"yscene serve printed no URL: {line!r}")
        self.base, self.token = match.group(1), match.group(2)
        self.url = f"{self.base}/?token={self.token}"

    def request(self, path, body=None):
        data = None if body is None else json.dumps(body).encode()
        request = urllib.request.Request(self.base + path, data=data,
                                         headers={"X-Token": self.token,
                                                  "Content-Type": "application/json"})
        with urllib.request.urlopen(request, timeout=60) as response:
            return response.read(), response.headers

    def state(self, after=None):
        path = "/api/state" + ("" if after is None else f"?after={after}")
        return json.loads(self.request(path)[0])

    def wait(self, condition, timeout=300, after=True):
        """Long-polls the state until condition(state) holds; returns it."""
        deadline = time.monotonic() + timeout
        state = self.state()
        while not condition(state):
            if time.monotonic() > deadline:
                raise RuntimeError("timed out waiting for the server")
            state = self.state(state["frame"]) if after else (time.sleep(1), self.state())[1]
        return state

    def stop(self):
        self.process.send_signal(2)
        try:
            self.process.wait(timeout=60)
        except subprocess.TimeoutExpired:
            self.process.kill()


def full_frame(generation, samples=1):
    return lambda s: (s["frame_generation"] >= generation and not s["preview"]
                      and s["samples"] >= samples)


def edit_offsets(count):
    """Where in a pass each edit lands, as fractions: spread, repeatable."""
    return [(0.15 + 0.618034 * k) % 1 for k in range(count)]


def eumelanin_edit(k):
    return {"material": 0, "parameter": "eumelanin", "value": DARK if k % 2 == 0 else LIGHT}


def measure_http(server, count, pass_seconds):
    """Per edit: seconds to the frame's publication and to its PNG in hand."""
    published, in_hand, previews = [], [], 0
    generation = server.wait(full_frame(0))["generation"]
    for k, offset in enumerate(edit_offsets(count)):
        time.sleep(offset * pass_seconds)
        start = time.perf_counter()
        generation = json.loads(server.request("/api/material", eumelanin_edit(k))[0])["generation"]
        state = server.wait(lambda s: s["frame_generation"] >= generation)
        published.append(time.perf_counter() - start)
        _, headers = server.request(f"/api/frame.png?n={state['frame']}")
        in_hand.append(time.perf_counter() - start)
        assert int(headers["X-Generation"]) >= generation, headers
        previews += state["preview"]
        server.wait(full_frame(generation))
    return published, in_hand, previews


# Records, in the page, the answers to its edits and state polls and its
# image's loads (with the centre's mean, to see the edit's direction).
BROWSER_HOOK = """
const bench = window.__bench = {edits: [], states: [], loads: []};
const original = window.fetch;
window.fetch = async function (path, options) {
  const response = await original(path, options);
  const time = performance.now();
  if (typeof path === 'string' && (path.startsWith('/api/material') || path.startsWith('/api/state')))
    response.clone().json().then((body) => {
      if (path.startsWith('/api/material')) bench.edits.push([time, body.generation]);
      else bench.states.push([time, body.frame, body.frame_generation, body.preview]);
    }).catch(() => {});
  return response;
};
const img = document.getElementById('frame');
img.addEventListener('load', () => {
  const time = performance.now();
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
  bench.loads.push([time, Number(img.dataset.requested), sum / (3 * 255 * data.length / 4)]);
});
"""

SLIDE = """
const slider = document.getElementById('m0-eumelanin');
const time = performance.now();
slider.value = arguments[0];
slider.dispatchEvent(new Event('input'));
return time;
"""


def start_browser():
    """A headless Chromium through Selenium, or None (and why) where there is none."""
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
    except ImportError:
        return None, "python3-selenium is not installed"
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    driver = shutil.which("chromedriver") or "/usr/bin/chromedriver"
    if not browser or not os.path.exists(driver):
        return None, "no chromium or chromedriver"
    options = webdriver.ChromeOptions()
    options.binary_location = browser
    for argument in ("--headless=new", "--no-sandbox", "--disable-gpu",
                     "--disable-dev-shm-usage", "--window-size=1400,900"):
        options.add_argument(argument)
    try:
        return webdriver.Chrome(service=Service(driver), options=options), ""
    except Exception as error:
        return None, f"chromium did not start ({str(error).splitlines()[0]})"


def measure_browser(page, server, count, pass_seconds):
    """Per edit: seconds from the slider's input event to the page's load of
    the first frame of its generation and of the first full frame; and
    whether each first frame moved the centre's mean the edit's way."""
    page.get(server.url)
    deadline = time.monotonic() + 120
    while not page.execute_script("return !!document.getElementById('m0-eumelanin')"):
        if time.monotonic() > deadline:
            raise RuntimeError("the page built no eumelanin control")
        time.sleep(0.1)
    page.execute_script(BROWSER_HOOK)
    server.wait(full_frame(0))
    time.sleep(0.5)  # the page loads that frame
    first, full, right_way = [], [], 0
    for k, offset in enumerate(edit_offsets(count)):
        time.sleep(offset * pass_seconds)
        value = eumelanin_edit(k)["value"]
        start = page.execute_script(SLIDE, value)
        before = page.execute_script("return window.__bench.loads.slice(-1)[0]")
        deadline = time.monotonic() + 120
        while True:
            bench = page.execute_script("return window.__bench")
            edits = [g for t, g in bench["edits"] if t >= start]
            if edits:
                generation = edits[0]
                frames = [(f, p) for _, f, g, p in bench["states"] if g is not None and g >= generation]
                if frames:
                    shown = min(f for f, _ in frames)
                    fulls = [f for f, p in frames if not p]
                    loads = [(t, f, m) for t, f, m in bench["loads"] if f >= shown]
                    full_loads = [t for t, f, _ in bench["loads"] if fulls and f >= min(fulls)]
                    if loads and full_loads:
                        break
            if time.monotonic() > deadline:
                raise RuntimeError(f"edit {k}: the page never showed it")
            time.sleep(0.02)
        first.append((loads[0][0] - start) / 1000)
        full.append((full_loads[0] - start) / 1000)
        darker = value == DARK
        right_way += (loads[0][2] < before[2]) == darker
    return first, full, right_way


def render_speed(yscene, scene, resolution, threads, samples, output):
    result = subprocess.run([yscene, "render", scene, "-r", str(resolution), "-t", str(threads),
                             "-s", str(samples), "--output", output, "--stats", "-q"],
                            capture_output=True, text=True, check=True)
    stats = dict(item.split("=", 1) for line in result.stdout.splitlines()
                 if line.startswith("stats ") for item in line.split()[1:])
    pixels = int(stats["width"]) * int(stats["height"]) * int(stats["spp"])
    return pixels / float(stats["render_seconds"])


def serve_speed(yscene, scene, resolution, threads, samples, output_dir):
    server = Server(yscene, scene, resolution, threads, samples, output_dir)
    try:
        state = server.wait(full_frame(0, samples), after=False)
        return state["samples_per_second"]
    finally:
        server.stop()


def median_ms(values):
    return f"{1000 * statistics.median(values):.0f}"


def spread_ms(values):
    return f"{1000 * min(values):.0f}–{1000 * max(values):.0f}"


def main():
    # Debian's Selenium is in its own Python: run there when another one
    # (a pyenv, a venv) lacks it.
    debian = "/usr/bin/python3"
    try:
        import selenium  # noqa: F401
    except ImportError:
        if os.path.exists(debian) and os.path.realpath(sys.executable) != os.path.realpath(debian):
            os.execv(debian, [debian] + sys.argv)
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--yscene", default=os.path.join(ROOT, "build/apps/yscene"))
    parser.add_argument("--scene", default=os.path.join(ROOT, "scenes/curly-hair/curly-hair.json"))
    parser.add_argument("--resolution", type=int, default=512)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--edits", type=int, default=20)
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--samples", type=int, default=16)
    parser.add_argument("--output", default=os.path.join(ROOT, "docs/benchmark/serve.md"))
    parser.add_argument("--screenshot", default="", help="also save the page's screenshot here")
    args = parser.parse_args()
    if not os.path.exists(args.scene):
        sys.exit(f"{args.scene}: no such scene (bash scripts/make_scenes.sh makes it)")
    work = tempfile.mkdtemp(prefix="serve_latency_")
    try:
        log("serve: http latency")
        server = Server(args.yscene, args.scene, args.resolution, args.threads, 1 << 20, work)
        try:
            state = server.wait(full_frame(0, 2))
            pass_seconds = state["seconds"] / state["samples"]
            published, in_hand, previews = measure_http(server, args.edits, pass_seconds)
        finally:
            server.stop()
        browser_rows, browser_note = None, ""
        page, why = start_browser()
        if page is None:
            browser_note = f"browser latency not measured: {why}"
            log(browser_note)
        else:
            log("serve: browser latency")
            server = Server(args.yscene, args.scene, args.resolution, args.threads, 1 << 20, work)
            try:
                first, full, right_way = measure_browser(page, server, args.edits, pass_seconds)
                browser_rows = (first, full, right_way)
                if args.screenshot:  # the page a while after the last edit
                    server.wait(lambda s: s["samples"] >= 8 and not s["preview"])
                    time.sleep(1)
                    page.save_screenshot(args.screenshot)
            finally:
                page.quit()
                server.stop()
        render, serve = [], []
        for run in range(args.runs):
            log(f"throughput run {run + 1} of {args.runs}")
            render.append(render_speed(args.yscene, args.scene, args.resolution, args.threads,
                                       args.samples, os.path.join(work, "render.exr")))
            serve.append(serve_speed(args.yscene, args.scene, args.resolution, args.threads,
                                     args.samples, work))
    finally:
        shutil.rmtree(work, ignore_errors=True)

    scene = os.path.relpath(args.scene, ROOT)
    lines = [
        "# yscene serve: edit latency and throughput",
        "",
        "Generated by `python3 scripts/bench/serve_latency.py` "
        f"({args.edits} edits, {args.runs} throughput runs) on {platform.node()}, "
        f"{os.cpu_count()} cores, {time.strftime('%Y-%m-%d')}.",
        "",
        f"Scene `{scene}` at {args.resolution}² on {args.threads} threads; a full pass "
        f"(one sample per pixel) takes {pass_seconds:.2f} s. Each edit changes the first hair "
        f"material's eumelanin ({LIGHT} ↔ {DARK}) at a different point of a pass; the first "
        "frame of an edit is a one-sample preview of fewer pixels, then the full passes follow.",
        "",
        "| from an edit to | median ms | min–max ms |",
        "|---|---:|---:|",
        f"| http: its first frame published (long poll of /api/state) | {median_ms(published)} | {spread_ms(published)} |",
        f"| http: that frame's PNG in the client's hands | {median_ms(in_hand)} | {spread_ms(in_hand)} |",
    ]
    if browser_rows:
        first, full, right_way = browser_rows
        lines += [
            f"| browser: slider input → first frame of the edit loaded by the page | {median_ms(first)} | {spread_ms(first)} |",
            f"| browser: slider input → first full-resolution frame loaded | {median_ms(full)} | {spread_ms(full)} |",
        ]
    lines += [""]
    lines += [f"{previews} of {args.edits} first frames were previews (the rest: the edit came when a "
              "full pass was about as quick)."]
    if browser_rows:
        lines += [f"In the browser, {browser_rows[2]} of {args.edits} first frames moved the centre's "
                  "mean the edit's way (darker for more eumelanin)."]
    else:
        lines += [browser_note + "."]
    ratio = statistics.median(serve) / statistics.median(render)
    lines += [
        "",
        f"Throughput at {args.samples} samples per pixel (pixel samples per second, median of "
        f"{args.runs}, alternating runs):",
        "",
        "| loop | median | runs |",
        "|---|---:|---|",
        f"| `yscene render` | {statistics.median(render) / 1e3:.1f}k | "
        + ", ".join(f"{v / 1e3:.1f}k" for v in render) + " |",
        f"| `yscene serve` | {statistics.median(serve) / 1e3:.1f}k | "
        + ", ".join(f"{v / 1e3:.1f}k" for v in serve) + " |",
        "",
        f"serve / render: **{ratio:.3f}**",
        "",
    ]
    report = "\n".join(lines)
    os.makedirs(os.path.dirname(os.path.abspath(args.output)), exist_ok=True)
    temporary = args.output + ".tmp"
    with open(temporary, "w") as file:
        file.write(report)
    os.replace(temporary, args.output)
    print(report)


if __name__ == "__main__":
    main()
