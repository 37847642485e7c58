"""The drivers a configuration can name (``driver``), registered here and nowhere else: each
builds its :class:`~drivers.base.Vehicle` from a validated plan, checks its ``--connect`` URL
before anything opens, and says which vehicle family it flies (whose configuration overlay,
``autopilot/vehicles/FAMILY.yaml``, is laid over ``config.yaml``: the vehicle's cameras,
limits and simulated airframe).

==========  =======  ==========================================================================
driver      family   what it flies
==========  =======  ==========================================================================
sim         (its     the MuJoCo simulator in process, running the firmware ``sim.firmware``
            sim's)   names
mavsdk      px4      a PX4 (or other MAVLink) vehicle through MAVSDK
pymavlink   px4      the same through pymavlink
ardrone     ardrone  a Parrot AR.Drone 2.0 over its SDK protocol (``ardrone://HOST``)
==========  =======  ==========================================================================

This module is light (no driver is imported until one is built): the configuration's model
takes its names from :data:`DRIVER_NAMES`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from autopilot.mission import MissionPlan


@dataclass(frozen=True, slots=True)
class DriverKind:
    """A driver: how it is built (``build(plan, realtime=, connect=, video=, calibration=,
    signing_key=, warn=)`` → (vehicle, the simulator's seed or None)), how its ``--connect``
    URL is checked (``check_connect(option, url, signing_key, insecure)``, raising the
    configuration's input errors), the family it flies (None: the simulator's firmware says),
    and its default connection (the configuration key that holds it)."""

    name: str
    build: Callable[..., tuple[Any, int | None]]
    family: str | None
    check_connect: Callable[[str, str, str | None, bool], None] | None = None
    default_connect: Callable[[Any], str] | None = None
    summary: str = ""
    #: ``autopilot doctor``'s checks of a connected vehicle (see :mod:`autopilot.doctor`)
    doctor: Callable[..., Any] | None = None

    @property
    def simulated(self) -> bool:
        return self.check_connect is None


def _build_sim(plan: MissionPlan, **kwargs):
    from autopilot.run import make_sim_vehicle

    return make_sim_vehicle(plan, **kwargs)


def _build_mavsdk(plan: MissionPlan, **kwargs):
    from autopilot.run import make_mavlink_vehicle
    from drivers.mavlink.mavsdk_driver import MavsdkDriver

    return make_mavlink_vehicle(plan, MavsdkDriver, **kwargs)


def _build_pymavlink(plan: MissionPlan, **kwargs):
    from autopilot.run import make_mavlink_vehicle
    from drivers.mavlink.pymavlink_driver import PymavlinkDriver

    return make_mavlink_vehicle(plan, PymavlinkDriver, **kwargs)


def _build_ardrone(plan: MissionPlan, **kwargs):
    from autopilot.run import make_ardrone_vehicle

    return make_ardrone_vehicle(plan, **kwargs)


async def _doctor_mavlink(*args, **kwargs):
    from autopilot.doctor import mavlink_checks

    await mavlink_checks(*args, **kwargs)


async def _doctor_ardrone(*args, **kwargs):
    from autopilot.doctor import ardrone_checks

    await ardrone_checks(*args, **kwargs)


def _check_mavlink(option: str, url: str, key: str | None, insecure: bool) -> None:
    from autopilot.cli.run import check_network_exposure

    check_network_exposure(option, url, key, insecure)


def _check_ardrone(option: str, url: str, key: str | None, insecure: bool) -> None:
    from autopilot.api import is_loopback
    from autopilot.config import ConfigError, Problem
    from drivers.ardrone.urls import ArdroneUrlError, parse_ardrone_url

    try:
        address = parse_ardrone_url(url)
    except ArdroneUrlError as exc:
        raise ConfigError([Problem("command line", None, option, str(exc))]) from None
    if key:
        raise ConfigError([Problem("command line", None, "--signing-key",
                                   "the AR.Drone's protocol has no signing")])
    if is_loopback(address.host) or insecure:
        return
    raise ConfigError([Problem("command line", None, option, (
        f"{url}: the AR.Drone 2.0's protocol has no authentication (anyone on its Wi-Fi can "
        "fly it): give --insecure to fly it over a network, on the drone's own Wi-Fi"))])


#: the drivers by name, in the order the command line lists them
DRIVER_KINDS: dict[str, DriverKind] = {kind.name: kind for kind in (
    DriverKind("sim", _build_sim, None, summary="the simulator, in process"),
    DriverKind("mavsdk", _build_mavsdk, "px4", _check_mavlink,
               lambda config: config.link.connect, "a MAVLink vehicle through MAVSDK",
               _doctor_mavlink),
    DriverKind("pymavlink", _build_pymavlink, "px4", _check_mavlink,
               lambda config: config.link.connect, "a MAVLink vehicle through pymavlink",
               _doctor_mavlink),
    DriverKind("ardrone", _build_ardrone, "ardrone", _check_ardrone,
               lambda config: config.link.connect,
               "a Parrot AR.Drone 2.0 over its SDK protocol", _doctor_ardrone),
)}
DRIVER_NAMES = tuple(DRIVER_KINDS)


def driver_kind(name: str) -> DriverKind:
    return DRIVER_KINDS[name]
