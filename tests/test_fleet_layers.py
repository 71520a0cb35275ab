"""A fleet image's layers: one per ROS package in dependency order, deterministic tars, the image's configuration,
and the bytes a robot pulls (no Docker)."""

from __future__ import annotations

import io
import json
import os
import tarfile
from pathlib import Path, PurePosixPath

from robocore.adapters.image_layers import layer_tar
from robocore.commands.support.fleet_layers import read_install_tree
from robocore.plan.fleet_layers import MAX_LAYERS, Layer, component_layers, layered_config, order_packages
from robocore.plan.fleet_release import LayerFile
from robocore.plan.pull_bytes import ImageLayers, human, parse_manifest, pull_bytes, robot_bytes

INSTALL = PurePosixPath("/robocore/install")


def colcon_tree(root: Path, packages: dict[str, str]) -> Path:
    """An isolated colcon install tree at ``root``: each package with its dependency record and one file."""
    install = root / "install"
    for name, deps in packages.items():
        record = install / name / "share/colcon-core/packages" / name
        record.parent.mkdir(parents=True)
        record.write_text(deps)
        (install / name / "lib").mkdir()
        (install / name / "lib" / "node.py").write_text(f"print('{name}')\n")
    (install / "setup.bash").write_text("# colcon\n")
    (install / "COLCON_IGNORE").write_text("")
    return install


def test_packages_come_after_those_they_depend_on_ties_by_name() -> None:
    assert order_packages({"app": ["msgs", "lib", "rclpy"], "lib": ["msgs"], "msgs": [], "zeta": []}) == [
        "msgs", "lib", "app", "zeta"]
    assert order_packages({"b": ["a"], "a": ["b"]}) == ["a", "b"]  # a cycle (colcon refuses one) still ends


def test_the_install_tree_is_each_packages_share_then_each_packages_code_then_the_project_files(
        tmp_path: Path) -> None:
    install = colcon_tree(tmp_path, {"demo_app": "demo_msgs:rclpy", "demo_msgs": "", "alpha": ""})
    tree = read_install_tree(install, INSTALL)
    assert dict(tree.packages) == {"alpha": (), "demo_app": ("demo_msgs", "rclpy"), "demo_msgs": ()}
    assert tree.others == ("COLCON_IGNORE", "setup.bash")
    assert tree.contents["demo_app"] == ("lib", "share")
    files = (LayerFile(install, INSTALL), LayerFile(tmp_path / "config", PurePosixPath("/params")))
    layers = component_layers(files, tree)
    assert [layer.name for layer in layers] == [
        "install tree /robocore/install: colcon's files",
        "package alpha: share", "package demo_msgs: share", "package demo_app: share",
        "package alpha", "package demo_msgs", "package demo_app",  # the code of the node built on the others last
        "project files /params"]
    assert layers[0].files == (LayerFile(install / "COLCON_IGNORE", INSTALL / "COLCON_IGNORE"),
                               LayerFile(install / "setup.bash", INSTALL / "setup.bash"))
    assert layers[3].files == (LayerFile(install / "demo_app/share", INSTALL / "demo_app/share"),)
    assert layers[6].files == (LayerFile(install / "demo_app/lib", INSTALL / "demo_app/lib"),)


def test_a_large_workspace_stays_within_the_layer_budget(tmp_path: Path) -> None:
    names = [f"pkg{i:02d}" for i in range(60)]
    install = colcon_tree(tmp_path, {name: "" for name in names})
    tree = read_install_tree(install, INSTALL)
    layers = component_layers((LayerFile(install, INSTALL),), tree)
    assert len(layers) == MAX_LAYERS
    assert layers[1].name == "packages " + ", ".join(names[:60 - (MAX_LAYERS - 1) + 1])  # the lowest, together
    assert [layer.name for layer in layers[2:]] == [f"package {n}" for n in names[60 - MAX_LAYERS + 2:]]
    covered = [f.target.name for layer in layers[1:] for f in layer.files]
    assert sorted(covered) == names  # every package is in the image, once
    few = colcon_tree(tmp_path / "small", {n: "" for n in names[:20]})
    small = component_layers((LayerFile(few, INSTALL),), read_install_tree(few, INSTALL))
    assert len(small) == 1 + 2 * 20  # split: within the budget


