"""Run one XML tree in our engine and in BehaviorTree.CPP (behaviortreepy) with scripted leaves.

Leaves: ``<Act name=..>`` (stateful action) and ``<Cond name=..>`` (condition). Each leaf name has a
script of statuses, consumed one per call (the last one repeats). Both runs record the same event
log (start / running / halted / cond, with the leaf name) and the root status after each tick.
"""

from __future__ import annotations

import random

from swarmbed.bt import Condition, NodeRegistry, StatefulAction, Status, load_tree


class Script:
    def __init__(self, scripts: dict[str, list[str]]) -> None:
        self.scripts = {k: list(v) for k, v in scripts.items()}
        self.log: list[tuple[str, str]] = []

    def next(self, name: str) -> str:
        seq = self.scripts[name]
        return seq.pop(0) if len(seq) > 1 else seq[0]


class Act(StatefulAction):
    ID = "Act"

    def on_start(self):
        self.config.context.log.append(("start", self.name))
        return Status[self.config.context.next(self.name)]

    def on_running(self):
        self.config.context.log.append(("running", self.name))
        return Status[self.config.context.next(self.name)]

    def on_halted(self):
        self.config.context.log.append(("halted", self.name))


class Cond(Condition):
    ID = "Cond"

    def tick(self):
        self.config.context.log.append(("cond", self.name))
        return Status[self.config.context.next(self.name)]


def run_ours(xml: str, scripts: dict[str, list[str]], ticks: int):
    script = Script(scripts)
    registry = NodeRegistry()
    registry.register(Act)
    registry.register(Cond)
    tree = load_tree("<test>", registry, text=xml, context=script)
    trace = []
    for _ in range(ticks):
        status = tree.tick_once()
        trace.append((status.name, tuple(script.log)))
        script.log.clear()
    tree.halt()
    trace.append(("HALT", tuple(script.log)))
    return trace, tree.blackboard


def btcpp_tree(xml: str, scripts: dict[str, list[str]]):
    """The tree of ``xml`` built by BehaviorTree.CPP with the scripted leaves (statuses only: no
    event log), its main tree as the file names it."""
    import xml.etree.ElementTree as ET

    import behaviortreepy as bt

    script = Script(scripts)
    factory = bt.BehaviorTreeFactory()

    def status(node):
        return getattr(bt.NodeStatus, script.next(node.name()))

    factory.register_simple_stateful_action("Act", status, status, lambda node: None)
    factory.register_simple_condition("Cond", status)
    factory.register_behavior_tree_from_text(xml)
    root = ET.fromstring(xml)
    return factory.create_tree(root.get("main_tree_to_execute") or root.find("BehaviorTree").get("ID"))


def run_btcpp(xml: str, scripts: dict[str, list[str]], ticks: int):
    import behaviortreepy as bt

    script = Script(scripts)
    factory = bt.BehaviorTreeFactory()

    def status(name):
        return getattr(bt.NodeStatus, script.next(name))

    def on_start(node):
        script.log.append(("start", node.name()))
        return status(node.name())

    def on_running(node):
        script.log.append(("running", node.name()))
        return status(node.name())

    def on_halted(node):
        script.log.append(("halted", node.name()))

    def cond(node):
        script.log.append(("cond", node.name()))
        return status(node.name())

    factory.register_simple_stateful_action("Act", on_start, on_running, on_halted)
    factory.register_simple_condition("Cond", cond)
    tree = factory.create_tree_from_text(xml)
    trace = []
    for _ in range(ticks):
        s = tree.tick_exactly_once()
        trace.append((s.name, tuple(script.log)))
        script.log.clear()
    tree.halt_tree()
    trace.append(("HALT", tuple(script.log)))
    return trace, tree


CONTROLS = ["Sequence", "Fallback", "ReactiveSequence", "ReactiveFallback", "Parallel"]
DECORATORS = ["Inverter", "ForceSuccess", "ForceFailure", "Repeat", "RetryUntilSuccessful", "KeepRunningUntilFailure"]


def random_case(seed: int, max_depth: int = 3):
    """A random tree (XML) and random leaf scripts."""
    rng = random.Random(seed)
    scripts: dict[str, list[str]] = {}
    counter = [0]

    def leaf() -> str:
        counter[0] += 1
        name = f"n{counter[0]}"
        if rng.random() < 0.35:
            scripts[name] = [rng.choice(["SUCCESS", "FAILURE"]) for _ in range(rng.randint(1, 6))]
            return f'<Cond name="{name}"/>'
        scripts[name] = [rng.choice(["SUCCESS", "FAILURE", "RUNNING", "RUNNING"]) for _ in range(rng.randint(1, 8))]
        return f'<Act name="{name}"/>'

    def node(depth: int) -> str:
        if depth >= max_depth or rng.random() < 0.3:
            return leaf()
        if rng.random() < 0.3:
            kind = rng.choice(DECORATORS)
            attrs = ""
            if kind == "Repeat":
                attrs = f' num_cycles="{rng.choice([1, 2, 3, -1])}"'
            elif kind == "RetryUntilSuccessful":
                attrs = f' num_attempts="{rng.choice([1, 2, 3, -1])}"'
            return f"<{kind}{attrs}>{node(depth + 1)}</{kind}>"
        kind = rng.choice(CONTROLS)
        children = [node(depth + 1) for _ in range(rng.randint(1, 4))]
        attrs = ""
        if kind == "Parallel":
            n = len(children)
            attrs = (
                f' success_count="{rng.choice([-1] + list(range(1, n + 1)))}"'
                f' failure_count="{rng.choice([-1] + list(range(1, n + 1)))}"'
            )
        return f"<{kind}{attrs}>{''.join(children)}</{kind}>"

    body = node(0)
    xml = f'<root BTCPP_format="4"><BehaviorTree ID="Main">{body}</BehaviorTree></root>'
    return xml, scripts
