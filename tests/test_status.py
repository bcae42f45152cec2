"""The progress sample ``swarmbed watch`` reads is a declared type: a crafted one is counted and
dropped with the field named, never drawn (tests/test_watch.py watches a real run's samples)."""

import math

import pytest

from swarmbed.results.watch import RunView, write_map
from swarmbed.wire.codec import pack
from swarmbed.wire.errors import WireError
from swarmbed.wire.run_status import NetworkCounters, RunStatus, decode_status, encode_status


def _status(**change) -> RunStatus:
    fields = {
        "name": "quickstart",
        "scenario": "sar",
        "allocator": "cbba",
        "tick": 41,
        "time": 42.0,
        "ticks": 600,
        "wall_s": 1.5,
        "row": {"tick": 42, "time": 42.0, "rescued": 3, "distance_total": 12.5},
        "network": NetworkCounters(messages_sent=10, bytes_sent=900, copies=40, delivered=35, dropped=5),
        "drops": {"loss": 5},
        "alive": [0, 1, 2],
        "late_ticks": 0,
        "positions": [(0, 1.0, 2.0), (1, 3.0, 4.0), (2, -1.0, 0.5)],
        "labels": {0: "red", 1: "blue", 2: "red"},
        "markers": [(5.0, 5.0, "green")],
    }
    return RunStatus(**{**fields, **change})


def test_a_sample_round_trips_and_is_drawn(tmp_path):
    status = _status()
    assert decode_status(encode_status(status)) == status
    view = RunView("r1")
    view.on_status(encode_status(status))
    view.on_status(encode_status(_status(tick=51, time=52.0)))
    assert view.malformed == 0 and view.status is not None and view.status.tick == 51
    assert "tick 52" in view.line() and "rescued=3" in view.line()
    view.render()
    write_map(view.status, tmp_path / "map.html", [math.inf, math.inf, -math.inf, -math.inf])
    assert "agent 2" in (tmp_path / "map.html").read_text()


CRAFTED = [
    ({"tick": "41"}, "tick"),
    ({"time": float("nan")}, "time"),
    ({"row": {"rescued": "many"}}, "row.rescued"),
    ({"network": {"messages_sent": -1}}, "network"),
    ({"alive": [0, -3]}, "alive.1"),
    ({"positions": [[0, 1.0]]}, "positions.0"),
    ({"positions": [[0, float("inf"), 1.0]]}, "positions.0.1"),
    ({"labels": {"0": "red"}}, "labels.0.[key]"),
    ({"markers": [[1.0, 2.0, 3]]}, "markers.0.2"),
    ({"name": "x" * 201}, "name"),
    ({"__class__": "os.system"}, "__class__"),
]


@pytest.mark.parametrize(("change", "where"), CRAFTED, ids=[w for _, w in CRAFTED])
def test_a_crafted_sample_names_its_field_and_is_counted_not_drawn(change, where):
    sample = {**_status().model_dump(), **change}
    with pytest.raises(WireError) as err:
        decode_status(pack(sample))
    assert f"status: {where}" in str(err.value)
    view = RunView("r1")
    view.on_status(pack(sample))
    assert view.malformed == 1 and view.status is None


def test_junk_samples_are_counted():
    view = RunView("r1")
    for junk in (b"\xc1", pack([1, 2, 3]), pack({"name": "x"})):
        view.on_status(junk)
    assert view.malformed == 3 and view.status is None
