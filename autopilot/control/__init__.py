"""Control laws turning estimates into setpoints (synchronous)."""
