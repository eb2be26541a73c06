"""Robot profiles: what the executive needs to know about a robot beyond its MJCF."""
