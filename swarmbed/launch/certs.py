"""``swarmbed certs``: a private certificate authority and one certificate per machine, for Zenoh's
TLS links between machines (``tls/HOST:PORT`` endpoints, mutual authentication).

Made with the ``cryptography`` package (the ``swarmbed[tls]`` extra): a few calls of a well-kept
library, where shelling out to ``openssl`` would need config files and a tool that may be missing.
Keys are EC P-256; each machine's certificate serves both ends of a link (server and client
authentication) and names the addresses others reach it by.
"""

from __future__ import annotations

import datetime
import ipaddress
from pathlib import Path

from swarmbed.files import safefiles
from swarmbed.wire.credentials import write_private

CA = "ca"


class CertError(ValueError):
    pass


def _crypto():
    try:
        from cryptography import x509
        from cryptography.hazmat.primitives import hashes, serialization
        from cryptography.hazmat.primitives.asymmetric import ec
        from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID
    except ImportError:
        raise CertError("swarmbed certs needs the cryptography package: pip install 'swarmbed[tls]'") from None
    return x509, hashes, serialization, ec, ExtendedKeyUsageOID, NameOID


def _write_key(path: Path, key) -> None:
    _, _, serialization, _, _, _ = _crypto()
    pem = key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption())
    write_private(path, pem)


def _names(addresses: list[str]):
    x509 = _crypto()[0]
    names = []
    for a in addresses:
        try:
            names.append(x509.IPAddress(ipaddress.ip_address(a)))
        except ValueError:
            names.append(x509.DNSName(a))
    return names


def parse_machine(spec: str) -> tuple[str, list[str]]:
    """``NAME=ADDR,ADDR`` (or just ``NAME``) -> (name, addresses); the name is always one of them."""
    name, _, rest = spec.partition("=")
    if not name or not all(c.isalnum() or c in "-_." for c in name):
        raise CertError(f"machine {spec!r}: the name must be letters, digits, - _ or .")
    addresses = [a for a in rest.split(",") if a]
    return name, [name, *[a for a in addresses if a != name]]


def make_certs(folder: Path, machines: list[str], days: int = 365) -> list[Path]:
    """A CA in ``folder`` (made once, reused after) and ``<name>.pem`` / ``<name>.key`` for each
    machine spec (see :func:`parse_machine`); returns the files written."""
    x509, hashes, serialization, ec, eku, oid = _crypto()
    safefiles.make_folder(folder)
    now = datetime.datetime.now(datetime.UTC)
    ca_pem, ca_key_path = folder / f"{CA}.pem", folder / f"{CA}.key"
    if ca_pem.exists() and ca_key_path.exists():
        ca_cert = x509.load_pem_x509_certificate(ca_pem.read_bytes())
        ca_key = serialization.load_pem_private_key(ca_key_path.read_bytes(), password=None)
        written = []
    else:
        ca_key = ec.generate_private_key(ec.SECP256R1())
        ca_name = x509.Name([x509.NameAttribute(oid.COMMON_NAME, "swarmbed lab CA")])
        ca_cert = (
            x509.CertificateBuilder()
            .subject_name(ca_name)
            .issuer_name(ca_name)
            .public_key(ca_key.public_key())
            .serial_number(x509.random_serial_number())
            .not_valid_before(now - datetime.timedelta(minutes=5))
            .not_valid_after(now + datetime.timedelta(days=days))
            .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
            .add_extension(
                x509.KeyUsage(
                    digital_signature=False,
                    content_commitment=False,
                    key_encipherment=False,
                    data_encipherment=False,
                    key_agreement=False,
                    key_cert_sign=True,
                    crl_sign=True,
                    encipher_only=False,
                    decipher_only=False,
                ),
                critical=True,
            )
            .sign(ca_key, hashes.SHA256())
        )
        _write_key(ca_key_path, ca_key)
        safefiles.write_bytes(ca_pem, ca_cert.public_bytes(serialization.Encoding.PEM))
        written = [ca_pem, ca_key_path]
    for spec in machines:
        name, addresses = parse_machine(spec)
        if name == CA:
            raise CertError(f"machine name {CA!r} is the authority's own file name; choose another")
        key = ec.generate_private_key(ec.SECP256R1())
        cert = (
            x509.CertificateBuilder()
            .subject_name(x509.Name([x509.NameAttribute(oid.COMMON_NAME, name)]))
            .issuer_name(ca_cert.subject)
            .public_key(key.public_key())
            .serial_number(x509.random_serial_number())
            .not_valid_before(now - datetime.timedelta(minutes=5))
            .not_valid_after(now + datetime.timedelta(days=days))
            .add_extension(x509.SubjectAlternativeName(_names(addresses)), critical=False)
            .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
            .add_extension(x509.ExtendedKeyUsage([eku.SERVER_AUTH, eku.CLIENT_AUTH]), critical=False)
            .sign(ca_key, hashes.SHA256())
        )
        _write_key(folder / f"{name}.key", key)
        safefiles.write_bytes(folder / f"{name}.pem", cert.public_bytes(serialization.Encoding.PEM))
        written += [folder / f"{name}.pem", folder / f"{name}.key"]
    return written
