"""A centralized leader that lies (tests/test_central_lies.py): agent 0, while it leads, sends every
other agent after a task no run has, a fresh id each time, somewhere in the arena."""

from swarmbed.plugins.central import SGA

PHANTOM = 1_000_000


class LyingLeader(SGA):
    def _plan(self, agents, speed):
        if self.agent_id != 0:
            return super()._plan(agents, speed)
        now = max((t for *_, t in self.tasks.values()), default=0.0)
        plan = {}
        for a in sorted(agents):
            if a != self.agent_id:
                phantom = PHANTOM + 1000 * int(now) + a
                self.tasks[phantom] = (float(self.rng.uniform(0, 200)), float(self.rng.uniform(0, 150)), 1.0, now)
                plan[a] = phantom
        self.plan = plan
        return plan
