"""fleet.yaml: many robots of one robot.yaml, the engine that runs them, and the rollout policy.

A fleet file sits next to robot.yaml (one per project). Each robot of the fleet is an instance of
the project's robot.yaml: it names, for every host of robot.yaml, that robot's address of it (and
optionally its user, ssh port, Docker access), and may override the ROS domain. The rollout policy
orders the robots into waves (a canary, a percentage, a label, the rest), gives the health gate that
each robot must pass after its change, and the timeouts.

The file is read by the same machinery as robot.yaml (:mod:`robocore.config.loader`: size, alias
and depth limits, links and FIFOs refused, ``file:line: key: problem`` lines) and checked against the
project's :class:`~robocore.config.model.Robot` by :mod:`robocore.config.fleet_checks`. A robot that no
wave selects is not an error: it goes in the last wave, ``rest`` (see :data:`REST_WAVE`).

Names are kept to the lower-case DNS-label grammar (:data:`ROBOT_NAME`) because each robot becomes a
Swarm node label, part of service names and a Kubernetes namespace (``robot-<name>``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any, Literal, get_args

from pydantic import (
    AfterValidator,
    ConfigDict,
    Field,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)

from robocore.config.fleet_checks import FleetParts
from robocore.config.model import DockerAccess, Host, Robot, Strict, TlsFiles
from robocore.config.sources import GitUrl
from robocore.config.values import (
    GitFolder,
    HostAddress,
    Name,
    Number,
    OneLine,
    Registry,
    UserName,
    pattern_field,
    shown,
)
from robocore.errors import ConfigError
from robocore.files import FLEET_FILE as FLEET_FILE

#: The command that prints the fleet file's JSON Schema (named in messages).
FLEET_SCHEMA_COMMAND = "robocore schema --fleet"
#: The name of the last wave: every robot no earlier wave selected. A wave of this name takes no selector.
REST_WAVE = "rest"

#: A robot's name: a lower-case DNS label of at most 40 characters (it becomes a node label, part of Swarm
#: service names of at most 63 characters, and a Kubernetes namespace ``robot-<name>``).
ROBOT_NAME = r"[a-z](?:[a-z0-9-]{0,38}[a-z0-9])?"
#: A label key (Docker node labels and Kubernetes label names both take it): lower case, digits, ``.``, ``_``,
#: ``-``; starts and ends with a letter or digit.
LABEL_KEY = r"[a-z0-9](?:[a-z0-9._-]{0,61}[a-z0-9])?"
#: A label value (Kubernetes' grammar, at most 63 characters).
LABEL_VALUE = r"[A-Za-z0-9](?:[A-Za-z0-9._-]{0,61}[A-Za-z0-9])?"
#: An absolute ROS graph name (a node or a topic): ``/talker``, ``/robot/chatter``.
ROS_NAME = r"(?=.{2,256}$)(?:/[A-Za-z_][A-Za-z0-9_]*)+"


def _grammar(core: str, what: str) -> AfterValidator:
    import re

    def check(value: str) -> str:
        if re.fullmatch(core, value):
            return value
        raise ValueError(f"{shown(value)} is not a valid value here (expected {what})")

    return AfterValidator(check)


RobotName = Annotated[str, _grammar(ROBOT_NAME, "a lower-case letter, then lower-case letters, digits or '-', "
                                    "at most 40, not ending in '-'"),
                      pattern_field(ROBOT_NAME, "Robot name: a lower-case DNS label of at most 40 characters.")]
LabelKey = Annotated[str, _grammar(LABEL_KEY, "a label key: lower-case letters, digits, '.', '_' or '-', at most "
                                   "63"), pattern_field(LABEL_KEY)]
LabelValue = Annotated[str, _grammar(LABEL_VALUE, "a label value: letters, digits, '.', '_' or '-', at most 63"),
                       pattern_field(LABEL_VALUE)]
RosName = Annotated[str, _grammar(ROS_NAME, "an absolute ROS name such as /talker or /robot/chatter"),
                    pattern_field(ROS_NAME)]
Labels = dict[LabelKey, LabelValue]


def _keyed(schema: dict[str, Any]) -> None:
    """A mapping's schema with its key grammar enforced: pydantic writes the key pattern as ``patternProperties``,
    which lets any other key through; it becomes ``propertyNames`` and the value schema ``additionalProperties``."""
    patterns = schema.pop("patternProperties", None)
    if isinstance(patterns, dict) and len(patterns) == 1:
        ((pattern, values),) = patterns.items()
        schema["propertyNames"] = {**schema.get("propertyNames", {}), "pattern": pattern}
        schema["additionalProperties"] = values

#: Most robots one fleet file lists (the loader's limits keep the file itself small; this keeps plans bounded).
MAX_ROBOTS = 10_000


def _keyed_optional(schema: dict[str, Any]) -> None:
    """:func:`_keyed` for a mapping that may also be null (``anyOf``: the mapping, null)."""
    for option in schema.get("anyOf", []):
        if option.get("type") == "object":
            _keyed(option)


class FleetHost(Strict):
    """One robot's address of one host of robot.yaml; what is not given here comes from robot.yaml's host."""

    ip: HostAddress = Field(description="This robot's address of the host (IP or host name; not loopback).")
    user: UserName | None = Field(default=None, description="SSH user (default: robot.yaml's host's).")
    ssh_port: Number | None = Field(default=None, ge=1, le=65535)
    docker: DockerAccess | None = Field(default=None, description="How the daemon is reached (default: ssh, or "
                                        "robot.yaml's host's when that is not local).")
    docker_port: Number | None = Field(default=None, ge=1, le=65535)

    def on(self, host: Host) -> Host:
        """robot.yaml's ``host`` as this robot has it: this address, and this user, ports and Docker access when
        given. A host robot.yaml reaches locally (the dev machine) is reached over ssh on a robot."""
        docker = self.docker
        if docker is None and host.docker is not DockerAccess.local:
            docker = host.docker
        update: dict[str, object] = {"ip": self.ip, "docker": docker}
        for key in ("user", "ssh_port", "docker_port"):
            if getattr(self, key) is not None:
                update[key] = getattr(self, key)
        return host.model_copy(update=update)


class Manager(Strict):
    """The Swarm manager robocore talks to (a machine whose daemon robocore reaches like a robot.yaml host)."""

    ip: HostAddress
    user: UserName = Field(default="root", description="SSH user.")
    docker: DockerAccess | None = Field(default=None, description="local, ssh (default for remote), tls or tcp.")
    docker_port: Number | None = Field(default=None, ge=1, le=65535)
    ssh_port: Number = Field(default=22, ge=1, le=65535)
    tls: TlsFiles | None = None
    insecure: bool = Field(default=False, description="Allow plain unauthenticated TCP to the manager's daemon.")

    def as_host(self) -> Host:
        """The manager as a robot.yaml :class:`Host` named ``manager``, for robocore's connection code."""
        return Host(name="manager", ip=self.ip, user=self.user, docker=self.docker, docker_port=self.docker_port,
                    ssh_port=self.ssh_port, tls=self.tls, insecure=self.insecure)


