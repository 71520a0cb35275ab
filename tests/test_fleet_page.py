"""``fleet page``: the pure renderer (every state, escaping, nothing secret), the look built from what the manager
holds (a fake one), the snapshot's folder checks, the flags, and the read-only server. The page in a real browser
is integration/test_fleet_page.py's."""

from __future__ import annotations

import http.client
import json
import os
from dataclasses import replace
from pathlib import Path
from typing import Any

import fleet_world
import pytest

from robocore.adapters import page_server, swarm
from robocore.cli import main
from robocore.commands import fleet_page
from robocore.commands.fleet import page_flags
from robocore.commands.fleet_status import Observed, status_rows
from robocore.commands.fleet_swarm import FleetProject
from robocore.errors import UsageError
from robocore.plan import naming
from robocore.plan import swarm_services as plan
from robocore.plan.fleet_page import (
    ComponentView,
    FleetView,
    ReleaseView,
    RobotView,
    render_fleet,
    render_page,
    rollout,
    verdict,
)

FLEET = """\
manager: {ip: 10.9.9.2}
registry: 10.9.9.2:5000
robots:
  - {name: r1, hosts: {main: {ip: 10.9.1.1}}, labels: {site: lab}}
  - {name: r2, hosts: {main: {ip: 10.9.2.1}}, labels: {site: depot}}
rollout:
  waves: [{name: canary, robots: [r1]}]
"""
SECRET = "hunter2-s3cret"
DIGEST = "@sha256:" + "b" * 64


def robot(name: str = "r1", **fields: Any) -> RobotView:
    base: dict[str, Any] = {"wave": "rest", "running": "v2", "target": "v2", "health": "healthy", "state": "online",
                            "changed": "2026-12-06T20:00:00Z"}
    return RobotView(robot=name, **{**base, **fields})


def view(*robots: RobotView, **fields: Any) -> FleetView:
    return FleetView(project="demo", taken="2026-12-06T21:00:00Z", robots=robots, waves=("canary", "rest"), **fields)


STATES = [  # (robot, tone, words): every state the page shows
    (robot(), "ok", "healthy"),
    (robot(health="failed", reason="talker failed with code 3"), "bad", "failed"),
    (robot(health="rolled-back", reason="talker failed with code 3 (restarting)"), "bad", "failed, back on v2"),
    (robot(running="v1", health="pending", state="offline, pending"), "off", "offline, pending"),
    (robot(running="?", health="healthy", state="offline"), "off", "offline"),
    (robot(running="v1", health="", state="pending"), "wait", "being gated"),
    (robot(running="v1", health="pending", state="pending"), "warn", "pending"),
    (robot(running="-", target="-", health="-"), "off", "not deployed"),
    (robot(running="v1", target="v1", state="online, busy since 2026-12-07T00:41:02Z"), "warn",
     "busy since 2026-12-07T00:41:02Z"),  # held back by its update lock or window (fleet_safe)
    (robot(running="v1", target="v1", health="busy"), "warn", "busy"),  # left as it was past timeouts.busy
]


@pytest.mark.parametrize(("one", "tone", "words"), STATES)
def test_every_state_is_said_in_words_with_a_symbol_and_a_colour(one: RobotView, tone: str, words: str) -> None:
    shown = verdict(one)
    assert (shown.tone, shown.words) == (tone, words)
    assert shown.symbol.strip()
    html = render_page(view(one))
    assert f'<tr class="robot {tone}" data-robot="r1"' in html
    assert f'<span class="badge {tone}"><span class="sym" aria-hidden="true">{shown.symbol}</span> {words}</span>' \
        in html
    if one.reason:
        assert one.reason in html


def test_the_rollout_says_who_is_gated_who_failed_and_who_waits() -> None:
    page = view(robot("r1", wave="canary", health="rolled-back", reason="talker failed with code 3"),
                robot("r2", running="v1", health="", state="pending"),
                robot("r3", running="v1", health="pending", state="offline, pending"))
    seen = rollout(page)
    assert (seen.target, [r.robot for r in seen.gating], [r.robot for r in seen.failed],
            [r.robot for r in seen.pending]) == ("v2", ["r2"], ["r1"], ["r3"])
    html = render_fleet(page)
    assert "r1 (wave canary): failed, back on v2; reason: talker failed with code 3" in html
    assert "r3: offline, pending: runs v1; Swarm starts v2 there when it is back" in html
    assert "rollout of v2 in progress: 1 robot(s) being gated" in html
    assert '<li data-wave="canary"><b>wave canary</b>: 1 robot(s): <span class="bad">1 failed, back on v2</span>' \
        in html


