"""The ROS graph the health gate saw, kept per robot: the probe's verdict kept by the gate, bounded into one service
label (plan/gate_graph.py), written beside the verdict (commands/fleet_gate_record.py), read back by ``fleet
status`` and shown, escaped, as text on the fleet page. No Docker: the swarm adapter's calls are faked."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import fleet_world
import pytest
from fleet_world import TWO_ROBOTS, Clock

from robocore.adapters import swarm
from robocore.commands import fleet_gate_record, fleet_page, fleet_rollout
from robocore.commands.fleet_gate import FAILED, HEALTHY, Change, Gate
from robocore.commands.fleet_status import Observed, status_rows
from robocore.commands.fleet_swarm import FleetProject
from robocore.commands.support.context import Options
from robocore.commands.support.reporting import as_result
from robocore.plan import gate_graph, naming
from robocore.plan import swarm_services as plan
from robocore.plan.fleet_page import FleetView, RobotView, render_fleet, render_page
from robocore.plan.gate_graph import LABEL_SEEN, MAX_BYTES, MAX_NAME, Seen

FLEET = TWO_ROBOTS + """\
rollout:
  health: {running: 2, nodes: [/talker], heard: [/chatter]}
"""
DIGEST = "@sha256:" + "a" * 64
RELEASE = plan.Release(version="v2", components={"talker": {"amd64": "10.0.0.2:5000/p-talker" + DIGEST}},
                       base={"amd64": "10.0.0.2:5000/p-base" + DIGEST})
VERDICT = {"ok": True, "nodes": ["/talker", "/listener"], "missing": [], "heard": ["/chatter"], "silent": []}


# --------------------------------------------------------------------------- the label (pure)


def test_a_verdict_becomes_a_label_and_reads_back_the_same() -> None:
    seen = gate_graph.from_verdict(VERDICT, "v2", "2026-12-07T04:00:00Z")
    assert seen == Seen("v2", "2026-12-07T04:00:00Z", ("/listener", "/talker"), ("/chatter",), 0)
    label = gate_graph.to_label(seen)
    assert json.loads(label)["nodes"] == ["/listener", "/talker"]
    assert gate_graph.from_label(label) == seen


@pytest.mark.parametrize("verdict", [None, {"ok": False}, {"nodes": [], "heard": []}, {"nodes": "/talker"},
                                     {"nodes": [3, None, ""], "heard": [{"x": 1}]}])
def test_no_verdict_or_one_that_names_nothing_is_no_graph(verdict: dict[str, object] | None) -> None:
    assert gate_graph.from_verdict(verdict, "v2", "T") is None


def test_a_huge_graph_is_cut_to_the_label_bound_nodes_first_and_says_how_much_was_left_out() -> None:
    nodes = [f"/robot/node_{i:04d}" for i in range(500)]
    heard = [f"/robot/topic_{i:04d}" for i in range(500)]
    seen = gate_graph.from_verdict({"nodes": nodes, "heard": heard}, "v2", "2026-12-07T04:00:00Z")
    assert seen is not None
    label = gate_graph.to_label(seen)
    assert MAX_BYTES - 25 < len(label.encode()) <= MAX_BYTES  # filled, within the bound
    assert seen.nodes == tuple(nodes[: len(seen.nodes)]) and seen.heard == ()  # the nodes first, in order
    assert len(seen.nodes) + seen.omitted == 1000
    assert gate_graph.from_label(label) == seen
    small = gate_graph.from_verdict({"nodes": nodes[:3], "heard": heard[:2]}, "v2", "T")
    assert small is not None and (len(small.nodes), len(small.heard), small.omitted) == (3, 2, 0)  # a control


def test_a_long_or_non_ascii_name_is_cut_and_still_within_the_bound() -> None:
    seen = gate_graph.from_verdict({"nodes": ["/" + "n" * 5000, "/ü" * 900]}, "v2", "T")
    assert seen is not None and all(len(name) <= MAX_NAME for name in seen.nodes)
    assert len(gate_graph.to_label(seen).encode()) <= MAX_BYTES


@pytest.mark.parametrize("text", ["", "not json", "[]", '{"release": 2, "at": "T"}', '{"release": "v2"}',
                                  '{"release": "v2", "at": "T", "omitted": -1}', "{" + " " * MAX_BYTES + "}"])
def test_a_label_of_another_shape_reads_as_nothing_seen(text: str) -> None:
    assert gate_graph.from_label(text) is None


def test_the_newest_record_of_a_robots_services_is_taken() -> None:
    old, new = Seen("v1", "2026-12-06T10:00:00Z", ("/a",)), Seen("v2", "2026-12-07T10:00:00Z", ("/b",))
    labels = [{}, {LABEL_SEEN: gate_graph.to_label(old)}, {LABEL_SEEN: gate_graph.to_label(new)}, {LABEL_SEEN: "x"}]
    assert gate_graph.latest(labels) == new
    assert gate_graph.latest([{}, {LABEL_SEEN: "x"}]) is None


# --------------------------------------------------------------------------- the gate keeps it, the record writes it


@pytest.fixture
def fleet_project(tmp_path: Path) -> FleetProject:
    return fleet_world.fleet_project(tmp_path / "p", FLEET)


def change_of(fleet_project: FleetProject, robot: str = "r1") -> Change:
    specs = plan.robot_services(fleet_project.project, robot, fleet_project.instances[robot], RELEASE)
    specs = [plan.release_labels(s, version="v2", previous="v1", previous_image="", changed="T", health="")
             for s in specs]
    return Change(robot=robot, wave="canary", release="v2", specs=specs, before={s.name: set() for s in specs},
                  started=1000.0, deadline=2000.0)


@pytest.mark.parametrize(("output", "verdict", "graph"), [
    (json.dumps(VERDICT), HEALTHY, VERDICT),
    ('{"ok": false, "nodes": ["/listener"], "missing": ["/talker"], "heard": [], "silent": ["/chatter"]}', FAILED,
     {"ok": False, "nodes": ["/listener"], "missing": ["/talker"], "heard": [], "silent": ["/chatter"]}),
])
def test_the_gate_keeps_what_its_probe_saw(fleet_project: FleetProject, monkeypatch: pytest.MonkeyPatch,
                                           output: str, verdict: str, graph: dict[str, object]) -> None:
    probe = swarm.TaskInfo(id="tp", node_id="n", state="complete", desired="shutdown", image=RELEASE.base["amd64"],
                           created="1", error="", exit_code=0, container="c")
    monkeypatch.setattr(fleet_rollout, "time", Clock())
    monkeypatch.setattr(swarm, "tasks", lambda _client, _service: [probe])
    monkeypatch.setattr(swarm, "service_logs", lambda _client, _service: f"p.1@h | {output}\n")
    monkeypatch.setattr(swarm, "remove_service", lambda _client, _service: None)
    gate = Gate(object(), fleet_project, RELEASE, {"v2": RELEASE},  # type: ignore[arg-type]
                Options(project_dir=fleet_project.project.root))
    change = change_of(fleet_project)
    change.probe = "p-r1-probe-1"
    gate.probe(change, 1000.0)
    assert (change.verdict, change.graph) == (verdict, graph)


def test_the_record_puts_the_graph_on_one_service_and_the_verdict_on_all(fleet_project: FleetProject,
                                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    written: list[tuple[str, dict[str, str]]] = []
    monkeypatch.setattr(swarm, "set_labels", lambda _client, name, labels: written.append((name, labels)))
    monkeypatch.setattr(fleet_gate_record, "now", lambda: "2026-12-07T04:10:00Z")
    specs = change_of(fleet_project).specs
    assert len(specs) >= 2  # the discovery service and the talker: the graph goes on one only
    fleet_gate_record.record_gate(object(), specs, HEALTHY, "", VERDICT)  # type: ignore[arg-type]
    assert [name for name, _ in written] == [s.name for s in specs]
    assert all(labels[plan.LABEL_HEALTH] == HEALTHY and labels[plan.LABEL_REASON] == "" for _, labels in written)
    assert [LABEL_SEEN in labels for _, labels in written] == [True] + [False] * (len(specs) - 1)
    assert gate_graph.from_label(written[0][1][LABEL_SEEN]) == Seen("v2", "2026-12-07T04:10:00Z",
                                                                    ("/listener", "/talker"), ("/chatter",))
    written.clear()
    fleet_gate_record.record_gate(object(), specs, FAILED, "talker failed", None)  # type: ignore[arg-type]
    assert written and not any(LABEL_SEEN in labels for _, labels in written)  # no probe ran: no graph


# --------------------------------------------------------------------------- read back and shown


def observed(fleet_project: FleetProject, seen_label: str) -> Observed:
    """r1's talker and discovery services, the graph on the discovery one; r2 with no graph recorded."""
    project = fleet_project.name

    def service(robot: str, role: str, extra: dict[str, str]) -> swarm.ServiceInfo:
        labels = {naming.LABEL_PROJECT: project, plan.LABEL_ROBOT: robot, naming.LABEL_ROLE: role,
                  naming.LABEL_COMPONENT: "talker", plan.LABEL_RELEASE: "v2", plan.LABEL_HEALTH: "healthy", **extra}
        return swarm.ServiceInfo(id=f"{robot}{role}", name=f"{project}-{robot}-{role}", labels=labels, image="i",
                                 version=1, attrs={})

    services = [service("r1", naming.ROLE_DISCOVERY, {LABEL_SEEN: seen_label}),
                service("r1", naming.ROLE_COMPONENT, {}), service("r2", naming.ROLE_COMPONENT, {})]
    return Observed(by_robot={}, services=services, tasks={})


