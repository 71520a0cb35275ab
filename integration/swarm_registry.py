"""The Swarm suite's registry as a team's: Debian's docker-registry with TLS (a CA of the test's own, made here)
and a login (htpasswd, bcrypt), at an address that is not loopback.

Why not loopback: dockerd treats every registry in 127.0.0.0/8 as insecure (no certificate check, plain HTTP
allowed), so a loopback registry would prove nothing about the CA. The registry listens on this machine's own
network address (:func:`outward_address`), which the DinD robot hosts, on a network of their own, reach through
this machine's INPUT chain as they would a registry on the LAN.

Who trusts what:

- this machine's daemon (which pushes the releases) trusts the CA through ``/etc/docker/certs.d/ADDR/ca.crt``,
  written here and removed afterwards (ADDR has a free port of this run, so no other registry's entry is touched);
- the robot hosts get the CA from ``fleet join`` only (fleet.yaml's ``registry_ca``), and never log in: Swarm
  hands them the login the manager was given with each service;
- robocore finds the login where ``docker login`` puts it: a ``config.json`` under ``DOCKER_CONFIG`` (a private
  folder of the test), read by docker-py as by the docker CLI.
"""

from __future__ import annotations

import base64
import contextlib
import datetime
import ipaddress
import json
import os
import secrets
import shutil
import ssl
import subprocess
import urllib.error
import urllib.request
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from deploy_helpers import free_tcp_port, wait_for

#: The user of the registry's htpasswd.
USER = "fleet"
#: Where dockerd reads registries' CAs.
CERTS_D = Path("/etc/docker/certs.d")


@dataclass(frozen=True)
class SecureRegistry:
    """A running registry with TLS and a login."""

    address: str  # IP:PORT, not loopback
    ca: Path  # the CA's certificate (PEM)
    password: str
    #: A ``DOCKER_CONFIG`` folder whose config.json holds the login (as ``docker login`` writes it).
    docker_config: Path
    #: A ``DOCKER_CONFIG`` folder with no login (the negative control).
    no_login: Path

    @property
    def auth(self) -> dict[str, str]:
        """docker-py's ``auth_config`` of the login."""
        return {"username": USER, "password": self.password}

    def secrets(self) -> list[str]:
        """Every form of the password a leak could take: as typed, and the base64 forms of config.json's ``auth``
        and of Docker's X-Registry-Auth header (JSON)."""
        basic = base64.b64encode(f"{USER}:{self.password}".encode()).decode()
        header = json.dumps({"username": USER, "password": self.password, "serveraddress": self.address})
        return [self.password, basic, base64.urlsafe_b64encode(header.encode()).decode().rstrip("="),
                base64.b64encode(header.encode()).decode().rstrip("=")]


def outward_address() -> str:
    """This machine's own network address: the source of its route to the outside (a UDP socket's connect sends
    nothing). Not ``docker0``'s 172.17.0.1: inside each DinD robot host that is the host's own bridge (its dockerd
    made one), so a robot dialling it reaches itself; nor any other range a robot host's daemon uses itself."""
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.connect(("198.51.100.1", 9))  # TEST-NET-2: only the route is looked up
        address = ipaddress.ip_address(probe.getsockname()[0])
    inner = [ipaddress.ip_network(n) for n in ("172.17.0.0/16", "172.18.0.0/16", "10.0.0.0/24")]
    assert not address.is_loopback and not any(address in net for net in inner), \
        f"this machine's address {address} is loopback or a range the robot hosts' own daemons use"
    return str(address)


