"""Pictures and tables of decisions and worlds."""
