"""Benchmarks that users run (``autopilot bench ...``): speed and accuracy targets are checked
here, with real numbers from this machine, never by timed tests."""
