"""Docker host access without a daemon: refusals, descriptions, ssh settings, timeouts."""

from __future__ import annotations

import socket
import time
from pathlib import Path

import pytest

from robocore.adapters import docker_hosts, ssh
from robocore.config.model import DockerAccess, Host
from robocore.errors import HostError


def test_plain_tcp_is_refused_unless_insecure() -> None:
    host = Host(name="r1", ip="10.0.0.9", docker=DockerAccess.tcp)
    with pytest.raises(HostError) as caught:
        docker_hosts.client_for(host)
    assert "r1" in caught.value.message and "insecure" in (caught.value.hint or "")


def test_descriptions_name_the_transport() -> None:
    assert docker_hosts.describe(Host(name="a", ip="10.0.0.1")) == "ssh://root@10.0.0.1:22"
    assert docker_hosts.describe(Host(name="a", ip="127.0.0.1")) == "local socket"
    assert "2376" in docker_hosts.describe(Host(name="a", ip="h", docker=DockerAccess.tls))
    assert "insecure" in docker_hosts.describe(Host(name="a", ip="h", docker=DockerAccess.tcp, insecure=True))


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.mark.parametrize("access", [DockerAccess.ssh, DockerAccess.tcp])
def test_unreachable_host_fails_fast_with_its_name(access: DockerAccess) -> None:
    port = _closed_port()
    extra = {"ssh_port": port} if access is DockerAccess.ssh else {"docker_port": port, "insecure": True}
    host = Host(name="nobody", ip="127.0.0.2", docker=access, **extra)
    start = time.monotonic()
    with pytest.raises(HostError) as caught:
        docker_hosts.client_for(host, timeout=60, connect_timeout=3)
    assert time.monotonic() - start < 10
    assert "nobody" in caught.value.message


