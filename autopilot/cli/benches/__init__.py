"""The benches of ``autopilot bench``: each module exports ``BENCHES``, a tuple of
:class:`~autopilot.cli.common.Command` (found by :func:`autopilot.cli.bench.benches`)."""
