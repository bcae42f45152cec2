"""A scenario whose agents send actions it does not declare: MT-SR with exploration waypoints that
are not numbers, so that every exploring agent sends ``["goto", nan, nan]`` each tick."""

import math

from swarmbed.scenarios.mtsr import MTSR


class NaNWaypoints(MTSR):
    def random_point(self, rng):
        return (math.nan, math.nan)
