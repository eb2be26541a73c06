"""Risk models: collision, fall, grasp, and their combination."""