def test_names_labels_and_reasons_are_text_never_markup() -> None:
    evil = '<script>alert("x")</script>\'"&'
    html = render_page(view(robot(evil, labels=(("k" + evil, evil),), reason=evil),
                            releases=(ReleaseView(evil, "-", ((evil, "amd64", "r/p" + DIGEST),)),)), live=True)
    assert "<script>alert" not in html and "alert(&#34;x&#34;)" in html
    assert 'data-robot="&lt;script&gt;alert(&#34;x&#34;)&lt;/script&gt;&#39;&#34;&amp;"' in html
    assert html.count("<script>") == 1  # the page's own


def test_a_secret_like_word_in_a_reason_is_hidden() -> None:
    html = render_page(view(robot(health="failed", reason=f"probe: error password={SECRET} token: {SECRET}")))
    assert SECRET not in html and "password=(hidden) token: (hidden)" in html


def test_the_snapshot_loads_nothing_from_elsewhere() -> None:
    html = render_page(view(robot()))
    assert "http://" not in html and "https://" not in html and "src=" not in html
    assert "default-src 'none'" in html and 'fetch("fleet"' not in html
    assert 'fetch("fleet"' in render_page(view(robot()), live=True)


# --------------------------------------------------------------------------- the look, from a fake manager


@pytest.fixture
def fleet_project(tmp_path: Path) -> FleetProject:
    return fleet_world.fleet_project(tmp_path / "p", FLEET)


def observed(project: str) -> Observed:
    """r1: its v3 canary failed and it went back to v2 (the reason in its label); r2: offline, targeted v3, still
    known to run v2. Every service carries an environment with a secret, as a component's may."""
    def service(robot: str, health: str, reason: str, image: str) -> swarm.ServiceInfo:
        labels = {naming.LABEL_PROJECT: project, plan.LABEL_ROBOT: robot, naming.LABEL_ROLE: naming.ROLE_COMPONENT,
                  naming.LABEL_COMPONENT: "talker", plan.LABEL_RELEASE: "v2" if robot == "r1" else "v3",
                  plan.LABEL_IMAGE: image, plan.LABEL_PREVIOUS: "v2", plan.LABEL_PREVIOUS_IMAGE: "reg/p-talker:v2",
                  plan.LABEL_CHANGED: "2026-12-06T20:00:00Z", plan.LABEL_HEALTH: health, plan.LABEL_REASON: reason}
        attrs = {"Spec": {"TaskTemplate": {"ContainerSpec": {"Env": [f"REGISTRY_PASSWORD={SECRET}"]}}}}
        return swarm.ServiceInfo(id=robot, name=f"{project}-{robot}-talker", labels=labels, image=image, version=1,
                                 attrs=attrs)

    services = [service("r1", "rolled-back", "talker failed with code 3 (restarting)", "reg/p-talker:v2"),
                service("r2", "pending", "offline (robot): Swarm starts it when it is back", "reg/p-talker:v3")]
    task = swarm.TaskInfo(id="t", node_id="n", state="running", desired="running", image="reg/p-talker:v2",
                          created="1", error="", exit_code=None, container="c")
    nodes = {"r1": [swarm.NodeInfo(id="n1", hostname="h1", labels=plan.node_labels(project, "r1", "main", "amd64"),
                                   state="ready", availability="active", addr="10.9.1.1")]}
    return Observed(by_robot=nodes, services=services, tasks={s.name: [task] for s in services})


