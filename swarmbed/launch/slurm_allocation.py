"""One run over the nodes of a Slurm allocation: ``swarmbed run EXP --slurm`` inside ``salloc`` or an
``sbatch`` script.

Slurm allocates the machines and starts one host daemon on each (``srun``); Zenoh carries the run
between them; swarmbed schedules nothing itself. The launching process (where ``swarmbed run`` was
called: the batch script's node, or the submitting machine under ``salloc``) keeps the hub, the
coordinator and the netem proxy, and writes the run folder; every agent runs on a node of the
allocation, in contiguous blocks of ids (node k of K takes the k-th block). The daemons' routers
connect to the hub at the address this machine has towards the nodes, with explicit endpoints
(scouting off, as every swarmbed session) and per-run host credentials the hub admits for that
node's name only. Placement never enters ``config.yaml``, so the result files are those of the
same experiment on one machine.

What Slurm gives: ``SLURM_JOB_ID`` and ``SLURM_JOB_NODELIST`` (expanded by ``scontrol show
hostnames``), each node's address (``scontrol show node``'s ``NodeAddr``). Each daemon is its own
job step (``srun --nodes=1 --ntasks=1 --nodelist=NODE --overlap``), stopped with SIGTERM when the
run ends (srun hands the signal to the daemon, which stops its agents).
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from swarmbed.files import safefiles
from swarmbed.files.safefiles import open_fresh
from swarmbed.launch.launcher import python_env
from swarmbed.wire.credentials import CredentialsError, Identity, check_host_name, write_credentials
from swarmbed.wire.keys import proxy_name
from swarmbed.wire.zenoh_session import free_port


class SlurmError(RuntimeError):
    """Why a run cannot use the Slurm allocation it is in: one line."""


@dataclass(frozen=True)
class Allocation:
    """The allocation a run was launched in: its job, its nodes in Slurm's order, and the address
    each is reached at."""

    job_id: str
    nodes: tuple[str, ...]
    addresses: Mapping[str, str]


def _scontrol(*args: str, env: Mapping[str, str] | None = None) -> str:
    try:
        done = subprocess.run(["scontrol", *args], capture_output=True, text=True, timeout=30, env=env, check=False)
    except FileNotFoundError:
        raise SlurmError("--slurm: scontrol is not installed here (Slurm's client commands are needed)") from None
    except subprocess.TimeoutExpired:
        raise SlurmError(f"--slurm: scontrol {' '.join(args)} did not answer in 30 s") from None
    if done.returncode != 0:
        raise SlurmError(f"--slurm: scontrol {' '.join(args)}: {done.stderr.strip() or done.returncode}")
    return done.stdout


#: a Slurm job id: digits, an array task's _N or a het job's +N (never a path: it names folders)
JOB_ID = re.compile(r"[0-9]{1,12}([_+][0-9]{1,9})?")


def _usable(node: str) -> bool:
    """Whether ``node`` can name a host: the one host-name rule of placements and host daemons."""
    try:
        check_host_name(node)
    except CredentialsError:
        return False
    return True


def read_allocation(env: Mapping[str, str] | None = None) -> Allocation:
    """The allocation this process runs in, from Slurm's environment; SlurmError outside one."""
    env = os.environ if env is None else env
    job, nodelist = env.get("SLURM_JOB_ID"), env.get("SLURM_JOB_NODELIST")
    if not job or not nodelist:
        raise SlurmError("--slurm: not inside a Slurm allocation (SLURM_JOB_ID unset): run it under salloc or sbatch")
    if not JOB_ID.fullmatch(job):
        raise SlurmError(f"--slurm: SLURM_JOB_ID {job[:40]!r} is not a Slurm job id (digits)")
    nodes = tuple(_scontrol("show", "hostnames", nodelist, env=dict(env)).split())
    bad = [n for n in nodes if not _usable(n)]
    if not nodes or bad:
        raise SlurmError(f"--slurm: job {job}'s node list {nodelist!r} gives no usable node names: {bad or 'none'}")
    addresses = {}
    for node in nodes:
        fields = dict(f.split("=", 1) for f in _scontrol("show", "node", "-o", node, env=dict(env)).split() if "=" in f)
        addresses[node] = fields.get("NodeAddr") or node
    return Allocation(job, nodes, addresses)


def address_towards(addresses: Sequence[str]) -> str:
    """This machine's address on the route to the first of ``addresses``: where the nodes reach it
    (no packet is sent: a UDP socket's connect only picks the route)."""
    host = addresses[0]
    try:
        target = socket.getaddrinfo(host, 9, socket.AF_INET, socket.SOCK_DGRAM)[0][4][0]
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            probe.connect((target, 9))
            return str(probe.getsockname()[0])
    except OSError as exc:
        raise SlurmError(f"--slurm: no route from here to node address {host!r}: {exc.strerror or exc}") from None


