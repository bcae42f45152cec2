"""The compiled kernels against their Python reference, bit for bit (on random calls and on the
calls of a real run), the reference against the formulas it computes, and the same bits whatever
the CPU's vector extensions."""

from __future__ import annotations

import hashlib
import math
import subprocess
import sys
from decimal import Decimal, getcontext

import numpy as np
import pytest

from swarmbed import kernels
from swarmbed.kernels import reference
from tests.conftest import ROOT, experiment

compiled = pytest.importorskip("swarmbed.kernels._compiled", reason="the kernels were not compiled at install")


def bits(a: np.ndarray) -> bytes:
    return np.ascontiguousarray(a).tobytes()


def exp_arguments(rng: np.random.Generator) -> np.ndarray:
    """Where the allocators call exp (small negative arguments), everywhere else, and every edge."""
    edges = [0.0, -0.0, 1e-300, -1e-300, 709.78, 709.79, 710.0, -708.4, -745.0, -745.2, -800.0, 800.0]
    edges += [np.inf, -np.inf, np.nan, math.log(2) / 2, -math.log(2) / 2, 0.5 * math.log(2) * 3]
    return np.concatenate([rng.uniform(-10, 0, 200_000), rng.uniform(-740, 705, 200_000), edges])


def test_compiled_exp_is_the_references_bit_for_bit():
    x = exp_arguments(np.random.default_rng(1))
    assert bits(compiled.exp(x)) == bits(reference.exp(x))


def test_exp_is_within_one_ulp_of_the_exact_value():
    """Against e**x to 40 digits (Python's decimal), on the allocators' range and beyond."""
    getcontext().prec = 40
    rng = np.random.default_rng(2)
    x = np.concatenate([rng.uniform(-10, 0, 2000), rng.uniform(-700, 700, 2000)])
    ours = reference.exp(x)
    exact = np.array([float(Decimal(v).exp()) for v in x.tolist()])
    ulps = np.abs(ours.view(np.int64) - exact.view(np.int64))
    assert ulps.max() <= 1
    edges = reference.exp(np.array([np.nan, np.inf, -np.inf, 710.0, -746.0, 0.0]))
    assert np.isnan(edges[0]) and edges[1] == np.inf and edges[2] == 0.0 and edges[3] == np.inf
    assert edges[4] == 0.0 and edges[5] == 1.0


def random_call(rng: np.random.Generator) -> tuple:
    """Arguments of a path_gains call: a path of 0-6 tasks, 0-40 candidates, some team slots."""
    n_path, n_cand = int(rng.integers(0, 7)), int(rng.integers(0, 41))
    px, py, cx, cy = (rng.uniform(-500, 500, n) for n in (n_path, n_path, n_cand, n_cand))
    pr, cr = rng.uniform(0.5, 200, n_path), rng.uniform(0.5, 200, n_cand)
    at_end = (rng.random(n_cand) < 0.2).astype(np.uint8)
    x0, y0 = rng.uniform(-500, 500, 2)
    speed, rate, log_l = rng.uniform(0.5, 12), rng.uniform(0.2, 3), math.log(rng.uniform(0.99, 0.99999))
    return float(x0), float(y0), speed, rate, log_l, cx, cy, cr, px, py, pr, at_end


def test_compiled_gains_are_the_references_bit_for_bit_on_random_calls():
    rng = np.random.default_rng(3)
    for _ in range(3000):
        args = random_call(rng)
        best, where = compiled.path_gains(*args)
        ref_best, ref_where = reference.path_gains(*args)
        assert bits(best) == bits(ref_best) and bits(where) == bits(ref_where.astype(np.int64))
        x0, y0, speed, _rate, log_l, cx, cy, cr = args[:8]
        assert bits(compiled.distance_gains(x0, y0, speed, log_l, cx, cy, cr)) == bits(
            reference.distance_gains(x0, y0, speed, log_l, cx, cy, cr)
        )


def path_score(x0, y0, speed, rate, log_l, tasks) -> float:
    """SPACE's Eq. 2 along a path, summed task by task: discount ** (arrival) * remaining, the
    arrival the travel so far plus the work of the tasks before."""
    t, x, y, total = 0.0, x0, y0, 0.0
    for tx, ty, r in tasks:
        t += math.hypot(tx - x, ty - y) / speed
        total += math.exp(log_l * t) * r
        t += r / rate
        x, y = tx, ty
    return total


