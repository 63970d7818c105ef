"""What a run's decisions add up to (:class:`Tally`, the summary's columns) and where an error a
plugin causes happened (:class:`Blame`), for the decision's pipeline and the dispatcher."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from dispatch.errors import PluginError

if TYPE_CHECKING:
    import simpy


def one_line(e: BaseException, limit: int = 400) -> str:
    """An exception's message on one line, at most ``limit`` characters."""
    text = " ".join(str(e).split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


@dataclass
class Tally:
    """What the run's decisions add up to (the summary's columns of the same names): decisions
    handed out, wall seconds building problems (``cost_seconds``) and in the allocator
    (``decide_seconds``), the allocators' rounds and messages, the simulated seconds spent
    deliberating, re-assignments, the per-agent critical path, the first decision's total
    cost and wall seconds, and with lazy costs the allocator calls and exact pairs."""

    decisions: int = 0
    cost_seconds: float = 0.0
    decide_seconds: float = 0.0
    rounds: int = 0
    messages: int = 0
    comm_delay: float = 0.0  # simulated seconds spent deliberating (hops * latency)
    reassignments: int = 0  # [dispatch] reassign: tasks a vehicle gave up for another
    agent_seconds: float = 0.0  # sum over decisions of the per-agent critical path
    first_cost: float = math.nan  # the first decision's total cost and wall seconds
    first_seconds: float = math.nan
    lazy_rounds: int = 0  # lazy costs: allocator calls (one per certificate round)
    lazy_pairs: int = 0  # lazy costs: pairs whose exact cost was computed


class Blame:
    """Where an error happened, for the messages of the errors a plugin causes: the plugin,
    the run, the decision and the simulated time."""

    def __init__(self, env: simpy.Environment, run_id: str, tally: Tally) -> None:
        self.env, self.run_id, self.tally = env, run_id, tally

    def where(self, kind: str, plugin) -> str:
        """``"<kind> '<name>', run <id>, decision <k>, t = <now> s"``."""
        name = plugin.name or type(plugin).__name__
        run = f", run {self.run_id}" if self.run_id else ""
        return f"{kind} {name!r}{run}, decision {self.tally.decisions}, t = {self.env.now:.6g} s"

    def failed(self, kind: str, plugin, e: Exception) -> PluginError:
        """The error to raise for a plugin's exception: one line naming it and where."""
        reason = one_line(e) or "(no message)"
        return PluginError(f"{self.where(kind, plugin)}: {kind} raised {type(e).__name__}: "
                           f"{reason}")
