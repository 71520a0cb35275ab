"""Two simulated robot hosts over ssh://: images without a registry, then the full deploy path.

- image delivery: images streamed (docker save -> load) onto both inner daemons, then skipped;
  a derived image moves only its new layer; a stopped host fails fast by name.
- the template project with talker on robot-a and listener on robot-b: ``stage build sync run``
  to both hosts over ssh, the discovery server on robot-a; the listener on robot-b hears the
  talker on robot-a (negative control: nothing is heard before the talker's host is deployed);
  ``status`` shows both nodes; a one-line change to the talker goes through build, sync and
  run and is heard on robot-b; with robot-b stopped, ``run`` names it and still deploys robot-a.
"""

from __future__ import annotations

import contextlib
import io
import json
import subprocess
import tarfile
import tempfile
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest
import yaml
from deploy_helpers import HEARD, log_lines, wait_for
from local_registry import serve_registry

from robocore.adapters.image_delivery import ensure_images
from robocore.config.model import Host
from robocore.errors import HostError

if TYPE_CHECKING:
    from conftest import Restorer, RobocoreCli
    from robot_host.hosts import RobotFleet

pytestmark = pytest.mark.docker

#: Names of this run's own (another run on the same daemon removes its own when it ends).
TINY_REPO = f"robocore-it-tiny-{uuid.uuid4().hex[:6]}"
TINY = f"{TINY_REPO}:v1"
DERIVED = f"{TINY_REPO}-derived:v1"


@pytest.fixture(scope="module")
def tiny_images(docker_client: Any) -> Iterator[list[str]]:
    """A 2 MB image made from scratch (docker import) and one derived from it with one more layer."""
    payload = io.BytesIO()
    with tarfile.open(fileobj=payload, mode="w") as tar:
        data = bytes(range(256)) * 8192
        info = tarfile.TarInfo("payload.bin")
        info.size = len(data)
        tar.addfile(info, io.BytesIO(data))
    docker_client.api.import_image_from_data(payload.getvalue(), repository=TINY_REPO, tag="v1")
    with tempfile.TemporaryDirectory() as ctx:
        Path(ctx, "Dockerfile").write_text(f"FROM {TINY}\nCOPY extra.txt /extra.txt\n")
        Path(ctx, "extra.txt").write_text("one more layer\n" * 100)
        docker_client.images.build(path=ctx, tag=DERIVED, rm=True)
    yield [TINY, DERIVED]
    remove_local_tags(docker_client, (TINY_REPO,))


def remove_local_tags(docker_client: Any, repositories: tuple[str, ...]) -> None:
    """Remove this machine's tags of ``repositories``, also under a registry prefix (push tags)."""
    names = set(repositories) | {f"{r}-derived" for r in repositories}
    for image in docker_client.images.list():
        for tag in image.tags:
            if tag.rsplit(":", 1)[0].rsplit("/", 1)[-1] in names:
                docker_client.images.remove(tag, force=True)


@pytest.fixture(scope="module")
def registry(fleet: RobotFleet, tmp_path_factory: pytest.TempPathFactory, docker_client: Any) -> Iterator[str]:
    """Debian's docker-registry on this machine's loopback, reachable as the same 127.0.0.1:PORT on
    every robot host through an ssh reverse tunnel (loopback registries need no TLS in dockerd).
    Afterwards this machine's tags under the registry (those ``release`` pushed) are removed."""
    with serve_registry(fleet, tmp_path_factory.mktemp("registry")) as address:
        try:
            yield address
        finally:
            for image in docker_client.images.list():
                for tag in image.tags:
                    if tag.startswith(f"{address}/"):
                        docker_client.images.remove(tag)


def registry_tags(registry: str, repo: str) -> list[str]:
    import urllib.request

    with urllib.request.urlopen(f"http://{registry}/v2/{repo}/tags/list", timeout=10) as resp:
        return list(json.loads(resp.read()).get("tags") or [])