class FleetRobot(Strict):
    """One robot of the fleet: an instance of robot.yaml at its own addresses."""

    name: RobotName
    labels: Labels = Field(default_factory=dict, description="Free labels, for wave selectors (site: lab).",
                           json_schema_extra=_keyed)
    hosts: dict[Name, FleetHost] = Field(description="For every host of robot.yaml (by name): this robot's "
                                         "address of it.", json_schema_extra=_keyed)
    ros_domain_id: Number | None = Field(default=None, ge=0, le=232, description="Override of robot.yaml's "
                                         "ros_domain_id for this robot.")


class Wave(Strict):
    """A step of the rollout. At most one selector; none selects every robot not yet placed."""

    name: Name
    robots: list[RobotName] | None = Field(default=None, description="These robots (by name).")
    percent: Number | None = Field(default=None, ge=1, le=100, description="This share of the robots not yet "
                                   "placed, rounded up, in fleet-file order.")
    labels: Labels | None = Field(default=None, description="Robots carrying all these labels.",
                                  json_schema_extra=lambda schema: _keyed_optional(schema))

    @model_validator(mode="after")
    def _one_selector(self) -> Wave:
        given = [key for key in ("robots", "percent", "labels") if getattr(self, key) is not None]
        if len(given) > 1:
            raise ValueError(f"a wave takes one selector, not {' and '.join(given)}")
        return self

    @property
    def selects_rest(self) -> bool:
        """True when the wave has no selector: it takes every robot not yet placed."""
        return self.robots is None and self.percent is None and self.labels is None


class HealthGate(Strict):
    """What a healthy robot is, checked after each robot's change."""

    running: Number = Field(default=10, ge=0, le=3600, description="Seconds every container of the robot must "
                            "run without a restart.")
    nodes: list[RosName] = Field(default_factory=list, description="ROS nodes present in the robot's graph.")
    heard: list[RosName] = Field(default_factory=list, description="Topics on which a message must be heard.")


class Timeouts(Strict):
    """How long robocore waits, in seconds."""

    robot: Number = Field(default=120, ge=1, le=86_400, description="For one robot to change and pass the gate.")
    heard: Number = Field(default=30, ge=1, le=86_400, description="For a robot's graph, from the moment every "
                          "container of it runs: its nodes seen and its topics heard (health.nodes, health.heard). "
                          "Shorter than robot, which must also cover a first pull: a robot that runs but is not "
                          "heard is decided on it.")
    wave: Number = Field(default=600, ge=1, le=86_400, description="For a whole wave.")
    busy: Number = Field(default=600, ge=1, le=86_400, description="For a robot that holds its update lock or is "
                         "outside its maintenance window to become free; past it the robot is left as it is.")


