"""Choosing what to run: assessment of alternatives, the risk-gated selector, approval, the audit log."""
