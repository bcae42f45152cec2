"""The agent's task table, rebuilt only where rows changed, equals a full rebuild at every tick."""

import numpy as np

from swarmbed.agent_runtime.runtime import AgentRuntime
from swarmbed.config import resolve_experiment
from swarmbed.extension.view import TaskInfo
from swarmbed.schema.experiment import agent_spec
from swarmbed.wire.codec import TASK_DTYPE
from tests.conftest import experiment


def _full(table):
    return {t[0]: t for t in map(TaskInfo._make, table.tolist())}


def test_the_incremental_task_table_equals_a_full_rebuild_at_every_tick():
    exp = experiment("agents.count=2")
    runtime = AgentRuntime(agent_spec(exp, resolve_experiment(exp).targets), 0)
    rng = np.random.default_rng(1)
    table = np.zeros(6, dtype=TASK_DTYPE)
    table["id"] = np.arange(6)
    table["x"] = rng.random(6)
    seen_kinds = set()
    for tick in range(400):
        table = table.copy()
        kind = rng.integers(6)
        seen_kinds.add(int(kind))
        if kind == 0 and len(table):  # a task worked
            table["remaining"][rng.integers(len(table))] -= 1.0
        elif kind == 1 and len(table):  # one leaves the view
            table = np.delete(table, rng.integers(len(table)))
        elif kind == 2:  # one comes into view
            row = np.zeros(1, dtype=TASK_DTYPE)
            row["id"], row["x"] = 100 + tick, rng.random()
            table = np.concatenate([table, row])
        elif kind == 3 and len(table) > 1:  # a repeated id (a crafted table): the last row wins, as in full
            table["id"][0] = table["id"][1]
        elif kind == 4 and len(table):  # a signed zero: bytes differ, values compare equal
            table["y"][0] = -table["y"][0] if table["y"][0] == 0 else 0.0
        view = runtime._tasks_in_view(table)
        expected = _full(table)
        assert view == expected and list(view) == list(expected), tick
        assert [str(v) for v in view.values()] == [str(v) for v in expected.values()], tick  # -0.0 too
        view.clear()  # a plugin may change its copy: the next tick must not see it
    assert seen_kinds == set(range(6))
