"""robocore.adapters.docker_socket against a stand-in daemon on a real unix socket (HTTP/1.0, as the Engine answers)."""

from __future__ import annotations

import json
import socket
import threading
from collections.abc import Iterator
from pathlib import Path
from urllib.parse import unquote

import pytest

from robocore.adapters import docker_socket

LISTED = [{"Id": "aaa"}, {"Id": "bbb"}]
INSPECTED = {"aaa": {"Id": "aaa", "Name": "/p-talker", "State": {"Status": "running"}},
             "bbb": {"Id": "bbb", "Name": "/p-listener", "State": {"Status": "exited"}}}


@pytest.fixture
def daemon(tmp_path: Path) -> Iterator[tuple[str, list[str], set[str]]]:
    """A unix socket answering the container list and inspect calls; the paths asked; ids to answer 404 for."""
    path = str(tmp_path / "docker.sock")
    asked: list[str] = []
    gone: set[str] = set()
    server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    server.bind(path)
    server.listen(8)

    def serve() -> None:
        while True:
            try:
                conn, _ = server.accept()
            except OSError:
                return
            with conn:
                request = b""
                while b"\r\n\r\n" not in request:
                    request += conn.recv(4096)
                target = request.split(b" ")[1].decode()
                asked.append(unquote(target))
                code, body = 404, b"{}"
                if target.startswith("/containers/json?"):
                    code, body = 200, json.dumps(LISTED).encode()
                elif target.startswith("/containers/") and target.split("/")[2] not in gone:
                    code, body = 200, json.dumps(INSPECTED[target.split("/")[2]]).encode()
                conn.sendall(f"HTTP/1.0 {code} X\r\nContent-Type: application/json\r\n\r\n".encode() + body)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    yield path, asked, gone
    server.close()


def test_containers_are_listed_by_label_then_inspected(daemon: tuple[str, list[str], set[str]]) -> None:
    path, asked, _ = daemon
    found = docker_socket.containers("dev.robocore.project=p", environ={"DOCKER_HOST": f"unix://{path}"})
    assert found == [INSPECTED["aaa"], INSPECTED["bbb"]]
    assert json.loads(asked[0].split("filters=", 1)[1]) == {"label": ["dev.robocore.project=p"]}
    assert "all=1" in asked[0] and asked[1:] == ["/containers/aaa/json", "/containers/bbb/json"]


def test_a_container_that_cannot_be_inspected_sends_the_caller_to_docker_py(
        daemon: tuple[str, list[str], set[str]]) -> None:
    path, _, gone = daemon
    gone.add("bbb")  # removed between the list and its inspect
    assert docker_socket.containers("x=y", environ={"DOCKER_HOST": f"unix://{path}"}) is None


def test_no_local_socket_means_no_answer(tmp_path: Path) -> None:
    assert docker_socket.containers("x=y", environ={"DOCKER_HOST": "tcp://10.0.0.1:2375"}) is None
    assert docker_socket.containers("x=y", environ={"DOCKER_HOST": f"unix://{tmp_path}/none.sock"}) is None
