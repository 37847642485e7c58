"""``autopilot bench console``: what the operator console costs the autopilot, and how late its
video reaches a viewer.

One real-time follow_ball flight in the simulator with ``--console``. While it follows the ball,
windows of ``--window`` wall seconds alternate: nobody watching, then one viewer of
``/video/front.mjpg`` at ``--fps`` (in a process of its own: its CPU is the viewer's, not the
autopilot's), and again. The autopilot process's CPU time per window (the simulator included,
the same in both) gives the console's cost as a share of one core; the encoder's own thread
time is reported too, and that nothing is encoded while nobody watches.

Latency, glass to viewer: each MJPEG part carries its frame's capture time on the run's
clock. In real time that clock is the monotonic clock shifted by a constant, which the viewer
learns from ``GET /api/status`` (the smallest shift seen over many requests, so the request's
own delay drops out); a frame's latency is its arrival at the viewer minus its capture. With
``--browser`` (Playwright and Debian's chromium), the viewer is the console's page itself and
the latency runs to the frame drawn on the page's canvas.
"""

from __future__ import annotations

import asyncio
import json
import multiprocessing
import shutil
import tempfile
import time
import urllib.request
from collections.abc import Callable
from pathlib import Path

import numpy as np

from autopilot import resources
from autopilot.mission import load_mission
from autopilot.run import fly


def _clock_shift(base: str, samples: int = 30) -> float:
    """monotonic − the run's clock: it lies between (sent − run time) and (answered − run
    time) of every request; the tightest bounds over many requests, halfway."""
    low, high = -np.inf, np.inf
    for _ in range(samples):
        before = time.monotonic()
        with urllib.request.urlopen(base + "/api/status", timeout=5) as r:
            run_time = json.loads(r.read())["time_s"]
        after = time.monotonic()
        low, high = max(low, before - run_time), min(high, after - run_time)
        time.sleep(0.02)
    return float(0.5 * (low + high))


def _viewer(base: str, fps: float, seconds: float, results, overlay: bool = True) -> None:
    """One MJPEG viewer (in a process of its own): latency of each frame as it arrives."""
    shift = _clock_shift(base)
    latencies, sizes = [], []
    deadline = time.monotonic() + seconds
    url = f"{base}/video/front.mjpg?fps={fps:g}&overlay={int(overlay)}"
    with urllib.request.urlopen(url, timeout=10) as resp:
        while time.monotonic() < deadline:
            head = b""
            while not head.endswith(b"\r\n\r\n"):
                head += resp.read(1)
            fields = dict(line.split(b": ", 1) for line in head.split(b"\r\n")
                          if b": " in line)
            jpeg = resp.read(int(fields[b"Content-Length"]))
            resp.read(2)
            arrived = time.monotonic()
            latencies.append((arrived - shift - float(fields[b"X-Frame-Time"])) * 1e3)
            sizes.append(len(jpeg))
    results.put({"latency_ms": latencies, "bytes": sizes, "seconds": seconds})


def _browser_viewer(base: str, fps: float, seconds: float, results, overlay: bool = True
                    ) -> None:
    """The console's page in headless chromium as the viewer: latency to the drawn frame."""
    from playwright.sync_api import sync_playwright

    chromium = next(p for p in map(shutil.which, ("chromium", "chromium-browser")) if p)
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=chromium, headless=True)
        page = browser.new_page(bypass_csp=True)
        page.goto(base + "/")
        page.wait_for_function("window.consoleState.hello !== null")
        page.select_option("#fps", str(int(fps)))
        if not overlay:
            page.uncheck("#overlay")
        start = page.evaluate("window.consoleState.frames")
        page.evaluate("window.consoleState.latencies = []")
        time.sleep(seconds)
        frames = page.evaluate("window.consoleState.frames") - start
        latencies = page.evaluate("window.consoleState.latencies")
        browser.close()
    results.put({"latency_ms": latencies, "bytes": [], "seconds": seconds, "frames": frames})


