"""The Swarm services of a fleet (pure): what each robot's services carry, and the adapter's docker-py arguments."""

from __future__ import annotations

from pathlib import Path

import pytest

from robocore.adapters.swarm import service_kwargs
from robocore.cli import CommandLineError, fleet_task
from robocore.config.fleet import parse_fleet_text
from robocore.config.loader import parse_robot_text
from robocore.plan import naming
from robocore.plan import swarm_services as plan
from robocore.plan.fleet import fleet_instances
from robocore.project import Project

ROBOT = """\
ros_distro: jazzy
ros_domain_id: 7
hosts:
  - {name: main, ip: 127.0.0.1, user: me}
  - {name: arm, ip: 127.0.0.1, arch: arm64}
components:
  - {name: talker, folder: components/talker, runs_on: main, entrypoint: ros2 run demo_talker talker,
     environment: {GREETING: hi}, restart: on-failure}
  - {name: listener, folder: components/listener, runs_on: arm, volumes: ["logs:/logs", "./config:/params:ro"]}
"""
FLEET = """\
manager: {ip: 10.0.0.2}
registry: 10.0.0.2:5000
robots:
  - {name: r1, hosts: {main: {ip: 10.1.1.1}, arm: {ip: 10.1.1.2}}}
  - {name: r2, hosts: {main: {ip: 10.1.2.1}, arm: {ip: 10.1.2.2}}, ros_domain_id: 9}
"""
DIGEST = "@sha256:" + "a" * 64
RELEASE = plan.Release(
    version="v1",
    components={"talker": {"amd64": "10.0.0.2:5000/p-talker" + DIGEST},
                "listener": {"arm64": "10.0.0.2:5000/p-listener" + DIGEST}},
    base={"amd64": "10.0.0.2:5000/p-base" + DIGEST, "arm64": "10.0.0.2:5000/p-base-arm" + DIGEST},
)


@pytest.fixture
def fleet_robots(tmp_path: Path) -> tuple[Project, dict[str, object]]:
    robot = parse_robot_text(ROBOT)
    fleet = parse_fleet_text(FLEET, robot)
    return Project(root=tmp_path / "proj", robot=robot), dict(fleet_instances(robot, fleet))


def services(fleet_robots: tuple[Project, dict[str, object]], name: str) -> dict[str, plan.ServiceSpec]:
    project, instances = fleet_robots
    from robocore.config.model import Robot

    instance = instances[name]
    assert isinstance(instance, Robot)
    return {s.component: s for s in plan.robot_services(project, name, instance, RELEASE)}


def test_one_service_per_component_and_discovery_server_pinned_to_the_robots_host(fleet_robots) -> None:  # type: ignore[no-untyped-def]
    found = services(fleet_robots, "r1")
    assert list(found) == ["discovery-0", "talker", "listener"]  # servers first, then file order
    talker = found["talker"]
    assert talker.name == "proj-r1-talker" and talker.image == RELEASE.components["talker"]["amd64"]
    assert talker.constraints == ("node.labels.dev.robocore.project==proj", "node.labels.dev.robocore.robot==r1",
                                  "node.labels.dev.robocore.host==main", "node.labels.dev.robocore.arch==amd64")
    assert found["listener"].image.endswith("p-listener" + DIGEST)  # its host's arch
    assert "node.labels.dev.robocore.arch==arm64" in found["listener"].constraints
    assert found["discovery-0"].image == RELEASE.base["amd64"] and found["discovery-0"].role == naming.ROLE_DISCOVERY


def test_each_robot_gets_its_own_addresses_domain_and_dds_profiles(fleet_robots) -> None:  # type: ignore[no-untyped-def]
    one, two = services(fleet_robots, "r1")["talker"], services(fleet_robots, "r2")["talker"]
    env1, env2 = dict(one.environment), dict(two.environment)
    assert env1["ROS_DISCOVERY_SERVER"].startswith("10.1.1.1:") and env2["ROS_DISCOVERY_SERVER"].startswith("10.1.2.1:")
    assert (env1["ROS_DOMAIN_ID"], env2["ROS_DOMAIN_ID"]) == ("7", "9")
    assert env1["GREETING"] == "hi"
    files1 = {c.target: c for c in one.configs}
    super_client = files1[f"{naming.CONTAINER_DDS}/super_client.xml"].text
    assert f"{naming.CONTAINER_DDS}/client.xml" in files1 and "10.1.1.1" in super_client
    names1, names2 = {c.name for c in one.configs}, {c.name for c in two.configs}
    assert not names1 & names2  # per robot and per content: a robot's profile never changes another's


