"""The wheels base's venv made in the Debian root robocore bootstraps (not in a build step), with the base's settings
in that root's image config, and the base's Dockerfile that then has robocore's files as its one step."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

from robocore.adapters import image_archive, rootfs
from robocore.adapters.image_builder import PROXY_VARS, ImageState
from robocore.commands import prepare_base
from robocore.config.model import BaseKind, Robot
from robocore.plan import arches, dockerfiles, naming, wheels_venv
from robocore.project import Project

ROBOT = """\
ros_distro: {distro}
base: {{kind: {kind}}}
hosts: [{{name: dev, ip: 127.0.0.1}}]
components:
  - {{name: talker, folder: components/talker, runs_on: dev}}
"""


def _project(tmp_path: Path, distro: str = "jazzy", kind: str = "wheels") -> Project:
    (tmp_path / "components" / "talker").mkdir(parents=True)
    (tmp_path / "robot.yaml").write_text(ROBOT.format(distro=distro, kind=kind))
    return Project.load(tmp_path)


def _steps(dockerfile: str) -> list[str]:
    return [line.split()[0] for line in dockerfile.splitlines() if line and not line.startswith((" ", "#"))]


def _env_of(dockerfile: str) -> dict[str, str]:
    """The ENV step's settings of a Dockerfile (one ENV, one setting a line)."""
    lines = dockerfile.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("ENV "))
    found: dict[str, str] = {}
    for line in lines[start:]:
        name, _, value = line.removeprefix("ENV ").strip().removesuffix("\\").strip().partition("=")
        found[name] = value
        if not line.endswith("\\"):
            return found
    return found


def test_the_wheels_root_holds_the_venv_installed_by_its_last_hook(tmp_path: Path) -> None:
    strap = prepare_base.root_strap(_project(tmp_path), "amd64")
    assert strap is not None and strap.venv == "/opt/ros/jazzy/venv"
    # the roots' own hooks first (the root's modules compiled), then the venv's
    assert strap.hooks[:-1] == arches.COMPILE_LATER_HOOKS
    assert strap.hooks[-1].startswith("--customize-hook=") and "uv pip install" in strap.hooks[-1]
    for pin in dockerfiles.WHEELS["jazzy"] + dockerfiles.WHEELS_TOOLS:
        assert pin in strap.hooks[-1]
    argv = strap.argv("/tmp/x/root.tar", "http://deb.debian.org/debian")
    assert argv[-4] == strap.hooks[-1] and argv[-3:] == ["bookworm", "/tmp/x/root.tar", "http://deb.debian.org/debian"]
    plain = arches.root_strap(BaseKind.wheels, "amd64", dockerfiles.WHEELS_APT)
    assert plain.venv == "" and plain.config is None and strap.key() != plain.key()


def test_each_distro_has_its_own_wheels_root_and_the_debian_root_has_no_venv(tmp_path: Path) -> None:
    jazzy = _project(tmp_path / "j", "jazzy")
    kilted = _project(tmp_path / "k", "kilted")
    assert arches.base_root(jazzy.robot, "amd64") == "robocore/amd64/debian:bookworm-wheels-jazzy"
    assert arches.base_root(kilted.robot, "amd64") == "robocore/amd64/debian:bookworm-wheels-kilted"
    j, k = prepare_base.root_strap(jazzy, "amd64"), prepare_base.root_strap(kilted, "amd64")
    assert j is not None and k is not None and j.key() != k.key() and "ros-rclpy==9.1.2" in k.hooks[-1]
    debian = prepare_base.root_strap(_project(tmp_path / "d", "noetic", "debian"), "amd64")
    assert debian is not None and debian.venv == "" and debian.hooks == arches.COMPILE_LATER_HOOKS
    # the debian root's name and content hash are as they were
    assert debian.key() == arches.RootStrap(debian.arch, debian.packages).key()
    assert arches.root_image(BaseKind.debian, "amd64") == "robocore/amd64/debian:bookworm-debian"


def test_a_venv_without_its_hook_is_refused() -> None:
    with pytest.raises(ValueError):
        arches.root_strap(BaseKind.wheels, "amd64", dockerfiles.WHEELS_APT, venv="/opt/ros/jazzy/venv")


def _robot(distro: str = "jazzy") -> Robot:
    return Robot.model_validate({"ros_distro": distro, "base": {"kind": "wheels"},
                                 "hosts": [{"name": "dev", "ip": "127.0.0.1"}],
                                 "components": [{"name": "c", "runs_on": "dev", "folder": "components/c"}]})


