"""Offline checks of exported Kubernetes files: kustomize renders them, kubernetes-validate --strict checks them.

Both run with no network: ``kubectl kustomize`` inside a network namespace of its own (``unshare -n``), and
kubernetes-validate against the schemas its wheel bundles. kubectl missing is a failure, never a skip.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path
from typing import Any

import kubernetes_validate
import yaml

#: The oldest Kubernetes the export is checked against, and the newest kubernetes-validate bundles.
OLDEST = "1.30"
NEWEST = kubernetes_validate.utils.latest_version()
VERSIONS = (OLDEST, NEWEST)


def kubectl() -> str:
    """kubectl's path (it carries kustomize); an assertion error when it is missing."""
    path = shutil.which("kubectl")
    assert path is not None, "kubectl is not installed (it is on every machine of this project: /usr/bin/kubectl)"
    return path


def render(folder: Path) -> list[dict[str, Any]]:
    """The objects ``kubectl kustomize folder`` renders, with no network (its own network namespace when this
    process may make one)."""
    argv = [kubectl(), "kustomize", "--", str(folder)]
    unshare = shutil.which("unshare")
    if unshare is not None and subprocess.run([unshare, "-n", "true"], capture_output=True).returncode == 0:
        argv = [unshare, "-n", *argv]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, f"kubectl kustomize {folder} failed: {done.stderr}"
    return [doc for doc in yaml.safe_load_all(done.stdout) if doc]


def validate(doc: dict[str, Any], versions: tuple[str, ...] = VERSIONS) -> None:
    """kubernetes-validate --strict of one object for each version (raises its ValidationError)."""
    for version in versions:
        kubernetes_validate.validate(doc, version, strict=True)


def by_kind(docs: list[dict[str, Any]], kind: str) -> dict[str, dict[str, Any]]:
    """The objects of ``kind`` by name."""
    return {d["metadata"]["name"]: d for d in docs if d["kind"] == kind}