#: A week day as fleet.yaml writes it; :data:`DAYS` has them Monday first (``datetime.weekday()`` order).
Day = Literal["mon", "tue", "wed", "thu", "fri", "sat", "sun"]
DAYS: tuple[Day, ...] = get_args(Day)
#: A time of day, ``HH:MM`` on a 24-hour clock (``to`` may also be ``24:00``, the end of the day).
TIME_OF_DAY = r"(?:[01][0-9]|2[0-3]):[0-5][0-9]"


def _zone(value: str) -> str:
    from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

    try:
        ZoneInfo(value)
    except (ZoneInfoNotFoundError, ValueError):
        raise ValueError(f"{shown(value)} is not a time zone this machine knows (an IANA name such as "
                         "Europe/Berlin, or UTC)") from None
    return value


class Window(Strict):
    """A maintenance window: the robots it selects (by name, by label, or all) are updated only inside it, on
    ``days``, from ``from`` to ``to`` in ``timezone`` (a window whose ``to`` is not after ``from`` ends the next
    day)."""

    model_config = ConfigDict(extra="forbid", frozen=True, populate_by_name=True)

    robots: list[RobotName] | None = Field(default=None, description="These robots (by name).")
    labels: Labels | None = Field(default=None, description="Robots carrying all these labels.",
                                  json_schema_extra=lambda schema: _keyed_optional(schema))
    days: list[Day] = Field(
        default_factory=lambda: list(DAYS), min_length=1, max_length=7, description="The days it opens on "
        "(default: every day).")
    start: Annotated[str, _grammar(TIME_OF_DAY, "a time of day HH:MM, 00:00 to 23:59"), pattern_field(TIME_OF_DAY)] \
        = Field(alias="from", description="When it opens, HH:MM.")
    end: Annotated[str, _grammar(f"{TIME_OF_DAY}|24:00", "a time of day HH:MM, 00:00 to 24:00"),
                   pattern_field(f"{TIME_OF_DAY}|24:00")] = Field(alias="to", description="When it closes, HH:MM.")
    timezone: Annotated[str, AfterValidator(_zone)] = Field(default="UTC", max_length=64, description="The "
                                                            "robot's IANA time zone (Europe/Berlin).")

    @model_validator(mode="after")
    def _one_selector(self) -> Window:
        if self.robots is not None and self.labels is not None:
            raise ValueError("a window takes one selector, not robots and labels")
        if self.start == self.end:
            raise ValueError(f"from and to are both {self.start}: an empty window (for all day: from 00:00 to 24:00)")
        return self


class Rollout(Strict):
    """The rollout policy: waves in order, the health gate, the timeouts."""

    waves: list[Wave] = Field(default_factory=list, description="In order; each robot goes in the first wave that "
                              f"selects it; robots no wave selects go in a last wave {REST_WAVE!r}.")
    health: HealthGate = Field(default_factory=HealthGate)
    timeouts: Timeouts = Field(default_factory=Timeouts)
    windows: list[Window] = Field(default_factory=list, description="Maintenance windows: a robot that some window "
                                  "selects is updated only inside one of them (docs/fleets.md).")


class GitOps(Strict):
    """Where the GitOps controllers pull the folder of `robocore export kubernetes` from (the kubernetes engine)."""

    allow_protocol: Literal["http"] | None = Field(default=None, description="http: let repo be an http:// URL "
                                                   "(neither encrypted nor authenticated).")
    repo: GitUrl = Field(description="The git repository the export is committed to (Argo CD's repoURL), without "
                         "credentials: the controllers keep those. `export kubernetes --git-repo` overrides it.")
    path: GitFolder = Field(default="", description="The export folder's path inside that repository (default: its "
                            "top). `export kubernetes --git-path` overrides it.")

    @field_validator("repo")
    @classmethod
    def _protocol(cls, repo: str, info: ValidationInfo) -> str:
        """https, ssh or scp-like; http only with allow_protocol: http (robot.yaml's repositories' rule)."""
        from robocore.config.sources import gitops_url

        return gitops_url(repo, info.data.get("allow_protocol"))


