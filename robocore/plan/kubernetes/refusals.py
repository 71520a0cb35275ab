"""What a robot.yaml asks for that robocore cannot say in Kubernetes objects: one problem per key (pure).

Each problem is a key path of robot.yaml and a message; the command turns them into
``robot.yaml:LINE: key.path: message`` lines (:func:`robocore.config.loader.located`) and writes nothing.
"""

from __future__ import annotations

from robocore.config.mappings import is_project_path, read_only_project_path
from robocore.config.model import Robot
from robocore.plan.kubernetes.names import DISCOVERY_PREFIX, is_dns_label, k8s_name

KeyPath = tuple[str | int, ...]
Found = list[tuple[KeyPath, str]]

#: Why each refusal: the one line robocore prints.
NOT_A_NAME = ("cannot be a Kubernetes name (letters, digits and '-' once lower-cased, '_' read as '-', ending "
              "with a letter or digit); rename it")
BRIDGE = ("the Kubernetes export runs every component on the host network (DDS needs it); network: bridge and "
          "ports cannot be expressed: remove them")
GUI = ("windows on a robot host's display (gui, desktop) need files robocore makes at each run; the Kubernetes "
       "export cannot carry them: remove the key, or keep this component off the fleet")
RESTART = ("a DaemonSet restarts every pod that stops; restart: {value} cannot be expressed: use always or "
           "unless-stopped (the default)")
NAMED_VOLUME = ("a named Docker volume has no counterpart on a robot's cluster; use an absolute host path "
                "(/var/lib/...:/data)")
SYNCED_FILES = ("read-only project files reach a pod only inside a fleet release's image, and this tag has no "
                "fleet release (images by tag are code-less; a hostPath copy of synced files is never exported): "
                "run `release --fleet --tag V` first, or remove the volume")
DEVICE_PERMISSIONS = ("a pod reaches devices only as privileged (read, write and mknod); permissions {value!r} "
                      "cannot be expressed: drop them")


#: Names a component's file (``<name>.yaml`` in its model's base folder) cannot take: the base's own files (its
#: kustomization, the health gate's Job); the discovery servers' files start with :data:`DISCOVERY_PREFIX`.
RESERVED_NAMES = ("kustomization", "health")


def _name_problems(robot: Robot) -> Found:
    found: Found = []
    seen: dict[str, str] = {}
    for index, host in enumerate(robot.hosts):
        if not is_dns_label(k8s_name(host.name), 63 - len(DISCOVERY_PREFIX)):
            found.append((("hosts", index, "name"), f"{host.name!r} {NOT_A_NAME}"))
        elif k8s_name(host.name) in seen:
            found.append((("hosts", index, "name"), f"{host.name!r} and {seen[k8s_name(host.name)]!r} are one "
                          "Kubernetes name; rename one"))
        seen.setdefault(k8s_name(host.name), host.name)
    seen = {}
    for index, component in enumerate(robot.components):
        name = k8s_name(component.name)
        if not is_dns_label(name):
            found.append((("components", index, "name"), f"{component.name!r} {NOT_A_NAME}"))
        elif name.startswith(DISCOVERY_PREFIX):
            found.append((("components", index, "name"), f"{component.name!r}: names starting with "
                          f"{DISCOVERY_PREFIX!r} are the discovery servers' on Kubernetes; rename it"))
        elif name in seen:
            found.append((("components", index, "name"), f"{component.name!r} and {seen[name]!r} are one "
                          "Kubernetes name; rename one"))
        elif name in RESERVED_NAMES:  # its file, <name>.yaml, would be the base folder's own
            found.append((("components", index, "name"), f"{component.name!r}: its file {name}.yaml would be the "
                          "base folder's own (kustomization.yaml lists the base's files, health.yaml holds the health "
                          "gate's Job); rename it"))
        seen.setdefault(name, component.name)
    return found


def problems(robot: Robot, *, fleet_images: bool = False) -> Found:
    """Every key of ``robot`` that the Kubernetes export cannot express, in file order, with the reason.

    ``fleet_images``: the pods run a fleet release's images (``release --fleet``), which carry each component's
    read-only project volumes at their container paths; the pods then leave those volumes out
    (:func:`~robocore.plan.fleet_release.baked_volumes`). Without them such a volume is refused: nothing would
    put its files in the pod. A writable project volume is a folder of the robot's host either way."""
    found = _name_problems(robot)
    for index, component in enumerate(robot.components):
        where: KeyPath = ("components", index)
        if component.network_mode == "bridge":
            found.append(((*where, "network" if component.network else "ports"), BRIDGE))
        if component.gui:
            found.append(((*where, "gui"), GUI))
        if component.desktop is not None:
            found.append(((*where, "desktop"), GUI))
        if component.restart in ("no", "on-failure"):
            found.append(((*where, "restart"), RESTART.format(value=component.restart)))
        for number, volume in enumerate(component.volumes):
            source = volume.split(":")[0]
            if read_only_project_path(volume) is not None:
                if not fleet_images:
                    found.append(((*where, "volumes", number), SYNCED_FILES))
            elif not source.startswith("/") and not is_project_path(source):
                found.append(((*where, "volumes", number), NAMED_VOLUME))
        for number, device in enumerate(component.devices):
            parts = device.split(":")
            if len(parts) > 2 and parts[2] and set(parts[2]) != set("rwm"):
                found.append(((*where, "devices", number), DEVICE_PERMISSIONS.format(value=parts[2])))
    return found
