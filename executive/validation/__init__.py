"""Checking predictions against physics: campaigns, statistics and the fidelity suite."""
