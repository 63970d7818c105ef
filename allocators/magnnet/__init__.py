"""MAGNNET (Ratnabala et al. 2025): decentralized task allocation with a GNN policy per agent,
trained with PPO under centralized training / decentralized execution.

Modules, in reading order:

* :mod:`~allocators.magnnet.rules` — the allocation game and the reward shaping;
* :mod:`~allocators.magnnet.problems` — training and evaluation instances, drawn exactly as
  real runs draw them (world, fleet, tasks, A* costs), cached;
* :mod:`~allocators.magnnet.game` — the game for one instance (numpy) and batched (torch);
* :mod:`~allocators.magnnet.env` — the PettingZoo ``ParallelEnv``;
* :mod:`~allocators.magnnet.model` — the paper's network;
* :mod:`~allocators.magnnet.match` — MAGNNET-match: a size-agnostic agent-task graph
  network trained to imitate the optimal assignment, with mutual-best requests;
* :mod:`~allocators.magnnet.views` — the view model for partial views (limited range), trained
  CTDE with DAgger against the optimal assignment of the whole remaining problem;
* :mod:`~allocators.magnnet.ppo` — the one PPO trainer (CTDE), GAE, checkpoints; its
  training environments in :mod:`~allocators.magnnet.ppo_env` (the paper's game, the
  plugin's decision rounds), the imitation warm start in :mod:`~allocators.magnnet.ppo_warm`;
* :mod:`~allocators.magnnet.train` — ``dispatch train magnnet``;
* :mod:`~allocators.magnnet.allocator` — the ``magnnet`` plugin (variants ``match``,
  ``paper``, ``paper_nb``).

torch is imported by the modules that need it, never by the kernel.
"""
