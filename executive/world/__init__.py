"""The MuJoCo world built from a scenario (estimate or truth), and the geometry of standing in it."""