@pytest.mark.parametrize("has_ca", [True, False])
def test_on_a_root_with_the_venv_the_base_is_robocores_files_alone(has_ca: bool) -> None:
    robot = _robot()
    full = dockerfiles.base_dockerfile(robot, root_image="r", has_ca=has_ca, common=[])
    lean = dockerfiles.base_dockerfile(robot, root_image="r", has_ca=has_ca, common=[], venv_in_root=True)
    assert _steps(full) == ["FROM", "SHELL", "COPY", "ENV", "ENTRYPOINT", "CMD", "RUN"]
    assert _steps(lean) == ["FROM", "COPY"]
    assert ("trust store" in lean) is has_ca  # the file is in the tree; its settings in the root's config
    # the root's image config has what the steps left out set: the same environment, entrypoint, command, shell
    config = dockerfiles.wheels_root_config("jazzy", has_ca=has_ca).image_config()
    env = _env_of(full)
    env["PATH"] = env["PATH"].replace("$PATH", arches.DEFAULT_PATH)
    assert dict(item.split("=", 1) for item in config["Env"]) == env
    assert config["Entrypoint"] == [naming.ENTRYPOINT] and config["Cmd"] == ["bash"]
    assert f"SHELL {json.dumps(config['Shell'])}" in full


def test_common_packages_still_build_on_a_root_with_the_venv() -> None:
    text = dockerfiles.base_dockerfile(_robot("kilted"), root_image="r", has_ca=False, common=["my_msgs"],
                                       venv_in_root=True)
    assert _steps(text) == ["FROM", "COPY", "COPY", "RUN"] and " build --merge-install" in text


def test_the_root_image_config_carries_the_settings() -> None:
    settings = dockerfiles.wheels_root_config("jazzy", has_ca=True)
    config = json.loads(image_archive.image_config(arch="amd64", diff_id="sha256:00", labels={"a": "b"},
                                                   cmd=("bash",), created="2026-01-01T00:00:00Z", comment="c",
                                                   settings=settings))["config"]
    assert config["Entrypoint"] == ["/robocore/entrypoint.sh"] and config["Shell"] == list(dockerfiles.SHELL)
    assert "PATH=/opt/ros/jazzy/venv/bin:" + arches.DEFAULT_PATH in config["Env"]
    assert "PIP_CERT=/etc/robocore/host-ca.pem" in config["Env"] and config["Labels"] == {"a": "b"}
    plain = json.loads(image_archive.image_config(arch="amd64", diff_id="sha256:00", labels={}, cmd=("bash",),
                                                  created="2026-01-01T00:00:00Z", comment="c"))["config"]
    assert plain == {"Cmd": ["bash"], "Labels": {}}


class _Images:
    def __init__(self, found: dict[str, Any]) -> None:
        self.found = found

    def get(self, ref: str) -> Any:
        from docker.errors import ImageNotFound

        if ref not in self.found:
            raise ImageNotFound(ref)
        return self.found[ref]


def _client(ref: str, labels: dict[str, str]) -> Any:
    image = SimpleNamespace(id="sha256:root", attrs={"Config": {"Labels": labels}, "Architecture": "amd64"})
    return SimpleNamespace(images=_Images({ref: image}))


def test_the_base_leaves_the_venv_out_only_on_the_root_bootstrapped_with_it(tmp_path: Path) -> None:
    project = _project(tmp_path)
    strap = prepare_base.root_strap(project, "amd64")
    assert strap is not None
    ref = arches.base_root(project.robot, "amd64")
    ours = {naming.LABEL_ROLE: rootfs.ROLE_ROOT, naming.LABEL_INPUTS: rootfs.strap_hash(strap)}
    lean = prepare_base.plan_base(project, _client(ref, ours), "amd64", dry_run=True).plan.dockerfile
    assert _steps(lean) == ["FROM", "COPY"]
    # negative controls: a pulled debian:bookworm tagged so, a root made from other inputs, no daemon at all
    stale = {**ours, naming.LABEL_INPUTS: "sha256:other"}
    for client in (_client(ref, {}), _client(ref, stale), None):
        full = prepare_base.plan_base(project, client, "amd64", dry_run=True).plan.dockerfile
        assert _steps(full)[-1] == "RUN" and "uv pip install" in full
    assert rootfs.made_from(ImageState(id="x", labels=ours, size=0, arch="amd64"), strap)
    assert not rootfs.made_from(ImageState(id="x", labels=ours, size=0, arch="arm64"), strap)
    assert not rootfs.made_from(None, strap)


