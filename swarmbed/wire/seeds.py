"""The run's random streams: every component draws from a child of the run seed, so the same seed
gives the same run however the processes are placed.

``SeedSequence(run seed).spawn(3)`` gives the world's (the coordinator's scenario), the netem
proxy's and the agents' sequences, in that order; the agents' spawns one sequence per agent, and
each agent's spawns as many as its parts need (runtime, allocator, ...). The radio spawns its
models' streams from the proxy's (``swarmbed.netem.radio``).
"""

from __future__ import annotations

import numpy as np

# SeedSequence children of the run seed, one per component; agents get their own sub-tree.
WORLD, NETEM, AGENTS = range(3)


def component_rng(seed: int, component: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence(seed).spawn(3)[component])


def agent_seeds(seed: int, agent_id: int, n_agents: int, parts: int) -> list[np.random.SeedSequence]:
    """``parts`` independent seed sequences for one agent (runtime, allocator, ...)."""
    if not 0 <= agent_id < n_agents:
        raise ValueError(f"agent {agent_id} is not one of {n_agents} agents")
    agents = np.random.SeedSequence(seed).spawn(3)[AGENTS]
    # the agent_id-th child of ``agents.spawn(n_agents)``, made alone: spawning all n children for
    # each of n agents (the in-process engine makes every agent) cost O(n^2), 4.6 s at 1,000 agents
    own = np.random.SeedSequence(agents.entropy, spawn_key=(*agents.spawn_key, agent_id), pool_size=agents.pool_size)
    return own.spawn(parts)