def test_the_look_shows_the_failed_canary_and_the_offline_robot_and_nothing_secret(fleet_project: FleetProject) -> None:
    seen = observed(fleet_project.name)
    page = fleet_page.fleet_view(fleet_project, status_rows(fleet_project, seen), seen, (), "2026-12-06T21:00:00Z")
    assert [(r.robot, r.wave, r.labels, r.running, r.target, r.state) for r in page.robots] == [
        ("r1", "canary", (("site", "lab"),), "v2", "v2", "online"),
        ("r2", "rest", (("site", "depot"),), "v2", "v3", "offline, pending")]
    assert page.robots[0].components == (ComponentView("talker", "running"),)
    html = render_page(page)
    assert "failed, back on v2" in html and "talker failed with code 3 (restarting)" in html
    assert "offline, pending" in html
    for hidden in (SECRET, "10.9.9.2", "10.9.1.1", "REGISTRY_PASSWORD"):
        assert hidden not in html


def test_release_records_are_listed_and_a_broken_one_says_why(fleet_project: FleetProject) -> None:
    folder = fleet_project.project.releases_dir
    folder.mkdir(parents=True)
    record = {"format": 1, "version": "v2", "registry": "10.9.9.2:5000",
              "components": {"talker": {"amd64": "10.9.9.2:5000/p-talker" + DIGEST}},
              "base": {"amd64": "10.9.9.2:5000/p-base" + DIGEST}}
    (folder / "v2.json").write_text(json.dumps(record))
    (folder / "v3.json").write_text("{not json")
    os.utime(folder / "v2.json", (1_700_000_000, 1_700_000_000))
    releases, older = fleet_page.release_views(fleet_project.project, "10.9.9.2:5000")
    assert older == 0
    assert [(r.version, bool(r.problem)) for r in releases] == [("v3", True), ("v2", False)]
    assert releases[1].recorded == "2023-11-14T22:13:20Z"
    assert releases[1].images == (("talker", "amd64", "10.9.9.2:5000/p-talker" + DIGEST),
                                  ("base", "amd64", "10.9.9.2:5000/p-base" + DIGEST))
    html = render_page(view(robot(), releases=releases))
    assert "p-talker" + DIGEST in html and "not readable:" in html


def test_a_look_reads_the_newest_records_and_those_the_robots_run(fleet_project: FleetProject,
                                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """The page takes a look every few seconds and ``.robocore/releases/`` keeps every release: a look reads the
    newest records and those a robot runs or targets, and the page says how many older ones it left."""
    monkeypatch.setattr(fleet_page, "MAX_RELEASES", 3)
    folder = fleet_project.project.releases_dir
    folder.mkdir(parents=True)
    for n in range(1, 9):
        (folder / f"v{n}.json").write_text("{not json")  # unreadable: listed with why, and cheap to write here
        os.utime(folder / f"v{n}.json", (1_700_000_000 + n, 1_700_000_000 + n))
    releases, older = fleet_page.release_views(fleet_project.project, None, frozenset({"v2", "-"}))
    assert [r.version for r in releases] == ["v8", "v7", "v6", "v2"] and older == 4
    html = render_page(replace(view(robot()), releases=releases, older_releases=older))
    assert "4 older release records not shown" in html


# --------------------------------------------------------------------------- the snapshot, the flags, the server


def test_the_snapshot_is_one_file_in_a_real_folder(tmp_path: Path) -> None:
    written = fleet_page.write_snapshot(view(robot()), tmp_path / "out")
    assert written == tmp_path / "out" / "index.html" and "<table id=\"robots\">" in written.read_text()
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "elsewhere")
    with pytest.raises(UsageError, match="is a symlink"):
        fleet_page.write_snapshot(view(robot()), tmp_path / "link")
    (tmp_path / "out2").mkdir()
    (tmp_path / "out2" / "index.html").symlink_to(tmp_path / "elsewhere" / "x.html")
    with pytest.raises(UsageError, match="not a regular file"):
        fleet_page.write_snapshot(view(robot()), tmp_path / "out2")
    assert list((tmp_path / "elsewhere").iterdir()) == []
    (tmp_path / "file").write_text("")
    with pytest.raises(UsageError, match="is not a folder"):
        fleet_page.write_snapshot(view(robot()), tmp_path / "file")


def test_a_folder_that_cannot_be_written_is_one_line(tmp_path: Path) -> None:
    (tmp_path / "file").write_text("")  # a folder below a file cannot be made, even by root
    with pytest.raises(UsageError, match="cannot be written"):
        fleet_page.write_snapshot(view(robot()), tmp_path / "file" / "out")


