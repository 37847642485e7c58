"""Where the project's data files are: in the clone, or inside the installed package."""

from __future__ import annotations

from pathlib import Path

_HERE = Path(__file__).resolve().parent


def _find(name: str) -> Path:
    for candidate in (_HERE.parent / name, _HERE / "_resources" / name):
        if candidate.exists():
            return candidate
    raise FileNotFoundError(
        f"{name} not found next to {_HERE} nor inside the installed package; "
        "reinstall the project (pip install .)"
    )


def default_config_path() -> Path:
    return _find("config.yaml")


def missions_dir() -> Path:
    return _find("missions")


def profile_path(name: str) -> Path | None:
    """The overlay of simulation profile ``name`` (``sim.profile``), or None: that profile is
    ``config.yaml`` as it stands."""
    path = _HERE / "profiles" / f"{name}.yaml"
    return path if path.exists() else None


def vehicle_path(name: str) -> Path | None:
    """The overlay of vehicle family ``name`` (``sim.firmware``, a driver's family), or None:
    no such family (validation says so where the name was written)."""
    if not name.isidentifier():
        return None
    path = _HERE / "vehicles" / f"{name}.yaml"
    return path if path.exists() else None
