"""MAVLink: PX4 conventions, the simulator's MAVLink face, and (later) the MAVLink drivers."""
