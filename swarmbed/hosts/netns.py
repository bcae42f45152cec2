"""Stand-in hosts on one machine: Linux network namespaces on a bridge, one ``swarmbed host`` in each.

For tests and benchmarks of runs over several hosts, and for trying placement and swaps without a
second machine (root and iproute2 needed).

The bridge lives in the default namespace with address 198.18.<net>.1 (198.18.0.0/15 is set aside
for network benchmarks: nothing real lives there); host i gets its own namespace, a veth pair into
the bridge, the address 198.18.<net>.(10 + i), and its daemon's router connects to the run's hub on
the bridge. Everything is removed again when the fixture ends, processes included.
"""

from __future__ import annotations

import os
import secrets
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

from swarmbed.files.safefiles import make_folder, open_fresh, own_folders, remove_tree
from swarmbed.launch.hub import HubOptions
from swarmbed.launch.launcher import python_env
from swarmbed.wire.credentials import Identity, write_credentials
from swarmbed.wire.zenoh_session import free_port


def _ip(*args: str, ns: str | None = None, check: bool = True) -> subprocess.CompletedProcess:
    cmd = ["ip", *(["netns", "exec", ns, "ip"] if ns else []), *args]
    return subprocess.run(cmd, capture_output=True, text=True, check=check)


def why_not() -> str | None:
    """Why namespaces cannot be made here, or None."""
    if sys.platform != "linux":
        return "network namespaces need Linux"
    if os.geteuid() != 0:
        return "creating network namespaces needs root"
    if shutil.which("ip") is None:
        return "the ip command (iproute2) is not installed"
    return None