def make_ca(folder: Path, ip: str) -> tuple[Path, Path, Path]:
    """A CA, and a server certificate for ``ip`` signed by it: (ca.crt, server.crt, server.key)."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID

    now = datetime.datetime.now(datetime.timezone.utc)
    ca_key = ec.generate_private_key(ec.SECP256R1())
    ca_name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "robocore test fleet CA")])
    ca = (x509.CertificateBuilder().subject_name(ca_name).issuer_name(ca_name).public_key(ca_key.public_key())
          .serial_number(x509.random_serial_number()).not_valid_before(now - datetime.timedelta(hours=1))
          .not_valid_after(now + datetime.timedelta(days=2))
          .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
          .add_extension(x509.KeyUsage(digital_signature=True, key_cert_sign=True, crl_sign=True,
                                       content_commitment=False, key_encipherment=False, data_encipherment=False,
                                       key_agreement=False, encipher_only=False, decipher_only=False), critical=True)
          .sign(ca_key, hashes.SHA256()))
    key = ec.generate_private_key(ec.SECP256R1())
    cert = (x509.CertificateBuilder().subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, ip)]))
            .issuer_name(ca_name).public_key(key.public_key()).serial_number(x509.random_serial_number())
            .not_valid_before(now - datetime.timedelta(hours=1)).not_valid_after(now + datetime.timedelta(days=2))
            .add_extension(x509.SubjectAlternativeName([x509.IPAddress(ipaddress.ip_address(ip))]), critical=False)
            .add_extension(x509.ExtendedKeyUsage([x509.oid.ExtendedKeyUsageOID.SERVER_AUTH]), critical=False)
            .sign(ca_key, hashes.SHA256()))
    paths = folder / "ca.crt", folder / "server.crt", folder / "server.key"
    paths[0].write_bytes(ca.public_bytes(serialization.Encoding.PEM))
    paths[1].write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    paths[2].write_bytes(key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                           serialization.NoEncryption()))
    paths[2].chmod(0o600)
    return paths


def docker_config(folder: Path, auths: dict[str, Any]) -> Path:
    """A private ``DOCKER_CONFIG`` folder whose config.json holds ``auths``."""
    folder.mkdir(mode=0o700)
    (folder / "config.json").write_text(json.dumps({"auths": auths}))
    (folder / "config.json").chmod(0o600)
    return folder


@contextlib.contextmanager
def secure_registry(folder: Path) -> Iterator[SecureRegistry]:
    """Serve a registry with TLS and a login (its data under ``folder``) on this machine's own address; this
    machine's daemon trusts its CA meanwhile."""
    binary = shutil.which("docker-registry")
    assert binary, "the Swarm suite needs Debian's docker-registry package (apt-get install docker-registry)"
    ip = outward_address()
    port = free_tcp_port()
    address = f"{ip}:{port}"
    folder.chmod(0o700)
    ca, cert, key = make_ca(folder, ip)
    password = secrets.token_urlsafe(18)
    with warnings.catch_warnings():  # crypt is deprecated (3.11) but here, and makes bcrypt through libcrypt
        warnings.simplefilter("ignore", DeprecationWarning)
        import crypt

        hashed = crypt.crypt(password, crypt.mksalt(crypt.METHOD_BLOWFISH, rounds=1 << 5))
    assert hashed.startswith("$2"), "this libcrypt makes no bcrypt hashes (htpasswd needs them)"
    (folder / "htpasswd").write_text(f"{USER}:{hashed}\n")
    (folder / "htpasswd").chmod(0o600)
    config = folder / "config.yml"
    config.write_text(f"version: 0.1\nstorage:\n  filesystem:\n    rootdirectory: {folder / 'data'}\n"
                      f"http:\n  addr: {address}\n  tls:\n    certificate: {cert}\n    key: {key}\n"
                      f"auth:\n  htpasswd:\n    realm: robocore-fleet\n    path: {folder / 'htpasswd'}\n"
                      "log:\n  level: warn\n")
    trusted = CERTS_D / address
    trusted.mkdir(parents=True, exist_ok=False)
    shutil.copy(ca, trusted / "ca.crt")
    server = subprocess.Popen([binary, "serve", str(config)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    context = ssl.create_default_context(cafile=str(ca))

    def serving() -> bool:  # 401 is an answer: the login is asked for
        try:
            urllib.request.urlopen(f"https://{address}/v2/", timeout=2, context=context)
        except urllib.error.HTTPError as exc:
            return exc.code == 401
        except OSError:
            return False
        return False

    try:
        assert wait_for(serving, 30, interval=0.2), f"docker-registry did not answer on {address}"
        basic = base64.b64encode(f"{USER}:{password}".encode()).decode()
        yield SecureRegistry(address, ca, password, docker_config(folder / "docker", {address: {"auth": basic}}),
                             docker_config(folder / "docker-no-login", {}))
    finally:
        server.kill()
        server.wait()
        shutil.rmtree(trusted, ignore_errors=True)
        with contextlib.suppress(OSError):
            CERTS_D.rmdir()  # only when empty: made here


def pull_with_login(host: Any, fleet: Any, ref: str, registry: SecureRegistry) -> None:
    """Pull ``ref`` on ``host``'s daemon with the registry's login in the request only (as Swarm's agent does with
    the login it was handed), nothing written on the robot: a robot that already holds its model's base."""
    client = host.docker(fleet)
    try:
        for event in client.api.pull(ref, stream=True, decode=True, auth_config=registry.auth):
            assert "error" not in event, (host.name, event)
    finally:
        client.close()


def ca_on(host: Any, fleet: Any, registry: SecureRegistry) -> bytes | None:
    """The CA the robot host's dockerd reads for the registry (None when it has none)."""
    out = host.ssh(fleet, "sh", "-c", f"cat {CERTS_D / registry.address / 'ca.crt'} 2>/dev/null || true")
    return out.encode() or None


def remove_ca(host: Any, fleet: Any, registry: SecureRegistry) -> None:
    """Take the registry's CA away from the robot host (the negative control)."""
    host.ssh(fleet, "rm", "-rf", "--", str(CERTS_D / registry.address))


def leaks(registry: SecureRegistry, texts: dict[str, str]) -> list[str]:
    """The names of ``texts`` that hold any form of the password (:meth:`SecureRegistry.secrets`)."""
    forms = registry.secrets()
    return [name for name, text in texts.items() if any(form in text for form in forms)]


def files_text(folder: Path) -> dict[str, str]:
    """Every regular file under ``folder`` (links not followed) of at most 64 MB (robocore's records, state and logs
    are far smaller; a compiler cache may not be), path -> its text (bytes decoded leniently)."""
    out = {}
    for path in folder.rglob("*"):
        if path.is_file() and not path.is_symlink() and path.stat().st_size <= 64 << 20:
            with contextlib.suppress(OSError):
                out[str(path)] = path.read_bytes().decode("utf-8", "replace")
    return out


def world_readable(folder: Path) -> list[str]:
    """Files under ``folder`` that others may read (robocore's own state must not include a secret anyway)."""
    return [str(p) for p in folder.rglob("*") if p.is_file() and not p.is_symlink() and os.stat(p).st_mode & 0o004]


def trust_in(root: Path, registry: SecureRegistry) -> None:
    """Give project ``root``'s fleet the registry's CA: ``certs/registry-ca.crt`` in the project, named by
    fleet.yaml's ``registry_ca`` (what ``fleet join`` installs on every robot host)."""
    import yaml

    (root / "certs").mkdir(exist_ok=True)
    shutil.copy(registry.ca, root / "certs" / "registry-ca.crt")
    fleet_file = root / "fleet.yaml"
    data = yaml.safe_load(fleet_file.read_text())
    data["registry_ca"] = "certs/registry-ca.crt"
    fleet_file.write_text(yaml.safe_dump(data, sort_keys=False))


def dockerd_log(host: Any, since: float) -> str:
    """What the robot host's dockerd logged since ``since`` (its container's output: dockerd runs in front)."""
    return bytes(host.container.get_wrapped_container().logs(since=int(since))).decode(errors="replace")