def test_ssh_uses_the_robocore_ssh_config_and_one_shared_connection(tmp_path: Path,
                                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    config = tmp_path / "ssh_config"
    config.write_text("Host 10.1.*\n  IdentityFile ~/keys/robot\n")
    monkeypatch.setenv(ssh.CONFIG_ENV, str(config))
    host = Host(name="r", ip="10.1.2.3", user="pi", ssh_port=2200)
    argv = ssh.ssh_argv(host, ["docker", "system", "dial-stdio"], connect_timeout=4)
    assert argv[:3] == ["ssh", "-F", str(config)]
    assert argv[argv.index("-p") + 1] == "2200" and "ConnectTimeout=4" in argv and "BatchMode=yes" in argv
    assert "ControlMaster=auto" in argv and any(a.startswith("ControlPath=") for a in argv)
    assert argv[-2:] == ["pi@10.1.2.3", "docker system dial-stdio"]


def test_docker_requests_go_through_the_ssh_child(tmp_path: Path) -> None:
    """The transport with a stand-in for ssh: a local process that answers one HTTP request on its
    stdin/stdout, as `docker system dial-stdio` relays them to the daemon."""
    import sys

    from robocore.adapters import docker_over_ssh

    server = tmp_path / "fake_dial_stdio.py"
    server.write_text(
        "import sys\n"
        "head = b''\n"
        "while not head.endswith(b'\\r\\n\\r\\n'):\n"
        "    head += sys.stdin.buffer.read(1)\n"
        "line = head.split(b'\\r\\n')[0].decode()\n"
        "body = ('{\"path\": \"' + line.split()[1] + '\"}').encode()\n"
        "sys.stdout.buffer.write(b'HTTP/1.1 200 OK\\r\\nContent-Type: application/json\\r\\n'\n"
        "    + b'Content-Length: ' + str(len(body)).encode() + b'\\r\\nConnection: close\\r\\n\\r\\n' + body)\n"
        "sys.stdout.buffer.flush()\n")
    pool = docker_over_ssh.DialStdioPool([sys.executable, str(server)], timeout=10)
    response = pool.request("GET", "/v1.41/version")
    assert response.status == 200 and response.json() == {"path": "/v1.41/version"}
    pool.close()
    # the same through a docker-py client: it never opens its placeholder Unix socket
    client = docker_over_ssh.client([sys.executable, str(server)], timeout=10, version="1.41")
    assert client.api.version() == {"path": "/v1.41/version"}
    client.close()


def test_tls_client_resolves_relative_files_and_fails_by_name(tmp_path: Path) -> None:
    from robocore.config.model import TlsFiles

    host = Host(name="secure", ip="127.0.0.2", docker=DockerAccess.tls, docker_port=_closed_port(),
                tls=TlsFiles(ca_cert="ca.pem", client_cert="cert.pem", client_key="key.pem"))
    for name in ("ca.pem", "cert.pem", "key.pem"):
        (tmp_path / name).write_text("x")
    with pytest.raises(HostError) as caught:
        docker_hosts.client_for(host, project_root=tmp_path, connect_timeout=2)
    assert "secure" in caught.value.message


def _tar(members: dict[str, bytes]) -> bytes:
    import io
    import tarfile

    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w", format=tarfile.PAX_FORMAT) as tar:
        for name, data in members.items():
            info = tarfile.TarInfo(name)
            info.size = len(data)
            tar.addfile(info, io.BytesIO(data))
    return buf.getvalue()


def test_layer_filter_drops_only_layers_the_host_has_and_keeps_the_rest_byte_for_byte() -> None:
    import hashlib
    import io
    import tarfile

    from robocore.adapters.image_delivery import without_layers

    base, top = b"B" * 3_000_000, b"T" * 1000
    long_name = "x" * 150 + "/layer.tar"  # needs a pax header
    raw = _tar({"a/layer.tar": base, long_name: top, "manifest.json": b"[]", "a/VERSION": b"1.0"})
    chunks = [raw[i:i + 7777] for i in range(0, len(raw), 7777)]
    assert b"".join(without_layers(iter(chunks), {"sha256:" + "0" * 64})) == raw
    have = {"sha256:" + hashlib.sha256(base).hexdigest()}
    out = b"".join(without_layers(iter(chunks), have))
    with tarfile.open(fileobj=io.BytesIO(out)) as tar:
        names = tar.getnames()
        assert tar.extractfile(long_name).read() == top  # type: ignore[union-attr]
    assert names == [long_name, "manifest.json", "a/VERSION"]
    assert len(out) < 20_000


def test_a_prefetched_connection_is_taken_once_with_its_error(monkeypatch: pytest.MonkeyPatch) -> None:
    import threading

    calls: list[tuple[str, int, int]] = []
    release = threading.Event()

    def fake_ssh_client(host: Host, timeout: int, connect_timeout: int) -> object:
        calls.append((threading.current_thread().name, timeout, connect_timeout))
        release.wait(5)
        if host.name == "down":
            raise HostError(f"host {host.name}: cannot reach its Docker daemon")
        return f"client of {host.name}"

    monkeypatch.setattr(docker_hosts, "ssh_client", fake_ssh_client)
    up, down = Host(name="up", ip="10.9.0.1"), Host(name="down", ip="10.9.0.2")
    docker_hosts.prefetch(up, 300, connect_timeout=8)
    docker_hosts.prefetch(up, 300, connect_timeout=8)  # already under way: not twice
    docker_hosts.prefetch(down, 300, connect_timeout=8)
    docker_hosts.prefetch(Host(name="here", ip="127.0.0.1"), 300, connect_timeout=8)  # local: nothing to fetch
    release.set()
    assert docker_hosts.client_for(up, 300, connect_timeout=8) == "client of up"  # type: ignore[comparison-overlap]
    with pytest.raises(HostError, match="host down: cannot reach"):
        docker_hosts.client_for(down, 300, connect_timeout=8)
    assert sorted(name for name, _, _ in calls) == ["robocore-prefetch-down", "robocore-prefetch-up"]
    # taken once; other settings connect anew
    docker_hosts.client_for(up, 300, connect_timeout=8)
    docker_hosts.client_for(up, 60, connect_timeout=8)
    assert [name for name, _, _ in calls[2:]] == ["MainThread", "MainThread"]


class _Images:
    """A daemon's images by name and ID, counting how often one is looked up."""

    def __init__(self, known: dict[str, str]) -> None:
        self.known = known
        self.asked: list[str] = []
        self.images = self

    def get(self, ref: str) -> object:
        from docker.errors import ImageNotFound

        self.asked.append(ref)
        if ref not in self.known:
            raise ImageNotFound(ref)
        return type("Image", (), {"id": self.known[ref]})()


def test_a_delivered_image_id_is_not_asked_for_again() -> None:
    from robocore.adapters.image_delivery import ensure_images
    from robocore.commands import run
    from robocore.config.model import Robot
    from robocore.plan.containers import host_specs
    from robocore.project import Project

    local = _Images({"demo-talker:latest": "sha256:aa"})
    remote = _Images({"demo-talker:latest": "sha256:aa"})
    delivered = ensure_images(remote, ["demo-talker"], registry=None, source=local)  # type: ignore[arg-type]
    assert delivered["demo-talker"].action == "present" and delivered["demo-talker"].image_id == "sha256:aa"
    robot = Robot.model_validate({
        "ros_distro": "jazzy", "hosts": [{"name": "pi", "ip": "192.168.1.20", "user": "pi"}],
        "components": [{"name": "cam", "runs_on": "pi", "folder": "components/cam"}],
    })
    project = Project(root=Path("/srv/r"), robot=robot)
    host = project.robot.hosts[0]
    specs = host_specs(project, host.name)
    known = {s.image: "sha256:aa" for s in specs}
    assert len(known) >= 2  # the component's image and the discovery server's
    remote.asked.clear()
    local.asked.clear()
    ids = run.host_image_ids(remote, local, specs, project, host, dry_run=False, known=known)  # type: ignore[arg-type]
    assert ids == known and remote.asked == [] and local.asked == []