@dataclass
class Lab:
    tag: str
    net: int
    logs: Path
    namespaces: list[str] = field(default_factory=list)
    links: list[str] = field(default_factory=list)
    daemons: dict[str, subprocess.Popen] = field(default_factory=dict)
    identities: dict[str, Identity] = field(default_factory=dict)  # each daemon's host credentials
    hub_port: int = 0

    @property
    def bridge_ip(self) -> str:
        return f"198.18.{self.net}.1"

    @property
    def admitted(self) -> list[Identity]:
        """The hosts' credentials."""
        return list(self.identities.values())

    def hub_options(self, *more: Identity) -> HubOptions:
        """A run's hub for this lab: listening where the hosts' routers connect, admitting their
        daemons and ``more`` (operators)."""
        return HubOptions(listen=(self.hub,), admit=(*self.admitted, *more))

    @property
    def hub(self) -> str:
        """Where the run's hub listens for the hosts' routers."""
        return f"tcp/{self.bridge_ip}:{self.hub_port}"

    def add_host(self, name: str) -> str:
        """A namespace for host ``name`` with its daemon running; returns the namespace."""
        ns = self.add_namespace()
        self.start_daemon(name, ns)
        return ns

    def address(self, ns: str) -> str:
        """The address of stand-in host ``ns`` on the bridge."""
        return f"198.18.{self.net}.{10 + self.namespaces.index(ns)}"

    def add_namespace(self) -> str:
        """A namespace on the bridge, nothing running in it; returns its name. Its default route is
        the bridge, so it reaches every address of this machine, as a machine on a LAN does."""
        i = len(self.namespaces)
        ns, veth = f"{self.tag}n{i}", f"{self.tag}v{i}"
        _ip("netns", "add", ns)
        self.namespaces.append(ns)
        _ip("link", "add", veth, "type", "veth", "peer", "name", f"{veth}p")
        self.links.append(veth)
        _ip("link", "set", f"{veth}p", "netns", ns)
        _ip("link", "set", veth, "master", f"{self.tag}br")
        _ip("link", "set", veth, "up")
        _ip("addr", "add", f"198.18.{self.net}.{10 + i}/24", "dev", f"{veth}p", ns=ns)
        _ip("link", "set", f"{veth}p", "up", ns=ns)
        _ip("link", "set", "lo", "up", ns=ns)
        _ip("route", "add", "default", "via", self.bridge_ip, ns=ns)
        return ns

    def start_daemon(self, name: str, ns: str) -> None:
        log = open_fresh(self.logs / f"host_{name}.log")
        identity = self.identities.setdefault(name, Identity.new(f"host-{name}", "host", host=name))
        credentials = write_credentials(self.logs / f"host_{name}.credentials", identity)
        cmd = [
            "ip",
            "netns",
            "exec",
            ns,
            sys.executable,
            "-m",
            "swarmbed",
            "host",
            "--name",
            name,
            "--connect",
            self.hub,
            "--listen",
            "tcp/127.0.0.1:7447",
            "--logs",
            str(self.logs / name),
            "--credentials",
            str(credentials),
        ]
        self.daemons[name] = subprocess.Popen(
            cmd, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, env=python_env()
        )
        log.close()

    def kill_host(self, name: str) -> None:
        """The machine dies: every process in its namespace is killed at once."""
        ns = self.namespaces[list(self.daemons).index(name)]
        daemon = self.daemons[name]
        # The daemon itself is killed by its pid too: just after start it may still be ``ip netns
        # exec`` on its way into the namespace, where ``ip netns pids`` does not list it yet.
        deadline = time.monotonic() + 10
        while True:
            pids = {int(p) for p in _ip("netns", "pids", ns, check=False).stdout.split()}
            if daemon.poll() is None:
                pids.add(daemon.pid)
            if not pids:
                break
            if time.monotonic() > deadline:
                raise LabError(f"processes {sorted(pids)} of stand-in host {name!r} survive SIGKILL")
            for pid in pids:
                try:
                    os.kill(pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
            time.sleep(0.05)
        daemon.wait(timeout=10)
        for private in own_folders(Path(tempfile.gettempdir()), f"swarmbed-host-{name}-*"):  # its identities
            remove_tree(private)

    def pids(self, name: str) -> list[str]:
        ns = self.namespaces[list(self.daemons).index(name)]
        return _ip("netns", "pids", ns, check=False).stdout.split()

    def close(self) -> None:
        for proc in self.daemons.values():
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
        for proc in self.daemons.values():
            try:
                proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        for ns in self.namespaces:
            for pid in _ip("netns", "pids", ns, check=False).stdout.split():
                try:
                    os.kill(int(pid), signal.SIGKILL)
                except ProcessLookupError:
                    pass
            _ip("netns", "del", ns, check=False)
        for link in self.links:
            _ip("link", "del", link, check=False)
        _ip("link", "del", f"{self.tag}br", check=False)


@dataclass
class Cut:
    """A namespace whose links were taken down, and what brings it back (:func:`cut_off`)."""

    namespace: str
    links: list[str]
    routes: list[str]


def namespace_of(pid: int) -> str | None:
    """The named network namespace (``ip netns``) process ``pid`` runs in; None where it runs in
    this process's own namespace, in an unnamed one, or where that cannot be known."""
    try:
        if os.stat(f"/proc/{pid}/ns/net").st_ino == os.stat("/proc/self/ns/net").st_ino:
            return None
        found = _ip("netns", "identify", str(pid), check=False).stdout.strip()
    except OSError:
        return None
    return found or None


def cut_off(ns: str) -> Cut:
    """Take every link of namespace ``ns`` but loopback down: the host it stands for drops off the
    network (its processes keep running; TCP peers see silence, then their lease runs out)."""
    listing = _ip("-o", "link", "show", ns=ns).stdout.splitlines()
    links = [line.split(":")[1].strip().split("@")[0] for line in listing if ":" in line]
    links = [link for link in links if link != "lo"]
    routes = [r for r in _ip("route", "show", ns=ns).stdout.splitlines() if r.strip()]
    for link in links:
        _ip("link", "set", link, "down", ns=ns)
    return Cut(ns, links, routes)


def reconnect(cut: Cut) -> None:
    """Bring a :func:`cut_off` namespace's links up again, with every route it had."""
    for link in cut.links:
        _ip("link", "set", link, "up", ns=cut.namespace)
    for route in cut.routes:  # a link's own prefix comes back with it; routes through it do not
        _ip("route", "replace", *route.split(), ns=cut.namespace, check=False)


class LabError(RuntimeError):
    pass


def make_lab(logs: Path) -> Lab:
    """A bridge for stand-in hosts (``lab.add_host(name)`` adds one); LabError where it cannot be made."""
    reason = why_not()
    if reason:
        raise LabError(reason)
    tag = "sb" + secrets.token_hex(2)
    lab = Lab(tag, net=int(secrets.randbelow(200)) + 20, logs=logs)
    make_folder(logs)
    try:
        _ip("link", "add", f"{tag}br", "type", "bridge")
        _ip("addr", "add", f"{lab.bridge_ip}/24", "dev", f"{tag}br")
        _ip("link", "set", f"{tag}br", "up")
    except subprocess.CalledProcessError as exc:
        lab.close()
        raise LabError(f"cannot create a bridge for stand-in hosts: {exc.stderr.strip()}") from None
    time.sleep(0.2)  # the bridge address must be usable before anything binds to it
    lab.hub_port = free_port(lab.bridge_ip)
    return lab