def test_the_gains_are_the_marginal_scores_of_eq_2():
    """Each candidate's gain is the best, over insertion positions, of the path's score with it
    minus without it; the position is where that best is."""
    rng = np.random.default_rng(4)
    for _ in range(300):
        x0, y0, speed, rate, log_l, cx, cy, cr, px, py, pr, _ = random_call(rng)
        path = list(zip(px, py, pr))
        base = path_score(x0, y0, speed, rate, log_l, path)
        best, where = reference.path_gains(
            x0, y0, speed, rate, log_l, cx, cy, cr, px, py, pr, np.zeros(len(cx), np.uint8)
        )
        for c in range(len(cx)):
            margins = [
                path_score(x0, y0, speed, rate, log_l, [*path[:n], (cx[c], cy[c], cr[c]), *path[n:]]) - base
                for n in range(len(path) + 1)
            ]
            assert best[c] == pytest.approx(max(margins), rel=1e-9, abs=1e-9)
            assert margins[where[c]] == pytest.approx(max(margins), rel=1e-9, abs=1e-9)


def test_compiled_gains_are_the_references_on_the_calls_of_a_real_run(monkeypatch, tmp_path):
    """Every call CBBA made in a 12-robot MT-SR run, again through both."""
    from swarmbed.launch.inprocess import run_in_process

    calls = []

    def recording(*args):
        calls.append(tuple(np.copy(a) if isinstance(a, np.ndarray) else a for a in args))
        return compiled.path_gains(*args)

    monkeypatch.setattr(kernels, "path_gains", recording)
    exp = experiment(
        "allocator.name=cbba", "agents.count=12", "run.duration=800", base=ROOT / "experiments" / "space_mtsr.yaml"
    )
    run_in_process(exp, tmp_path / "run")
    assert len(calls) > 100 and max(len(c[8]) for c in calls) >= 2  # paths of several tasks
    for args in calls:
        best, where = compiled.path_gains(*args)
        ref_best, ref_where = reference.path_gains(*args)
        assert bits(best) == bits(ref_best) and bits(where) == bits(ref_where.astype(np.int64))


_PROBE = """
import hashlib, math, numpy as np
from swarmbed.kernels import reference, _compiled
from tests.test_kernels import exp_arguments, random_call
h = hashlib.sha256()
for impl in (reference, _compiled):
    h.update(impl.exp(exp_arguments(np.random.default_rng(5))).tobytes())
    rng = np.random.default_rng(6)
    for _ in range(300):
        best, where = impl.path_gains(*random_call(rng))
        h.update(best.tobytes() + where.astype(np.int64).tobytes())
print(h.hexdigest())
"""


@pytest.mark.slow  # two Python processes
def test_the_kernels_give_the_same_bits_with_and_without_avx512():
    """numpy's own exp changes its last bit with AVX-512 on or off; ours (both twins) does not."""
    import os

    plain = {**os.environ, "NPY_DISABLE_CPU_FEATURES": "X86_V4 AVX512_ICL AVX512_SPR AVX512F AVX512_SKX"}
    run = [sys.executable, "-c", _PROBE]
    here, without = (
        subprocess.run(run, capture_output=True, text=True, env=env, cwd=ROOT, check=True).stdout
        for env in (None, plain)
    )
    assert here == without and len(here) == 65


@pytest.mark.slow  # a run in a process whose compiled kernels cannot be imported
def test_without_the_compiled_kernels_a_run_says_so_once_and_writes_the_same_files(tmp_path):
    from swarmbed.launch.inprocess import run_in_process

    overrides = ["allocator.name=cbba", "agents.count=8", "run.duration=150"]
    base = ROOT / "experiments" / "space_mtsr.yaml"
    here = run_in_process(experiment(*overrides, base=base), tmp_path / "compiled")
    blocker = tmp_path / "site" / "sitecustomize.py"
    blocker.parent.mkdir()
    blocker.write_text(
        "import sys\n"
        "class NoCompiledKernels:\n"
        "    def find_spec(self, name, path=None, target=None):\n"
        "        if name == 'swarmbed.kernels._compiled':\n"
        "            raise ImportError('no compiled kernels: a machine without a C compiler at install')\n"
        "sys.meta_path.insert(0, NoCompiledKernels())\n"
    )
    import os

    env = {**os.environ, "PYTHONPATH": str(blocker.parent)}
    sets = [arg for value in overrides for arg in ("--set", value)]
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "swarmbed",
            "run",
            str(base),
            "--engine",
            "inprocess",
            "--no-progress",
            *sets,
            "--out",
            str(tmp_path / "python"),
        ],
        capture_output=True,
        text=True,
        env=env,
    )
    assert done.returncode == 0, done.stderr
    notices = [line for line in done.stderr.splitlines() if "compiled kernels were not built" in line]
    assert len(notices) == 1
    from tests.conftest import same_results

    same_results(here.out_dir, tmp_path / "python")


