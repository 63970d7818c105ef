"""planners plugins."""
