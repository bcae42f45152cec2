"""Bandwidth accounting as a researcher reads it: wire bytes, the receiver-level ledger, and the
HTML report of a run and of a sweep, opened in a real headless Chromium."""

import json
import re
import shutil
import subprocess
import textwrap

import pandas as pd
import pytest

from swarmbed.campaigns.sweep import load_sweep, run_sweep
from swarmbed.cli.main import main as cli
from swarmbed.launch.runner import run_experiment
from swarmbed.results.report import report, run_report, sweep_report
from tests.conftest import QUICKSTART, experiment

LOSSY = ("network.loss=0.2", "network.ledger=per_receiver")


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    base = tmp_path_factory.mktemp("report")
    return {
        name: run_experiment(experiment(*LOSSY, "run.seed=4"), base / name, progress=False).out_dir
        for name in ("a", "b")
    }


@pytest.fixture(scope="module")
def sweep_dir(tmp_path_factory):
    base = tmp_path_factory.mktemp("report_sweep")
    (base / "sweep.yaml").write_text(
        textwrap.dedent(f"""
        name: costs
        base: {QUICKSTART}
        seed: 5
        runs: 2
        scenarios:
          - {{name: fcg, set: {{agents.count: 3}}}}
          - {{name: cbba, set: {{agents.count: 3, allocator: {{name: cbba}}}}}}
    """)
    )
    run_sweep(load_sweep(base / "sweep.yaml", extra=["run.duration=150"]), base / "out", jobs=2, progress=False)
    return base / "out"


def test_wire_bytes_are_measured_per_process_and_cover_the_payload(runs):
    wire = json.loads((runs["a"] / "transport.json").read_text())
    t = wire["totals"]
    assert t["agents_reporting"] == 5 and set(wire["processes"]) == {"netem", *(f"agent_{i}" for i in range(5))}
    # each layer carries the one above it: radio payload < the samples that carry it < TCP bytes
    assert 0 < t["radio_payload_bytes"] < t["agent_sample_bytes_out"] < t["agent_tcp_bytes_sent"]
    assert t["agent_sample_bytes_in"] < t["agent_tcp_bytes_received"]
    assert t["overhead_ratio"] == pytest.approx(t["agent_tcp_bytes_sent"] / t["radio_payload_bytes"])
    for name, proc in wire["processes"].items():
        assert proc["tcp"]["sockets"] >= 1 and proc["tcp"]["segments_out"] > 0, name
    # what every agent sent reached the hub and was relayed: the proxy received at least the samples
    assert wire["processes"]["netem"]["tcp"]["received"] >= t["agent_sample_bytes_out"]


def test_receiver_ledger_has_a_row_per_copy_and_repeats_under_the_seed(runs):
    a, b = runs["a"], runs["b"]
    per_copy = pd.read_parquet(a / "network_ledger_receivers.parquet")
    summary = json.loads((a / "summary.json").read_text())
    net = summary["network"]
    assert len(per_copy) == net["copies"]
    outcomes = per_copy["outcome"].value_counts().to_dict()
    assert outcomes["delivered"] == net["delivered"]
    assert {k: v for k, v in outcomes.items() if k != "delivered"} == {k: v for k, v in net["dropped"].items() if v}
    assert (per_copy["receiver"] != per_copy["sender"]).all()
    for name in ("network_ledger_receivers.parquet", "network_ledger.csv", "summary.json"):
        assert (a / name).read_bytes() == (b / name).read_bytes(), name


def test_run_report_is_one_offline_page_whose_numbers_come_from_the_run(runs, tmp_path):
    run = runs["a"]
    out = report(run, tmp_path / "r.html")
    page = out.read_text()
    assert not re.search(r"<script[^>]+src=", page), "the page must not load scripts from anywhere"
    assert "cdn" not in re.sub(r"<script.*?</script>", "", page, flags=re.S).lower()
    summary = json.loads((run / "summary.json").read_text())
    wire = json.loads((run / "transport.json").read_text())["totals"]
    assert f"seed {summary['seed']}" in page and summary["name"] in page
    for value in (
        summary["network"]["messages_sent"],
        summary["network"]["bytes_sent"],
        wire["agent_tcp_bytes_sent"],
        summary["network"]["dropped"]["loss"],
    ):
        assert f">{value:,}<" in page
    assert "Copies delivered, sender by receiver" in page  # the receiver-level ledger's matrices
    _, figures = run_report(run)
    assert figures == page.count('class="plotly-graph-div"') >= 10


