"""Shared fixtures: the configuration, loaded once per session.

``app_config`` / ``sim_config`` are the shipped configuration in the **ideal** world
(``sim.profile=ideal``: RTK-grade navigation, the camera's true calibration, no dropped
frames): the simulator's and the detectors' geometry tests compare renders and responses
against truth to the pixel or the centimetre, which the realistic world's fitted calibrations
and GNSS wander would blur. Tests of the realistic world (the shipped default) use
``realistic_app_config`` / ``realistic_sim_config``, and missions flown through
``load_mission`` get the default unless a test pins ``sim.profile=ideal`` itself."""

from __future__ import annotations

import os
import tempfile

import pytest

from autopilot.config import AppConfig, load_config

# the benches' flight times (autopilot.bench.schedule) go to a file of the test session's, not
# to the user's cache (the tests' flights, on a machine shared by the workers, would make the
# user's estimates wrong); workers and the processes they start inherit it
os.environ.setdefault("AUTOPILOT_FLIGHT_TIMES", os.path.join(
    tempfile.mkdtemp(prefix="autopilot-test-times-"), "flight_times.json"))

#: what the geometry tests pin (see the module's docstring)
IDEAL = ("sim.profile=ideal",)


@pytest.fixture(scope="session")
def app_config() -> AppConfig:
    return load_config(overrides=IDEAL)


@pytest.fixture(scope="session")
def realistic_app_config() -> AppConfig:
    """The shipped configuration as it flies by default (the realistic world)."""
    config = load_config()
    assert config.sim.profile == "realistic"
    return config


@pytest.fixture(scope="session")
def realistic_sim_config(realistic_app_config):
    return realistic_app_config.sim


@pytest.fixture(scope="session")
def sim_config(app_config):
    return app_config.sim


def sim_with(sim_config, **changes):
    """A copy of the simulator configuration with dotted-path changes, e.g.
    ``sim_with(cfg, **{"wind.gust_mps": 2.0})``."""
    data = sim_config.model_dump()
    for dotted, value in changes.items():
        target = data
        *parents, last = dotted.split(".")
        for part in parents:
            target = target[part]
        target[last] = value
    return type(sim_config).model_validate(data)


@pytest.fixture(scope="session")
def no_camera_config(sim_config):
    """The simulator configuration with both cameras disabled (nothing renders)."""
    cams = {k: v.model_copy(update={"enabled": False}) for k, v in sim_config.cameras.items()}
    return sim_config.model_copy(update={"cameras": cams})


# -- Hypothesis: bounded in CI; `pytest --hypothesis-profile=long` runs the long fuzzing -----

from hypothesis import settings as _hypothesis_settings  # noqa: E402

_hypothesis_settings.register_profile("ci", max_examples=60, deadline=None, derandomize=True,
                                      print_blob=True)
_hypothesis_settings.register_profile("long", max_examples=3000, deadline=None,
                                      print_blob=True)
_hypothesis_settings.load_profile("ci")


# -- long suites: real-time flights of external clients, soak and long profiles --------------

def pytest_addoption(parser):
    parser.addoption("--run-long", action="store_true", default=False,
                     help="also run the long cases: real-time flights of MAVSDK's mission, "
                          "offboard and MAVProxy examples end to end, and the heavier closed "
                          "loops (following under stress, precision landing without a target, "
                          "the doctor on two camera streams): several minutes")


@pytest.hookimpl(trylast=True)  # (after pytest's faulthandler plugin)
def pytest_configure(config):
    _crash_dump_current_thread_only(config)
    config.addinivalue_line("markers", "long: a long case (a real-time flight, a heavy closed "
                            "loop); runs with --run-long")
    config.addinivalue_line("markers", "serial: runs on the wall clock, measures time or "
                            "listens on fixed ports: with pytest-xdist (-n), the modules that "
                            "mark it run one test at a time in one worker while the lockstep "
                            "tests share the others (set it as the module's pytestmark)")


def pytest_xdist_auto_num_workers(config):
    """``-n auto``: a worker per core for the lockstep tests, which keep their cores busy, and
    one more for the serial group, whose real-time flights spend most of their time waiting on
    the wall clock (they are built to keep their timing on a busy machine)."""
    import os

    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return (cores or 1) + 1


def pytest_xdist_make_scheduler(config, log):
    """With ``-n`` (``--dist load``, the default): each test is its own unit of work, except
    the modules that mark tests ``serial`` (``pytestmark = pytest.mark.serial``), which are one
    unit together, run in one worker one test at a time, while the other workers take the
    lockstep tests. (xdist's own ``--dist loadgroup`` cannot do it under pytest ≥ 9.2: the
    group it writes into a test's node id no longer reaches the scheduler.)"""
    if config.getvalue("dist") != "load":
        return None
    from pathlib import Path

    from xdist.scheduler import LoadScopeScheduling

    root = Path(config.rootpath)
    serial = {str(path.relative_to(root)) for path in (root / "tests").rglob("test_*.py")
              if "pytest.mark.serial" in path.read_text(encoding="utf-8")}

    class SerialGroupScheduling(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return "serial" if nodeid.split("::", 1)[0] in serial else nodeid

    return SerialGroupScheduling(config, log)


def _crash_dump_current_thread_only(config) -> None:
    """A crash (a segfault in native code) prints the stack of the thread that crashed only:
    with every thread's (pytest's default) a worker's dump is long enough for the lines that
    matter to be cut from a CI log."""
    import faulthandler

    try:
        from _pytest.faulthandler import fault_handler_stderr_fd_key  # (pytest's own fd)
        fd = config.stash[fault_handler_stderr_fd_key]
    except (ImportError, KeyError):
        return
    faulthandler.enable(file=fd, all_threads=False)


def pytest_collection_modifyitems(config, items):
    if config.getoption("--run-long"):
        for item in items:  # longer than a CI case may take
            if "long" in item.keywords and item.get_closest_marker("timeout") is None:
                item.add_marker(pytest.mark.timeout(900))
        return
    skip = pytest.mark.skip(reason="long case: run with --run-long (the default run keeps "
                                   "CI short; a shorter sibling covers the same code)")
    for item in items:
        if "long" in item.keywords:
            item.add_marker(skip)