def test_images_are_streamed_without_registry_then_skipped(fleet: RobotFleet, tiny_images: list[str],
                                                           docker_client: Any) -> None:
    local_ids = {name: docker_client.images.get(name).id for name in tiny_images}
    for index, host in enumerate(fleet.hosts):
        client = fleet.client(index)
        # negative control: the inner daemon starts without them
        assert not {t for img in client.images.list() for t in img.tags} & set(tiny_images)
        first = ensure_images(client, [TINY], registry=None, progress=False, label=host.name)
        assert first[TINY].action == "loaded" and first[TINY].bytes > 2_000_000
        second = ensure_images(client, tiny_images, registry=None, progress=False, label=host.name)
        assert second[TINY].action == "present" and second[TINY].bytes == 0
        # the derived image shares the base layer: only its own small layer is sent
        assert second[DERIVED].action == "loaded" and second[DERIVED].bytes < 200_000, second[DERIVED]
        third = ensure_images(client, tiny_images, registry=None, progress=False, label=host.name)
        assert all(d.action == "present" for d in third.values())
        for name in tiny_images:
            assert client.images.get(name).id == local_ids[name], (index, name)


def test_images_go_through_a_registry_when_one_is_configured(fleet: RobotFleet, tiny_images: list[str],
                                                            registry: str, docker_client: Any) -> None:
    client = fleet.client(0)
    for name in tiny_images:
        client.images.remove(name, force=True)
    result = ensure_images(client, [TINY], registry=registry, progress=False, label="robot-a")
    assert result[TINY].action == "pulled"
    assert registry_tags(registry, TINY_REPO) == ["v1"]  # pushed once, from this machine
    assert client.images.get(TINY).id == docker_client.images.get(TINY).id
    assert client.images.get(f"{registry}/{TINY}").id == docker_client.images.get(TINY).id


def test_unreachable_host_fails_fast_with_its_name(fleet: RobotFleet) -> None:
    start = time.monotonic()
    with pytest.raises(HostError) as caught:
        from robocore.adapters.docker_hosts import client_for

        # an address on the fleet's network where no host answers
        prefix = fleet.hosts[0].ip.rsplit(".", 1)[0]
        client_for(Host(name="ghost", ip=f"{prefix}.250"), timeout=60)
    assert time.monotonic() - start < 10
    assert "ghost" in caught.value.message


# --------------------------------------------------------------------------- the full path


