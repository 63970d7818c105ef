"""How runs are compared, shared by the ``dispatch`` CLI's tables and the ``analysis`` package
(neither imports the other): :mod:`paired.compare` (allocator order, paired gap, run keys'
defaults, batch-window labels), :mod:`paired.per_task` (a run's per-task figures) and
:mod:`paired.stats` (Student-t intervals of a mean). Standard library only."""
