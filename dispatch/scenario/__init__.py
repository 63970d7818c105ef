"""Scenario files read once into the typed configuration: the TOML reader, its sections,
command-line
overrides and the work budget."""