@pytest.mark.parametrize(("args", "message"), [
    (["fleet", "page"], "fleet page needs one of --out DIR"),
    (["fleet", "page", "--serve", "--port", "70000"], "--port takes a port number from 0 to 65535"),
    (["fleet", "page", "--serve", "--port", "x1"], "--port takes a port number"),
    (["fleet", "page", "--out", "d", "--port", "1"], "--port and --bind go with --serve"),
    (["fleet", "status", "--serve"], "are fleet page's, not fleet status's"),
])
def test_bad_flags_are_one_line_and_exit_2(args: list[str], message: str, capsys: pytest.CaptureFixture[str],
                                           tmp_path: Path) -> None:
    with pytest.raises(SystemExit) as done:
        main(["-p", str(tmp_path), *args])
    err = capsys.readouterr().err
    assert done.value.code == 2, err
    assert message in err and "Traceback" not in err and len(err.strip().splitlines()) <= 2, err


def test_page_flags_are_checked() -> None:
    assert page_flags(None, True, "0", None).port == 0
    with pytest.raises(UsageError, match="empty value"):
        page_flags(None, True, None, " ")


def get(url: str, path: str, method: str = "GET", headers: dict[str, str] | None = None) -> http.client.HTTPResponse:
    host, port = url.split("//")[1].rstrip("/").rsplit(":", 1)
    connection = http.client.HTTPConnection(host, int(port), timeout=10)
    connection.request(method, path, headers=headers or {})
    return connection.getresponse()


def test_the_server_is_read_only_and_answers_a_known_look_with_304() -> None:
    looks = {"part": "<p>one</p>"}
    server = page_server.start(page_server.Pages(page=lambda: "<html>page</html>", part=lambda: looks["part"]),
                               "127.0.0.1", 0)
    page_server.serve_in_thread(server)
    try:
        answer = get(server.url, "/")
        assert (answer.status, answer.read()) == (200, b"<html>page</html>")
        assert "default-src 'none'" in answer.headers["Content-Security-Policy"]
        first = get(server.url, "/fleet")
        tag = first.headers["ETag"]
        assert first.read() == b"<p>one</p>" and tag
        assert get(server.url, "/fleet", headers={"If-None-Match": tag}).status == 304
        looks["part"] = "<p>two</p>"
        again = get(server.url, "/fleet", headers={"If-None-Match": tag})
        assert (again.status, again.read()) == (200, b"<p>two</p>")
        for method in ("POST", "PUT", "DELETE"):
            assert get(server.url, "/", method).status == 405
        assert get(server.url, "/../etc/passwd").status == 404
        with pytest.raises(UsageError, match="the port is in use"):
            page_server.start(page_server.Pages(page=str, part=str), "127.0.0.1", int(server.url.rsplit(":", 1)[1]
                                                                                          .rstrip("/")))
    finally:
        server.shutdown()
        server.server_close()


def test_looks_are_taken_at_most_once_per_interval_and_a_failed_one_keeps_the_last() -> None:
    now = [0.0]
    taken: list[int] = []

    def read() -> FleetView:
        taken.append(1)
        if len(taken) == 3:
            raise UsageError("cannot reach the manager")
        return view(robot(running=f"v{len(taken)}"))

    looks = fleet_page.Looks(read, every=2.0, clock=lambda: now[0])
    assert looks.current().robots[0].running == "v1"
    now[0] = 1.0
    assert looks.current().robots[0].running == "v1" and len(taken) == 1
    now[0] = 2.5
    assert looks.current().robots[0].running == "v2"
    now[0] = 5.0
    failed = looks.current()
    assert failed.robots[0].running == "v2" and "cannot reach the manager" in failed.problem
    assert "cannot reach the manager" in render_fleet(failed)


def test_only_loopback_is_quiet() -> None:
    assert all(fleet_page.is_loopback(a) for a in ("127.0.0.1", "::1", "localhost", "127.1.2.3"))
    assert not any(fleet_page.is_loopback(a) for a in ("0.0.0.0", "10.0.0.1", "::", "example.org"))


