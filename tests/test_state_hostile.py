"""Restoring a snapshot rebuilds declared data and nothing else, whatever the bytes say.

Each crafted payload below is a shape of attack on an unpickler-like decoder: name a function
through a module, walk attributes to one, name a class by a prefix of a trusted module, ask the
random-generator path or the enum path to call something, set dunder attributes, smuggle an object
array. Every one must raise StateError and run nothing (the canary file stays absent).
"""

from __future__ import annotations

import dataclasses
import enum

import msgpack
import numpy as np
import pytest

from swarmbed.wire import state as st
from swarmbed.wire.codec import pack
from swarmbed.wire.state import StateError, pack_state, state_type, unpack_state


def ext(code: int, value) -> msgpack.ExtType:
    return msgpack.ExtType(code, pack(value))


def crafted(value) -> bytes:
    return pack(value)


@pytest.fixture
def canary(tmp_path):
    path = tmp_path / "pwned"
    yield path
    assert not path.exists(), "a crafted snapshot ran code"


def hostile_payloads(canary) -> dict[str, bytes]:
    cmd = f"touch {canary}"
    return {
        # a function reached through a swarmbed module, called by the enum path with a chosen value
        "enum names os.system via a module": crafted(ext(st.EXT_ENUM, ["os:system", cmd])),
        "enum walks to os.system": crafted(ext(st.EXT_ENUM, ["swarmbed.wire.child_process:os.system", cmd])),
        "enum walks from a prefix module": crafted(ext(st.EXT_ENUM, ["swarmbedx:system", cmd])),
        "enum names subprocess": crafted(ext(st.EXT_ENUM, ["subprocess:getoutput", cmd])),
        "enum names a declared module's import": crafted(
            ext(st.EXT_ENUM, ["swarmbed.wire.state:msgpack.unpackb", b"\x00"])
        ),
        # the object path: a class whose __new__ or attribute setting would do work
        "object names subprocess.Popen": crafted(ext(st.EXT_OBJECT, ["subprocess:Popen", {"args": cmd}])),
        "object walks attributes": crafted(ext(st.EXT_OBJECT, ["swarmbed.extension.view:np.random.Generator", {}])),
        "object names a builtin": crafted(ext(st.EXT_OBJECT, ["builtins:eval", {}])),
        "named tuple of a declared type with extra fields": crafted(
            ext(st.EXT_OBJECT, ["swarmbed.extension.view:TaskInfo", {"id": 1, "__class__": 2}])
        ),
        "dunder attribute on a declared class": crafted(
            ext(st.EXT_OBJECT, ["swarmbed.plugins.taskbook:TaskBook", {"__class__": 1}])
        ),
        "non-string attribute name": crafted(ext(st.EXT_OBJECT, ["swarmbed.plugins.taskbook:TaskBook", {1: 2}])),
        "an enum as an object": crafted(ext(st.EXT_OBJECT, ["swarmbed.bt.status:Status", {}])),
        "a plain class as an enum": crafted(ext(st.EXT_ENUM, ["swarmbed.plugins.taskbook:TaskBook", 1])),
        "class reference not a string": crafted(ext(st.EXT_OBJECT, [["os", "system"], {}])),
        # the random-generator path: np.random.<name>() with a chosen name
        "rng names a numpy function": crafted(ext(st.EXT_RNG, {"bit_generator": "bytes", "state": 1})),
        "rng names a numpy module": crafted(ext(st.EXT_RNG, {"bit_generator": "_pickle", "state": {}})),
        "rng state not a map": crafted(ext(st.EXT_RNG, ["PCG64"])),
        # arrays and scalars of Python objects would unpickle
        "object array": crafted(ext(st.EXT_ARRAY, ["|O", [1], b"\x00" * 8])),
        "object field in a record array": crafted(ext(st.EXT_ARRAY, [[["a", "|O"]], [1], b"\x00" * 8])),
        "object scalar": crafted(ext(st.EXT_SCALAR, ["|O", b"\x00" * 8])),
        "array larger than its buffer": crafted(ext(st.EXT_ARRAY, ["<f8", [10**6], b"\x00" * 8])),
        "unknown extension code": crafted(msgpack.ExtType(99, b"")),
        "huge big integer": crafted(ext(st.EXT_BIGINT, "9" * 100_000)),
        "not msgpack": b"\xc1\xc1\xc1",
        "truncated": pack_state({"a": list(range(100))})[:-3],
        "deep nesting": b"\x91" * 200_000 + b"\xc0",
    }


