"""``dispatch bench``: a fixed, versioned suite of robot-team and city-fleet instances on which
allocators are compared with the shipped baselines (see ``docs/howto/bench.md``).

Above the kernel: registered as a command through the ``dispatch.commands`` entry point; the
kernel ``dispatch`` imports nothing of it."""
