"""dispatch: an event-driven multi-vehicle task allocation simulator.

The kernel: scenario loading, world, vehicles, tasks, SimPy processes, the allocator and
planner contracts, the plugin registry, Parquet recording and the CLI. It imports no concrete
allocator or planner; those are found through the registry (``dispatch.api.registry``).
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("dispatch-sim")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0.0.0+unknown"

__all__ = ["__version__"]