@pytest.fixture(scope="module")
def robot(fleet: RobotFleet, new_demo_project: Callable[[], Path], run_robocore: RobocoreCli) -> Path:
    """The template project (wheels) with talker on robot-a and listener on robot-b."""
    root = new_demo_project()
    data = yaml.safe_load((root / "robot.yaml").read_text())
    data["hosts"] = [{"name": n, "ip": h.ip, "user": "root", "arch": "amd64"}
                     for n, h in zip(["robot-a", "robot-b"], fleet.hosts, strict=True)]
    for comp in data["components"]:
        comp["runs_on"] = "robot-a" if comp["name"] == "talker" else "robot-b"
    (root / "robot.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    for step in ("prepare-base", "stage", "build"):
        run_robocore(root, step, "--quiet")
    return root


def heard(fleet: RobotFleet, index: int, container: str) -> list[str]:
    """The "I heard" lines of ``container`` on host ``index``."""
    return log_lines(fleet.client(index).containers.get(container), HEARD)


def wait_heard(fleet: RobotFleet, index: int, container: str, needle: str, timeout: float = 60) -> list[str]:
    """The heard lines holding ``needle``, once there are any (empty after ``timeout`` seconds without)."""
    lines = wait_for(lambda: [line for line in heard(fleet, index, container) if needle in line], timeout, 1)
    return lines or []


def test_stage_build_sync_run_over_ssh_one_graph_across_hosts(fleet: RobotFleet, robot: Path,
                                                              run_robocore: RobocoreCli) -> None:
    listener = f"{robot.name}-listener"
    run_robocore(robot, "sync", "--quiet")
    # listener host first: with no talker anywhere it hears nothing (negative control)
    run_robocore(robot, "run", "--host", "robot-b", "--quiet")
    time.sleep(8)
    assert heard(fleet, 1, listener) == []
    # then robot-a: the discovery server and the talker
    run_robocore(robot, "run", "--host", "robot-a", "--quiet")
    lines = wait_heard(fleet, 1, listener, "hello from talker")
    assert lines, "the listener on robot-b never heard the talker on robot-a"
    # images arrived without a registry, on both inner daemons
    for index, comp in ((0, "talker"), (1, "listener")):
        assert fleet.client(index).images.get(f"{robot.name}-{comp}:latest")

    status = run_robocore(robot, "status", "--json", "--nodes")
    data = json.loads(status.stdout)
    [graph] = [r for r in data["results"] if r["kind"] == "ros_graph"]
    nodes = " ".join(graph["nodes"] or [])
    assert "talker" in nodes and "listener" in nodes, data
    states = {row["component"]: (row["host"], row["state"]) for row in data["results"] if row["kind"] == "container"}
    assert states["talker"] == ("robot-a", "running") and states["listener"] == ("robot-b", "running"), states

    # through the same ssh connections: a command in the live talker container (its output and exit code
    # come back over the Docker API's multiplexed stream) and `logs -f` (a live stream from robot-b)
    graph = run_robocore(robot, "connect", "--component", "talker", "--cmd", "ros2 node list --no-daemon --spin-time 3")
    assert "/talker" in graph.stdout and "/listener" in graph.stdout, graph.stdout
    assert run_robocore(robot, "connect", "--component", "talker", "--cmd", "exit 3", check=False).returncode == 3
    assert followed_lines(run_robocore, robot, "listener", count=3), \
        "logs -f printed no new lines of the remote listener"

    # a second run changes nothing
    again = run_robocore(robot, "run", "--json")
    assert "create" not in again.stdout and "replace" not in again.stdout, again.stdout

    # a one-line change of the talker: build, sync, run; robot-b hears the new text
    code = robot / "components" / "talker" / "src" / "demo_talker" / "demo_talker" / "talker.py"
    code.write_text(code.read_text().replace('f"hello from talker #', 'f"edited talker #'))
    run_robocore(robot, "build", "--component", "talker", "--quiet")
    synced = json.loads(run_robocore(robot, "sync", "--json").stdout)
    moved = {row["component"]: row["sent"] for row in synced["results"]}
    assert moved["talker"] < 50_000, moved
    run_robocore(robot, "run", "--quiet")
    assert wait_heard(fleet, 1, listener, "edited talker #"), "the edited talker was never heard on robot-b"


def followed_lines(run_robocore: RobocoreCli, project: Path, component: str, count: int,
                   timeout: float = 30) -> list[str]:
    """``robocore logs -f --tail 1``: the first ``count`` distinct heard lines it prints live (empty if none)."""
    proc = run_robocore.start(project, "logs", "-f", "--component", component, "--tail", "1",
                              stderr=subprocess.DEVNULL)
    seen: list[str] = []
    done = threading.Event()

    def read() -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            if line.startswith(component) and "I heard" in line and line not in seen:
                seen.append(line)
                if len(seen) >= count:
                    break
        done.set()

    threading.Thread(target=read, daemon=True).start()
    done.wait(timeout)
    proc.terminate()
    proc.wait(timeout=10)
    return seen if len(seen) >= count else []


def container_image(fleet: RobotFleet, index: int, name: str) -> str:
    return str(fleet.client(index).containers.get(name).attrs["Config"]["Image"])


def test_release_run_tag_and_rollback(fleet: RobotFleet, robot: Path, registry: str, run_robocore: RobocoreCli,
                                      restore: Restorer) -> None:
    listener, talker = f"{robot.name}-listener", f"{robot.name}-talker"
    # rollback first: robot-a goes back to the release synced before the one-line edit
    before = fleet.hosts[0].ssh(fleet, "readlink", "/root/robocore/talker/current").strip()
    run_robocore(robot, "rollback", "--host", "robot-a")
    after = fleet.hosts[0].ssh(fleet, "readlink", "/root/robocore/talker/current").strip()
    assert after != before
    since = time.time()

    def recent() -> str:
        return str(fleet.client(1).containers.get(listener).logs(since=int(since) + 2).decode(errors="replace"))

    wait_for(lambda: "I heard: hello from talker" in recent(), 60, interval=1)
    text = recent()
    assert "I heard: hello from talker" in text and "edited talker" not in text, text[-500:]

    # release: needs a registry; pushes base and component images with the tag
    assert run_robocore(robot, "release", "--tag", "v1", check=False).returncode != 0  # no registry yet
    restore.keep(robot / "robot.yaml")  # the next test runs without the registry
    data = yaml.safe_load((robot / "robot.yaml").read_text())
    data["registry"] = registry
    (robot / "robot.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    run_robocore(robot, "release", "--tag", "v1")
    for repo in ("base", "talker", "listener"):
        assert sorted(registry_tags(registry, f"{robot.name}-{repo}")) == ["v1", "v1-amd64"]  # list + arch
    run_robocore(robot, "run", "--tag", "v1", "--quiet")
    assert container_image(fleet, 0, talker) == f"{registry}/{robot.name}-talker:v1"
    assert container_image(fleet, 1, listener) == f"{registry}/{robot.name}-listener:v1"
    # rollback returns each host to what it ran before: the untagged images
    run_robocore(robot, "rollback")
    assert container_image(fleet, 0, talker) == f"{robot.name}-talker:latest"
    assert container_image(fleet, 1, listener) == f"{robot.name}-listener:latest"


def test_run_with_a_stopped_host_names_it_and_deploys_the_other(fleet: RobotFleet, robot: Path,
                                                                run_robocore: RobocoreCli) -> None:
    # last test of the module: stops robot-b
    fleet.client(0).containers.get(f"{robot.name}-talker").remove(force=True)
    fleet.stop(1)
    start = time.monotonic()
    proc = run_robocore(robot, "run", check=False)
    elapsed = time.monotonic() - start
    assert proc.returncode != 0
    assert "robot-b" in proc.stderr, proc.stderr
    assert elapsed < 30, f"run took {elapsed:.1f} s with robot-b down"
    assert fleet.client(0).containers.get(f"{robot.name}-talker").status == "running"


# --------------------------------------------------------------------------- TLS and plain TCP


def _pki(folder: Path, server_ip: str) -> dict[str, Path]:
    """A CA, a server certificate for ``server_ip``, a client certificate, and a rogue client
    certificate from another CA (the negative control)."""
    import datetime
    import ipaddress

    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

    now = datetime.datetime.now(datetime.timezone.utc)

    def name(text: str) -> x509.Name:
        return x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, text)])

    def write_key(key: Any, path: Path) -> Path:
        path.write_bytes(key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                           serialization.NoEncryption()))
        return path

    def cert(subject: str, key: Any, issuer: str, issuer_key: Any, *, ca: bool = False,
             ip: str | None = None, client: bool = False) -> x509.Certificate:
        builder = (x509.CertificateBuilder().subject_name(name(subject)).issuer_name(name(issuer))
                   .public_key(key.public_key()).serial_number(x509.random_serial_number())
                   .not_valid_before(now - datetime.timedelta(minutes=5))
                   .not_valid_after(now + datetime.timedelta(days=1))
                   .add_extension(x509.BasicConstraints(ca=ca, path_length=None), critical=True))
        if ip:
            builder = builder.add_extension(
                x509.SubjectAlternativeName([x509.IPAddress(ipaddress.ip_address(ip))]), critical=False)
            builder = builder.add_extension(x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH]), critical=False)
        if client:
            builder = builder.add_extension(x509.ExtendedKeyUsage([ExtendedKeyUsageOID.CLIENT_AUTH]), critical=False)
        return builder.sign(issuer_key, hashes.SHA256())

    def pem(c: x509.Certificate, path: Path) -> Path:
        path.write_bytes(c.public_bytes(serialization.Encoding.PEM))
        return path

    ca_key, rogue_key = ec.generate_private_key(ec.SECP256R1()), ec.generate_private_key(ec.SECP256R1())
    server_key, client_key = ec.generate_private_key(ec.SECP256R1()), ec.generate_private_key(ec.SECP256R1())
    out = {
        "ca": pem(cert("robocore test CA", ca_key, "robocore test CA", ca_key, ca=True), folder / "ca.pem"),
        "server": pem(cert("robot", server_key, "robocore test CA", ca_key, ip=server_ip), folder / "server.pem"),
        "server_key": write_key(server_key, folder / "server-key.pem"),
        "client": pem(cert("dev", client_key, "robocore test CA", ca_key, client=True), folder / "cert.pem"),
        "client_key": write_key(client_key, folder / "key.pem"),
        "rogue": pem(cert("mallory", rogue_key, "mallory", rogue_key, client=True), folder / "rogue.pem"),
        "rogue_key": write_key(rogue_key, folder / "rogue-key.pem"),
    }
    return out