def test_swarm_has_no_ipc_so_shm_is_bind_mounted_and_nothing_comes_from_sync(fleet_robots) -> None:  # type: ignore[no-untyped-def]
    found = services(fleet_robots, "r1")
    for spec in found.values():
        targets = [m.target for m in spec.mounts]
        assert "/dev/shm" in targets, spec.component  # same-host containers share memory through the host's /dev/shm
        assert naming.CONTAINER_INSTALL not in targets and naming.CONTAINER_DDS not in targets  # image + configs
    assert any(m.source == "logs" and m.is_named_volume for m in found["listener"].mounts)
    assert "/params" not in [m.target for m in found["listener"].mounts]  # read-only project files: in the image
    assert (found["talker"].restart, found["listener"].restart) == ("on-failure", "any")
    assert found["talker"].args == ("ros2", "run", "demo_talker", "talker")
    assert found["talker"].command == (naming.ENTRYPOINT,)


def test_docker_py_arguments_are_host_network_one_global_task_stop_first(fleet_robots) -> None:  # type: ignore[no-untyped-def]
    talker = services(fleet_robots, "r1")["talker"]
    kwargs = service_kwargs(talker, {c.name: f"id-{c.name}" for c in talker.configs})
    assert kwargs["networks"] == ["host"]
    assert kwargs["mode"] == {"global": {}}  # pinned to one node by the constraints: one task, never replaced elsewhere
    assert kwargs["update_config"]["Order"] == "stop-first"
    assert kwargs["restart_policy"]["Condition"] == "on-failure"
    assert kwargs["env"][0].startswith("FASTDDS_DEFAULT_PROFILES_FILE=")
    assert {c["File"]["Name"] for c in kwargs["configs"]} == {c.target for c in talker.configs}
    assert {m["Target"] for m in kwargs["mounts"]} == {"/dev/shm"}


def test_a_release_without_an_image_of_a_component_is_a_key_error(fleet_robots) -> None:  # type: ignore[no-untyped-def]
    project, instances = fleet_robots
    partial = plan.Release(version="v0", components={"talker": RELEASE.components["talker"]}, base=RELEASE.base)
    with pytest.raises(KeyError, match="listener for arm64"):
        plan.robot_services(project, "r1", instances["r1"], partial)  # type: ignore[arg-type]


def test_release_labels_keep_target_previous_and_when(fleet_robots) -> None:  # type: ignore[no-untyped-def]
    talker = services(fleet_robots, "r1")["talker"]
    labelled = plan.release_labels(talker, version="v2", previous="v1", previous_image="old" + DIGEST,
                                   changed="2026-01-01T00:00:00Z", health="")
    labels = labelled.label_map
    assert labels[plan.LABEL_RELEASE] == "v2" and labels[plan.LABEL_IMAGE] == talker.image
    assert (labels[plan.LABEL_PREVIOUS], labels[plan.LABEL_PREVIOUS_IMAGE]) == ("v1", "old" + DIGEST)
    assert plan.replace_label(labelled, plan.LABEL_HEALTH, "healthy").label_map[plan.LABEL_HEALTH] == "healthy"
    assert labels[naming.LABEL_PROJECT] == "proj" and labels[plan.LABEL_ROBOT] == "r1"


def test_long_names_stay_dns_labels() -> None:
    name = plan.service_name("p" * 40, "r" * 40, "listener")
    assert len(name) <= plan.MAX_SERVICE_NAME and name != plan.service_name("p" * 40, "r" * 40, "talker")
    assert plan.service_name("proj", "r1", "talker") == "proj-r1-talker"