def test_a_merged_install_tree_stays_one_layer(tmp_path: Path) -> None:
    install = tmp_path / "install"
    (install / "share/colcon-core/packages").mkdir(parents=True)
    (install / "share/colcon-core/packages/demo_app").write_text("")
    tree = read_install_tree(install, INSTALL)
    assert not tree.packages  # no package folder at the top
    assert component_layers((LayerFile(install, INSTALL),), tree) == (
        Layer("install tree /robocore/install", (LayerFile(install, INSTALL),)),)


def members(data: bytes) -> list[tuple[str, int, int, int, int, str]]:
    with tarfile.open(fileobj=io.BytesIO(data)) as tar:
        return [(m.name, m.type[0], m.mode, m.mtime, m.uid + m.gid, m.uname + m.gname) for m in tar.getmembers()]


def test_a_layer_tar_is_the_same_bytes_for_the_same_files_and_holds_its_folders(tmp_path: Path) -> None:
    one = colcon_tree(tmp_path / "one", {"demo_app": ""})
    two = colcon_tree(tmp_path / "two", {"demo_app": ""})
    (two / "demo_app" / "lib" / "__pycache__").mkdir()
    (two / "demo_app" / "lib" / "__pycache__" / "node.cpython-311.pyc").write_bytes(b"cache")
    os.utime(two / "demo_app" / "lib" / "node.py", (1e9, 1e9))
    os.chmod(two / "demo_app" / "lib", 0o700)
    (one / "demo_app" / "lib" / "run").symlink_to("node.py")
    (two / "demo_app" / "lib" / "run").symlink_to("node.py")

    def tar(install: Path) -> bytes:
        return layer_tar(Layer("package demo_app", (LayerFile(install / "demo_app", INSTALL / "demo_app"),))).data

    assert tar(one) == tar(two)  # other times, modes of folders and caches: the same layer
    names = [m[0] for m in members(tar(one))]
    assert names[:3] == ["robocore", "robocore/install", "robocore/install/demo_app"]  # folders first, parents too
    assert all(m[3] == 0 and m[4] == 0 and m[5] == "" for m in members(tar(one)))
    assert ("robocore/install/demo_app/lib/run", ord("2"), 0o777, 0, 0, "") in members(tar(one))
    (two / "demo_app" / "lib" / "node.py").write_text("print('changed')\n")
    assert tar(one) != tar(two)  # the control: a changed file is another layer
    other = layer_tar(Layer("x", (LayerFile(one / "demo_app", INSTALL / "demo_app"),)))
    assert other.diff_id == "sha256:" + __import__("hashlib").sha256(tar(one)).hexdigest()


PARENT = {"Architecture": "amd64", "Os": "linux", "Created": "2026-12-07T00:34:01.5Z",
          "Config": {"Env": ["A=1"], "Labels": {"base": "yes"}, "Entrypoint": ["/robocore/entrypoint.sh"]},
          "RootFS": {"Type": "layers", "Layers": ["sha256:" + "1" * 64, "sha256:" + "2" * 64]}}
HISTORY = [{"Created": 20, "CreatedBy": "COPY x", "Size": 10, "Comment": ""},
           {"Created": 10, "CreatedBy": "ENV A=1", "Size": 0, "Comment": ""},
           {"Created": 5, "CreatedBy": "ADD root", "Size": 99, "Comment": "debootstrap"}]


def test_the_image_configuration_is_the_parents_with_the_layers_and_labels_on_top() -> None:
    config = layered_config(PARENT, HISTORY, ["sha256:" + "3" * 64], ["package demo_app"], {"dev.robocore.c": "t"})
    assert config["rootfs"] == {"type": "layers", "diff_ids": ["sha256:" + "1" * 64, "sha256:" + "2" * 64,
                                                              "sha256:" + "3" * 64]}
    assert config["config"] == {"Env": ["A=1"], "Labels": {"base": "yes", "dev.robocore.c": "t"},
                                "Entrypoint": ["/robocore/entrypoint.sh"]}
    assert config["created"] == PARENT["Created"]  # the parent's time, never this run's: reproducible
    history = config["history"]
    assert isinstance(history, list)
    assert [h.get("created_by") for h in history] == [None, None, None, "robocore release --fleet: package demo_app"]
    assert [h["created"] for h in history][:3] == ["1970-01-01T00:00:05Z", "1970-01-01T00:00:10Z",
                                                   "1970-01-01T00:00:20Z"]
    assert sum(not h.get("empty_layer") for h in history) == 3  # one entry per layer, as the daemon checks
    again = layered_config(PARENT, HISTORY, ["sha256:" + "3" * 64], ["package demo_app"], {"dev.robocore.c": "t"})
    assert json.dumps(again, sort_keys=True) == json.dumps(config, sort_keys=True)


