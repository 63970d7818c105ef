"""How runs are compared, shared by the ``dispatch`` CLI's tables and the ``analysis`` package
(neither imports the other): :mod:`paired.compare` (allocator order, paired gap, run keys'
defaults, batch-window labels), :mod:`paired.per_task` (a run's per-task figures),
:mod:`paired.stats` (Student-t intervals of a mean) and :mod:`paired.voxel_bodies` (the voxel
world's PyBullet bodies, for the run's mirror and its pictures). Standard library only (PyBullet
imported by :func:`paired.voxel_bodies.import_pybullet` when called)."""