def test_fleet_page_out_from_the_command_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    """``robocore fleet page --out DIR`` end to end, the manager's answer faked (fleet_status.observe)."""
    root = tmp_path / "proj"
    (root / "components" / "talker").mkdir(parents=True)
    (root / "robot.yaml").write_text(fleet_world.ONE_TALKER)
    (root / "fleet.yaml").write_text(FLEET)
    monkeypatch.setattr(fleet_page, "observe", lambda fleet: observed(fleet.name))
    main(["-p", str(root), "fleet", "page", "--out", str(tmp_path / "out"), "--json"])
    out = capsys.readouterr()
    result = json.loads(out.out)["results"][0]
    assert (result["kind"], result["robots"], result["path"]) == ("fleet_page", 2, str(tmp_path / "out" / "index.html"))
    html = (tmp_path / "out" / "index.html").read_text()
    assert "failed, back on v2" in html and "offline, pending" in html and SECRET not in html
    assert result["bytes"] == len(html.encode())


def test_a_big_wave_folds_only_its_healthy_robots() -> None:
    from robocore.plan.fleet_page import FOLD_ABOVE, fold

    small = [robot(f"r{i}") for i in range(FOLD_ABOVE)]
    assert fold(small) == (small, [])
    big = [robot("bad", health="failed"), *(robot(f"r{i}") for i in range(FOLD_ABOVE))]
    shown, folded = fold(big)
    assert [r.robot for r in shown] == ["bad"] and len(folded) == FOLD_ABOVE
    html = render_fleet(view(*big))
    assert f"✓</span> {FOLD_ABOVE} healthy robot(s) of wave rest, folded: show them</button>" in html
    assert '<tbody class="folded" data-wave="rest" hidden>' in html and html.count('<tr class="robot') == FOLD_ABOVE + 1


@pytest.mark.parametrize(("bind", "warned"), [(None, False), ("127.0.0.1", False), ("0.0.0.0", True)])
def test_serve_binds_loopback_unless_told_and_warns_when_told(bind: str | None, warned: bool, tmp_path: Path,
                                                              monkeypatch: pytest.MonkeyPatch,
                                                              capsys: pytest.CaptureFixture[str]) -> None:
    """``fleet page --serve [--bind ADDR]`` end to end, the manager's answer faked and Ctrl-C pressed at once: it
    listens on 127.0.0.1 by default and warns, naming what is on the page, only for an address others reach."""
    root = tmp_path / "proj"
    (root / "components" / "talker").mkdir(parents=True)
    (root / "robot.yaml").write_text(fleet_world.ONE_TALKER)
    (root / "fleet.yaml").write_text(FLEET)
    monkeypatch.setattr(fleet_page, "observe", lambda fleet: observed(fleet.name))
    started = []
    real_start = page_server.start

    def start(pages: page_server.Pages, address: str, port: int) -> Any:
        server = real_start(pages, address, port)
        started.append((address, pages.page()))

        def interrupted() -> None:
            raise KeyboardInterrupt

        server.serve_forever = interrupted  # type: ignore[method-assign]
        return server

    monkeypatch.setattr(page_server, "start", start)
    main(["-p", str(root), "fleet", "page", "--serve", "--port", "0", *(["--bind", bind] if bind else [])])
    err = capsys.readouterr().err
    assert [address for address, _ in started] == [bind or "127.0.0.1"]
    assert "failed, back on v2" in started[0][1] and 'fetch("fleet"' in started[0][1]  # the live page
    assert ("anyone who reaches this address sees the fleet's robot names" in err) is warned, err
    assert "serving the fleet page of" in err and "Traceback" not in err


def test_each_release_says_how_many_robots_run_it_and_which() -> None:
    page = view(robot("r1"), robot("r2", running="v1", target="v2"), robot("r3"),
                releases=(ReleaseView("v2", "-", ()), ReleaseView("v1", "-", ()), ReleaseView("v0", "-", ())))
    html = render_fleet(page)
    assert '<tr data-release="v2"><td>v2</td><td>-</td>\n<td>2: r1, r3</td>' in html
    assert '<tr data-release="v1"><td>v1</td><td>-</td>\n<td>1: r2</td>' in html
    assert '<tr data-release="v0"><td>v0</td><td>-</td>\n<td>0</td>' in html
