"""A scenario's typed configuration: frozen dataclasses, data only (no behaviour), each default
written once."""