def _fake_chroot(tmp_path: Path) -> Path:
    """A ``chroot`` on PATH that records its arguments and the trust store it finds in the root."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    stub = bin_dir / "chroot"
    stub.write_text('#!/bin/sh\nfor arg in "$@"; do printf "%s\\n" "$arg"; done > "$RECORD"\n'
                    f'cp "$1{wheels_venv.CA_IN_ROOT}" "$RECORD.ca"\n')
    stub.chmod(0o755)
    return bin_dir


def _run_hook(hook: str, root: Path, env: dict[str, str]) -> None:
    script = hook.removeprefix("--customize-hook=")
    subprocess.run(["sh", "-c", script, "exec", str(root)], check=True, env=env)  # as mmdebstrap runs a hook


def test_the_hook_installs_in_the_root_with_the_trust_store_and_only_the_proxies_set(tmp_path: Path) -> None:
    root = tmp_path / "root"
    (root / "tmp").mkdir(parents=True)
    ca = tmp_path / "my ca.pem"
    ca.write_text("CERT\n")
    record = tmp_path / "argv"
    env = {"PATH": f"{_fake_chroot(tmp_path)}:{os.environ['PATH']}", "RECORD": str(record),
           "https_proxy": "http://proxy.local:3128", "NO_PROXY": "a b", "http_proxy": "",
           "PYTHONPATH": "/somewhere/else", "VIRTUAL_ENV": "/host/venv"}
    hook = wheels_venv.root_hook("/opt/ros/jazzy/venv", "ros-rclpy==7.1.6", ca=str(ca), passed=PROXY_VARS)
    assert "proxy.local" not in hook  # by name: the values are no part of the root's content hash
    _run_hook(hook, root, env)
    argv = record.read_text().splitlines()
    assert argv[:3] == [str(root), "/usr/bin/env", "-i"]
    settings = argv[3:argv.index("/bin/bash")]
    assert f"PATH={arches.DEFAULT_PATH}" in settings and "HOME=/root" in settings
    # hash-based .pyc files: the root's tarball clamps mtimes, which would make timestamp-based ones stale
    assert any(s.startswith("SOURCE_DATE_EPOCH=") for s in settings)
    assert {f"{name}={wheels_venv.CA_IN_ROOT}" for name in wheels_venv.CA_VARIABLES} <= set(settings)
    assert "https_proxy=http://proxy.local:3128" in settings and "NO_PROXY=a b" in settings
    assert not any(s.startswith(("http_proxy=", "PYTHONPATH=", "VIRTUAL_ENV=")) for s in settings)
    assert argv[-3:-1] == ["-o", "pipefail"] or argv[-4:-1] == ["-o", "pipefail", "-c"]
    assert argv[-1] == wheels_venv.install_script("/opt/ros/jazzy/venv", "ros-rclpy==7.1.6").replace(" \\\n", "")
    # the trust store was there for the install, and is gone from the root after it
    assert Path(f"{record}.ca").read_text() == "CERT\n"
    assert not (root / wheels_venv.CA_IN_ROOT.lstrip("/")).exists()


def test_without_a_trust_store_the_hook_sets_none(tmp_path: Path) -> None:
    root = tmp_path / "root"
    (root / "tmp").mkdir(parents=True)
    hook = wheels_venv.root_hook("/opt/ros/kilted/venv", "x", ca=None, passed=())
    assert "cp --" not in hook and "SSL_CERT_FILE" not in hook
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    (bin_dir / "chroot").write_text('#!/bin/sh\nprintf "%s\\n" "$@" > "$RECORD"\n')
    (bin_dir / "chroot").chmod(0o755)
    record = tmp_path / "argv"
    _run_hook(hook, root, {"PATH": f"{bin_dir}:{os.environ['PATH']}", "RECORD": str(record)})
    assert "python3 -m venv --without-pip /opt/ros/kilted/venv" in record.read_text()


def test_a_failed_venv_hook_fails_the_bootstrap_naming_pypi_too(tmp_path: Path, monkeypatch: Any) -> None:
    """A bootstrap whose install fails (here a stand-in mmdebstrap that fails as a hook would) says which mirror and,
    for a root with a venv only, PyPI."""
    from robocore.errors import BuildError

    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    (bin_dir / "mmdebstrap").write_text("#!/bin/sh\necho 'E: hook failed: uv: connection refused' >&2\nexit 1\n")
    (bin_dir / "mmdebstrap").chmod(0o755)
    monkeypatch.setenv("PATH", f"{bin_dir}:{os.environ['PATH']}")
    monkeypatch.setenv(rootfs.SCRATCH_ENV, "")
    with_venv = prepare_base.root_strap(_project(tmp_path / "p"), "amd64")
    plain = arches.root_strap(BaseKind.wheels, "amd64", dockerfiles.WHEELS_APT)
    hints = []
    for strap in (with_venv, plain):
        assert strap is not None
        with pytest.raises(BuildError) as info:
            rootfs.bootstrap(object(), strap, target="t:x", work_dir=tmp_path / "w")  # type: ignore[arg-type]
        assert "connection refused" in info.value.message
        hints.append(info.value.hint or "")
    assert "PyPI" in hints[0] and "PyPI" not in hints[1]
