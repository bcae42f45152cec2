"""TLS between machines: certificates made by swarmbed certs, a host daemon that reaches the hub
over a tls/ endpoint with mutual authentication, and sessions without the lab's CA refused."""

import signal
import subprocess
import sys
from pathlib import Path

import pytest
import zenoh

from swarmbed.launch.hub import HubOptions
from swarmbed.launch.runner import run_experiment
from swarmbed.wire.credentials import CredentialsError, Identity, write_credentials
from swarmbed.wire.zenoh_session import free_loopback_endpoint, tls_settings, zenoh_config
from tests.conftest import experiment, reference_run, same_results

x509 = pytest.importorskip("cryptography.x509", reason="swarmbed certs needs the tls extra (cryptography)")


def certs(folder: Path, *machines: str) -> None:
    subprocess.run(
        [sys.executable, "-m", "swarmbed", "certs", str(folder), *machines],
        check=True,
        capture_output=True,
        text=True,
        timeout=60,
    )


def test_certs_make_a_ca_and_one_certificate_per_machine(tmp_path):
    certs(tmp_path, "hub=127.0.0.1,hub.lab", "labpc2")
    for name in ("ca", "hub", "labpc2"):
        assert (tmp_path / f"{name}.key").stat().st_mode & 0o777 == 0o600
    hub = x509.load_pem_x509_certificate((tmp_path / "hub.pem").read_bytes())
    ca = x509.load_pem_x509_certificate((tmp_path / "ca.pem").read_bytes())
    names = hub.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert {str(n.value) for n in names} == {"hub", "127.0.0.1", "hub.lab"}
    assert hub.issuer == ca.subject
    ca_before = (tmp_path / "ca.pem").read_bytes()
    certs(tmp_path, "labpc3")  # a machine added later: same CA
    assert (tmp_path / "ca.pem").read_bytes() == ca_before
    assert x509.load_pem_x509_certificate((tmp_path / "labpc3.pem").read_bytes()).issuer == ca.subject
    with pytest.raises(CredentialsError, match="nobody.pem"):
        tls_settings(tmp_path, "nobody")
    bad = subprocess.run(
        [sys.executable, "-m", "swarmbed", "certs", str(tmp_path), "no/slash"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert bad.returncode == 2 and "no/slash" in bad.stderr


def test_a_host_over_tls_gives_the_all_local_results_and_strangers_are_refused(tmp_path):
    lab, elsewhere = tmp_path / "lab", tmp_path / "elsewhere"
    certs(lab, "hub=127.0.0.1", "h1")
    certs(elsewhere, "intruder")
    hub = free_loopback_endpoint().replace("tcp/", "tls/")
    host_id = Identity.new("host-h1", "host", host="h1")
    creds = write_credentials(tmp_path / "h1.credentials", host_id)
    daemon = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "swarmbed",
            "host",
            "--name",
            "h1",
            "--connect",
            hub,
            "--tls",
            str(lab),
            "--credentials",
            str(creds),
            "--logs",
            str(tmp_path / "h1"),
        ],
        stdout=subprocess.DEVNULL,
        stderr=open(tmp_path / "host.log", "wb"),
    )
    refused = {}
    # an admitted operator's valid credentials, the lab's CA trusted, but no certificate of its own:
    # only mutual TLS refuses it (the other strangers would be refused by the password check alone)
    insider = Identity.new("tester", "operator")
    insider_file = write_credentials(tmp_path / "insider.json", insider)
    no_cert = {
        "transport/link/tls": {"root_ca_certificate": str((lab / "ca.pem").resolve()), "verify_name_on_connect": True}
    }

    def strangers(keys, endpoint):
        for name, settings, creds in (
            ("foreign CA", tls_settings(elsewhere, "intruder"), None),
            ("plain", None, None),
            ("credentials, no certificate", no_cert, str(insider_file)),
        ):
            target = hub if settings else hub.replace("tls/", "tcp/")
            try:
                zenoh.open(zenoh_config("client", [target], credentials=creds, settings=settings)).close()
                refused[name] = False
            except zenoh.ZError:
                refused[name] = True

    sets = ["agents.count=4", "allocator={name: cbba}", "run.duration=120", "run.stop_when_done=false"]
    try:
        run_experiment(
            experiment(*sets, "placement={h1: '1-2'}"),
            tmp_path / "tls",
            progress=False,
            on_ready=strangers,
            hub=HubOptions(listen=[hub], admit=[host_id, insider], tls=tls_settings(lab, "hub")),
        )
    finally:
        daemon.send_signal(signal.SIGTERM)
        daemon.wait(timeout=20)
    reference_run(experiment(*sets), tmp_path / "local")
    same_results(tmp_path / "local", tmp_path / "tls")
    assert refused == {"foreign CA": True, "plain": True, "credentials, no certificate": True}
    assert '"1": "h1"' in (tmp_path / "tls" / "deployment.json").read_text()
