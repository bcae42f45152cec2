"""Worlds by scenario kind. A world owns the ground truth of one run and offers the coordinator:
``positions()``, ``observations()``, ``apply(actions)``, ``draw_losses()``, ``kill(i)``,
``finished``, ``tick``/``time``/``alive``, and ``row()`` / ``summary()`` / ``per_agent()`` for results."""

from __future__ import annotations

import numpy as np

from swarmbed.coordinator.mtsr import MTSRWorld
from swarmbed.coordinator.sar import SARWorld
from swarmbed.experiments.config import Experiment, MTSRScenario
from swarmbed.plugins import resolve


def make_world(exp: Experiment, rng: np.random.Generator) -> MTSRWorld | SARWorld:
    if isinstance(exp.scenario, MTSRScenario):
        return MTSRWorld(exp, rng)
    return SARWorld(exp, rng, bids_with_colors=resolve(exp.allocator.name, "sar").bids_with_colors)
