"""The Parrot AR.Drone 2.0, the seed reports' own drone, spoken to over its SDK 2.0 protocol
directly (no ROS): AT commands to UDP 5556 (:mod:`drivers.ardrone.at`), navdata from UDP 5554
(:mod:`drivers.ardrone.navdata`, :mod:`~drivers.ardrone.session`), PaVE H.264 video from TCP
5555 (:mod:`~drivers.ardrone.pave`, :mod:`~drivers.ardrone.video`), its configuration over TCP
5559 (:mod:`~drivers.ardrone.config`); the driver (:mod:`~drivers.ardrone.driver`). The codecs
serve both sides: the driver's and the simulated drone's (:mod:`drivers.sim.ardrone_face`)."""
