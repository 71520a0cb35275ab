"""A fleet registry with TLS and a login: fleet.yaml's registry_ca (its checks), the CA's way onto a robot host
(the archive, the helper container, the join's refusal), and what a failed push or pull tells the user."""

from __future__ import annotations

import io
import tarfile
from pathlib import Path
from typing import Any

import pytest

from robocore.adapters import registry_trust as adapter
from robocore.adapters.swarm import TaskInfo
from robocore.commands.support.registry_ca import Trust
from robocore.config.fleet import parse_fleet_text
from robocore.config.loader import parse_robot_text
from robocore.config.model import Host
from robocore.config.registry_ca import read_registry_ca
from robocore.errors import ConfigError, DockerError, HostError, UsageError
from robocore.plan.registry_trust import (
    ca_archive,
    ca_file,
    file_in_archive,
    pull_hint,
    push_hint,
    registry_host,
    trust_problem,
)

ROBOT = """\
ros_distro: jazzy
hosts:
  - {name: main, ip: 192.168.1.10}
components:
  - {name: talker, folder: components/talker, runs_on: main}
"""

PEM = b"-----BEGIN CERTIFICATE-----\nMIIB\n-----END CERTIFICATE-----\n"


def fleet_text(ca: str | None, registry: str | None = "reg.lan:5000") -> str:
    return "\n".join(line for line in [
        "manager: {ip: 10.0.0.2}",
        f"registry: {registry}" if registry else "",
        f"registry_ca: {ca}" if ca is not None else "",
        "robots:",
        "  - {name: r1, hosts: {main: {ip: 10.0.1.5}}}",
    ] if line) + "\n"


def problems(project: Path, ca: str | None, registry: str | None = "reg.lan:5000") -> list[str]:
    robot = parse_robot_text(ROBOT)
    try:
        parse_fleet_text(fleet_text(ca, registry), robot, project=project)
    except ConfigError as exc:
        return exc.lines()
    return []


def test_registry_ca_names_a_pem_certificate_of_the_project(tmp_path: Path) -> None:
    (tmp_path / "certs").mkdir()
    (tmp_path / "certs" / "ca.crt").write_bytes(PEM)
    assert problems(tmp_path, "certs/ca.crt") == []
    robot = parse_robot_text(ROBOT)
    fleet = parse_fleet_text(fleet_text("certs/ca.crt"), robot, project=tmp_path)
    assert fleet.registry_ca == "certs/ca.crt"
    assert read_registry_ca("certs/ca.crt", tmp_path) == PEM
    assert problems(tmp_path, None) == []  # optional: a registry of a public CA needs none


@pytest.mark.parametrize(("content", "said"), [
    (b"hello\n", "is not a PEM certificate"),
    (PEM + b"-----BEGIN PRIVATE KEY-----\nxx\n-----END PRIVATE KEY-----\n", "holds a private key"),
    (PEM + b"-----BEGIN EC PRIVATE KEY-----\n", "holds a private key"),
    (PEM + b"x" * 70_000, "larger than 65,536 bytes"),
])
def test_registry_ca_that_is_no_ca_certificate_is_refused(tmp_path: Path, content: bytes, said: str) -> None:
    (tmp_path / "ca.crt").write_bytes(content)
    [line] = problems(tmp_path, "ca.crt")
    assert line.startswith("fleet.yaml:3: registry_ca: file 'ca.crt' ") and said in line, line
    with pytest.raises(UsageError, match=said):
        read_registry_ca("ca.crt", tmp_path)


def test_registry_ca_missing_outside_or_without_registry_is_one_line_each(tmp_path: Path) -> None:
    project = tmp_path / "project"
    project.mkdir()
    (tmp_path / "outside.crt").write_bytes(PEM)
    assert problems(project, "certs/ca.crt") == ["fleet.yaml:3: registry_ca: file 'certs/ca.crt' not found"]
    [line] = problems(project, "../outside.crt")
    assert "names a file outside the project folder" in line, line
    (project / "link.crt").symlink_to(tmp_path / "outside.crt")
    [line] = problems(project, "link.crt")
    assert "leads through a symlink to a file outside the project folder" in line, line
    assert problems(project, str(tmp_path / "outside.crt")) == []  # an absolute path names a file outside
    (project / "dir.crt").mkdir()
    assert problems(project, "dir.crt") == ["fleet.yaml:3: registry_ca: file 'dir.crt' not found"]
    (project / "ca.crt").write_bytes(PEM)
    lines = problems(project, "ca.crt", registry=None)
    assert any("registry_ca: registry_ca is the CA of the fleet's registry, but no registry is set" in line
               for line in lines), lines


