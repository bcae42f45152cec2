"""The two baselines without consensus (CBBA-ETC paper, Section 5.2).

``tree``: a behavior tree and nothing else (Figure 4). The robot goes for the nearest victim it
remembers that it has not found incompatible; it never sends a byte.

``comm``: the same tree, plus two broadcasts: a claim when it chooses a victim (repeated every
``claim_refresh`` seconds while it keeps it) and the colour of a victim it found incompatible.
Others skip claimed victims and victims whose known colour is not theirs. A claim lapses after
``claim_ttl`` seconds without a refresh, so the claims of a robot that is lost stop mattering.
"""

from __future__ import annotations

from pydantic import Field

from swarmbed.extension import LocalView
from swarmbed.extension.space_nodes import ExplorationNode
from swarmbed.plugins.sar.base import TREES, SARStrategy, StrategyParams
from swarmbed.plugins.sar.nodes import SAR_NODES

CLAIM, COLOR = "claim", "color"


class TreeStrategy(SARStrategy):
    bt_nodes = SAR_NODES + (ExplorationNode,)
    default_tree = str(TREES / "tree.xml")

    def choosable(self, v: int) -> bool:
        known = self.colors.get(v, -1)
        return known < 0 or known == self.my_color

    def acquire(self, view: LocalView) -> bool:
        options = [v for v in self.candidates() if self.choosable(v)]
        self.target = min(options, key=lambda v: (self.distance(view, v), v)) if options else None
        if self.target is not None:
            self.chosen(view)
        return self.target is not None

    def chosen(self, view: LocalView) -> None:
        """Hook: a new target was chosen."""


class CommParams(StrategyParams):
    claim_ttl: float = Field(30.0, gt=0, description="seconds a claim holds without a refresh")
    claim_refresh: float = Field(10.0, gt=0, description="seconds between repeats of a held claim")


class CommStrategy(TreeStrategy):
    Params = CommParams
    params: CommParams
    message_kinds = (CLAIM, COLOR)
    default_tree = str(TREES / "comm.xml")

    def __init__(self, agent_id, params, rng, run_seed=0):
        super().__init__(agent_id, params, rng, run_seed)
        self.claims: dict[int, tuple[float, int]] = {}  # victim -> (expiry, claimer)
        self.claimed_at = -1e18

    def receive(self, view: LocalView) -> None:
        for msg in view.inbox:
            if msg.kind == CLAIM:
                victim = int(msg.data)
                if victim not in self.gone:
                    self.claims[victim] = (self.now + self.params.claim_ttl, msg.sender)
            elif msg.kind == COLOR:
                victim, color = msg.data
                if int(victim) not in self.gone:
                    self.colors[int(victim)] = int(color)
        due = self.now - self.claimed_at >= self.params.claim_refresh
        if self.target is not None and due and self.target_valid(view):
            self._claim(view)

    def forget(self, victim: int) -> None:
        super().forget(victim)
        self.claims.pop(victim, None)

    def choosable(self, v: int) -> bool:
        expiry, claimer = self.claims.get(v, (-1e18, -1))
        return super().choosable(v) and (expiry <= self.now or claimer == self.agent_id)

    def chosen(self, view: LocalView) -> None:
        self._claim(view)

    def _claim(self, view: LocalView) -> None:
        view.broadcast(CLAIM, self.target)
        self.claimed_at = self.now

    def released(self, victim: int, view: LocalView) -> None:
        view.broadcast(COLOR, [victim, self.colors[victim]])
