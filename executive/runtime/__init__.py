"""Running a mission: the embeddable Executive and one-shot execution of a plan."""
