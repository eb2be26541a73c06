"""py_trees task-level behaviours for the risk-gated executive."""
