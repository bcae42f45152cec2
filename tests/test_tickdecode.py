"""The agent's typed decode of its tick sample (``swarmbed.wire.tickdecode``) and the inbox's accept
exactly what the Python checks accept, with the same values and types, and leave every sample they
do not take to those checks (so that the error that names it is unchanged)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from swarmbed import config as cfg
from swarmbed.wire import codec
from swarmbed.wire.codec import (
    TASK_DTYPE,
    TickIn,
    WireError,
    decode_agent_in,
    decode_inbox,
    decode_inbox_checked,
    encode_inbox,
    encode_stop,
    encode_tick,
    pack,
)
from swarmbed.wire.observation import Observation
from swarmbed.wire.tickdecode import TickDecoder

ROOT = Path(__file__).resolve().parent.parent
SCENARIOS = {
    "mtsr": (ROOT / "experiments" / "space_mtsr.yaml", []),
    "mtsr-teams": (ROOT / "experiments" / "space_mtsr.yaml", ["scenario.robots_needed=[1,3]"]),
    "sar": (ROOT / "experiments" / "sar" / "_base.yaml", []),
}


def _observations(name: str) -> list[Observation]:
    path, sets = SCENARIOS[name]
    scenario = cfg.resolve_experiment(cfg.load(path, ["agents.count=6", *sets])).scenario()
    return list(scenario.make_world(np.random.default_rng(3)).observations().values())


def _same(a: object, b: object) -> bool:
    """Equal, and of the same types all the way down (1 is not 1.0, a tuple is not a list)."""
    if type(a) is not type(b):
        return False
    if isinstance(a, np.ndarray):
        return a.dtype == b.dtype and a.tobytes() == b.tobytes()  # type: ignore[union-attr]
    if dataclasses.is_dataclass(a) and not isinstance(a, type):
        return all(_same(getattr(a, f.name), getattr(b, f.name)) for f in dataclasses.fields(a))
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))  # type: ignore[arg-type]
    if isinstance(a, float) and a != a:
        return b != b
    return a == b


def _old_way(obs_cls: type[Observation], data: bytes) -> object:
    """What the agent made of a sample before the typed decoder: the input, or the error's text."""
    try:
        msg = decode_agent_in(data)
    except WireError as exc:
        return f"sample: {exc}"
    if not isinstance(msg, TickIn):
        return msg
    try:
        return TickIn(msg.tick, obs_cls.from_wire(msg.obs), msg.inbox, msg.decision, msg.shard)
    except WireError as exc:
        return f"observation: {exc}"


def _new_way(decoder: TickDecoder, data: bytes) -> object:
    try:
        msg = decoder.decode(data)
    except WireError as exc:
        return f"sample: {exc}"
    if not isinstance(msg, TickIn) or isinstance(msg.obs, Observation):
        return msg
    try:
        return TickIn(msg.tick, decoder.obs_cls.from_wire(msg.obs), msg.inbox, msg.decision, msg.shard)
    except WireError as exc:
        return f"observation: {exc}"


BAD_VALUES = (None, True, 0, -3, 2.5, float("nan"), "x", b"\x00" * 5, b"", [], [1], [1.5, 2], [[1, 2.0, 3]], {"a": 1})


def _variants(wire: dict) -> list[dict]:
    """The observation with each field replaced by values of other types, removed, and a field added."""
    out = [wire, {**wire, "extra": 1}, {**wire, 7: 1}]
    for name in wire:
        out.append({k: v for k, v in wire.items() if k != name})
        out += [{**wire, name: bad} for bad in BAD_VALUES]
    out.append({**wire, "t": 5})  # an int time: a float after decoding
    out.append({**wire, "me": [1, 2, 3, 4]})
    out.append({**wire, "tasks": np.zeros(2, TASK_DTYPE).tobytes()})
    return out


