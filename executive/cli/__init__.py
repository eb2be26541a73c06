"""The ``executive`` command line."""