def test_the_package_uses_the_compiled_kernels_where_they_were_built():
    assert kernels.COMPILED and kernels.path_gains is compiled.path_gains and kernels.fallback_notice() is None
    digest = hashlib.sha256(bits(kernels.exp(np.linspace(-5, 0, 11)))).hexdigest()
    assert digest == hashlib.sha256(bits(reference.exp(np.linspace(-5, 0, 11)))).hexdigest()


def test_compiled_table_1_takes_the_scalar_tables_action_in_every_case():
    """Every combination of sender and receiver belief (agents NONE, 0-3; bids 0-2) and of how the
    sender's news of the two winners compares with the receiver's (older, same, newer), for receiver
    0 and sender 1: the compiled Table 1 gives plugins/consensus.table's action in all 3,600 cases
    (an entry the same on both sides left, an update to nobody a reset, as a receive applies them)."""
    import itertools

    from swarmbed.plugins.consensus import NONE, table

    agents, bids, cmps = (NONE, 0, 1, 2, 3), (0.0, 1.0, 2.0), (-1, 0, 1)
    out = 4  # agent ids 0-3; the last entry stands for NONE
    for a, ya, b, yb, cm, cn in itertools.product(agents, bids, agents, bids, cmps, cmps):
        if a == b and cm != cn:
            continue  # a winner named on both sides is one agent: one comparison
        mine, their = np.zeros(out + 1), np.zeros(out + 1)
        their[a if a >= 0 else out] = cm
        their[b if b >= 0 else out] = cn
        compare = {a: cm, b: cn}.get
        want = table(0, 1, a, ya, b, yb, lambda m: compare(m, 0))  # noqa: B023 (called at once)
        want = "reset" if want == "update" and a == NONE else want
        want = "leave" if (a, ya) == (b, yb) else want
        args = (np.array([a]), np.array([ya]), np.array([b]), np.array([yb]), mine, their)
        got = ("leave", "update", "reset")[compiled.table_actions(0, 1, *args)[0]]
        assert got == want, (a, ya, b, yb, cm, cn)


def test_a_receive_decides_as_task_by_task_in_python(monkeypatch):
    """Random beliefs, whole messages and deltas, tasks to ignore and a scope: a receive done by the
    compiled kernel leaves the winners, bids (in their maps' order) and stamps that Python task by
    task leaves (numpy's masks: tests/test_allocators.py)."""
    from swarmbed.plugins import consensus
    from tests.test_allocators import beliefs, copy_state, random_receive

    rng = np.random.default_rng(7)
    for trial in range(400):
        receiver, msg, ignore, within = random_receive(rng, trial)
        left = []
        for python in (True, False):
            st = copy_state(receiver)
            monkeypatch.setattr(kernels, "receive", None if python else compiled.receive)
            monkeypatch.setattr(consensus, "FEW_TASKS", 10**9 if python else 0)
            st.receive(1, msg, ignore=ignore, within=within)
            left.append(beliefs(st))
        assert left[0] == left[1], trial


def test_compiled_winners_changed_is_the_pythons():
    """What a message tells and what changed since the last one: the same map, in the same order,
    and the same changed entries, on random beliefs against random last messages."""
    from swarmbed.plugins.consensus import winners_changed

    rng = np.random.default_rng(8)
    for _ in range(500):
        tasks = rng.permutation(60)[: int(rng.integers(0, 60))].tolist()
        z = {t: int(rng.integers(0, 5)) for t in tasks}
        y = {t: float(rng.integers(0, 3)) for t in tasks}
        told = {t: (int(rng.integers(0, 5)), float(rng.integers(0, 3))) for t in rng.permutation(60)[:30].tolist()}
        ours, theirs = compiled.winners_changed(z, y, told), winners_changed(z, y, told)
        assert list(ours[0].items()) == list(theirs[0].items()) and ours[1] == theirs[1]


