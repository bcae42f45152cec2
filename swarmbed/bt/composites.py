"""Control nodes: Sequence, Fallback, their reactive variants, and Parallel (BehaviorTree.CPP v4)."""

from __future__ import annotations

from swarmbed.bt.node import BTError, ControlNode, InputPort, Port
from swarmbed.bt.status import FAILURE, IDLE, RUNNING, SUCCESS, Status


class _Ordered(ControlNode):
    """Sequence and Fallback: tick children in order, resuming at the RUNNING one. A child that
    returns ``NEXT`` moves on to the following child; any other completion ends the node with that
    status; when every child returned ``NEXT`` the node returns ``NEXT`` too."""

    NEXT = SUCCESS

    def __init__(self, name, config):
        super().__init__(name, config)
        self.current = 0

    def tick(self) -> Status:
        self.status = RUNNING
        while self.current < len(self._children):
            child_status = self._children[self.current].execute_tick()
            if child_status is RUNNING:
                return RUNNING
            if child_status is not self.NEXT:
                self.reset_children()
                self.current = 0
                return child_status
            self.current += 1
        self.reset_children()
        self.current = 0
        return self.NEXT

    def halt(self) -> None:
        self.current = 0
        super().halt()


class Sequence(_Ordered):
    """Succeeds when every child succeeds; fails (and resets) at the first FAILURE."""

    ID = "Sequence"
    NEXT = SUCCESS


class Fallback(_Ordered):
    """Succeeds at the first child that succeeds; fails when all fail."""

    ID = "Fallback"
    NEXT = FAILURE


class _Reactive(ControlNode):
    """Reactive variants: every tick starts again from the first child; a RUNNING child halts all
    the others (BT.CPP v4 halts every child but the running one)."""

    NEXT = SUCCESS

    def tick(self) -> Status:
        self.status = RUNNING
        for index, child in enumerate(self._children):
            child_status = child.execute_tick()
            if child_status is RUNNING:
                for i, other in enumerate(self._children):
                    if i != index and other.status is not IDLE:
                        self.halt_child(i)
                return RUNNING
            if child_status is not self.NEXT:
                self.reset_children()
                return child_status
        self.reset_children()
        return self.NEXT


class ReactiveSequence(_Reactive):
    ID = "ReactiveSequence"
    NEXT = SUCCESS


class ReactiveFallback(_Reactive):
    ID = "ReactiveFallback"
    NEXT = FAILURE


class Parallel(ControlNode):
    """Ticks all unfinished children; succeeds at ``success_count`` successes, fails at ``failure_count``
    failures (negative counts are relative to the number of children: -1 means all)."""

    ID = "Parallel"

    def __init__(self, name, config):
        super().__init__(name, config)
        self._completed: set[int] = set()
        self._successes = 0
        self._failures = 0

    @classmethod
    def provided_ports(cls) -> dict[str, Port]:
        return {
            "success_count": InputPort(int, -1, "children that must succeed (-1: all)"),
            "failure_count": InputPort(int, 1, "children that must fail to fail (-1: all)"),
        }

    def _threshold(self, value: int) -> int:
        n = len(self._children)
        return max(n + value + 1, 0) if value < 0 else value

    def _clear(self) -> None:
        self._completed.clear()
        self._successes = 0
        self._failures = 0

    def tick(self) -> Status:
        n = len(self._children)
        need_success = self._threshold(self.get_input("success_count"))
        need_failure = self._threshold(self.get_input("failure_count"))
        if n < need_success:
            raise BTError(f"{self.config.path}: fewer children than success_count: can never succeed")
        if n < need_failure:
            raise BTError(f"{self.config.path}: fewer children than failure_count: can never fail")
        self.status = RUNNING
        for i, child in enumerate(self._children):
            if i not in self._completed:
                child_status = child.execute_tick()
                if child_status is SUCCESS:
                    self._completed.add(i)
                    self._successes += 1
                elif child_status is FAILURE:
                    self._completed.add(i)
                    self._failures += 1
            if self._successes >= need_success:
                self._clear()
                self.reset_children()
                return SUCCESS
            if n - self._failures < need_success or self._failures == need_failure:
                self._clear()
                self.reset_children()
                return FAILURE
        return RUNNING

    def halt(self) -> None:
        self._clear()
        super().halt()


CONTROLS = (Sequence, Fallback, ReactiveSequence, ReactiveFallback, Parallel)
