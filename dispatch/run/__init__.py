"""The wiring on top: one run's simulation, the runner and sweeps, plugin construction, time limits,
progress and the command line."""
