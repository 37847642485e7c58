"""Where the process's log messages go: the run's ``autopilot.log``, and the terminal.

The terminal shows what a person watching needs (our warnings and errors, the progress lines
the CLI prints itself); the file keeps everything, including the chatter of the libraries we
drive — MAVSDK's C++ core (which would otherwise print its own coloured lines on stderr) and
FFmpeg (through PyAV) — which reaches the terminal only with ``--verbose``.
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path

#: Loggers of other people's code that stay out of the terminal unless --verbose.
LIBRARY_LOGGERS = ("mavsdk", "libav", "OpenGL", "py.warnings")
LOG_FILE = "autopilot.log"
_FORMAT = "%(asctime)s.%(msecs)03d %(levelname)-7s %(name)s: %(message)s"


class _NotLibraries(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        return not record.name.startswith(LIBRARY_LOGGERS)


def setup_logging(out_dir: Path | None, *, verbose: bool = False) -> Path | None:
    """Log to ``out_dir/autopilot.log`` (everything, INFO and up; DEBUG with ``verbose``) and
    to stderr (our warnings; everything from INFO with ``verbose``). Returns the file's path."""
    root = logging.getLogger()
    for handler in list(root.handlers):
        if getattr(handler, "_autopilot", False):
            root.removeHandler(handler)
            handler.close()
    root.setLevel(logging.DEBUG if verbose else logging.INFO)
    console = logging.StreamHandler(sys.stderr)
    console.setLevel(logging.INFO if verbose else logging.WARNING)
    console.setFormatter(logging.Formatter("%(levelname)s %(name)s: %(message)s"))
    if not verbose:
        console.addFilter(_NotLibraries())
    console._autopilot = True  # type: ignore[attr-defined]
    root.addHandler(console)
    path = None
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
        path = out_dir / LOG_FILE
        file = logging.FileHandler(path)
        file.setFormatter(logging.Formatter(_FORMAT, "%H:%M:%S"))
        file._autopilot = True  # type: ignore[attr-defined]
        root.addHandler(file)
    logging.captureWarnings(True)  # libraries' warnings.warn() (GLFW's, say) into the log
    route_library_logs()
    return path


def route_library_logs() -> None:
    """Send MAVSDK's and FFmpeg's own messages into Python logging (loggers ``mavsdk`` and
    ``libav.*``) instead of straight to stderr."""
    try:
        import av.logging

        av.logging.set_level(av.logging.WARNING)
    except ImportError:  # pragma: no cover - PyAV is a dependency
        pass
    try:
        from mavsdk.logging import LogLevel, log_subscribe
    except ImportError:  # pragma: no cover - mavsdk is a dependency
        return
    logger = logging.getLogger("mavsdk")
    levels = {LogLevel.DEBUG: logging.DEBUG, LogLevel.INFO: logging.INFO,
              LogLevel.WARN: logging.WARNING, LogLevel.ERROR: logging.ERROR}

    def forward(level, message, file, line) -> bool:
        logger.log(levels.get(level, logging.INFO), "%s (%s:%s)", message, file, line)
        return True  # and not on stderr

    log_subscribe(forward)