def test_sweep_report_has_intervals_and_the_cost_benefit_plots(sweep_dir):
    text, figures = sweep_report(sweep_dir)
    assert "fcg" in text and "cbba" in text and "± " in text
    assert "tasks_completed against network.bytes_sent" in text
    assert "tasks_completed against wire.agent_tcp_bytes_sent" in text
    assert figures >= 6
    table = pd.read_csv(sweep_dir / "sweep.csv")
    assert (table["wire.agent_tcp_bytes_sent"] > table["network.bytes_sent"]).all()


def test_report_command_names_a_folder_that_is_neither_run_nor_sweep(tmp_path, capsys):
    assert cli(["report", str(tmp_path)]) == 2
    assert f"{tmp_path}: neither a completed run" in capsys.readouterr().err


def test_every_run_writes_a_summary_its_model_accepts_and_a_crafted_one_is_named(runs, tmp_path, capsys):
    """summary.json has a model (swarmbed.records.summary): the coordinator checks it before writing,
    and a report of a summary that does not fit it is one line that names the field."""
    from swarmbed.records.run_folder import read_summary

    summary = read_summary(runs["a"] / "summary.json")
    assert summary.network.per_kind["claim"].model_extra["delivered"] > 0
    assert summary.outcome("tasks_completed") == summary.document["tasks_completed"] > 0
    assert (runs["a"] / "summary.json").read_text() == json.dumps(summary.document, indent=2, sort_keys=True) + "\n"
    document = summary.document
    bad = tmp_path / "bad"
    shutil.copytree(runs["a"], bad)
    document["network"]["per_kind"]["claim"]["loss"] = "many"
    (bad / "summary.json").write_text(json.dumps(document))
    assert cli(["report", str(bad)]) == 2
    assert "network.per_kind.claim.loss: Input should be a valid integer" in capsys.readouterr().err


CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")
# Installed before the page's own scripts: records every uncaught error and console.error, then
# writes them into the page once it has loaded, where --dump-dom shows them.
ERROR_PROBE = (
    "<script>window.__errors=[];addEventListener('error',e=>__errors.push(String(e.message)));"
    "const __ce=console.error;console.error=(...a)=>{__errors.push(a.join(' '));__ce(...a)};"
    "addEventListener('load',()=>setTimeout(()=>{const p=document.createElement('pre');"
    "p.id='errors';p.textContent=JSON.stringify(__errors);document.body.appendChild(p)},0));</script>"
)


NO_CHROMIUM = "no Chromium here (Debian: apt-get install chromium; .ci/run does)"


@pytest.mark.skipif(CHROMIUM is None, reason=NO_CHROMIUM)
@pytest.mark.parametrize("which", ["run", "sweep"])
def test_reports_render_every_plot_in_a_real_browser(which, runs, sweep_dir, tmp_path):
    folder = runs["a"] if which == "run" else sweep_dir
    assert_renders(report(folder, tmp_path / "page.html").read_text(), tmp_path)


def dump_dom(page: str, probe: str, tmp_path) -> str:
    """``page`` with ``probe`` (a script) first in its head, opened in headless Chromium at 1400 px
    wide: the DOM once it has loaded (where the probe writes what it found)."""
    assert CHROMIUM is not None
    probed = tmp_path / "probed.html"
    probed.write_text(page.replace("<head>", "<head>" + probe, 1))
    argv = [
        CHROMIUM,
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--window-size=1400,1000",
        "--user-data-dir=" + str(tmp_path / "profile"),
        "--virtual-time-budget=20000",
        "--dump-dom",
        probed.as_uri(),
    ]
    return subprocess.run(argv, capture_output=True, text=True, timeout=120).stdout


