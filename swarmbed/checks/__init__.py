"""Checkers for extension authors, in one public place (as PettingZoo ships ``pettingzoo.test``):
:func:`check_scenario` drives a scenario's world with random actions and checks its contract;
the allocator conformance kit (:func:`run_all`, :func:`check_snapshot`) runs an allocator
in-process on static instances with the real radio model. ``swarmbed check-scenario`` and
``swarmbed check-allocator`` run them from the command line."""

from swarmbed.checks.allocator_kit import ConformanceError, check_snapshot, run_all
from swarmbed.checks.scenario_check import ScenarioCheckError, check_scenario

__all__ = ["ConformanceError", "ScenarioCheckError", "check_scenario", "check_snapshot", "run_all"]
