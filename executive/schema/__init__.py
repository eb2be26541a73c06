"""What a scenario can say: its typed values, their ranges, the YAML readers, the bundled catalog."""
