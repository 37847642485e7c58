"""Where the simulator's data files are: in the clone, or inside the installed package."""

from __future__ import annotations

from pathlib import Path

_HERE = Path(__file__).resolve().parent


def sim_models_dir() -> Path:
    """``sim_models/`` of the clone (editable install, running from source) or of the wheel."""
    for candidate in (_HERE.parent / "sim_models", _HERE / "_resources" / "sim_models"):
        if candidate.is_dir():
            return candidate
    raise FileNotFoundError(
        f"sim_models/ not found next to {_HERE} nor inside the installed package; "
        "reinstall the project (pip install .)"
    )


def sim_model_path(name: str) -> Path:
    """Path of a model file named in the configuration (relative to ``sim_models/``)."""
    path = Path(name)
    if not path.is_absolute():
        path = sim_models_dir() / path
    if not path.is_file():
        raise FileNotFoundError(f"simulation model {name!r} not found (looked at {path})")
    return path
