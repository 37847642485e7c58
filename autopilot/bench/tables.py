"""The documentation's benchmark tables, generated from the benches' ``--json`` output, so that
no figure in them is typed by hand::

    autopilot bench land_pad --seeds 2 --json > land_pad.json
    autopilot bench hover_image --seeds 2 --json > hover_image.json
    python -m autopilot.bench.tables land_pad.json hover_image.json \\
        --note "2 seeds, on a shared 2-core machine" > docs/benchmarks.md

The page as published: ``python -m autopilot.bench.tables @docs/bench-data/benchmarks.args >
docs/benchmarks.md`` (the file holds the inputs in order and the note, an argument a line).

Each input is one bench's JSON; its ``bench`` names the formatter (:data:`FORMATTERS`). Several
inputs of the same bench (its rows or scenarios flown as separate processes, ``--row``,
``--scenario``) are pooled into one table (:data:`MERGERS`).
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
from collections.abc import Callable
from pathlib import Path

from autopilot.bench import down, follow, landing, load_figures, mavlink, offboard, speed


def _preformatted(bench: str, format_table: Callable[[dict], str],
                  about: str) -> Callable[[dict], list[str]]:
    """A bench whose table is its own text table (``format_table``), shown as it prints it."""
    def lines(result: dict) -> list[str]:
        extra = "; overrides: " + ", ".join(f"`{o}`" for o in result["overrides"]) \
            if result.get("overrides") else ""
        return [f"### `{bench}`", "", about + extra + ".", "", "```",
                format_table(result), "```", ""]
    return lines


#: bench name → its Markdown formatter (lines)
FORMATTERS: dict[str, Callable[[dict], list[str]]] = {
    "follow_ball": follow.format_markdown,
    "follow_marker": follow.format_markdown,
    "hover_image": down.format_markdown,
    "land_pad": down.format_markdown,
    "offboard": _preformatted(
        "offboard", offboard.format_table,
        "Orbit and survey, our tracker against seed 004's PID; mean (worst) over the seeds; "
        "`rms_cross_track_m` against truth (the navigation's error included), "
        "`rms_cross_track_nav_m` against the vehicle's own navigation (what the tracker "
        "controls)"),
    "landing": _preformatted(
        "landing", landing.format_table,
        "Landing on the moving rover: ours against seed 004's fused filter and gain-scheduled "
        "PID, and ours without the tag, in the same trials; a trial that did not land on the "
        "deck counts in the success rate and as infinite in the error percentiles"),
    "mavlink": _preformatted(
        "mavlink", mavlink.format_table,
        "Every shipped mission through each MAVLink driver against `autopilot sim` as PX4 "
        "SITL and as ArduCopter SITL, in real time, each part its own process (H.264 video, "
        "the simulator's calibrations), scored against truth: the step's headline figures"),
    "speed": _preformatted(
        "speed", speed.format_table,
        "Lockstep runs, each mission alone in a process of its own (`autopilot run --stages`): "
        "the real-time factor, the process's CPU per simulated second and its costliest "
        "stages (CPU on the thread that did the work; the rasteriser is Mesa llvmpipe's "
        "threads; `other`: what no stage counts — the event loop, hand-overs, modules loaded "
        "during the run), and what bounds the wall time"),
    "load": _preformatted(
        "load", load_figures.format_table,
        "Real-time follow_ball on a busy CPU: `autopilot sim` on a core of its own, the "
        "autopilot over a MAVLink driver (the table's first line names it; H.264 video in, a "
        "console viewer) sharing the other with N busy processes, each in a session of its own "
        "(Linux's autogroups give each the autopilot's share); a row per flight"),
}


def command_of(result: dict) -> str:
    """The command that reproduces a result (its bench, seeds, variant and overrides)."""
    parts = ["autopilot bench", result["bench"]]
    if result["bench"] == "landing":
        parts += [f"--trials {result['trials']}", f"--rover-speed {result['rover_speed_m_s']:g}"]
        parts += [f"--strategy {n}" for n in landing.STRATEGIES if n in result]
    elif result["bench"] == "load":
        parts += ["--hogs " + ",".join(str(n) for n in result["hogs"])]
        if result.get("repeat", 1) > 1:
            parts.append(f"--repeat {result['repeat']}")
        parts += [f"--follow-s {result['follow_s']:g}", f"--driver {result['driver']}"]
    elif result["bench"] == "speed":
        missions = list(result["missions"])
        if set(missions) != set(speed.DEFAULT_MISSIONS):
            parts += [f"--mission {m}" for m in missions]
        if set(result["profiles"]) != set(speed.PROFILES):
            parts += [f"--profile {p}" for p in result["profiles"]]
    elif result["bench"] == "mavlink":
        cells = result["cells"]
        for flag, key, every in (("--mission", "mission", mavlink.MISSIONS),
                                 ("--firmware", "firmware", tuple(mavlink.FACES)),
                                 ("--driver", "driver", mavlink.DRIVERS)):
            flown = list(dict.fromkeys(c[key] for c in cells))
            if set(flown) != set(every):
                parts += [f"{flag} {v}" for v in flown]
    elif result.get("quick"):
        parts.append("--quick")
    else:
        parts.append(f"--seeds {result.get('seeds', 1)}")
        if result.get("seed_start", 1) != 1:
            parts.append(f"--seed-start {result['seed_start']}")
        every = SCENARIOS[result["bench"]]
        flown = list(result.get("scenarios") or ())
        if flown and set(flown) != set(every):
            parts += [f"--scenario {s}" for s in flown]
        rows = list(result.get("controllers") or result.get("rows") or ())
        if rows and set(rows) != set(ROWS.get(result["bench"], rows)):
            parts += [f"--row {r}" for r in rows]
    parts += [f"--set {o}" for o in result.get("overrides") or ()]
    return " ".join(parts) + " --json"


#: bench name → its scenarios (all of them: the command names none)
SCENARIOS: dict[str, tuple[str, ...]] = {
    **{name: tuple(b.scenarios) for name, b in follow.BENCHES.items()},
    **{name: tuple(b.scenarios) for name, b in down.BENCHES.items()},
    "offboard": tuple(offboard.SCENARIOS),
}

#: bench name → its rows (controllers; all of them: the command names none)
ROWS: dict[str, tuple[str, ...]] = {
    **{name: tuple(b.controllers) for name, b in follow.BENCHES.items()},
    **{name: tuple(b.rows) for name, b in down.BENCHES.items()},
}

#: bench name → how several of its results (rows or scenarios flown apart) become one
MERGERS: dict[str, Callable[[list[dict]], dict]] = {
    "follow_ball": follow.merge,
    "follow_marker": follow.merge,
    "hover_image": down.merge,
    "land_pad": down.merge,
    "mavlink": mavlink.merge,
}


def _override(result: dict, name: str) -> str | None:
    for item in result.get("overrides") or ():
        key, _, value = item.partition("=")
        if key.strip() == name:
            return value.strip()
    return None


def profile_of(result: dict) -> str | None:
    """The simulated world a result was flown in, when its overrides name it."""
    return _override(result, "sim.profile")


def vehicle_of(result: dict) -> str | None:
    """The simulated vehicle a result was flown on, when its overrides name another firmware
    than the default's."""
    from drivers.sim.firmwares import FIRMWARE_TITLES

    firmware = _override(result, "sim.firmware")
    return None if firmware in (None, "px4") else FIRMWARE_TITLES.get(firmware, firmware)