def test_probe_runs_on_the_robots_server_host_as_an_observer(fleet_robots) -> None:  # type: ignore[no-untyped-def]
    project, instances = fleet_robots
    check = plan.GateCheck(nodes=("/talker",), heard=("/chatter",), timeout=20)
    probe = plan.probe_service(project, "r2", instances["r2"], RELEASE, check, "print(1)\n", "abc")  # type: ignore[arg-type]
    assert probe.restart == "none" and probe.image == RELEASE.base["amd64"]
    assert "node.labels.dev.robocore.robot==r2" in probe.constraints
    assert probe.args == ("python3", plan.PROBE_SCRIPT, "--timeout", "20", "--node", "/talker", "--heard", "/chatter")
    env = dict(probe.environment)
    assert env.get("ROS_SUPER_CLIENT") == "TRUE" and env["ROS_DOMAIN_ID"] == "9"
    assert plan.PROBE_SCRIPT in {c.target for c in probe.configs}


def test_probe_verdict_is_the_last_json_line_of_its_logs() -> None:
    logs = ("probe.1.x@node    | starting\n"
            'probe.1.x@node    | {"ok": false, "missing": ["/talker"]}\n')
    assert plan.probe_verdict(logs) == {"ok": False, "missing": ["/talker"]}
    assert plan.probe_verdict("nothing here\n") is None


def test_fleet_words_become_the_fleet_tasks() -> None:
    assert fleet_task(["fleet", "rollout", "v2", "--json"]) == ["fleet", "--verb", "rollout", "--version", "v2",
                                                                "--json"]
    assert fleet_task(["fleet", "rollback", "r1", "r2"]) == ["fleet", "--verb", "rollback", "--robot", "r1",
                                                             "--robot", "r2"]
    assert fleet_task(["fleet", "rollback", "--", "-odd"]) == ["fleet", "--verb", "rollback", "--robot", "-odd"]
    assert fleet_task(["fleet", "status"]) == ["fleet", "--verb", "status"]
    assert fleet_task(["status"]) == ["status"]
    with pytest.raises(CommandLineError, match="unknown fleet command"):
        fleet_task(["fleet", "explode"])


class _Service:
    """A docker-py Service whose first ``refusals`` updates are refused with ``error``."""

    def __init__(self, mode: dict[str, object], refusals: int, error: str) -> None:
        self.id, self.version, self.attrs = "svc1", 1, {"Spec": {"Mode": mode}}
        self.refusals, self.error, self.reloads = refusals, error, 0
        self.updates: list[int] = []  # the version each accepted update was made on

    def update(self, **kwargs: object) -> None:
        from docker.errors import APIError

        if self.refusals:
            self.refusals -= 1
            self.version += 1  # what happened meanwhile
            raise APIError("500 Server Error", explanation=self.error)
        self.updates.append(self.version)

    def reload(self) -> None:
        self.reloads += 1


class _Services:
    def __init__(self, service: _Service) -> None:
        self.service = service

    def get(self, name: str) -> _Service:
        return self.service


class _Client:
    def __init__(self, service: _Service) -> None:
        self.services = _Services(service)


@pytest.mark.parametrize("refusals", [0, 1, 4])
def test_an_update_out_of_sequence_is_made_again_on_the_new_version(fleet_robots, refusals: int) -> None:  # type: ignore[no-untyped-def]
    from robocore.adapters.swarm import apply_service

    talker = services(fleet_robots, "r1")["talker"]
    service = _Service({"global": {}}, refusals, "update out of sequence")
    ids = {c.name: f"id-{c.name}" for c in talker.configs}
    assert apply_service(_Client(service), talker, ids) == "svc1"  # type: ignore[arg-type]
    assert service.updates == [1 + refusals] and service.reloads == refusals