def test_the_ca_archive_unpacks_as_certs_d_wants_it() -> None:
    assert registry_host("reg.lan:5000/team/images") == "reg.lan:5000" == registry_host("reg.lan:5000")
    assert ca_file("reg.lan:5000/team") == "reg.lan:5000/ca.crt"
    data = ca_archive("reg.lan:5000/team", PEM, mtime=1_700_000_000)
    with tarfile.open(fileobj=io.BytesIO(data)) as tar:
        members = {m.name: (m.isdir(), m.mode, m.mtime) for m in tar.getmembers()}
    assert members == {"reg.lan:5000": (True, 0o755, 1_700_000_000),
                       "reg.lan:5000/ca.crt": (False, 0o644, 1_700_000_000)}
    assert file_in_archive(data) == PEM
    assert ca_archive("reg.lan:5000", PEM) == ca_archive("reg.lan:5000", PEM)  # the same bytes each time
    folder_only = io.BytesIO()
    with tarfile.open(fileobj=folder_only, mode="w") as tar:
        info = tarfile.TarInfo("x")
        info.type = tarfile.DIRTYPE
        tar.addfile(info)
    assert file_in_archive(folder_only.getvalue()) is None


def test_push_and_pull_failures_say_what_to_do_naming_the_registry() -> None:
    assert trust_problem("no basic auth credentials") == "login"
    assert trust_problem("unauthorized: authentication required") == "login"
    assert trust_problem('Get "https://10.0.0.2:5000/v2/": x509: certificate signed by unknown authority') == "ca"
    assert trust_problem("connection refused") == ""
    assert push_hint("10.0.0.2:5000/robot-talker", "no basic auth credentials") == \
        "log this machine's Docker in to the registry: docker login 10.0.0.2:5000"
    assert "/etc/docker/certs.d/10.0.0.2:5000/ca.crt" in push_hint("10.0.0.2:5000/x", "x509: certificate signed")
    assert "10.0.0.2:5000" in push_hint("10.0.0.2:5000/x", "connection refused")
    image = "10.0.0.2:5000/robot-talker@sha256:" + "a" * 64
    hint = pull_hint(image, f"No such image: {image}")
    assert "could not pull it from 10.0.0.2:5000" in hint and "docker login 10.0.0.2:5000" in hint
    assert pull_hint(image, "task: non-zero exit (3)") == ""
    assert pull_hint("robot-talker:v1", "No such image: robot-talker:v1") == ""  # no registry: no such advice
    task = TaskInfo(id="t", node_id="n", state="rejected", desired="shutdown", image=image, created="",
                    error=f"No such image: {image}", exit_code=None, container="")
    assert task.why.startswith(f"No such image: {image} (the robot could not pull it from 10.0.0.2:5000")
    assert TaskInfo(**{**task.__dict__, "error": "exit 3"}).why == "exit 3"


class FakeApi:
    """The parts of docker-py's APIClient the CA's install uses, recording what it was asked."""

    def __init__(self, existing: bytes | None = None, *, refuse: str = "") -> None:
        self.existing, self.refuse = existing, refuse
        self.calls: list[str] = []
        self.written: bytes | None = None
        self.binds: Any = None

    def import_image_from_data(self, data: bytes, repository: str, tag: str) -> None:
        self.calls.append(f"import {repository}:{tag}")

    def create_host_config(self, binds: Any) -> dict[str, Any]:
        self.binds = binds
        return {"Binds": binds}

    def create_container(self, image: str, **kwargs: Any) -> dict[str, str]:
        from docker.errors import APIError

        if self.refuse:
            raise APIError(self.refuse, explanation=self.refuse)
        self.calls.append(f"create {image}")
        return {"Id": "c1"}

    def get_archive(self, container: str, path: str) -> tuple[list[bytes], dict[str, Any]]:
        from docker.errors import NotFound

        self.calls.append(f"get {path}")
        if self.existing is None:
            raise NotFound("no such file")
        return [ca_archive("x", self.existing)], {}

    def put_archive(self, container: str, path: str, data: bytes) -> bool:
        self.calls.append(f"put {path}")
        self.written = data
        return True

    def remove_container(self, container: str, force: bool) -> None:
        self.calls.append(f"remove {container}")


class FakeClient:
    def __init__(self, api: FakeApi, has_helper: bool = False) -> None:
        self.api = api
        self.has_helper = has_helper
        outer = self

        class Images:
            def get(self, name: str) -> object:
                from docker.errors import ImageNotFound

                if not outer.has_helper:
                    raise ImageNotFound(name)
                return object()

        self.images = Images()


def test_install_ca_writes_through_a_never_started_container_with_certs_d_mounted() -> None:
    api = FakeApi()
    assert adapter.install_ca(FakeClient(api), "reg.lan:5000", PEM) == "installed"  # type: ignore[arg-type]
    assert api.binds == {"/etc/docker/certs.d": {"bind": "/certs.d", "mode": "rw"}}
    assert api.calls == ["import robocore-certs-helper:1", "create robocore-certs-helper:1",
                         "get /certs.d/reg.lan:5000/ca.crt", "put /certs.d", "remove c1"]
    assert api.written is not None and file_in_archive(api.written) == PEM
    same = FakeApi(existing=PEM)
    assert adapter.install_ca(FakeClient(same, has_helper=True), "reg.lan:5000", PEM) == "unchanged"  # type: ignore[arg-type]
    assert "put /certs.d" not in same.calls and same.calls[-1] == "remove c1"
    other = FakeApi(existing=b"an older CA")
    assert adapter.install_ca(FakeClient(other, has_helper=True), "reg.lan:5000", PEM) == "installed"  # type: ignore[arg-type]


