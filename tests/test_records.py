"""The control plane's records are declared types: a host's information, a swap's answer, and the
swap and restart records the coordinator writes. What a host or a hub answers may be crafted: it is
decoded into these types only, or refused with the field named (tests/test_hosts.py and
tests/test_swaps.py use them against real daemons and runs)."""

import json

import pytest

from swarmbed.wire.control import (
    HostInfo,
    RestartRecord,
    SwapPending,
    SwapQueued,
    SwapRecord,
    SwapRefused,
    decode_host_info,
    decode_swap_answer,
    encode_json,
    encode_swap_answer,
)
from swarmbed.wire.errors import WireError

HOST = {"name": "h1", "cores": 2, "mem_free_mb": 2048, "pid": 4242, "endpoint": "tcp/10.0.0.2:7447", "agents": {}}


def test_a_host_answer_round_trips():
    info = HostInfo(**{**HOST, "agents": {"abc123": [0, 3]}})
    assert decode_host_info(encode_json(info).encode()) == info


@pytest.mark.parametrize(
    ("change", "where"),
    [
        ({"pid": "4242"}, "pid"),
        ({"pid": 0}, "pid"),
        ({"pid": True}, "pid"),
        ({"agents": {"run/../x": [1]}}, "agents"),
        ({"agents": {"abc": [-1]}}, "agents.abc.0"),
        ({"name": "x" * 65}, "name"),
        ({"shell": "rm -rf /"}, "shell"),
    ],
)
def test_a_crafted_host_answer_names_its_field(change, where):
    with pytest.raises(WireError, match=f"host information: {where}"):
        decode_host_info(json.dumps({**HOST, **change}).encode())


def test_a_host_answer_nested_too_deep_or_too_large_is_one_line():
    with pytest.raises(WireError, match="nested too deep"):
        decode_host_info(b"[" * 100_000)
    with pytest.raises(WireError, match="more than"):
        decode_host_info(b" " * (2 << 20))


def test_swap_answers_round_trip_and_crafted_ones_are_refused():
    record = SwapRecord(tick=5, agent=2, from_host="local", to="h1", outcome="ok", snapshot_bytes=900, pause_ms=12.5)
    for answer in (record, SwapPending(pending=True), SwapQueued(queued=3), SwapRefused(error="no")):
        assert decode_swap_answer(encode_swap_answer(answer).encode()) == answer
    assert json.loads(encode_swap_answer(record))["from"] == "local"  # the file's and the answer's name
    for crafted in (b'{"queued": -1}', b'{"tick": 1, "agent": 2}', b'{"pending": false}', b"[]", b"nope"):
        with pytest.raises(WireError, match="swap answer"):
            decode_swap_answer(crafted)


def test_record_columns_are_the_files_headers():
    assert SwapRecord.columns() == ["tick", "agent", "from", "to", "outcome", "reason", "snapshot_bytes", "pause_ms"]
    restart = RestartRecord(tick=9, agent=1, lost_at_tick=7, incarnation=2, host="local", checkpoint_tick="")
    assert restart.columns() == [
        "tick",
        "agent",
        "lost_at_tick",
        "incarnation",
        "host",
        "checkpoint_tick",
        "outcome",
        "reason",
        "wait_ms",
    ]
    assert restart.row() == [9, 1, 7, 2, "local", "", "failed", "", 0.0]