def test_status_reads_the_graph_back_and_json_carries_it(fleet_project: FleetProject) -> None:
    seen = Seen("v2", "2026-12-07T04:10:00Z", ("/listener", "/talker"), ("/chatter",))
    rows = {r.robot: r for r in status_rows(fleet_project, observed(fleet_project, gate_graph.to_label(seen)))}
    assert (rows["r1"].seen, rows["r2"].seen) == (seen, None)
    shown = json.loads(json.dumps(as_result(rows["r1"])))
    assert shown["seen"] == {"release": "v2", "at": "2026-12-07T04:10:00Z", "nodes": ["/listener", "/talker"],
                             "heard": ["/chatter"], "omitted": 0}
    assert json.loads(json.dumps(as_result(rows["r2"])))["seen"] is None


def graph_cell(html: str, robot: str) -> str:
    row = html.split(f'data-robot="{robot}" data-search=', 1)[1].split("</tr>", 1)[0]
    return row.split('<td class="graph">', 1)[1].split("</td>", 1)[0]


def test_the_page_shows_the_nodes_and_topics_as_text_and_says_when_none_were_seen(
        fleet_project: FleetProject) -> None:
    seen = Seen("v2", "2026-12-07T04:10:00Z", ("/listener", "/talker"), ("/chatter",), omitted=2)
    look = observed(fleet_project, gate_graph.to_label(seen))
    page = fleet_page.fleet_view(fleet_project, status_rows(fleet_project, look), look, (), "2026-12-07T04:11:00Z")
    html = render_page(page)
    assert graph_cell(html, "r1") == ('<span class="nodes">nodes: /listener, /talker</span><br><span class="heard">'
                                      "heard: /chatter</span><br>(2 more name(s) left out)<br><small>on v2 at "
                                      "2026-12-07T04:10:00Z</small>")
    assert graph_cell(html, "r2") == "<small>no graph recorded</small>"
    assert "<th>Last gate saw</th>" in render_fleet(page)


