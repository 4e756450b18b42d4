"""Parking by switching travel direction and gain (spec: parking-time-state.md)."""
