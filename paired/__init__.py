"""How runs are compared, shared by the ``dispatch`` CLI's tables and the ``analysis`` package
(neither imports the other): :mod:`paired.compare`. Standard library only."""