TLS_DIR = "/etc/robocore-tls"


@pytest.fixture(scope="module")
def tcp_fleet(robot_fleets: Callable[..., RobotFleet],
              tmp_path_factory: pytest.TempPathFactory) -> tuple[RobotFleet, dict[str, Path]]:
    """robot 0 serves Docker on TCP 2376 with TLS client verification, robot 1 on plain TCP 2375."""
    pki: dict[str, Path] = {}
    folder = tmp_path_factory.mktemp("pki")

    def setup(host: Any) -> None:
        if host.name.endswith("-0"):
            pki.update(_pki(folder, host.ip))
            archive = io.BytesIO()
            with tarfile.open(fileobj=archive, mode="w") as tar:
                for key, file in (("ca", "ca.pem"), ("server", "server.pem"), ("server_key", "server-key.pem")):
                    tar.add(pki[key], arcname=f"robocore-tls/{file}")
                info = tarfile.TarInfo("robocore-tls/ready")
                tar.addfile(info, io.BytesIO(b""))
            host.container.get_wrapped_container().put_archive("/etc", archive.getvalue())

    tls_args = (f"--tlsverify --tlscacert={TLS_DIR}/ca.pem --tlscert={TLS_DIR}/server.pem "
                f"--tlskey={TLS_DIR}/server-key.pem --host tcp://0.0.0.0:2376")
    env = [{"DOCKERD_ARGS": tls_args, "DOCKERD_WAIT_FILE": f"{TLS_DIR}/ready"},
           {"DOCKERD_ARGS": "--host tcp://0.0.0.0:2375"}]
    return robot_fleets(2, env=env, setup=setup), pki