def test_a_robot_whose_daemon_refuses_the_ca_is_named_with_what_to_do(tmp_path: Path) -> None:
    trust = Trust(registry="reg.lan:5000", source="certs/ca.crt", pem=PEM)
    host = Host(name="main", ip="10.0.1.5")
    with pytest.raises(HostError) as caught:
        trust.install(FakeClient(FakeApi(refuse="permission denied")), host)  # type: ignore[arg-type]
    lines = caught.value.lines()
    assert lines[0] == ("10.0.1.5: the registry's CA could not be installed: installing the registry's CA at "
                        "/etc/docker/certs.d/reg.lan:5000/ca.crt: permission denied"), lines
    assert lines[1] == ("hint: copy certs/ca.crt to /etc/docker/certs.d/reg.lan:5000/ca.crt on 10.0.1.5 yourself "
                        "(as root), then run `fleet join` again")
    assert trust.dry_run() == "put certs/ca.crt at /etc/docker/certs.d/reg.lan:5000/ca.crt on it"
    with pytest.raises(DockerError):
        adapter.install_ca(FakeClient(FakeApi(refuse="no")), "r:1", PEM)  # type: ignore[arg-type]


class _Answer:
    """A Docker API answer (what docker-py's ``_result`` reads)."""

    status_code = 200

    def __init__(self, body: dict[str, Any]) -> None:
        self.body = body

    def raise_for_status(self) -> None:
        return None

    def json(self) -> dict[str, Any]:
        return self.body


def _sent_logins(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, auths: dict[str, Any]) -> list[dict[str, Any]]:
    """What robocore's swarm adapter sends as X-Registry-Auth when it creates a service and then updates it (a
    docker-py client whose HTTP calls are answered here), with ``auths`` as this machine's docker login."""
    import base64
    import json

    import docker
    from docker.errors import NotFound

    from robocore.adapters.swarm import apply_service
    from robocore.plan.swarm_services import ServiceSpec

    tmp_path.mkdir()
    (tmp_path / "config.json").write_text(json.dumps({"auths": auths}))
    monkeypatch.setenv("DOCKER_CONFIG", str(tmp_path))
    client = docker.DockerClient(base_url="tcp://127.0.0.1:9", version="1.41")
    image = "reg.lan:5000/robot-talker@sha256:" + "0" * 64
    spec = ServiceSpec(name="robot-r1-talker", robot="r1", component="talker", role="component", image=image,
                       command=None, args=None, environment=(), mounts=(), configs=(), constraints=(), restart="any")
    stored = {"ID": "svc1", "Version": {"Index": 1}, "Spec": {"Name": spec.name, "Labels": {}, "Mode": {"Global": {}},
                                                              "TaskTemplate": {"ContainerSpec": {"Image": image}}}}
    made: list[bool] = []

    def inspect_service(service: str, insert_defaults: bool | None = None) -> dict[str, Any]:
        if not made:
            raise NotFound(service)
        return stored

    posts: list[tuple[str, dict[str, str]]] = []

    def post_json(url: str, data: Any, params: Any = None, headers: dict[str, str] | None = None,
                  **kwargs: Any) -> _Answer:
        posts.append((url, dict(headers or {})))
        made.append(True)
        return _Answer({"ID": "svc1"})

    monkeypatch.setattr(client.api, "inspect_service", inspect_service)
    monkeypatch.setattr(client.api, "_post_json", post_json)
    assert apply_service(client, spec, {}) == "svc1"
    assert [url.rsplit("/", 2)[-2:] for url, _ in posts] == [["services", "create"], ["svc1", "update"]]
    sent = []
    for _, headers in posts:
        header: str | bytes | None = headers.get("X-Registry-Auth")  # docker-py sends bytes
        raw = header.encode() if isinstance(header, str) else header
        sent.append(json.loads(base64.urlsafe_b64decode(raw + b"==")) if raw else {})
    return sent


def test_the_manager_is_handed_this_machines_login_on_every_service_create_and_update(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """As `docker service create/update --with-registry-auth`: the login `docker login reg.lan:5000` wrote goes
    with each create and update of a service of that registry's image, so Swarm hands it to the robots' pulls."""
    import base64

    basic = base64.b64encode(b"fleet:s3cret").decode()
    sent = _sent_logins(tmp_path / "login", monkeypatch, {"reg.lan:5000": {"auth": basic}})
    assert [(s.get("username"), s.get("password"), s.get("serveraddress")) for s in sent] == \
        [("fleet", "s3cret", "reg.lan:5000")] * 2
    # the control: no login for that registry, none sent (the robots pull anonymously)
    assert _sent_logins(tmp_path / "other", monkeypatch, {"other.lan:5000": {"auth": basic}}) == [{}, {}]