def assert_renders(page: str, tmp_path) -> None:
    """Open ``page`` in headless Chromium: no script error, and every plot drew its SVG."""
    assert CHROMIUM is not None
    dom = dump_dom(page, ERROR_PROBE, tmp_path)
    errors = re.search(r'<pre id="errors">(.*?)</pre>', dom, re.S)
    assert errors, "the page never finished loading"
    assert json.loads(errors.group(1).replace("&quot;", '"')) == []
    plots = re.split(r'id="(fig\d+)"', dom)[1:]
    names, bodies = plots[0::2], plots[1::2]
    assert len(names) == page.count('class="plotly-graph-div"') > 0
    for name, body in zip(names, bodies):
        assert 'class="main-svg"' in body, f"{name} did not render"  # the text up to the next plot's div


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    base = tmp_path_factory.mktemp("replay")
    return {
        rec: run_experiment(
            experiment(*LOSSY, "run.seed=4", f"run.record_trajectories={rec}"), base / str(rec), progress=False
        ).out_dir
        for rec in (True, False)
    }


def test_recording_for_a_replay_changes_no_result(recorded, runs):
    with_rec, without = recorded[True], recorded[False]
    assert (with_rec / "markers.csv").exists() and not (without / "markers.csv").exists()
    for name in (
        "summary.json",
        "timeseries.csv",
        "agents.csv",
        "network_ledger.csv",
        "network_ledger_receivers.parquet",
    ):
        assert (with_rec / name).read_bytes() == (without / name).read_bytes() == (runs["a"] / name).read_bytes()


def test_replay_is_a_movie_with_one_frame_per_chosen_tick(recorded, tmp_path):
    from PIL import Image

    from swarmbed.results.replay import replay

    run = recorded[True]
    markers = pd.read_csv(run / "markers.csv")
    assert set(markers["event"]) == {"appear", "vanish"} and (markers["label"].dropna() == "task").all()
    out, frames = replay(run, tmp_path / "m.gif", start=10, end=59, fps=5, every=2)
    assert frames == 25  # ticks 10, 12, ..., 58
    with Image.open(out) as movie:
        assert movie.n_frames == 25 and movie.size == (512, 512)
        first = movie.convert("RGB").tobytes()
        movie.seek(24)
        assert movie.convert("RGB").tobytes() != first  # the agents moved
    before = sorted(p.name for p in run.iterdir())
    assert cli(["replay", str(run), "-o", str(tmp_path / "all.gif"), "--every", "20"]) == 0
    assert sorted(p.name for p in run.iterdir()) == before  # nothing written into the run


def test_replay_frames_have_a_legend_and_each_agents_id(recorded, tmp_path, monkeypatch):
    """Issue 82 item 27: the frames had no legend and no agent ids."""
    from matplotlib.axes import Axes

    from swarmbed.results.replay import replay

    written, legends = [], []
    annotate, legend = Axes.annotate, Axes.legend
    monkeypatch.setattr(
        Axes, "annotate", lambda self, text, *a, **k: written.append(text) or annotate(self, text, *a, **k)
    )
    monkeypatch.setattr(Axes, "legend", lambda self, *a, **k: legends.append(k.get("handles")) or legend(self, *a, **k))
    replay(recorded[True], tmp_path / "m.gif", start=10, end=13)
    agents = pd.read_csv(recorded[True] / "trajectories.csv")["agent"].unique()
    assert {str(a) for a in agents} <= set(written)
    labels = [h.get_label() for h in legends[0]]
    assert "agent (its id beside it)" in labels and "task or victim" in labels


def test_replay_says_what_is_missing(runs, capsys):
    assert cli(["replay", str(runs["a"])]) == 2
    assert "run.record_trajectories=true" in capsys.readouterr().err


