"""Shared fixtures: the shipped configuration, loaded once per session."""

from __future__ import annotations

import pytest

from autopilot.config import AppConfig, load_config


@pytest.fixture(scope="session")
def app_config() -> AppConfig:
    return load_config()


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
