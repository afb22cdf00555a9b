"""Regenerate the images of docs/usage.md: ``python docs/images/make_images.py`` (about 20 s), and with
``--dashboard`` the two screenshots of the dashboard too (a real ``finaldrive serve`` and the system's headless
Chromium through Playwright, from the test extra; about a minute).
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

import numpy as np

from finaldrive.engine import Design, Road, SimSettings, evaluate
from finaldrive.engine.model import coordinates as C
from finaldrive.engine.study.sweep import parse_grid
from finaldrive.service.media import plots
from finaldrive.service.media.recording import record, scene_at

HERE = Path(__file__).resolve().parent
ROAD = Road.parse("sine:0.04:3")
TABLE14 = [("geometry 1 (a2 0°, L2 0, R_WS 93 mm)", Design.from_deg(0.0, 0.0, 0.093)),
           ("geometry 2 (a2 270°, L2 150 mm, R_WS 150 mm)", Design.from_deg(270.0, 0.15, 0.15))]


def sweep_map() -> None:
    grid = parse_grid("a2_deg=0:354:6,l2_m=0:0.2:0.02,rws_m=0.093")
    batch = evaluate(grid, ROAD, SimSettings())
    best = int(np.nanargmax(batch.fitness_m))
    plots.sweep_map_png(HERE / "sweep-map.png", grid, batch.distance_m, best=(grid[best, 0], grid[best, 1]),
                        best_label="best fitness (eq. 67)",
                        title="Distance in 3.5 s on sine:0.04:3 (R_WS = 93 mm), as the paper's Fig. 10")


def recording_frame(t: float = 2.0) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        rrd = Path(tmp) / "table14.rrd"
        runs = record(rrd, TABLE14, ROAD)
        strips, arrows = scene_at(rrd, t)
    k = round(t * 50)
    xs = [r.series["q"][k][[C.X6, C.X13]] for r in runs]
    plots.scene_png(
        HERE / "recording-frame.png",
        strips,
        arrows,
        xlim=(float(np.min(xs)) - 0.7, float(np.max(xs)) + 0.7),
        title=f"One frame (t = {t:.2f} s) read back from the .rrd, sine:0.04:3; orange: tyre forces (1 m = 5 kN)\n"
        f"blue: {TABLE14[0][0]}    red: {TABLE14[1][0]}",
    )
    plots.series_png(HERE / "series.png", [(r.label, r.series) for r in runs],
                     title="Fig. 13 quantities of the Table 14 geometries on sine:0.04:3")


#: The job of the dashboard's screenshot: a sweep of the paper's Fig. 10 grid on two roads.
SWEEP = {"kind": "sweep", "roads": ["sine:0.04:3", "flat"], "grid": "a2_deg=0:354:6,l2_m=0:0.2:0.02,rws_m=0.093"}


def _call(url: str, body: dict | None = None) -> dict:
    data = None if body is None else json.dumps(body).encode()
    request = urllib.request.Request(url, data, {"Content-Type": "application/json"})
    with urllib.request.urlopen(request, timeout=30) as answer:
        return json.loads(answer.read())


def dashboard() -> None:
    """The job page of SWEEP (a design selected on the map, the tooltip of another) and the design page of
    its best on sine:0.04:3 beside the Table 11 design, the recording playing in rerun's viewer."""
    from playwright.sync_api import sync_playwright

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    base = f"http://127.0.0.1:{port}"
    with tempfile.TemporaryDirectory() as tmp:
        env = {k: v for k, v in os.environ.items() if k != "FINALDRIVE_API_TOKEN"}
        server = subprocess.Popen([sys.executable, "-m", "finaldrive.service.cli", "serve", "--port", str(port),
                                   "--db", f"sqlite:///{tmp}/fd.db", "--executor", "process"], env=env,
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            for _ in range(600):
                try:
                    if _call(base + "/v1/health")["schedulers"]:
                        break
                except OSError:
                    pass
                time.sleep(0.2)
            job = _call(base + "/v1/jobs", SWEEP)["id"]
            while (state := _call(f"{base}/v1/jobs/{job}")["state"]) != "succeeded":
                if state in ("failed", "cancelled"):
                    raise RuntimeError(f"the screenshot's sweep {state}")
                time.sleep(0.5)
            best = _call(f"{base}/v1/jobs/{job}")["roads"][0]["best"]
            chromium = os.environ.get("FINALDRIVE_CHROMIUM") or shutil.which("chromium")
            with sync_playwright() as p:
                browser = p.chromium.launch(executable_path=chromium, args=["--no-sandbox", "--disable-gpu"])
                page = browser.new_page(viewport={"width": 1400, "height": 1000})
                page.goto(f"{base}/jobs/{job}")
                page.wait_for_selector("body[data-ready]", timeout=60_000)
                canvas = page.locator("#map canvas")
                first, other = page.evaluate("[window.fdMap.best, window.fdMap.layout.shown.at(-40)]")
                page.set_viewport_size({"width": 1400, "height": page.evaluate("document.body.scrollHeight")})
                for i, click in ((first, True), (other, False)):   # the whole page in the viewport: the tooltip stays
                    x, y = page.evaluate(f"window.fdMap.positionOf({i})")
                    canvas.click(position={"x": x, "y": y}) if click else canvas.hover(position={"x": x, "y": y})
                page.screenshot(path=HERE / "dashboard-job.png")
                page.goto(f"{base}/design?road=sine:0.04:3&a={best['a2_deg']},{best['l2_m']},{best['rws_m']}"
                          f"&label_a=job {job} best&b=195.3,0.037,0.088&label_b=Table 11")
                page.wait_for_selector("body[data-ready]", timeout=180_000)
                time.sleep(30)   # the viewer's own start in a headless Chromium without a GPU (docs/performance.md)
                page.screenshot(path=HERE / "dashboard-design.png", full_page=True)
                browser.close()
        finally:
            server.terminate()
            server.wait(timeout=30)


if __name__ == "__main__":
    sweep_map()
    recording_frame()
    if "--dashboard" in sys.argv[1:]:
        dashboard()
    print("wrote", ", ".join(sorted(p.name for p in HERE.glob("*.png"))))