def image(config: str, *layers: tuple[str, int]) -> ImageLayers:
    return ImageLayers(config=(config, 1000), layers=tuple(layers))


BASE = [("b1", 100_000_000), ("b2", 30_000_000), ("comp", 130_000)]


def test_a_robot_pulls_the_layers_it_lacks_from_the_first_whose_chain_it_lacks() -> None:
    v1 = image("c1", *BASE, ("colcon", 5_800), ("demo_msgs", 20_000), ("demo_app", 4_300))
    v2 = image("c2", *BASE, ("colcon", 5_800), ("demo_msgs", 20_000), ("demo_app2", 4_316))
    assert pull_bytes([v2], [v1]) == 1000 + 4_316  # the configuration and the changed package only
    assert pull_bytes([v1], [v1]) == 0  # the same image: nothing
    # a package below others changed: Docker Engine pulls every layer above it again (it keeps layers by chain)
    v3 = image("c3", *BASE, ("colcon", 5_800), ("demo_msgs2", 21_000), ("demo_app", 4_300))
    assert pull_bytes([v3], [v1]) == 1000 + 21_000 + 4_300
    # a new apt package: the component's own layer changed, so everything above it comes again
    v4 = image("c4", *BASE[:2], ("comp2", 900_000), ("colcon", 5_800), ("demo_msgs", 20_000), ("demo_app", 4_300))
    assert pull_bytes([v4], [v1]) == 1000 + 900_000 + 5_800 + 20_000 + 4_300
    assert v4.size == 1000 + 130_000_000 + 930_100


def test_layers_two_new_images_share_are_counted_once_and_an_unknown_robot_pulls_the_whole() -> None:
    talker = image("t", *BASE, ("colcon", 5_800), ("talk", 4_000))
    listener = image("l", *BASE, ("colcon", 5_800), ("listen", 3_000))
    base = image("b", *BASE[:2])
    assert pull_bytes([talker, listener], [base]) == 2000 + 130_000 + 5_800 + 4_000 + 3_000
    fresh = robot_bytes("r9", [talker, listener], None)
    assert (fresh.pull, fresh.whole, fresh.known) == (fresh.whole, 2000 + 130_000_000 + 130_000 + 5_800 + 7_000,
                                                      False)
    assert robot_bytes("r1", [talker], [talker]).pull == 0
    assert human(6_316) == "6.3 kB" and human(999) == "999 B" and human(130_138_000) == "130.1 MB"


def test_a_registry_manifest_is_read_and_a_manifest_list_refused() -> None:
    data = {"schemaVersion": 2, "config": {"digest": "sha256:c", "size": 2517},
            "layers": [{"digest": "sha256:a", "size": 10}, {"digest": "sha256:b", "size": 20}]}
    assert parse_manifest(data) == ImageLayers(("sha256:c", 2517), (("sha256:a", 10), ("sha256:b", 20)))
    for bad in ({"manifests": []}, {"config": {"digest": "x"}, "layers": []}):
        try:
            parse_manifest(bad)
        except ValueError:
            continue
        raise AssertionError(f"{bad} was read as an image manifest")


def test_the_rollout_says_per_group_of_robots_what_each_pulls_reading_each_manifest_once() -> None:
    from robocore.commands.fleet_bytes import lines, robots_bytes

    v1 = image("c1", *BASE, ("colcon", 5_800), ("app", 4_300))
    v2 = image("c2", *BASE, ("colcon", 5_800), ("app2", 4_316))
    read: list[str] = []

    def manifest(ref: str) -> ImageLayers:
        read.append(ref)
        return {"reg/t@v1": v1, "reg/t@v2": v2}[ref]

    found = robots_bytes({"r1": ["reg/t@v2"], "r2": ["reg/t@v2"], "r3": ["reg/t@v2"], "r4": ["reg/t@v2"]},
                         {"r1": ["reg/t@v1"], "r2": ["reg/t@v1"], "r3": ["reg/t@v2"]}, manifest)
    assert [(f.robot, f.pull, f.known) for f in found] == [("r1", 5_316, True), ("r2", 5_316, True),
                                                           ("r3", 0, True), ("r4", v2.size, False)]
    assert sorted(read) == ["reg/t@v1", "reg/t@v2"]  # once per image, not per robot
    assert lines(found) == ["  r1, r2: 5.3 kB of 130.1 MB", "  r3: 0 B of 130.1 MB",
                            "  r4: at most 130.1 MB (runs nothing of it yet)"]
