"""learning: reinforcement learning and value learning beside the simulator kernel.

The environments over the simulator's decisions (:mod:`learning.rl`: Gymnasium and
PettingZoo), the learned value of where a vehicle ends up and its trainer
(:mod:`learning.value`, with its zones, :mod:`learning.zones`), and allocation instances drawn
as a run draws them (:mod:`learning.instances`). It uses the kernel (``dispatch``) through its
public modules only; the kernel imports nothing of it. Plugins use it (``hungarian``'s
``value`` option) and ``dispatch train`` finds its trainers through the ``dispatch.trainers``
entry points.
"""
