"""Content hashes of image inputs and of workspaces: what changes a hash, and what does not."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from robocore.commands import build, stage
from robocore.commands.support import machine
from robocore.config.model import Robot
from robocore.plan import colcon
from robocore.plan.inputs import FileDigest, inputs_hash, tree_hash
from robocore.project import Project

BASE = stage.BaseRef(ref="proj-base:latest", arch="amd64", inputs="sha256:base1")


def make_project(root: Path, kind: str = "wheels", **changes: Any) -> Project:
    comps: list[dict[str, Any]] = [
        {"name": "talker", "runs_on": "dev", "folder": "ws/talker", "apt_packages": ["curl"]},
        {"name": "listener", "runs_on": "dev", "folder": "ws/listener", "pip_packages": ["numpy"]},
    ]
    for comp in comps:
        comp.update(changes.get(comp["name"], {}))
        pkg = root / comp["folder"] / "src" / f"pkg_{comp['name']}"
        pkg.mkdir(parents=True, exist_ok=True)
        if not (pkg / "package.xml").exists():
            (pkg / "package.xml").write_text(f"<package><name>pkg_{comp['name']}</name></package>")
            (pkg / "node.py").write_text("print('hi')\n")
    robot = Robot.model_validate({"ros_distro": "jazzy", "base": {"kind": kind},
                                  "hosts": [{"name": "dev", "ip": "127.0.0.1"}], "components": comps})
    return Project(root=root, robot=robot)


def hashes(project: Project, base: stage.BaseRef = BASE) -> dict[str, str]:
    return {c.name: stage.plan_component(project, c, base).inputs for c in project.robot.components}


def test_inputs_hash_is_order_independent_and_content_sensitive() -> None:
    a = FileDigest("a", False, "1")
    b = FileDigest("b", True, "2")
    h = inputs_hash("FROM x\n", [a, b], parent="p", platform="linux/amd64")
    assert h == inputs_hash("FROM x\n", [b, a], parent="p", platform="linux/amd64")
    assert h != inputs_hash("FROM y\n", [a, b], parent="p", platform="linux/amd64")
    assert h != inputs_hash("FROM x\n", [a, FileDigest("b", False, "2")], parent="p", platform="linux/amd64")
    assert h != inputs_hash("FROM x\n", [a, b], parent="q", platform="linux/amd64")
    assert h != inputs_hash("FROM x\n", [a, b], parent="p", platform="linux/arm64")
    assert h.startswith("sha256:")


def test_changing_one_components_apt_list_changes_only_its_hash(tmp_path: Path) -> None:
    before = hashes(make_project(tmp_path))
    after = hashes(make_project(tmp_path, talker={"apt_packages": ["curl", "jq"]}))
    assert after["talker"] != before["talker"]
    assert after["listener"] == before["listener"]


def test_same_inputs_same_hash(tmp_path: Path) -> None:
    assert hashes(make_project(tmp_path)) == hashes(make_project(tmp_path))


def test_user_code_never_changes_an_image_hash(tmp_path: Path) -> None:
    for kind in ("wheels", "official"):
        project = make_project(tmp_path / kind, kind=kind)
        before = hashes(project)
        (tmp_path / kind / "ws/talker/src/pkg_talker/node.py").write_text("print('changed')\n")
        assert hashes(project) == before


def test_package_xml_changes_the_hash_only_where_rosdep_reads_it(tmp_path: Path) -> None:
    official = make_project(tmp_path / "o", kind="official")
    wheels = make_project(tmp_path / "w", kind="wheels")
    before_o, before_w = hashes(official), hashes(wheels)
    for root in ("o", "w"):
        xml = tmp_path / root / "ws/talker/src/pkg_talker/package.xml"
        xml.write_text(xml.read_text().replace("</name>", "</name><depend>rclpy</depend>"))
    assert hashes(official)["talker"] != before_o["talker"]
    assert hashes(official)["listener"] == before_o["listener"]
    assert hashes(wheels) == before_w  # no rosdep on the wheels base: package.xml is not an input


def test_official_component_context_holds_only_package_xml(tmp_path: Path) -> None:
    project = make_project(tmp_path, kind="official")
    planned = stage.plan_component(project, project.robot.component("talker"), BASE)
    assert [f.dest for f in planned.files] == ["rosdep/src/pkg_talker/package.xml"]


def test_a_new_base_changes_every_component_hash(tmp_path: Path) -> None:
    project = make_project(tmp_path)
    other = stage.BaseRef(ref=BASE.ref, arch="amd64", inputs="sha256:base2")
    before, after = hashes(project), hashes(project, other)
    assert all(before[name] != after[name] for name in before)


def test_package_hashes_follow_content_not_timestamps(tmp_path: Path) -> None:
    import os

    project = make_project(tmp_path)
    ws = tmp_path / "ws/talker"
    first = build.package_hashes(ws)
    assert list(first) == ["pkg_talker"]
    node = ws / "src/pkg_talker/node.py"
    os.utime(node, (1, 1))
    assert build.package_hashes(ws) == first
    node.write_text("print('edited')\n")
    assert build.package_hashes(ws) != first
    # build outputs and caches inside the workspace are not sources
    (ws / "build").mkdir()
    (ws / "build/x.txt").write_text("x")
    (ws / "src/pkg_talker/__pycache__").mkdir()
    (ws / "src/pkg_talker/__pycache__/node.cpython-311.pyc").write_bytes(b"\0")
    assert build.package_hashes(ws) == build.package_hashes(ws)
    assert project.robot.component("talker").folder == "ws/talker"


def test_tree_hash_depends_on_paths_and_content() -> None:
    assert tree_hash([FileDigest("a", False, "1")]) != tree_hash([FileDigest("b", False, "1")])
    assert tree_hash([FileDigest("a", False, "1")]) == tree_hash([FileDigest("a", False, "1")])


def test_colcon_events_and_argv() -> None:
    assert colcon.parse_event("Starting >>> demo_talker") == colcon.PackageEvent("demo_talker", "started")
    finished = colcon.PackageEvent("demo_talker", "finished", 1.23)
    assert colcon.parse_event("Finished <<< demo_talker [1.23s]") == finished
    assert colcon.parse_event("Failed   <<< broken [0.5s, exited with code 1]") == colcon.PackageEvent(
        "broken", "failed", 0.5)
    assert colcon.parse_event("random output") is None
    argv = colcon.workspace_build_argv(["a"])
    assert argv[:4] == ["colcon", "--log-base", "/robocore/log", "build"]
    assert argv[argv.index("--base-paths") + 1] == "/robocore/ws"
    assert argv[argv.index("--install-base") + 1] == "/robocore/install"
    assert argv[argv.index("--packages-above") + 1] == "a"
    assert argv[argv.index("--event-handlers") + 1:] == list(colcon.EVENT_HANDLERS)
    assert colcon.package_name("<package><name> foo_bar </name></package>") == "foo_bar"


def _git_repo(path: Path, text: str) -> str:
    import subprocess

    path.mkdir(parents=True, exist_ok=True)
    run = lambda *a: subprocess.run(["git", *a], cwd=path, check=True, capture_output=True, text=True)  # noqa: E731
    if not (path / ".git").exists():
        run("init", "-q", "-b", "main")
    (path / "package.xml").write_text(f"<package><name>dep_pkg</name><!-- {text} --></package>")
    run("add", "-A")
    run("-c", "user.name=t", "-c", "user.email=t@t", "commit", "-q", "-m", text)
    return run("rev-parse", "HEAD").stdout.strip()


def test_repositories_are_fetched_into_the_context_and_pinned_versions_hash(tmp_path: Path, monkeypatch: Any) -> None:
    # a local (file://) repository: as if the entry said allow_protocol: file
    monkeypatch.setattr(stage, "allowed_protocol", lambda entry: "file")
    upstream = tmp_path / "upstream"
    first = _git_repo(upstream, "one")
    second = _git_repo(upstream, "two")
    url = upstream.as_uri()
    project = make_project(tmp_path / "p", talker={"repositories": [{"url": url, "version": first}]})
    planned = stage.plan_component(project, project.robot.component("talker"), BASE)
    dests = [f.dest for f in planned.files]
    assert dests == ["repos/upstream/package.xml"]  # no .git in the context
    assert b"one" in planned.files[0].data
    assert "COPY repos /tmp/robocore/deps" in planned.plan.dockerfile
    other = make_project(tmp_path / "p", talker={"repositories": [{"url": url, "version": second}]})
    again = stage.plan_component(other, other.robot.component("talker"), BASE)
    assert b"two" in again.files[0].data and again.inputs != planned.inputs


def test_fetch_failure_is_a_one_line_build_error(tmp_path: Path) -> None:
    import pytest

    from robocore.adapters import vcs
    from robocore.errors import BuildError

    with pytest.raises(BuildError) as info:
        vcs.fetch((tmp_path / "missing").as_uri(), "main", tmp_path / "dest")
    assert "cannot fetch" in info.value.message and "missing" in info.value.message


def test_cross_arch_without_binfmt_says_how_to_set_up_qemu(tmp_path: Path, monkeypatch: Any) -> None:
    import pytest

    from robocore.errors import ToolMissing

    monkeypatch.setattr(machine, "BINFMT_DIR", tmp_path)
    machine.check_emulation("amd64", "amd64", "x")  # native: nothing to check
    with pytest.raises(ToolMissing) as info:
        machine.check_emulation("arm64", "amd64", "component cam")
    assert "component cam" in info.value.message and "qemu-user-static" in (info.value.hint or "")
    (tmp_path / "qemu-aarch64").write_text("enabled\nflags: PO\n")
    with pytest.raises(ToolMissing, match="lacks the F flag"):  # containers could not find the interpreter
        machine.check_emulation("arm64", "amd64", "component cam")
    (tmp_path / "qemu-aarch64").write_text("enabled\ninterpreter /usr/bin/qemu\nflags: POF\n")
    machine.check_emulation("arm64", "amd64", "component cam")  # registered: fine


def test_missing_mmdebstrap_is_tool_missing_with_a_hint(tmp_path: Path, monkeypatch: Any) -> None:
    import pytest

    from robocore.adapters import rootfs
    from robocore.config.model import BaseKind
    from robocore.errors import ToolMissing
    from robocore.plan import arches

    monkeypatch.setattr(rootfs.shutil, "which", lambda name: None)
    with pytest.raises(ToolMissing) as info:
        rootfs.bootstrap(object(), arches.root_strap(BaseKind.wheels, "arm64", ["python3"]),  # type: ignore[arg-type]
                         target="robocore/arm64/debian:bookworm-wheels", work_dir=tmp_path)
    assert "mmdebstrap" in info.value.message and "apt-get install mmdebstrap" in (info.value.hint or "")


def test_the_root_bootstrap_works_in_memory_only_where_there_is_room(tmp_path: Path, monkeypatch: Any) -> None:
    """/dev/shm (or ROBOCORE_ROOTFS_SCRATCH) when it is a writable, executable folder with 2 GiB free; else none
    (the project's cache on disk), and an empty setting turns it off."""
    import os

    from robocore.adapters import rootfs

    monkeypatch.setenv(rootfs.SCRATCH_ENV, str(tmp_path))
    real = os.statvfs(tmp_path)

    def free(nbytes: int, flag: int = 0) -> Any:
        fields = list(real)
        fields[4] = nbytes // real.f_frsize  # f_bavail
        fields[8] = flag  # f_flag
        return os.statvfs_result(fields)

    monkeypatch.setattr(rootfs.os, "statvfs", lambda path: free(rootfs.SCRATCH_NEEDS))
    assert rootfs.scratch_dir() == str(tmp_path)
    monkeypatch.setattr(rootfs.os, "statvfs", lambda path: free(rootfs.SCRATCH_NEEDS - real.f_frsize))
    assert rootfs.scratch_dir() is None  # too small: the bootstrap would fail half-way
    monkeypatch.setattr(rootfs.os, "statvfs", lambda path: free(rootfs.SCRATCH_NEEDS, os.ST_NOEXEC))
    assert rootfs.scratch_dir() is None  # noexec: the chroot's maintainer scripts could not run
    monkeypatch.undo()
    monkeypatch.setenv(rootfs.SCRATCH_ENV, str(tmp_path / "missing"))
    assert rootfs.scratch_dir() is None
    monkeypatch.setenv(rootfs.SCRATCH_ENV, "")
    assert rootfs.scratch_dir() is None