def test_docker_over_tls_with_client_certificates(tcp_fleet: tuple[RobotFleet, dict[str, Path]],
                                                  tiny_images: list[str], docker_client: Any) -> None:
    from robocore.adapters.docker_hosts import client_for
    from robocore.config.model import DockerAccess, TlsFiles

    fleet, pki = tcp_fleet
    ip = fleet.hosts[0].ip
    host = Host(name="tls-robot", ip=ip, docker=DockerAccess.tls, docker_port=2376,
                tls=TlsFiles(ca_cert=str(pki["ca"]), client_cert="cert.pem", client_key="key.pem"))
    # relative paths: project folder
    with contextlib.closing(client_for(host, timeout=120, project_root=pki["ca"].parent)) as client:
        assert client.version()["Version"]
        assert client.api.base_url.startswith("https://")
        result = ensure_images(client, [TINY], registry=None, progress=False, label=host.name)
        assert result[TINY].action == "loaded"
        assert client.images.get(TINY).id == docker_client.images.get(TINY).id
    # negative control: a client certificate from another CA is refused, and the host is named
    rogue = Host(name="tls-robot", ip=ip, docker=DockerAccess.tls, docker_port=2376,
                 tls=TlsFiles(ca_cert=str(pki["ca"]), client_cert=str(pki["rogue"]), client_key=str(pki["rogue_key"])))
    with pytest.raises(HostError) as caught:
        client_for(rogue, timeout=30)
    assert "tls-robot" in caught.value.message


def test_plain_tcp_only_when_insecure_and_with_a_warning(tcp_fleet: tuple[RobotFleet, dict[str, Path]],
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    from robocore.adapters.docker_hosts import client_for
    from robocore.config.model import DockerAccess

    fleet, _ = tcp_fleet
    ip = fleet.hosts[1].ip
    with pytest.raises(HostError):
        client_for(Host(name="plain", ip=ip, docker=DockerAccess.tcp, docker_port=2375), timeout=30)
    capsys.readouterr()
    insecure = Host(name="plain", ip=ip, docker=DockerAccess.tcp, docker_port=2375, insecure=True)
    with contextlib.closing(client_for(insecure, timeout=30)) as client:
        assert client.version()["Version"]
    err = capsys.readouterr().err
    assert "warning" in err and "plain" in err and "tcp://" in err, err