def test_every_hostile_snapshot_is_refused_and_runs_nothing(canary):
    for name, payload in hostile_payloads(canary).items():
        with pytest.raises(StateError):
            unpack_state(payload)
        assert not canary.exists(), name


def test_a_snapshot_over_the_size_limit_is_refused_before_it_is_parsed():
    with pytest.raises(StateError, match="over the limit"):
        unpack_state(b"\x00" * 1025, max_bytes=1024)


class Undeclared:
    def __init__(self) -> None:
        self.x = 1


@state_type
class Declared:
    def __init__(self) -> None:
        self.x = 1


@state_type
@dataclasses.dataclass(frozen=True)
class Point:
    x: float
    y: float


@state_type
class Mood(enum.Enum):
    CALM = 1
    BUSY = 2


def test_declared_types_round_trip_and_undeclared_ones_are_refused_by_name():
    rng = np.random.default_rng(3)
    value = {
        "d": Declared(),
        "p": Point(1.0, 2.0),
        "m": Mood.BUSY,
        "rng": rng,
        "a": np.arange(3),
        "t": (1, 2),
        "big": 2**70,
        "s": {1, 2},
        "f": frozenset({3}),
    }
    back = unpack_state(pack_state(value))
    assert type(back["d"]) is Declared and back["d"].x == 1
    assert back["p"] == Point(1.0, 2.0) and back["m"] is Mood.BUSY and back["big"] == 2**70
    assert back["rng"].random() == np.random.default_rng(3).random()
    with pytest.raises(StateError, match=r"state\.u: cannot snapshot a .*Undeclared: not a declared state type"):
        pack_state({"u": Undeclared()})


def test_a_dataclass_restores_only_its_own_fields():
    payload = crafted(ext(st.EXT_OBJECT, [st.type_ref(Point), {"x": 1.0, "y": 2.0, "z": 3.0}]))
    with pytest.raises(StateError, match="has no field 'z'"):
        unpack_state(payload)


def test_state_type_refuses_local_classes_and_two_classes_under_one_name():
    def local():
        class Inner:
            pass

        return Inner

    with pytest.raises(TypeError, match="inside a function"):
        state_type(local())
    impostor = type("Declared", (), {"__module__": __name__, "__qualname__": "Declared"})
    with pytest.raises(TypeError, match="declared twice"):
        state_type(impostor)


@pytest.mark.parametrize(
    ("report", "named"),
    [
        ({"kind": "final", "agent": 1, "ticks": 3, "sent": {"bid": [1]}, "malformed": 0}, "sent.bid"),
        ({"kind": "fatal", "agent": "1", "tick": 0, "error": "x"}, "agent"),
        ({"kind": "fatal", "agent": -1, "tick": 0, "error": "x"}, "agent"),
        ({"kind": "checkpoint", "agent": 1, "incarnation": 0, "ticks": 1, "state": "s", "ticket": b""}, "state"),
        ({"kind": "restored", "agent": 1, "incarnation": 0, "call": "os.system"}, "call"),
        ({"kind": "launch", "agent": 1}, "kind"),
        (["final"], "agent report"),
    ],
)
def test_a_crafted_agent_report_is_a_wire_error_naming_its_field(report, named):
    from swarmbed.wire.codec import WireError, pack
    from swarmbed.wire.control import decode_agent_report

    with pytest.raises(WireError, match=named):
        decode_agent_report(pack(report))


def test_every_report_a_process_writes_decodes_to_its_model():
    from swarmbed.wire.control import (
        Final,
        NetemFatal,
        Transport,
        decode_agent_report,
        decode_netem_report,
        decode_swap,
        encode_report,
    )

    final = Final(
        kind="final",
        agent=2,
        ticks=5,
        sent={"bid": [3, 120]},
        malformed=0,
        transport=Transport.model_validate({"tcp": None, "samples": {"in": 10, "out": 20}}),
    )
    assert decode_agent_report(encode_report(final)) == final
    assert decode_netem_report(encode_report(NetemFatal(kind="fatal", error="disk full"))).error == "disk full"
    assert decode_swap(b'{"agent": 3, "to": "b"}').to == "b" and decode_swap(b'{"swap": 0}').swap == 0
    for bad in (b'{"agent": 3}', b'{"agent": "3", "to": "b"}', b"[1]", b"nope", None):
        with pytest.raises(ValueError):
            decode_swap(bad)
