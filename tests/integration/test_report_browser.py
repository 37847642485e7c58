"""The flight report in a real browser: headless Chromium opens ``report.html`` from disk
(offline, nothing fetched) and every plot is loaded and laid out; its screenshot is taken as
the README documents. Needs Chromium (Debian: ``apt install chromium``); skipped without it."""

import html
import json
import os
import re
import shutil
import subprocess

import cv2
import numpy as np
import pytest
from mcap.reader import make_reader

from autopilot.report.html import write_report
from autopilot.report.panels import ALWAYS, panels_in_order
from autopilot.steps import STEP_KINDS

CHROMIUM = os.environ.get("CHROMIUM") or next(
    (p for p in map(shutil.which, ("chromium", "chromium-browser", "google-chrome")) if p), None)
pytestmark = pytest.mark.skipif(CHROMIUM is None,
                                reason="needs Chromium (Debian: apt install chromium)")

# offline and quiet: no sandbox (CI runs as root), no GPU, no background connections
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--no-first-run", "--hide-scrollbars"]

CHECK = """<script>
window.addEventListener("load", () => {
  const plots = [...document.images].map(i => ({alt: i.alt, complete: i.complete,
    width: i.naturalWidth, shown: i.getBoundingClientRect().width,
    height: i.getBoundingClientRect().height}));
  document.body.setAttribute("data-plots", JSON.stringify(plots));
});
</script>"""


def _chromium(*args, profile):
    return subprocess.run([CHROMIUM, *FLAGS, f"--user-data-dir={profile}", *args],
                          capture_output=True, text=True, timeout=120, check=True)


def test_every_plot_is_visible_in_headless_chromium(logged_flight, tmp_path):
    run_dir, _ = logged_flight
    report = write_report(run_dir)
    page = tmp_path / "report.html"  # the report, plus a script that reports on its images
    page.write_text(report.read_text().replace("</body>", CHECK + "</body>"))
    dom = _chromium("--virtual-time-budget=10000", "--dump-dom", page.as_uri(),
                    profile=tmp_path / "profile").stdout
    found = re.search(r'data-plots="([^"]*)"', dom)
    assert found, "the page did not finish loading"
    plots = json.loads(html.unescape(found.group(1)))
    # the panels follow_ball's steps ask for (and those every report has), in the panels' order
    wanted = set(ALWAYS) | set(STEP_KINDS["follow_ball"].report)
    assert [p["alt"] for p in plots] == [panel.title for panel in panels_in_order()
                                         if panel.name in wanted]
    for plot in plots:
        assert plot["complete"], plot
        assert plot["width"] > 300, plot
        assert plot["shown"] > 300, plot
        assert plot["height"] > 100, plot


def test_the_report_lists_the_channels_that_hold_messages(logged_flight):
    run_dir, _ = logged_flight
    text = write_report(run_dir).read_text()
    with open(run_dir / "flight.mcap", "rb") as f:
        summary = make_reader(f).get_summary()
    counts = summary.statistics.channel_message_counts
    assert len(summary.channels) >= 10
    for channel_id, channel in summary.channels.items():
        schema = summary.schemas[channel.schema_id].name
        row = (f"<tr><td>{channel.topic}</td><td>{schema}</td>"
               f"<td>{channel.message_encoding}</td><td>{counts.get(channel_id, 0)}</td></tr>")
        if counts.get(channel_id, 0):
            assert row in text
        else:  # a channel declared but never written is not listed
            assert f"<tr><td>{channel.topic}</td>" not in text


def test_the_documented_screenshot_command(logged_flight, tmp_path):
    run_dir, _ = logged_flight
    report = write_report(run_dir)
    shot = tmp_path / "report.png"
    _chromium("--window-size=1100,4000", f"--screenshot={shot}", report.as_uri(),
              profile=tmp_path / "profile")
    image = cv2.imread(str(shot))
    assert image.shape[:2] == (4000, 1100)
    assert np.std(image) > 10  # not a blank page
