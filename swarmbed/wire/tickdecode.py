"""The agent's typed decode of its tick sample: the sample straight into the scenario's observation.

:func:`~swarmbed.wire.codec.decode_agent_in` unpacks a sample into Python lists and dicts, checks
their shape, and :meth:`Observation.from_wire <swarmbed.wire.observation.Observation.from_wire>`
then checks the observation's fields one by one and copies them into the typed observation: three
Python layers, about 50-90 us of an agent's CPU at every tick in a live run (issue 43). Here one
msgspec decoder, built per observation class from the same annotations, reads and checks a tick
sample in one C pass.

It accepts exactly what the two layers accept and gives the same values (ints where a field says
``float`` become floats, arrays become tuples where it says ``tuple``); tests/test_tickdecode.py
holds it to that on valid and crafted samples. Anything it does not take (a stop or swap order, a
malformed sample, an observation with a field type it does not handle) goes the old way, so what
is dropped and counted, and the one-line error that names why, stay as they were.
"""

from __future__ import annotations

import typing
from typing import Annotated, Any

import msgspec
import numpy as np

from swarmbed.wire.codec import (
    MAX_AGENT_SAMPLE_BYTES,
    MAX_SHARDS,
    TAG_TICK,
    TASK_DTYPE,
    ControlIn,
    StopIn,
    TickIn,
    decode_agent_in,
)
from swarmbed.wire.observation import Observation, _is_union, _optional

_TICK = Annotated[int, msgspec.Meta(ge=0)]
_DECISION = Annotated[int, msgspec.Meta(ge=-(2**31), lt=2**31)]
_SHARD = Annotated[int, msgspec.Meta(ge=0, lt=MAX_SHARDS)]
_SCALARS = (int, float, bool, str, bytes)


def _typed(annotation: Any) -> bool:
    """Whether msgspec reads ``annotation`` as ``Observation.from_wire`` does: scalars, lists,
    tuples, and ``X | None`` (a union of two other types would pick its member by another rule)."""
    if annotation in _SCALARS:
        return True
    origin, args = typing.get_origin(annotation), typing.get_args(annotation)
    if _is_union(annotation):
        rest = [a for a in args if a is not type(None)]
        return len(args) == 2 and len(rest) == 1 and _typed(rest[0])
    if origin is list:
        return len(args) == 1 and _typed(args[0])
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return _typed(args[0])
        return bool(args) and all(_typed(a) for a in args)
    return False


class TickDecoder:
    """Decodes an agent's input samples; a tick's observation arrives as ``obs_cls``."""

    def __init__(self, obs_cls: type[Observation]) -> None:
        self.obs_cls = obs_cls
        extras = obs_cls.extra_fields()
        self.extra_names = tuple(name for name, _ in extras)
        self._decoder: msgspec.msgpack.Decoder | None = None
        self._obs_decoder: msgspec.msgpack.Decoder | None = None
        if not all(_typed(annotation) for _, annotation in extras):
            return  # every sample goes the old way
        fields: list[Any] = [("t", float), ("me", tuple[float, float, float, float]), ("tasks", bytes)]
        for name, annotation in extras:  # a missing optional field is None, as in from_wire
            fields.append((name, annotation, None) if _optional(annotation) else (name, annotation))
        obs_wire = msgspec.defstruct(
            f"{obs_cls.__name__}Wire", fields, kw_only=True, forbid_unknown_fields=True, omit_defaults=False
        )
        tick_wire = msgspec.defstruct(
            "TickWire",
            [
                ("tick", _TICK),
                ("obs", obs_wire),
                ("inbox", bytes),
                # only where one is sent; nil only before a shard
                ("decision", _DECISION | None | msgspec.UnsetType, msgspec.UNSET),
                ("shard", _SHARD | msgspec.UnsetType, msgspec.UNSET),  # a radio split by region's
            ],
            array_like=True,
            tag=TAG_TICK,
            forbid_unknown_fields=True,  # an array with elements after these is not a tick sample
        )
        self._decoder = msgspec.msgpack.Decoder(tick_wire)
        self._obs_decoder = msgspec.msgpack.Decoder(obs_wire)

    def decode(self, data: bytes) -> TickIn | StopIn | ControlIn:
        """What :func:`~swarmbed.wire.codec.decode_agent_in` returns, but a tick's ``obs`` is the typed
        observation when the sample reads as one; a WireError names what is wrong with it."""
        if self._decoder is not None and len(data) <= MAX_AGENT_SAMPLE_BYTES:
            try:
                wire = self._decoder.decode(data)
            except msgspec.MsgspecError:
                pass  # not a tick, or not a well-formed one: the old way says which
            else:
                typed = self._typed(wire.obs)
                unset = msgspec.UNSET
                if typed is not None and (wire.decision is not None or wire.shard is not unset):
                    decision = None if wire.decision is unset else wire.decision
                    shard = None if wire.shard is unset else wire.shard
                    return TickIn(wire.tick, typed, wire.inbox, decision, shard)
        return decode_agent_in(data)

    def observation(self, raw: dict[str, Any]) -> Observation:
        """An observation's wire map (``Observation.to_wire``) read back as the agent reads it: in one
        C pass where the class allows, else by ``from_wire``; the same values either way. The
        in-process engine hands each agent its observation this way."""
        if self._obs_decoder is not None:
            try:
                typed = self._typed(self._obs_decoder.decode(msgspec.msgpack.encode(raw)))
            except msgspec.MsgspecError:
                typed = None
            if typed is not None:
                return typed
        return self.obs_cls.from_wire(raw)

    def _typed(self, obs: Any) -> Observation | None:
        if len(obs.tasks) % TASK_DTYPE.itemsize:
            return None
        x, y, heading, speed = obs.me
        extras = {name: getattr(obs, name) for name in self.extra_names}
        tasks = np.frombuffer(obs.tasks, dtype=TASK_DTYPE)
        return self.obs_cls(obs.t, x, y, heading, speed, tasks, **extras)
