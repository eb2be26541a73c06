"""Whole-body motion planning with mink: hand targets to joint trajectories, within the robot's limits."""
