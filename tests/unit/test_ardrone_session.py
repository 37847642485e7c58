"""The navdata handshake and upkeep (drivers/ardrone/session.py) against a scripted drone that
answers as the developer guide's 7.1 describes: bootstrap until it is asked for demo navdata,
the command acknowledgement until the client clears it, the communication watchdog."""

from drivers.ardrone import at, navdata
from drivers.ardrone.navdata import ControlState, Demo, State
from drivers.ardrone.session import CONFIG_RETRY_S, NavdataSession

DEMO = Demo(ControlState.LANDED << 16, 90, 0.0, 0.0, 0.0, 0, 0.0, 0.0, 0.0)


class Drone:
    """Takes AT commands, sends navdata (built and parsed through the real codecs)."""

    def __init__(self, deaf_to_first_config: bool = False) -> None:
        self.demo = False
        self.ack = False
        self.watchdog = False
        self.seq = 0
        self.config: dict[str, str] = {}
        self.ids: tuple = ()
        self.deaf = deaf_to_first_config

    def take(self, datagrams) -> None:
        for datagram in datagrams:
            for cmd in at.parse(datagram):
                if cmd.name == "CONFIG_IDS":
                    self.ids = cmd.args
                elif cmd.name == "CONFIG":
                    if self.deaf:
                        self.deaf = False
                        continue
                    key, value = cmd.args
                    self.config[key] = value
                    self.demo = self.demo or (key == "general:navdata_demo" and value == "TRUE")
                    self.ack = True
                elif cmd.name == "CTRL" and cmd.args[0] == 5:
                    self.ack = False
                elif cmd.name == "COMWDG":
                    self.watchdog = False

    def packet(self):
        self.seq += 1
        state = (State.NAVDATA_DEMO if self.demo else State.NAVDATA_BOOTSTRAP) | \
            (State.COMMAND if self.ack else 0) | (State.COM_WATCHDOG if self.watchdog else 0)
        return navdata.parse(navdata.build(state, self.seq, DEMO if self.demo else None))


def _run(session, drone, packets, t0=0.0, period=1 / 15):
    used = []
    for k in range(packets):
        step = session.on_packet(drone.packet(), t0 + k * period)
        drone.take(step.commands)
        if step.navdata is not None:
            used.append(step.navdata)
    return used


def test_the_handshake_reaches_demo_navdata():
    session, drone = NavdataSession(at.AtCommands()), Drone()
    assert not session.demo
    used = _run(session, drone, 6)
    assert drone.config == {"general:navdata_demo": "TRUE"}
    assert drone.ids == ("00000000", "00000000", "00000000")
    assert not drone.ack  # cleared with CTRL 5
    assert session.demo
    assert used
    assert all(n.demo == DEMO for n in used)


def test_a_lost_config_is_sent_again_and_queued_ones_follow_in_order():
    session, drone = NavdataSession(at.AtCommands()), Drone(deaf_to_first_config=True)
    session.configure("video:video_channel", 1)
    session.configure("control:altitude_max", 3000)
    _run(session, drone, 3)
    assert drone.config == {}  # the first CONFIG was lost; not yet CONFIG_RETRY_S later
    _run(session, drone, int(4 * CONFIG_RETRY_S * 15), t0=1.0)
    assert drone.config == {"general:navdata_demo": "TRUE", "video:video_channel": "1",
                            "control:altitude_max": "3000"}
    assert session.demo


def test_old_packets_are_dropped_and_a_restarted_count_is_taken():
    session = NavdataSession(at.AtCommands())
    build = lambda seq: navdata.parse(navdata.build(State.NAVDATA_DEMO, seq, DEMO))  # noqa: E731
    assert session.on_packet(build(500), 0.0).navdata is not None
    assert session.on_packet(build(499), 0.1).navdata is None  # reordered: older
    assert session.dropped == 1
    assert session.on_packet(build(1), 0.2).navdata is not None  # the drone counts from 1 again
    assert session.restarts == 1
    assert session.on_packet(build(2), 0.3).navdata is not None


def test_the_communication_watchdog_is_answered():
    session, drone = NavdataSession(at.AtCommands()), Drone()
    _run(session, drone, 6)
    drone.watchdog = True
    step = session.on_packet(drone.packet(), 1.0)
    assert any(cmd.name == "COMWDG" for d in step.commands for cmd in at.parse(d))
    drone.take(step.commands)
    assert not drone.watchdog
    assert session.watchdog_resets == 1


def test_the_users_keys_go_after_the_navdata_mode_and_are_waited_for():
    """``link.ardrone_config``'s keys: written once the drone is past the bootstrap, in
    order, each until acknowledged; ``configured`` says when all are."""
    keys = {"control:outdoor": True, "control:euler_angle_max": 0.3}
    session, drone = NavdataSession(at.AtCommands(), configs=keys), Drone()
    assert not session.configured
    _run(session, drone, 2)
    assert not session.configured
    assert session.pending_key in keys
    _run(session, drone, 12, t0=1.0)
    assert session.configured
    assert session.pending_key is None
    assert list(drone.config) == ["general:navdata_demo", "control:outdoor",
                                  "control:euler_angle_max"]
    assert drone.config["control:outdoor"] == "TRUE"
    assert float(drone.config["control:euler_angle_max"]) == 0.3