def test_a_hostile_name_in_the_probes_output_is_text_and_a_secret_like_one_is_hidden() -> None:
    evil = '<script>window.pwned=1</script>"\''
    seen = gate_graph.from_verdict({"nodes": [evil, "/ok"], "heard": ["/token=abc123"]}, "v2", "T")
    html = render_fleet(FleetView("demo", "T", (RobotView("r1", "rest", seen=seen),)))
    cell = graph_cell(html, "r1")
    assert "<script>" not in cell and "&lt;script&gt;window.pwned=1&lt;/script&gt;&#34;&#39;" in cell
    assert "abc123" not in cell and "/token=(hidden)" in cell


def test_the_record_read_back_from_what_rollout_wrote(fleet_project: FleetProject,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """What record_gate writes is what status reads: the labels it set, merged into the services' labels."""
    labels: dict[str, dict[str, str]] = {}
    monkeypatch.setattr(swarm, "set_labels", lambda _c, name, new: labels.setdefault(name, {}).update(new))
    specs = change_of(fleet_project).specs
    fleet_gate_record.record_gate(object(), specs, HEALTHY, "", VERDICT)  # type: ignore[arg-type]
    services = [swarm.ServiceInfo(id=s.name, name=s.name, labels={**dict(s.labels), **labels[s.name]}, image=s.image,
                                  version=1, attrs={}) for s in specs]
    rows = status_rows(fleet_project, Observed(by_robot={}, services=services, tasks={}))
    seen: Any = rows[0].seen
    assert (rows[0].robot, seen.release, seen.nodes, seen.heard) == ("r1", "v2", ("/listener", "/talker"),
                                                                      ("/chatter",))
    assert rows[1].seen is None
