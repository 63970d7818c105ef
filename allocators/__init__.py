"""allocators plugins."""
