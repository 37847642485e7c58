"""Where an AR.Drone 2.0 is: ``ardrone://HOST[:PORT]`` (the drone's own address on its Wi-Fi is
192.168.1.1), and its four ports. ``PORT`` is the navdata port when the drone's ports are not
the SDK's (another simulated drone on the same host: ``autopilot sim --firmware ardrone
--instance N`` moves all four by 10 N)."""

from __future__ import annotations

import ipaddress
import re
from dataclasses import dataclass

#: the drone's address on its own Wi-Fi network
DEFAULT_HOST = "192.168.1.1"
DEFAULT_URL = f"ardrone://{DEFAULT_HOST}"

_URL = re.compile(r"ardrone://(?P<host>\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9.\-]+)(?::(?P<port>\d+))?/?$")


class ArdroneUrlError(ValueError):
    """Not an ``ardrone://`` URL."""


@dataclass(frozen=True, slots=True)
class ArdronePorts:
    """The drone's ports (the SDK's: navdata 5554, video 5555, AT 5556, configuration 5559)."""

    navdata: int = 5554
    video: int = 5555
    at: int = 5556
    config: int = 5559

    def offset(self, by: int) -> ArdronePorts:
        """All four moved by ``by``."""
        return ArdronePorts(self.navdata + by, self.video + by, self.at + by, self.config + by)


@dataclass(frozen=True, slots=True)
class ArdroneAddress:
    host: str
    ports: ArdronePorts = ArdronePorts()

    @property
    def url(self) -> str:
        port = "" if self.ports == ArdronePorts() else f":{self.ports.navdata}"
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"ardrone://{host}{port}"


def parse_ardrone_url(url: str) -> ArdroneAddress:
    """The drone's host and ports from ``ardrone://HOST[:NAVDATA_PORT]``."""
    match = _URL.match(url.strip())
    if match is None:
        raise ArdroneUrlError(f"{url!r}: expected ardrone://HOST or ardrone://HOST:PORT (the "
                              f"drone on its own Wi-Fi: {DEFAULT_URL})")
    host = match["host"].strip("[]")
    if ":" in host:
        try:
            ipaddress.ip_address(host)
        except ValueError:
            raise ArdroneUrlError(f"{url!r}: {host!r} is not an IP address") from None
    ports = ArdronePorts()
    if match["port"] is not None:
        navdata = int(match["port"])
        if not 1 <= navdata <= 65535 - 5:
            raise ArdroneUrlError(f"{url!r}: port {navdata} out of range (1-65530)")
        ports = ports.offset(navdata - ports.navdata)
    return ArdroneAddress(host, ports)
