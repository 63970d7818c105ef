"""``fixed``: the fleet the start file (or ``[fleet] agents``) gives, on duty by its shifts."""

from __future__ import annotations

from dispatch.api.sizer import Sizer, SizingView


class FixedSizer(Sizer):
    """The fleet as given: every vehicle on duty over its shift (the default)."""

    name = "fixed"
    passive = True

    def size(self, view: SizingView) -> int:
        return view.on_duty