class Fleet(Strict):
    """A whole fleet: one fleet.yaml."""

    engine: Literal["swarm", "kubernetes"] = Field(
        default="swarm", description="swarm: robocore runs the fleet on Docker Swarm; kubernetes: export only.")
    manager: Manager | None = Field(default=None, description="The Swarm manager (required by the swarm engine).")
    registry: Registry | None = Field(default=None, description="Where release images live (default: robot.yaml's "
                                      "registry).")
    registry_ca: OneLine | None = Field(default=None, description="The CA certificate (PEM, a file of the project) "
                                        "that signed the registry's TLS certificate; `fleet join` installs it on "
                                        "every robot host (/etc/docker/certs.d/<registry>/ca.crt).")
    robots: list[FleetRobot] = Field(min_length=1, max_length=MAX_ROBOTS)
    rollout: Rollout = Field(default_factory=Rollout)
    gitops: GitOps | None = Field(default=None, description="kubernetes engine: the git repository (and folder) the "
                                  "GitOps controllers pull the export from; without it the Argo CD ApplicationSet "
                                  "names a placeholder that never syncs.")

    def robot(self, name: str) -> FleetRobot:
        """The robot called ``name`` (KeyError if none)."""
        for robot in self.robots:
            if robot.name == name:
                return robot
        raise KeyError(name)

    @property
    def robot_names(self) -> list[str]:
        """The robots' names, in file order."""
        return [robot.name for robot in self.robots]

    def registry_for(self, robot: Robot) -> str | None:
        """The registry release images live in: this file's, else robot.yaml's."""
        return self.registry or robot.registry


# --- loading --------------------------------------------------------------------------------------------------


def fleet_parts(data: dict[str, object], fleet: Fleet | None) -> FleetParts:
    """The parts of a fleet file that validated: all of them from a valid ``fleet``, else each robot and wave of
    the raw ``data`` that validates on its own (so that one run reports a bad type and a duplicate name)."""
    from robocore.config.checks import salvage_list

    if fleet is not None:
        return FleetParts(robots=list(enumerate(fleet.robots)), waves=list(enumerate(fleet.rollout.waves)),
                          engine=fleet.engine, has_manager=fleet.manager is not None, registry=fleet.registry,
                          manager=fleet.manager, registry_ca=fleet.registry_ca,
                          windows=list(enumerate(fleet.rollout.windows)))
    rollout = data.get("rollout")
    waves = rollout.get("waves") if isinstance(rollout, dict) else None
    engine = data.get("engine", "swarm")
    registry = data.get("registry")
    return FleetParts(robots=salvage_list(data.get("robots"), FleetRobot), waves=salvage_list(waves, Wave),
                      engine=engine if isinstance(engine, str) else None, has_manager="manager" in data,
                      registry=registry if isinstance(registry, str) else None,
                      registry_ca=ca if isinstance(ca := data.get("registry_ca"), str) else None,
                      manager=next((m for _, m in salvage_list([data.get("manager")], Manager)), None),
                      windows=salvage_list(rollout.get("windows") if isinstance(rollout, dict) else None, Window))


def parse_fleet_text(text: str, robot: Robot, *, file: str = FLEET_FILE, project: Path | None = None) -> Fleet:
    """Parse and validate fleet.yaml text against ``robot`` (the project's robot.yaml); ``project`` (its folder) adds
    the checks that look at files (the manager's TLS files).

    Raises :class:`ConfigError` with every problem found, one per line, sorted by line.
    """
    from robocore.config.fleet_checks import check_fleet
    from robocore.config.loader import field_problems, format_path, not_a_mapping, ordered
    from robocore.config.yamltext import problem, read_yaml

    data, lines = read_yaml(text, file, kind=FLEET_FILE, schema_hint=FLEET_SCHEMA_COMMAND)
    if not isinstance(data, dict):
        raise not_a_mapping(data, lines, file, "engine, gitops, manager, registry, registry_ca, robots, rollout")
    problems = [problem(file, line, format_path(path), "this key appears twice") for path, line in lines.duplicates]
    fleet: Fleet | None = None
    try:
        fleet = Fleet.model_validate(data)
    except ValidationError as exc:
        problems += field_problems(exc, file, lines, Fleet)
    except RecursionError:
        raise ConfigError([problem(file, None, "", "YAML is nested too deeply")]) from None
    found = check_fleet(fleet_parts(data, fleet), robot, project)
    problems += [problem(file, lines.line_of(path), format_path(path), message) for path, message in found]
    if problems:
        raise ConfigError(ordered(problems))
    assert fleet is not None
    return fleet


def load_fleet(project: Path, robot: Robot, *, file_name: str = FLEET_FILE) -> Fleet:
    """Load ``project/fleet.yaml`` and check it against ``robot``; raise :class:`ConfigError` naming every problem
    (``file:line: key: problem``), under the same input rules as robot.yaml."""
    from robocore.config.loader import read_config_file

    text, shown_path = read_config_file(project, file_name, schema_hint=FLEET_SCHEMA_COMMAND)
    return parse_fleet_text(text, robot, file=shown_path, project=project)