def test_compiled_packing_is_the_pythons():
    """A message's winner rows and timestamp columns packed by the kernels: the key and bytes of
    ``pack_rows`` / ``pack_columns`` on CBBA's keys, for every layout (narrow ids, wide ids, whole
    and fractional stamps, infinities), short and long vectors; what the kernels leave to the
    Python (a NaN stamp, ids past the widest layout, another type) they say with None."""
    from swarmbed.plugins.consensus import STAMP_KEYS, WINNER_KEYS
    from swarmbed.plugins.packed import pack_columns, pack_rows

    rng = np.random.default_rng(10)
    keys_seen = set()
    for trial in range(3000):
        n = int(rng.choice([1, 2, 5, 31, 32, 33, 120]))
        top_task = int(rng.choice([100, 65535, 65536, 4294967295]))
        top_agent = int(rng.choice([127, 128, 32767]))
        rows = [
            (int(rng.integers(0, top_task + 1)), int(rng.integers(-1, top_agent + 1)), float(rng.normal()) * 100)
            for _ in range(n)
        ]
        ours = compiled.pack_winners(rows)
        assert ours == pack_rows(rows, WINNER_KEYS), trial
        agents = np.sort(rng.choice(top_agent + 1, n, replace=False)).astype(np.int64)
        kind = trial % 5
        stamps = rng.integers(0, [100, 65535, 2**31 - 1, 2**40, 10][kind], n).astype(float)
        if kind == 4:
            stamps[int(rng.integers(0, n))] = float(rng.choice([0.5, np.inf, -np.inf, -3.0, 1e300]))
        ours = compiled.pack_stamps(agents, stamps)
        assert ours == pack_columns((agents, stamps), STAMP_KEYS), trial
        keys_seen.update([ours[0], compiled.pack_winners(rows)[0]])
    assert keys_seen == {"s", "r", "q", "p", "w", "v", "u"}  # every layout was made
    one = np.array([3], np.int64)
    assert compiled.pack_stamps(one, np.array([np.nan])) is None
    assert compiled.pack_stamps(np.array([40000], np.int64), np.array([1.0])) is None
    assert compiled.pack_stamps(np.zeros(0, np.int64), np.zeros(0)) is None
    assert compiled.pack_winners([(1, 2, 3)]) is None  # an int bid: the Python's
    assert compiled.pack_winners([(2**32, 1, 1.0)]) is None
    assert compiled.pack_winners([(True, 1, 1.0)]) is None
    assert compiled.pack_winners([]) is None


def test_the_bid_a_bundle_adds_is_the_same_in_each_way():
    """Algorithm 3's choice of the next bid: the compiled and the reference ``best_bid`` agree with
    each other and with the numpy formula CBBA used before them (eligible where the gain beats the
    known winning bid, positive, the first highest, none where it is not finite), on random gains
    with ties, zeros, NaN and infinities against random beliefs; ``task_columns`` reads the same
    floats as the attributes do."""
    from swarmbed.extension.view import TaskInfo
    from swarmbed.plugins.consensus import ConsensusState

    rng = np.random.default_rng(11)
    chosen = 0
    for trial in range(3000):
        st = ConsensusState(int(rng.integers(0, 5)))
        items = sorted(rng.choice(50, int(rng.integers(0, 12)), replace=False).tolist())
        gains = rng.choice([0.0, -1.0, 1.0, 2.0, 2.5, np.nan, np.inf, -np.inf], len(items))
        if trial % 3 == 0:
            gains = rng.normal(1.0, 1.0, len(items))
        for t in items:
            if rng.random() < 0.5:
                st.z[t], st.y[t] = int(rng.integers(0, 5)), float(rng.choice([0.0, 1.0, 2.0, 2.5]))
        eligible = np.array([st.eligible(t, g) for t, g in zip(items, gains)], dtype=bool)
        masked = np.where(eligible & (gains > 0), gains, -np.inf)
        before = int(np.argmax(masked)) if len(items) and np.isfinite(masked[int(np.argmax(masked))]) else -1
        ours = compiled.best_bid(st.agent_id, items, gains, st.z, st.y)
        assert ours == reference.best_bid(st.agent_id, items, gains, st.z, st.y) == before, trial
        chosen += ours >= 0
    assert 500 < chosen < 2900  # both outcomes were exercised
    tasks = [TaskInfo(int(i), float(x), float(y), float(r)) for i, x, y, r in rng.normal(0, 100, (40, 4))]
    tasks.append(TaskInfo(7, 1, -0.0, np.float64(3.5)))  # an int, a negative zero, a numpy float
    columns = compiled.task_columns(tasks)
    want = [np.array([getattr(t, f) for t in tasks], dtype=float) for f in ("x", "y", "remaining")]
    assert all(a.tobytes() == b.tobytes() for a, b in zip(columns, want))
    assert all(a.tobytes() == b.tobytes() for a, b in zip(reference.task_columns(tasks), want))