def spread(nodes: Sequence[str], n_agents: int) -> dict[str, str]:
    """The placement of ``n_agents`` over ``nodes``: contiguous blocks of ids, the first
    ``n_agents % len(nodes)`` nodes one agent more; a node left without agents is left out."""
    placement = {}
    start = 0
    per, extra = divmod(n_agents, len(nodes))
    for k, node in enumerate(nodes):
        count = per + (1 if k < extra else 0)
        if count:
            placement[node] = f"{start}-{start + count - 1}"
        start += count
    return placement


@dataclass
class SlurmHosts:
    """One host daemon per node of ``allocation``, each a job step; a context manager that stops
    them (and removes their credentials) on exit. ``hub``: the endpoint the run's hub must listen
    on; ``identities``: the hosts' credentials it must admit."""

    allocation: Allocation
    logs: Path
    env: Mapping[str, str] | None = None
    hub: str = ""
    identities: list[Identity] = field(default_factory=list)
    steps: dict[str, subprocess.Popen] = field(default_factory=dict)
    _private: Path | None = None

    def __enter__(self) -> SlurmHosts:
        address = address_towards([self.allocation.addresses[n] for n in self.allocation.nodes])
        self.hub = f"tcp/{address}:{free_port(address)}"
        missing = [tool for tool in ("srun", "squeue", "scancel") if shutil.which(tool) is None]
        if missing:
            raise SlurmError(f"--slurm: {', '.join(missing)} not installed here (Slurm's client commands are needed)")
        # the daemons read their credentials from the shared file system Slurm jobs run on
        self._private = Path(tempfile.mkdtemp(prefix=f"swarmbed-slurm-{self.allocation.job_id}-", dir=self.logs))
        try:
            for node in self.allocation.nodes:
                self._start(node)
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def _start(self, node: str) -> None:
        assert self._private is not None
        identity = Identity.new(f"host-{node}", "host", host=node)
        self.identities.append(identity)
        credentials = write_credentials(self._private / f"{node}.credentials", identity)
        step = [
            "srun",
            "--nodes=1",
            "--ntasks=1",
            f"--nodelist={node}",
            "--overlap",
            f"--job-name=swarmbed-host-{node}",
            "--kill-on-bad-exit=0",
            sys.executable,
            "-m",
            "swarmbed",
            "host",
            "--name",
            node,
            "--connect",
            self.hub,
            "--logs",
            str(self.logs / node),
            "--credentials",
            str(credentials),
        ]
        env = dict(python_env() if self.env is None else {**python_env(), **self.env})
        with open_fresh(self.logs / f"host_{node}.log") as log:
            self.steps[node] = subprocess.Popen(
                step, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, env=env, start_new_session=True
            )

    def proxy_command(self, shard: int, args: list[str]) -> list[str]:
        """Proxy ``shard`` of a radio split over proxies as a job step on node ``shard`` mod the
        nodes, connecting to the hub where the daemons do, with its own credentials copied to the
        shared private folder (the run's own are in this machine's temporary folder)."""
        assert self._private is not None
        node = self.allocation.nodes[shard % len(self.allocation.nodes)]
        args = list(args)
        args[args.index("--connect") + 1] = self.hub
        if "--credentials" in args:
            at = args.index("--credentials") + 1
            shared = self._private / f"{proxy_name(shard)}.credentials"
            if not shared.exists():
                safefiles.write_bytes(shared, safefiles.read_regular(args[at], 1 << 20), mode=0o600)
            args[at] = str(shared)
        step = ["srun", "--nodes=1", "--ntasks=1", f"--nodelist={node}", "--overlap"]
        step += [f"--job-name=swarmbed-netem-{shard}", "--kill-on-bad-exit=0"]
        return [*step, sys.executable, "-m", "swarmbed.netem", *args]

    def __exit__(self, *exc: object) -> None:
        self._terminate_steps()
        for proc in self.steps.values():
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:  # srun on SIGTERM kills its step's tasks, then exits
                proc.send_signal(signal.SIGTERM)
                try:
                    proc.wait(timeout=30)
                except subprocess.TimeoutExpired:
                    os.killpg(proc.pid, signal.SIGKILL)
                    proc.wait()
        if self._private is not None:
            safefiles.remove_tree(self._private)

    def _terminate_steps(self) -> None:
        """SIGTERM to each daemon through Slurm (``scancel --signal``), which a daemon takes as its
        stop: it stops its agents and exits, and its srun with it. (srun itself, sent SIGTERM, kills
        its step's tasks outright.)"""
        listing = subprocess.run(
            ["squeue", "--steps", "-h", "-j", self.allocation.job_id, "-o", "%i %j"],
            capture_output=True,
            text=True,
            timeout=30,
            env=None if self.env is None else dict(self.env),
            check=False,
        ).stdout.split("\n")
        ours = {f"swarmbed-host-{node}" for node in self.steps}
        for line in listing:
            step, _, name = line.strip().partition(" ")
            if name in ours:
                subprocess.run(["scancel", "--signal=TERM", step], capture_output=True, timeout=30, check=False)
