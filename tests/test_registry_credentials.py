"""A team's registry login kept by a Docker credential helper (``credHelpers`` in the Docker config, as ``docker
login`` with a helper writes it) reaches the registry as ``docker push`` and ``docker service create
--with-registry-auth`` send it: in the ``X-Registry-Auth`` header of robocore's push and of every service it creates,
for that registry only. The Swarm suite proves a login of ``docker login`` (``auths``) end to end on real robots;
this is the credential-helper form of the same path, against a Docker API that records what it is sent.

The helper is a real program on ``PATH`` (``docker-credential-<name>``) that answers the registry's name on its
standard input with the login, as the helpers of pass, secretservice or a cloud's registry do."""

from __future__ import annotations

import base64
import json
import os
import stat
import threading
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any

import pytest

from robocore.adapters import image_delivery, swarm
from robocore.adapters.docker_hosts import client_for
from robocore.config.model import Host
from robocore.plan.swarm_services import ServiceSpec

REGISTRY = "registry.lab:5000"
SECRET = "s3cret-from-the-helper"
DIGEST = "sha256:" + "ab" * 32


class FakeDocker(BaseHTTPRequestHandler):
    """Just enough of Docker's API for a ping, a service create and a push; records each request's auth header."""

    seen: list[tuple[str, str, str | None]] = []  # (method, path, X-Registry-Auth)

    def log_message(self, *args: Any) -> None:
        pass

    protocol_version = "HTTP/1.1"  # a push's progress is a chunked stream of JSON objects

    def _answer(self, code: int, body: Any, *, lines: bool = False) -> None:
        self.send_response(code)
        self.send_header("Content-Type", "application/json")
        self.send_header("Api-Version", "1.41")
        if lines:
            self.send_header("Transfer-Encoding", "chunked")
            self.end_headers()
            for item in body:
                data = json.dumps(item).encode() + b"\r\n"
                self.wfile.write(f"{len(data):x}\r\n".encode() + data + b"\r\n")
            self.wfile.write(b"0\r\n\r\n")
            return
        data = json.dumps(body).encode()
        self.send_header("Content-Length", str(len(data)))
        self.end_headers()
        self.wfile.write(data)

    def do_GET(self) -> None:
        self.seen.append(("GET", self.path, self.headers.get("X-Registry-Auth")))
        if self.path.endswith("/_ping"):
            self.send_response(200)
            self.send_header("Content-Length", "2")
            self.end_headers()
            self.wfile.write(b"OK")
        elif self.path.endswith("/version"):
            self._answer(200, {"ApiVersion": "1.41", "Version": "20.10.24"})
        elif self.path.split("?")[0].endswith("/services/service1"):  # the service just created
            self._answer(200, {"ID": "service1", "Version": {"Index": 1}, "Spec": {"Name": "p-r1-talker"}})
        else:  # GET /services/NAME: no such service yet
            self._answer(404, {"message": "service not found"})

    def do_POST(self) -> None:
        length = int(self.headers.get("Content-Length") or 0)
        self.rfile.read(length)
        self.seen.append(("POST", self.path, self.headers.get("X-Registry-Auth")))
        if "/services/create" in self.path:
            self._answer(201, {"ID": "service1"})
        elif "/push" in self.path:
            self._answer(200, [{"status": "Pushed"}, {"aux": {"Tag": "v1", "Digest": DIGEST, "Size": 1}}],
                         lines=True)
        else:
            self._answer(404, {"message": "not here"})


@pytest.fixture
def docker_api() -> Iterator[int]:
    FakeDocker.seen = []
    server = ThreadingHTTPServer(("127.0.0.1", 0), FakeDocker)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield server.server_address[1]
    finally:
        server.shutdown()
        server.server_close()


@pytest.fixture
def helper(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A Docker config whose login for :data:`REGISTRY` is kept by the helper ``robocoretest``; returns the file the
    helper writes each registry it was asked for to."""
    config = tmp_path / "docker-config"
    config.mkdir(mode=0o700)
    (config / "config.json").write_text(json.dumps({"credHelpers": {REGISTRY: "robocoretest"}}))
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    asked = tmp_path / "asked"
    program = bin_dir / "docker-credential-robocoretest"
    program.write_text(f"""#!/bin/sh
[ "$1" = get ] || exit 1
read -r server
printf '%s\\n' "$server" >> '{asked}'
printf '{{"ServerURL": "%s", "Username": "robot-pusher", "Secret": "{SECRET}"}}' "$server"
""")
    program.chmod(program.stat().st_mode | stat.S_IXUSR)
    monkeypatch.setenv("DOCKER_CONFIG", str(config))
    monkeypatch.setenv("PATH", f"{bin_dir}{os.pathsep}{os.environ['PATH']}")
    return asked


def spec(image: str) -> ServiceSpec:
    return ServiceSpec(name="p-r1-talker", robot="r1", component="talker", role="component", image=image,
                       command=None, args=None, environment=(), mounts=(), configs=(), constraints=(),
                       restart="none")


def login_in(header: str | None) -> dict[str, Any]:
    """The login an X-Registry-Auth header carries, its keys in lower case (the daemon reads them so, as Go's JSON
    does; docker-py passes a helper's ``Username`` and ``Password`` on as they came)."""
    assert header is not None, "no X-Registry-Auth header"
    sent = json.loads(base64.urlsafe_b64decode(header + "=" * (-len(header) % 4)))
    return {str(key).lower(): value for key, value in sent.items()}


def test_a_credential_helpers_login_goes_with_the_push_and_the_services_of_its_registry(
        helper: Path, docker_api: int, capsys: pytest.CaptureFixture[str]) -> None:
    manager = Host(name="manager", ip="127.0.0.1", docker="tcp", docker_port=docker_api, insecure=True)
    client = client_for(manager, timeout=10)
    swarm.apply_service(client, spec(f"{REGISTRY}/p-talker@{DIGEST}"), {})
    pushed = image_delivery.push_digest(client, f"{REGISTRY}/p-talker", "v1")
    assert pushed == DIGEST
    sent = {(method, path.split("?")[0].split("/", 2)[-1]): auth for method, path, auth in FakeDocker.seen}
    for request in (("POST", "services/create"), ("POST", f"images/{REGISTRY}/p-talker/push")):
        login = login_in(sent[request])
        assert (login["username"], login["password"], login["serveraddress"]) == ("robot-pusher", SECRET, REGISTRY), \
            request
    assert REGISTRY in helper.read_text().split()
    out = capsys.readouterr()
    assert SECRET not in out.out + out.err


def test_negative_control_an_image_of_another_registry_is_sent_no_login(helper: Path, docker_api: int) -> None:
    """The helper keeps the login of registry.lab:5000 only: a service of another registry's image carries none of
    it (the header, when docker-py sends one, holds no password)."""
    manager = Host(name="manager", ip="127.0.0.1", docker="tcp", docker_port=docker_api, insecure=True)
    client = client_for(manager, timeout=10)
    swarm.apply_service(client, spec(f"other.lab:5000/p-talker@{DIGEST}"), {})
    created = [auth for method, path, auth in FakeDocker.seen if method == "POST" and "services/create" in path]
    assert len(created) == 1
    assert created[0] is None or not login_in(created[0]).get("password"), login_in(created[0])
