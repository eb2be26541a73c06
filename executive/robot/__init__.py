"""The robot: its profile, the bundled simulation of it, and the interface to a host's own robot."""
