"""Running a plan on a robot: the bundled simulated robot, a host's robot, one-shot execution."""