def test_other_refusals_and_a_service_that_never_settles_are_errors(fleet_robots) -> None:  # type: ignore[no-untyped-def]
    from robocore.adapters.swarm import UPDATE_ATTEMPTS, apply_service
    from robocore.errors import DockerError

    talker = services(fleet_robots, "r1")["talker"]
    for refusals, error in ((1, "rpc error: code = InvalidArgument"), (UPDATE_ATTEMPTS, "update out of sequence")):
        service = _Service({"global": {}}, refusals, error)
        with pytest.raises(DockerError, match=f"docker service update .*talker: {error}"):
            apply_service(_Client(service), talker, {c.name: f"id-{c.name}" for c in talker.configs})  # type: ignore[arg-type]
        assert service.updates == []


class _Api:
    """docker-py's low-level API as far as a label-only update uses it: records what was sent."""

    def __init__(self, attrs: dict[str, object]) -> None:
        self.attrs, self.sent = attrs, []  # type: list[dict[str, object]]

    def inspect_service(self, name: str) -> dict[str, object]:
        return self.attrs

    def update_service(self, service: str, version: int, **kwargs: object) -> None:
        self.sent.append({"service": service, "version": version, **kwargs})


class _StoredClient(_Client):
    def __init__(self, service: _Service) -> None:
        super().__init__(service)
        self.api = _Api(service.attrs)


def _stored(spec: plan.ServiceSpec, ids: dict[str, str]) -> _Service:
    """A service as the manager stores it after robocore made it from ``spec`` (its template digest label)."""
    from robocore.adapters.swarm import LABEL_TEMPLATE, service_kwargs, template_digest

    kwargs = service_kwargs(spec, ids)
    service = _Service({"global": {}}, 0, "")
    labels = {**spec.label_map, LABEL_TEMPLATE: template_digest(kwargs)}
    service.attrs = {"ID": "svc1", "Version": {"Index": 7}, "Spec": {
        "Name": spec.name, "Mode": {"Global": {}}, "Labels": labels,
        "TaskTemplate": {"ContainerSpec": {"Image": spec.image}, "Networks": [{"Target": "host"}]},
        "UpdateConfig": {"Order": "stop-first"}, "EndpointSpec": {"Mode": "vip"}}}
    return service


def test_an_unchanged_service_gets_its_labels_only_and_keeps_its_task(fleet_robots) -> None:  # type: ignore[no-untyped-def]
    """A release that does not change a service (a discovery server: same base image) sends its stored template
    back as it is, with the new labels: Swarm replaces no task, so no second server ever starts beside the first."""
    from robocore.adapters.swarm import LABEL_TEMPLATE, apply_service

    server = services(fleet_robots, "r1")["discovery-0"]
    service = _stored(server, {})
    template = service.attrs["Spec"]["TaskTemplate"]  # type: ignore[index]
    client = _StoredClient(service)
    relabelled = plan.release_labels(server, version="v1", previous="v2", previous_image=server.image, changed="now",
                                     health="")
    assert apply_service(client, relabelled, {}) == "svc1"  # type: ignore[arg-type]
    assert service.updates == []  # no update of the template
    (sent,) = client.api.sent
    assert sent["task_template"] is template and sent["version"] == 7 and sent["mode"] == {"Global": {}}
    assert sent["labels"][plan.LABEL_RELEASE] == "v1"  # type: ignore[index]
    assert sent["labels"][LABEL_TEMPLATE] == service.attrs["Spec"]["Labels"][LABEL_TEMPLATE]  # type: ignore[index]


def test_a_changed_service_is_updated_in_full(fleet_robots) -> None:  # type: ignore[no-untyped-def]
    """The negative control: a new image (or any other part of the template) is a real, stop-first update."""
    from dataclasses import replace

    from robocore.adapters.swarm import apply_service

    talker = services(fleet_robots, "r1")["talker"]
    ids = {c.name: f"id-{c.name}" for c in talker.configs}
    for changed in (replace(talker, image="10.0.0.2:5000/p-talker@sha256:" + "b" * 64),
                    replace(talker, environment=(*talker.environment, ("EXTRA", "1")))):
        service = _stored(talker, ids)
        client = _StoredClient(service)
        apply_service(client, changed, ids)  # type: ignore[arg-type]
        assert service.updates == [1] and client.api.sent == []


