"""An allocator that allocates nothing: for benchmarks of the runtime itself.

With ``peers > 0`` it sends ``messages`` small messages per tick (one by default) to the ``peers``
agents after it (by id, wrapping around), so that the radio and the inboxes carry traffic.
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

from swarmbed.extension import Allocator, LocalView


class NoopParams(BaseModel):
    model_config = ConfigDict(extra="forbid")
    peers: int = Field(0, ge=0)
    payload_bytes: int = Field(16, ge=0, le=65536)
    messages: int = Field(1, ge=1, le=16, description="messages sent per tick, each to every peer")


class NoopAllocator(Allocator):
    Params = NoopParams
    params: NoopParams
    message_kinds = ("noop",)

    def decide(self, view: LocalView) -> int | None:
        p = self.params
        if p.peers and view.n_agents > 1:
            n = view.n_agents
            peers = sorted({(self.agent_id + k) % n for k in range(1, min(p.peers, n - 1) + 1)})
            for _ in range(p.messages):
                view.send(peers, "noop", b"\0" * p.payload_bytes)
        return None