def _flown(result: dict) -> set[tuple[str, str, int]]:
    """(scenario, row, seed) of every run in a result (the mavlink bench: each cell)."""
    if "cells" in result:
        return {(c["mission"], c["firmware"], c["driver"]) for c in result["cells"]}
    return {(scenario, row, run.get("seed")) for scenario, data in result["scenarios"].items()
            for row, runs in data.get("runs", {}).items() for run in runs}


def render(results: list[dict], note: str = "") -> str:
    lines = ["# Benchmarks", "",
             "Generated by `python -m autopilot.bench.tables` from the benches' `--json` output "
             "(do not edit by hand; run the commands below and generate it again)."]
    if note:
        lines += ["", note]
    lines.append("")
    # one table per bench and set of overrides (e.g. each sensor profile), in input order
    by_bench: dict[tuple[str, tuple[str, ...]], list[dict]] = {}
    for result in results:
        bench = result.get("bench")
        if bench not in FORMATTERS:
            raise ValueError(f"no table for bench {bench!r} (known: {', '.join(FORMATTERS)})")
        # pooled: the same bench and overrides, flown apart (scenarios, rows or seeds in
        # separate processes); a result that would count a seed twice starts a table of its own
        overrides = tuple(result.get("overrides") or ())
        if bench not in MERGERS:
            by_bench[(bench, overrides, len(by_bench))] = [result]
            continue
        flown = _flown(result)
        for n in itertools.count():
            group = by_bench.setdefault((bench, overrides, n), [])
            if not any(flown & _flown(other) for other in group):
                group.append(result)
                break
    for (bench, _, _), group in by_bench.items():
        result = MERGERS[bench](group) if len(group) > 1 else group[0]
        table = FORMATTERS[bench](result)
        world, vehicle = profile_of(result), vehicle_of(result)
        label = ", ".join(x for x in (world and f"{world} world", vehicle) if x)
        if label and table and table[0].startswith("### "):
            table = [f"{table[0]} — {label}", *table[1:]]
        lines += table
        lines += [f"Command: `{command_of(result)}`"
                  + (f" (flown as {len(group)} processes, pooled)"
                     if len(group) > 1 else ""), ""]
    return "\n".join(lines).rstrip() + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m autopilot.bench.tables",
                                     description=__doc__.split("\n\n")[0],
                                     fromfile_prefix_chars="@")
    parser.add_argument("files", nargs="+", type=Path, help="bench --json outputs")
    parser.add_argument("--note", default="", help="a paragraph under the title (the "
                        "machine, its load, what was run)")
    args = parser.parse_args(argv)
    try:
        results = [json.loads(f.read_text()) for f in args.files]
        sys.stdout.write(render(results, args.note))
    except (OSError, ValueError, KeyError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