def test_every_task_has_an_init_that_passes_sigterm_on(fleet_robots) -> None:  # type: ignore[no-untyped-def]
    """The discovery server has no SIGTERM handler: without an init as PID 1 it ignores the stop and is killed
    after the grace period, holding its port meanwhile."""
    for spec in services(fleet_robots, "r1").values():
        assert service_kwargs(spec, {c.name: "id" for c in spec.configs})["init"] is True, spec.component


def test_set_labels_sends_the_stored_spec_back_without_defaults(fleet_robots) -> None:  # type: ignore[no-untyped-def]
    from robocore.adapters.swarm import set_labels

    server = services(fleet_robots, "r1")["discovery-0"]
    service = _stored(server, {})
    client = _StoredClient(service)
    set_labels(client, server.name, {plan.LABEL_HEALTH: "healthy"})  # type: ignore[arg-type]
    (sent,) = client.api.sent
    assert sent["task_template"] is service.attrs["Spec"]["TaskTemplate"]  # type: ignore[index]
    assert "fetch_current_spec" not in sent  # docker-py's fetch fills in the daemon's defaults
    assert sent["labels"][plan.LABEL_HEALTH] == "healthy"  # type: ignore[index]
    assert sent["labels"][plan.LABEL_ROBOT] == "r1"  # type: ignore[index]


USER_IMAGE = """\
ros_distro: jazzy
hosts:
  - {name: main, ip: 127.0.0.1, user: me}
components:
  - {name: cam, runs_on: main, image: "vendor/cam:1.2", volumes: ["./config:/params:ro"]}
  - {name: tool, runs_on: main, image: "vendor/tool:3"}
"""


def test_a_user_image_runs_as_its_release_image_carrying_the_baked_files(tmp_path: Path) -> None:
    """The read-only project volume is not mounted on Swarm: the release's image of the component carries it, so
    that image runs, not the bare ``image:`` (which would lack /params); with no release image, a component with
    baked files is a KeyError (refused), one without any runs its own image."""
    from robocore.config.model import Robot

    robot = parse_robot_text(USER_IMAGE)
    fleet = parse_fleet_text("manager: {ip: 10.0.0.2}\nregistry: 10.0.0.2:5000\n"
                             "robots:\n  - {name: r1, hosts: {main: {ip: 10.1.1.1}}}\n", robot)
    instance = dict(fleet_instances(robot, fleet))["r1"]
    assert isinstance(instance, Robot)
    project = Project(root=tmp_path / "proj", robot=robot)
    release = plan.Release(version="v1", components={"cam": {"amd64": "10.0.0.2:5000/proj-cam" + DIGEST},
                                                     "tool": {"amd64": "10.0.0.2:5000/proj-tool" + DIGEST}},
                           base={"amd64": "10.0.0.2:5000/proj-base" + DIGEST})
    found = {s.component: s for s in plan.robot_services(project, "r1", instance, release)}
    assert found["cam"].image == "10.0.0.2:5000/proj-cam" + DIGEST and found["tool"].image.endswith(DIGEST)
    assert "/params" not in [m.target for m in found["cam"].mounts]
    bare = plan.Release(version="v0", components={}, base=release.base)
    with pytest.raises(KeyError, match="cam for amd64"):
        plan.robot_services(project, "r1", instance, bare)
    only_tool = plan.Release(version="v0", components={"cam": release.components["cam"]}, base=release.base)
    tool = {s.component: s for s in plan.robot_services(project, "r1", instance, only_tool)}["tool"]
    assert tool.image == "vendor/tool:3"


def test_only_a_real_change_of_mode_makes_a_service_anew() -> None:
    """The daemon answers ``Global`` where docker-py sent ``global``: the same mode, never a reason to remove a
    service (its old task would still be stopping beside the new service's)."""
    from robocore.adapters.swarm import mode_of

    assert mode_of({"Spec": {"Mode": {"Global": {}}}}) == mode_of({"Spec": {"Mode": {"global": {}}}}) == {"global"}
    assert mode_of({"Spec": {"Mode": {"Replicated": {"Replicas": 1}}}}) != mode_of({"Spec": {"Mode": {"global": {}}}})
