"""The Parrot AR.Drone 2.0, the seed reports' own drone, spoken to over its SDK 2.0 protocol
directly (no ROS): AT commands to UDP 5556 (:mod:`drivers.ardrone.at`), navdata from UDP 5554
(:mod:`drivers.ardrone.navdata`). Issue 33 builds the driver and the simulated AR.Drone on
these; so far the protocol's encoding and parsing, on both sides."""
