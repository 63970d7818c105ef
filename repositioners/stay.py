"""The ``stay`` repositioner: idle vehicles wait where they are (the default)."""

from __future__ import annotations

from collections.abc import Mapping

from dispatch.api.repositioner import Repositioner, RepositionView


class StayRepositioner(Repositioner):
    """Idle vehicles wait where they are (the default; the kernel never calls it)."""

    name = "stay"
    spaces = ("voxel", "road")
    passive = True

    def reposition(self, view: RepositionView) -> Mapping[int, int]:
        """No moves, ever."""
        return {}