def run_bench(window_s: float, windows: int, fps: float, browser: bool,
              log: Callable[[str], None], overlay: bool = True) -> dict:
    # follow_ball, following for as long as the windows take
    text = (resources.missions_dir() / "follow_ball.yaml").read_text()
    follow_s = 60 + windows * 2 * (window_s + 5.0)
    folder = Path(tempfile.mkdtemp(prefix="bench-console-"))
    mission = folder / "follow_ball.yaml"
    mission.write_text(text.replace("follow_ball: {duration_s: 60}",
                                    f"follow_ball: {{duration_s: {follow_s:.0f}}}"))
    plan = load_mission(str(mission))
    servers: list = []
    out: dict = {"window_s": window_s, "fps": fps, "viewer": "browser" if browser else "mjpeg",
                 "overlay": overlay}

    async def main() -> None:
        flight = asyncio.ensure_future(fly(plan, None, realtime=True, api="127.0.0.1:0",
                                           console=True, on_api=servers.append))
        while not servers or not servers[0].started.is_set():  # noqa: ASYNC110
            await asyncio.sleep(0.05)
        server = servers[0]
        base = f"http://127.0.0.1:{server.bound_port}"

        def status() -> dict:
            with urllib.request.urlopen(base + "/api/status") as r:
                return json.loads(r.read())

        while (await asyncio.to_thread(status))["status_code"] != 13:  # noqa: ASYNC110
            await asyncio.sleep(0.2)
        await asyncio.sleep(3.0)  # (the follow settles)
        spawn = multiprocessing.get_context("spawn")
        rows: list[dict] = []
        latencies: list[float] = []
        sizes: list[int] = []
        feed = server.console.feed("front", overlay=overlay)
        for i in range(2 * windows):
            watching = i % 2 == 1
            results = spawn.Queue()
            viewer = None
            if watching:
                viewer = spawn.Process(target=_browser_viewer if browser else _viewer,
                                       args=(base, fps, window_s + 4.0, results, overlay),
                                       daemon=True)
                viewer.start()
                await asyncio.sleep(3.0)  # (it connects, learns the clock, starts watching)
            encoded0, enc_cpu0 = feed.encoded, feed.cpu_s
            cpu0, wall0 = time.process_time(), time.perf_counter()
            await asyncio.sleep(window_s)
            cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
            rows.append({"watching": watching, "cpu_share": cpu / wall,
                         "frames_encoded": feed.encoded - encoded0,
                         "encoder_cpu_share": (feed.cpu_s - enc_cpu0) / wall})
            log(f"window {i + 1}/{2 * windows}: {'1 viewer' if watching else 'no viewer'}: "
                f"process {100 * cpu / wall:.1f} % of a core, "
                f"{(feed.encoded - encoded0) / wall:.1f} frames/s encoded")
            if viewer is not None:
                got = await asyncio.to_thread(results.get, True, 60)
                await asyncio.to_thread(viewer.join, 10)
                latencies += got["latency_ms"][len(got["latency_ms"]) // 4:]
                sizes += got["bytes"]
        out["windows"] = rows
        # what the camera itself takes (exposure, readout, delivery: before the console)
        out["camera_latency_ms_p50"] = feed.stats()["capture_to_arrival_ms_p50"]
        server.console.host.flight.request_stop("benchmark done")
        await flight
        idle = [r["cpu_share"] for r in rows if not r["watching"]]
        busy = [r["cpu_share"] for r in rows if r["watching"]]
        watched = [r for r in rows if r["watching"]]
        out.update(
            process_core_share_no_viewer=float(np.mean(idle)),
            process_core_share_one_viewer=float(np.mean(busy)),
            console_core_share=float(np.mean(busy) - np.mean(idle)),
            encoder_core_share=float(np.mean([r["encoder_cpu_share"] for r in watched])),
            frames_per_s=float(np.mean([r["frames_encoded"] for r in watched])) / window_s,
            frames_encoded_no_viewer=int(sum(r["frames_encoded"] for r in rows
                                             if not r["watching"])),
            latency_ms_p50=float(np.percentile(latencies, 50)) if latencies else None,
            latency_ms_p95=float(np.percentile(latencies, 95)) if latencies else None,
            frame_kb_mean=float(np.mean(sizes) / 1024) if sizes else None,
            latency_frames=len(latencies))

    asyncio.run(main())
    return out


def format_table(r: dict) -> str:
    def pct(x):
        return f"{100 * x:5.1f} %"

    lat = "n/a" if r["latency_ms_p50"] is None else \
        f"p50 {r['latency_ms_p50']:.0f} ms, p95 {r['latency_ms_p95']:.0f} ms " \
        f"({r['latency_frames']} frames)"
    return "\n".join([
        f"console cost, follow_ball in real time, {r['fps']:g} fps 640×480, viewer: "
        f"{r['viewer']}{'' if r.get('overlay', True) else ', bare frames (overlay=0)'} "
        f"({len(r['windows']) // 2} windows of {r['window_s']:g} s each way)",
        f"  autopilot process, no viewer     {pct(r['process_core_share_no_viewer'])} of a core",
        f"  autopilot process, one viewer    {pct(r['process_core_share_one_viewer'])} of a core",
        f"  the console's cost               {pct(r['console_core_share'])} of a core "
        f"(its encoder thread alone: {pct(r['encoder_core_share'])})",
        f"  frames encoded                   {r['frames_per_s']:.1f}/s with a viewer, "
        f"{r['frames_encoded_no_viewer']} with none",
        f"  capture → viewer latency         {lat}"
        + (f", {r['frame_kb_mean']:.0f} KB a frame" if r["frame_kb_mean"] else ""),
        f"    of which the camera itself     p50 {r['camera_latency_ms_p50']:.0f} ms (capture → "
        "the frame reaching the autopilot)" if r.get("camera_latency_ms_p50") is not None
        else "    (the camera's own share not measured)",
        *(["  (a browser on this machine shares its cores with the autopilot: the CPU figures "
           "of this run are not the console's; run without --browser for them)"]
          if r["viewer"] == "browser" else [])])