def test_a_crafted_message_is_received_alike_by_the_compiled_and_the_python_receive(monkeypatch):
    """Messages anyone in range could send: tasks out of order and named twice, winners that are no
    agent (negative, huge), NaN and infinite bids and stamps, negative zeros, stamps in every layout
    and torn, vectors of random bytes. The compiled
    receive leaves the maps and stamps that Python task by task leaves, and neither raises."""
    from swarmbed.plugins import consensus
    from swarmbed.plugins.consensus import STAMP_KEYS, WINNER_KEYS, ConsensusState

    rng = np.random.default_rng(9)
    odd_bids = np.array([np.nan, np.inf, -np.inf, 0.0, -0.0, 1.0, 2.0, 1e308])
    changed = 0
    for trial in range(400):
        msg: dict = {"t": float(rng.choice([0.0, 1.0, 3.0, np.nan, np.inf]))}
        if trial % 2:
            msg["d"] = 1
        key, dtype = WINNER_KEYS[int(rng.integers(0, len(WINNER_KEYS)))]
        n = int(rng.integers(0, 30))
        if trial % 5 == 0:
            msg[key] = rng.bytes(n * dtype.itemsize + int(rng.integers(0, 2)))  # random bytes, maybe torn
        else:
            rows = np.zeros(n, dtype)
            rows["task"] = rng.integers(0, 40, n)
            rows["winner"] = rng.choice([-1, -5, 0, 1, 2, 3, 100, np.iinfo(dtype["winner"]).max], n)
            rows["bid"] = rng.choice(odd_bids, n)
            msg[key] = rows.tobytes()
        skey, sdtype = STAMP_KEYS[int(rng.integers(0, len(STAMP_KEYS)))]
        stamps = np.zeros(int(rng.integers(0, 6)), sdtype)
        stamps["agent"] = rng.integers(-2, 8, len(stamps))
        if sdtype["stamp"].kind == "f":
            stamps["stamp"] = rng.choice([0.0, -0.0, 1.0, 2.0, np.nan, np.inf, -np.inf], len(stamps))
        else:
            info = np.iinfo(sdtype["stamp"])
            stamps["stamp"] = rng.choice([0, 1, 2, info.max, info.min], len(stamps))
        raw = stamps.tobytes()
        msg[skey] = raw + b"x" if trial % 7 == 0 else raw  # now and then torn: no stamps
        receiver = ConsensusState(0)
        receiver.now = 1.0
        receiver.stamps = rng.choice([-np.inf, 0.0, 1.0, 2.0], int(rng.integers(1, 10)))
        receiver.stamps[0] = -np.inf  # never news of itself
        for t in range(40):
            if rng.random() < 0.6:
                receiver.z[t], receiver.y[t] = int(rng.integers(0, 4)), float(rng.choice(odd_bids))
        states = []
        for compiled_receive in (False, True):
            st = ConsensusState(0)
            st.now, st.z, st.y, st.stamps = receiver.now, dict(receiver.z), dict(receiver.y), receiver.stamps.copy()
            monkeypatch.setattr(kernels, "receive", compiled.receive if compiled_receive else None)
            monkeypatch.setattr(consensus, "FEW_TASKS", 0 if compiled_receive else 10**9)
            st.receive(1, msg, ignore={3}, within=set(range(0, 40, 2)) if trial % 3 == 0 else None)
            states.append((repr(list(st.z.items())), repr(list(st.y.items())), st.stamps.tobytes()))
        assert states[0] == states[1], trial
        changed += states[0][:2] != (repr(list(receiver.z.items())), repr(list(receiver.y.items())))
    assert changed > 100  # the messages took decisions, not only refusals
