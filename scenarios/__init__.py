"""Bundled scenarios and robot models (installed as ``executive.bundled``)."""
