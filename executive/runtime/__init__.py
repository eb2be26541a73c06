"""Running a mission: the embeddable Executive."""
