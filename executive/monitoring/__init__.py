"""Watching execution: failure detectors and the live risk guards."""