# After load: for every plot, its title, its x tick labels left to right, and each bar trace's
# horizontal extents (screen coordinates), written into the page for --dump-dom.
GEOMETRY_PROBE = (
    "<script>addEventListener('load',()=>setTimeout(()=>{const out=[];"
    "document.querySelectorAll('.plotly-graph-div').forEach(d=>{"
    "const ticks=[...d.querySelectorAll('.xtick text')].map(t=>[t.getBoundingClientRect().x,"
    "t.textContent]).sort((a,b)=>a[0]-b[0]).map(t=>t[1]);"
    "const bars=[...d.querySelectorAll('.trace.bars')].map(tr=>[...tr.querySelectorAll('.point path')]"
    ".map(p=>{const r=p.getBoundingClientRect();return [r.left,r.right]}));"
    "const title=(d.querySelector('.gtitle')||{}).textContent||'';out.push({title,ticks,bars})});"
    "const p=document.createElement('pre');p.id='geometry';p.textContent=JSON.stringify(out);"
    "document.body.appendChild(p)},500));</script>"
)


@pytest.mark.skipif(CHROMIUM is None, reason=NO_CHROMIUM)
def test_charts_order_agents_by_number_and_draw_paired_bars_side_by_side(tmp_path):
    """Twelve agents (so that string order, 0 1 10 11 2 ..., would show): every per-agent chart lists
    them by number, and the bars of a chart with two y axes stand beside each other, not on top."""
    assert CHROMIUM is not None
    run = run_experiment(
        experiment("agents.count=12", "run.duration=120", *LOSSY), tmp_path / "run", progress=False
    ).out_dir
    page = report(run, tmp_path / "page.html").read_text()
    dom = dump_dom(page, GEOMETRY_PROBE, tmp_path)
    found = re.search(r'<pre id="geometry">(.*?)</pre>', dom, re.S)
    assert found, "the page never finished loading"
    plots = {p["title"]: p for p in json.loads(found.group(1).replace("&quot;", '"'))}
    numbers = [str(i) for i in range(12)]
    for title in ("What each agent sent, layer by layer", "Bytes and messages each agent sent"):
        assert plots[title]["ticks"] == numbers, (title, plots[title]["ticks"])
    for title in ("Bytes and messages each agent sent", "Bytes and messages per kind"):
        left, right = plots[title]["bars"]
        assert len(left) == len(right) > 0
        for (l0, l1), (r0, r1) in zip(left, right):
            assert l1 <= r0 + 0.5 or r1 <= l0 + 0.5, f"{title}: bars overlap ({l0}-{l1} and {r0}-{r1})"


def test_a_run_with_the_radio_models_gets_the_radio_pages_and_outages_are_counted_between_deliveries(tmp_path):
    from swarmbed.results.radio_pages import loss_runs

    radio = [
        "agents.count=12",
        "run.duration=60",
        "run.stop_when_done=false",
        "network.range=null",
        "network.ledger=per_receiver",
        "network.propagation={shadowing_db: 6.0, tx_power_dbm: 40.0, fading: rayleigh}",
        "network.burst={mean_loss: 0.2, mean_burst: 3.0}",
        "network.delay={mean: 0.05, jitter: 0.02}",
    ]
    run = run_experiment(experiment(*radio), tmp_path / "radio", progress=False).out_dir
    html, _ = run_report(run)
    for title in ("Delivery ratio against distance", "Outages of working links", "Delay of delivered copies"):
        assert title in html
    plain, _ = run_report(run_experiment(experiment("run.duration=20"), tmp_path / "disk", progress=False).out_dir)
    assert "Delivery ratio against distance" not in plain  # no per-copy figures: no radio pages
    toy = pd.DataFrame(
        {
            "sender": [0] * 9 + [1] * 3,
            "receiver": [1] * 9 + [0] * 3,
            "tick": [*range(9), 0, 1, 2],
            "outcome": [
                "burst",
                "delivered",
                "burst",
                "burst",
                "delivered",
                "loss",
                "delivered",
                "burst",
                "burst",
                "delivered",
                "loss",
                "delivered",
            ],
        }
    )
    assert loss_runs(toy).tolist() == [2, 1, 1]  # the trailing run of link 0->1 never ended: not an outage
