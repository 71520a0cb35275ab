"""robocore's workload check for a robot on Kubernetes: the first step of the robot's health Job.

python3 daemonsets.py --timeout S

Reads the DaemonSets of the Job's own namespace (the robot's) from the API server, with the Job's service account
(allowed to get and list DaemonSets there, nothing else), until every one of them has a pod scheduled, updated to its
current spec and available (ready for its minReadySeconds), or S seconds have passed. A DaemonSet that schedules no
pod counts as failed: Kubernetes calls it ready, but its component runs nowhere (no node carries its robocore.dev/robot,
robocore.dev/host and kubernetes.io/arch labels). Prints one JSON line {"ok": bool, "problems": [...]}; exit 0 when
ok, 1 otherwise. The standard library only: the probe runs in the release's base image.
"""

from __future__ import annotations

import argparse
import json
import os
import ssl
import sys
import time
import urllib.request
from typing import Any

ACCOUNT = "/var/run/secrets/kubernetes.io/serviceaccount"
#: Seconds between two reads of the DaemonSets.
POLL = 2.0


def problems(items: list[dict[str, Any]]) -> list[str]:
    """What keeps the DaemonSets ``items`` (as the API returns them) from counting as rolled out; [] when none."""
    if not items:
        return ["no DaemonSet in the robot's namespace"]
    found = []
    for item in items:
        name = item.get("metadata", {}).get("name", "?")
        status = item.get("status") or {}
        desired = int(status.get("desiredNumberScheduled") or 0)
        if int(status.get("observedGeneration") or 0) < int(item.get("metadata", {}).get("generation") or 0):
            found.append(f"{name}: its change is not yet seen by the DaemonSet controller")
        elif desired < 1:
            found.append(f"{name}: schedules no pod: no node has its nodeSelector labels")
        elif int(status.get("updatedNumberScheduled") or 0) < desired:
            found.append(f"{name}: not yet updated")
        elif int(status.get("numberAvailable") or 0) < desired:
            found.append(f"{name}: not yet available")
    return found


def read() -> list[dict[str, Any]]:
    """The DaemonSets of this pod's namespace, from the API server, as this pod's service account."""
    host = os.environ["KUBERNETES_SERVICE_HOST"]
    port = os.environ.get("KUBERNETES_SERVICE_PORT", "443")
    host = f"[{host}]" if ":" in host else host
    with open(f"{ACCOUNT}/namespace") as file:
        namespace = file.read().strip()
    with open(f"{ACCOUNT}/token") as file:
        token = file.read().strip()
    context = ssl.create_default_context(cafile=f"{ACCOUNT}/ca.crt")
    request = urllib.request.Request(f"https://{host}:{port}/apis/apps/v1/namespaces/{namespace}/daemonsets",
                                     headers={"Authorization": f"Bearer {token}"})
    with urllib.request.urlopen(request, context=context, timeout=10) as response:
        items: list[dict[str, Any]] = json.load(response)["items"]
        return items


def main() -> int:
    """Check until ok or the timeout; print the verdict."""
    parser = argparse.ArgumentParser()
    parser.add_argument("--timeout", type=float, default=120.0)
    args = parser.parse_args()
    deadline = time.monotonic() + args.timeout
    while True:
        try:
            found = problems(read())
        except (OSError, ValueError, KeyError) as error:  # the API server unreachable, a reply that is no list
            found = [f"cannot read the DaemonSets: {error}"]
        if not found or time.monotonic() >= deadline:
            break
        time.sleep(POLL)
    print(json.dumps({"ok": not found, "problems": found}), flush=True)
    return 0 if not found else 1


if __name__ == "__main__":
    sys.exit(main())
