"""robocore as users install it: the sdist and the wheel carry the template, and init works from them.

Builds robocore (``python -m build``: the sdist, then the wheel from the sdist) from a copy of
its source files, and installs it with pip (``--no-deps --target``, so only robocore itself is
installed and its dependencies come from this environment) the two ways a user would: from the
wheel, and from a git repository at its version tag. pip's build backend comes from PyPI (or
pip's cache), like in any ``pip install``.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tarfile
import zipfile
from pathlib import Path

import pytest
import yaml
from template_repo import GIT_ENV, commit_all, copy_sources, git, robocore_repository, source_files

import robocore

TAG = f"v{robocore.__version__}"
BUNDLED = "robocore/resources/template/"


def template_files() -> set[str]:
    return {name.removeprefix("template/") for name in source_files() if name.startswith("template/")}


@pytest.fixture(scope="module")
def dist(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The folder with robocore's sdist and wheel, built from a copy of its source files."""
    root = tmp_path_factory.mktemp("dist")
    done = subprocess.run([sys.executable, "-m", "build", "--outdir", str(root / "out"),
                           str(copy_sources(root / "src"))], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    return root / "out"


def pip_target(requirement: str, target: Path) -> Path:
    done = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--target", str(target),
                           requirement], capture_output=True, text=True, timeout=300, env={**os.environ, **GIT_ENV})
    assert done.returncode == 0, done.stderr[-3000:]
    return target


def robocore_from(target: Path, *args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    """Run the robocore installed in ``target`` (and only that one: no source checkout on the path)."""
    env = {**os.environ, **GIT_ENV, "PYTHONPATH": str(target)}
    return subprocess.run([sys.executable, "-m", "robocore", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=300)


def answers(project: Path) -> dict[str, str]:
    doc = yaml.safe_load((project / ".copier-answers.yml").read_text())
    assert isinstance(doc, dict)
    return doc


def test_the_wheel_carries_the_template(dist: Path) -> None:
    [wheel] = dist.glob("*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    bundled = {name.removeprefix(BUNDLED) for name in names if name.startswith(BUNDLED)}
    assert template_files() and bundled == template_files()
    assert "copier.yml" in bundled
    assert "tests/graph/{% if ros_version == 2 %}test_talker_listener.py{% endif %}" in bundled
    assert not [name for name in names if "__pycache__" in name or name.endswith(".pyc")]
    assert not [name for name in names if name.startswith("template/")]  # no top-level package named template


def test_the_sdist_carries_the_template_and_the_root_copier_yml(dist: Path) -> None:
    [sdist] = dist.glob("*.tar.gz")
    with tarfile.open(sdist) as archive:
        names = {name.split("/", 1)[1] for name in archive.getnames() if "/" in name}
    assert {f"template/{name}" for name in template_files()} <= names
    assert {"copier.yml", "setup.py", "MANIFEST.in", "pyproject.toml"} <= names


def test_init_from_an_installed_wheel_renders_the_bundled_template(dist: Path, tmp_path: Path) -> None:
    [wheel] = dist.glob("*.whl")
    target = pip_target(str(wheel), tmp_path / "site")
    where = robocore_from(target, "--version", cwd=tmp_path)
    assert where.returncode == 0 and robocore.__version__ in where.stdout
    done = robocore_from(target, "init", str(tmp_path / "bot"), "--defaults", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert f"no git repository of robocore with tag {TAG} was found" in done.stderr
    assert f"{tmp_path / 'bot' / 'robot.yaml'}: ok" in done.stderr
    assert answers(tmp_path / "bot")["_src_path"] == str(target / BUNDLED.rstrip("/"))
    assert (tmp_path / "bot" / "noxfile.py").is_file() and (tmp_path / "bot" / ".github").is_dir()


def test_init_from_a_git_install_renders_that_repository_at_its_tag_and_updates(tmp_path: Path) -> None:
    repo = robocore_repository(tmp_path / "robocore", TAG)
    target = pip_target(f"robocore @ git+{repo.as_uri()}@{TAG}", tmp_path / "site")
    done = robocore_from(target, "init", str(tmp_path / "bot"), "--defaults", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    project = tmp_path / "bot"
    assert (answers(project)["_src_path"], answers(project)["_commit"]) == (f"git+{repo.as_uri()}", TAG)
    workflow = yaml.safe_load((project / ".github" / "workflows" / "robot.yml").read_text())
    assert workflow["env"]["ROBOCORE"] == f"robocore[testing] @ git+{repo.as_uri()}@{TAG}"

    git(project, "init", "-q", "-b", "main")
    commit_all(project, "generated")
    with (repo / "template" / "README.md.jinja").open("a") as readme:
        readme.write("\nA line of the next version.\n")
    commit_all(repo, "next version", "v9.0.0")
    update = subprocess.run([sys.executable, "-m", "copier", "update", "--defaults", "--vcs-ref", "v9.0.0"],
                            cwd=project, capture_output=True, text=True, timeout=300, env={**os.environ, **GIT_ENV})
    assert update.returncode == 0, update.stderr
    assert "A line of the next version." in (project / "README.md").read_text()
    workflow = yaml.safe_load((project / ".github" / "workflows" / "robot.yml").read_text())
    assert workflow["env"]["ROBOCORE"] == f"robocore[testing] @ git+{repo.as_uri()}@v9.0.0"
