"""Which containers ``run``, ``down`` and ``status`` treat as the project's own."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from robocore.commands.support.hosts import managed_containers
from robocore.plan import naming


@dataclass
class FakeContainer:
    name: str
    labels: dict[str, str]


@dataclass
class FakeContainers:
    found: list[FakeContainer]
    calls: list[dict[str, Any]] = field(default_factory=list)

    def list(self, **kwargs: Any) -> list[FakeContainer]:
        self.calls.append(kwargs)
        wanted = kwargs["filters"]["label"].split("=", 1)[1]
        return [c for c in self.found if c.labels.get(naming.LABEL_PROJECT) == wanted]


@dataclass
class FakeClient:
    containers: FakeContainers


def labels(role: str, project: str = "robot") -> dict[str, str]:
    return {naming.LABEL_PROJECT: project, naming.LABEL_ROLE: role}


def test_only_the_projects_named_components_and_servers_are_managed() -> None:
    client = FakeClient(FakeContainers([
        FakeContainer("robot-talker", labels(naming.ROLE_COMPONENT)),
        FakeContainer("robot-discovery-0", labels(naming.ROLE_DISCOVERY)),
        # a build's intermediate container, started from the project's talker image: its labels, Docker's name
        FakeContainer("eager_turing", labels(naming.ROLE_COMPONENT)),
        FakeContainer("robot-talker-shell", labels("shell")),
        FakeContainer("other-talker", labels(naming.ROLE_COMPONENT, "other")),
    ]))
    found = managed_containers(client, "robot")  # type: ignore[arg-type]
    assert [c.name for c in found] == ["robot-talker", "robot-discovery-0"]
    # a container removed between docker's list and inspect calls is left out, not an error
    assert client.containers.calls == [{"all": True, "filters": {"label": f"{naming.LABEL_PROJECT}=robot"},
                                        "ignore_removed": True}]