@pytest.mark.parametrize("name", sorted(SCENARIOS))
def test_the_typed_decoder_reads_every_sample_as_the_python_checks_do(name):
    observations = _observations(name)
    obs_cls = type(observations[0])
    decoder = TickDecoder(obs_cls)
    inbox = encode_inbox([[1, "bid", pack({"a": 1})]])
    fast = 0
    samples = []
    for obs in observations:
        for wire in _variants(obs.to_wire()):
            samples.append(encode_tick(9, wire, inbox))
            samples.append(encode_tick(9, wire, inbox, decision=-1))
            samples.append(encode_tick(9, wire, inbox, shard=3))
        samples += [
            pack([0, 9, obs.to_wire(), inbox, None]),  # an explicit nil is no decision
            pack([0, 9, obs.to_wire(), inbox, 2**31]),
            pack([0, 9, obs.to_wire(), inbox, 1, 2]),  # a decision and the proxy that reads the answer
            pack([0, 9, obs.to_wire(), inbox, None, 63]),
            pack([0, 9, obs.to_wire(), inbox, None, 64]),
            pack([0, 9, obs.to_wire(), inbox, None, -1]),
            pack([0, 9, obs.to_wire(), inbox, None, True]),
            pack([0, 9, obs.to_wire(), inbox, None, None]),
            pack([0, 9, obs.to_wire(), inbox, 1, 2, 3]),
            pack([0, -1, obs.to_wire(), inbox]),
            pack([0, True, obs.to_wire(), inbox]),
            pack([0, 9, obs.to_wire(), "inbox"]),
            pack([0, 9, obs.to_wire()]),
            pack([False, 9, obs.to_wire(), inbox]),
            encode_stop("done"),
            pack([2, 1, b"ticket"]),
            b"\xc1",
            b"",
        ]
    for data in samples:
        old, new = _old_way(obs_cls, data), _new_way(decoder, data)
        assert _same(old, new), (data, old, new)
        msg = None
        try:
            msg = decoder.decode(data)
        except WireError:
            pass
        fast += isinstance(msg, TickIn) and isinstance(msg.obs, Observation)
    # the well-formed ticks took the typed way (not the old one behind it)
    assert fast >= 6 * len(observations), fast
    obs = observations[0]
    msg = decoder.decode(encode_tick(9, obs.to_wire(), inbox, decision=5))
    assert isinstance(msg, TickIn) and _same(msg.obs, obs) and msg.decision == 5 and msg.inbox == inbox
    msg = decoder.decode(encode_tick(9, obs.to_wire(), inbox, shard=7))
    assert isinstance(msg, TickIn) and (msg.decision, msg.shard) == (None, 7) and _same(msg.obs, obs)


@pytest.mark.parametrize("name", sorted(SCENARIOS))
def test_the_in_process_engines_observation_reads_as_the_python_checks_do(name):
    """``TickDecoder.observation`` (how the in-process engine hands each agent its observation) gives
    what ``from_wire`` gives, types included, and the same error on a crafted one."""
    observations = _observations(name)
    obs_cls = type(observations[0])
    decoder = TickDecoder(obs_cls)
    for obs in observations:
        for wire in _variants(obs.to_wire()):
            try:
                old: object = obs_cls.from_wire(wire)
            except WireError as exc:
                old = str(exc)
            try:
                new: object = decoder.observation(wire)
            except WireError as exc:
                new = str(exc)
            assert _same(old, new), (wire, old, new)


def test_an_observation_with_a_field_type_the_decoder_does_not_read_goes_the_old_way():
    @dataclasses.dataclass(frozen=True, slots=True)
    class Odd(Observation):
        either: int | str  # which member a union picks is the Python checks' rule

    decoder = TickDecoder(Odd)
    wire = {"t": 1.0, "me": [0.0, 0.0, 0.0, 0.0], "tasks": b"", "either": 3}
    msg = decoder.decode(encode_tick(1, wire, encode_inbox([])))
    assert isinstance(msg, TickIn) and msg.obs == wire


def test_the_inbox_decodes_as_its_checks_do(monkeypatch):
    good = [[0, "bid", b"\x01"], [2**40, "k" * 70, b""], [-5, "", b"\x90"]]
    cases = [good, []]
    for i in range(3):
        for bad in (None, True, 1.5, "s", b"b", [1]):
            entry = list(good[0])
            entry[i] = bad
            cases.append([entry])
    cases += [[[1, "a"]], [[1, "a", b"", 4]], [(1, "a", b"")], {"a": 1}, "inbox"]
    for items in cases:
        data = pack(items)
        try:
            old = decode_inbox_checked(data)
        except WireError as exc:
            old = str(exc)
        try:
            new = decode_inbox(data)
        except WireError as exc:
            new = str(exc)
        assert _same(old, new), (items, old, new)
    assert decode_inbox(pack(good)) == [tuple(e) for e in good]
    # a well-formed inbox never reaches the Python checks (the one-pass decode took it)
    monkeypatch.setattr(codec, "decode_inbox_checked", lambda data: pytest.fail("took the slow way"))
    assert decode_inbox(pack(good)) == [tuple(e) for e in good]
