"""A Slurm cluster on one machine: slurmctld here, one slurmd per stand-in host (a network namespace of
:mod:`.netns`), for tests and benchmarks of ``swarmbed run --slurm`` (root, iproute2 and Debian's
``slurm-wlm`` needed).

Each slurmd enters only its namespace's network (``nsenter --net``): ``ip netns exec`` would also
remount ``/sys``, and slurmd wants the machine's cgroup file system. The nodes are ``n1``..``nK``
with the namespaces' addresses as ``NodeAddr``; the controller listens on the bridge. Everything
runs from a private folder and its own ``slurm.conf`` (``SLURM_CONF`` in :attr:`SlurmLab.env`), on
ports of its own, so a cluster this machine may belong to is not touched.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path

from swarmbed.files import safefiles
from swarmbed.hosts.netns import Lab, LabError
from swarmbed.wire.zenoh_session import free_port

DAEMONS = ("slurmctld", "slurmd", "srun", "salloc", "scontrol", "sinfo", "munged")


def why_not() -> str | None:
    """Why a Slurm cluster cannot be started here, or None (namespaces aside: :func:`.netns.why_not`)."""
    missing = [d for d in DAEMONS if shutil.which(d) is None and not Path("/usr/sbin", d).exists()]
    if missing:
        return f"Slurm is not installed ({', '.join(missing)} missing: apt-get install slurm-wlm)"
    if not Path("/etc/munge/munge.key").exists():
        return "munge has no key (/etc/munge/munge.key): slurm-wlm's install makes one"
    return None


def _tool(name: str) -> str:
    return shutil.which(name) or str(Path("/usr/sbin", name))


@dataclass
class SlurmLab:
    lab: Lab
    folder: Path
    nodes: list[str] = field(default_factory=list)
    daemons: list[subprocess.Popen] = field(default_factory=list)

    @property
    def env(self) -> dict[str, str]:
        """What a Slurm command of this cluster needs in its environment."""
        return {**os.environ, "SLURM_CONF": str(self.folder / "slurm.conf")}

    def sinfo(self) -> str:
        return subprocess.run(
            [_tool("sinfo"), "-h", "-o", "%N %t"], env=self.env, capture_output=True, text=True, check=False
        ).stdout.strip()

    def close(self) -> None:
        subprocess.run([_tool("scancel"), "--full", "--user", "root"], env=self.env, capture_output=True, check=False)
        for proc in self.daemons:
            if proc.poll() is None:
                proc.terminate()
        for proc in self.daemons:
            try:
                proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def _munge() -> None:
    """munged, once per machine: slurm's daemons and commands authenticate through its socket."""
    if subprocess.run(["pgrep", "-x", "munged"], capture_output=True).returncode == 0:
        return
    Path("/run/munge").mkdir(parents=True, exist_ok=True)
    shutil.chown("/run/munge", "munge", "munge")
    started = subprocess.run(["runuser", "-u", "munge", "--", _tool("munged")], capture_output=True, timeout=30)
    if started.returncode != 0:  # a key or log folder owned by root, as some images leave them
        subprocess.run([_tool("munged"), "--force"], capture_output=True, check=True, timeout=30)


def make_slurm_lab(lab: Lab, folder: Path, nodes: int) -> SlurmLab:
    """A cluster of ``nodes`` stand-in hosts on ``lab``, every node idle; LabError where it cannot start."""
    reason = why_not()
    if reason:
        raise LabError(reason)
    safefiles.make_folder(folder)
    cluster = SlurmLab(lab, folder)
    ctld_port = free_port(lab.bridge_ip)
    slurmd_port = free_port(lab.bridge_ip)
    lines = [
        f"ClusterName=swb{lab.net}",
        f"SlurmctldHost={os.uname().nodename}({lab.bridge_ip})",
        f"SlurmctldPort={ctld_port}",
        f"SlurmdPort={slurmd_port}",
        "SlurmUser=root",
        "SlurmdUser=root",
        "AuthType=auth/munge",
        f"StateSaveLocation={folder}/state",
        f"SlurmdSpoolDir={folder}/spool_%n",
        f"SlurmdPidFile={folder}/slurmd_%n.pid",
        f"SlurmdLogFile={folder}/slurmd_%n.log",
        f"SlurmctldPidFile={folder}/slurmctld.pid",
        f"SlurmctldLogFile={folder}/slurmctld.log",
        "ProctrackType=proctrack/linuxproc",
        "TaskPlugin=task/none",
        "JobAcctGatherType=jobacct_gather/none",
        "SelectType=select/cons_tres",
        "SelectTypeParameters=CR_Core",
        "ReturnToService=2",
        "MpiDefault=none",
        "SwitchType=switch/none",
    ]
    # memory is not a consumable here (CR_Core); slurmd drains a node that claims more than it has
    memory_mb = int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") * 0.9) // 2**20
    namespaces = []
    for k in range(1, nodes + 1):
        ns = lab.add_namespace()
        namespaces.append(ns)
        cluster.nodes.append(f"n{k}")
        lines.append(f"NodeName=n{k} NodeAddr={lab.address(ns)} CPUs={os.cpu_count() or 1} RealMemory={memory_mb}")
    lines.append(f"PartitionName=lab Nodes=n[1-{nodes}] Default=YES MaxTime=INFINITE State=UP OverSubscribe=YES")
    safefiles.make_folder(folder / "state")
    safefiles.write_text(folder / "slurm.conf", "\n".join(lines) + "\n")
    conf = str(folder / "slurm.conf")
    try:
        _munge()
        with safefiles.open_fresh(folder / "slurmctld.out") as noise:  # its start-up lines stay out of a terminal
            ctld = [_tool("slurmctld"), "-D", "-i", "-f", conf]
            cluster.daemons.append(subprocess.Popen(ctld, env=cluster.env, stdout=noise, stderr=noise))
        for node, ns in zip(cluster.nodes, namespaces):
            cmd = ["nsenter", f"--net=/var/run/netns/{ns}", _tool("slurmd"), "-D", "-f", conf, "-N", node]
            cluster.daemons.append(subprocess.Popen(cmd, env=cluster.env, stderr=subprocess.DEVNULL))
        deadline = time.monotonic() + 60
        while True:
            states = dict(line.split() for line in cluster.sinfo().splitlines() if len(line.split()) == 2)
            if states and all(s.startswith("idle") for s in states.values()):
                return cluster
            if time.monotonic() > deadline:
                raise LabError(f"slurm nodes not idle after 60 s: {states or 'no answer'} (logs in {folder})")
            time.sleep(0.5)
    except (OSError, subprocess.SubprocessError) as exc:
        cluster.close()
        raise LabError(f"cannot start slurm: {exc}") from None
    except LabError:
        cluster.close()
        raise
