"""Where init takes the template from, and ``copier update`` on the projects it makes.

robocore's repository is a copier template (root copier.yml -> template/). These tests make
throw-away git repositories of robocore's files with version tags and check that projects made
from them, by ``robocore init`` or by plain ``copier copy``, record the repository and the tag,
install that same robocore version in CI, and take a later version with ``copier update`` while
keeping the user's own edits.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
import yaml
from template_repo import GIT_ENV, TEMPLATE, commit_all, git, hide_origin, robocore_repository, set_git_identity

import robocore
from robocore.adapters import copier_adapter, origin
from robocore.commands import init
from robocore.config.loader import load_robot
from robocore.errors import UsageError

TAG = f"v{robocore.__version__}"


@pytest.fixture(scope="module")
def pristine(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """robocore's files as a git repository tagged with the running version (never changed by tests)."""
    return robocore_repository(tmp_path_factory.mktemp("pristine") / "robocore", TAG)


@pytest.fixture
def repo(pristine: Path, tmp_path: Path) -> Path:
    """A clone of :func:`pristine` that a test may change."""
    git(tmp_path, "clone", "-q", str(pristine), "robocore")
    return tmp_path / "robocore"


@pytest.fixture(autouse=True)
def _isolated(monkeypatch: pytest.MonkeyPatch) -> None:
    hide_origin(monkeypatch)
    set_git_identity(monkeypatch)


def answers(project: Path) -> dict[str, Any]:
    doc = yaml.safe_load((project / ".copier-answers.yml").read_text())
    assert isinstance(doc, dict)
    return doc


def ci_requirement(project: Path) -> str:
    workflow = yaml.safe_load((project / ".github" / "workflows" / "robot.yml").read_text())
    requirement = workflow["env"]["ROBOCORE"]
    assert f"ROBOCORE = {json.dumps(requirement)}" in (project / "noxfile.py").read_text()
    assert isinstance(requirement, str)
    return requirement


def run(argv: list[str], cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(argv, cwd=cwd, capture_output=True, text=True, timeout=180,
                          env={**os.environ, **GIT_ENV, "PYTHONPATH": str(TEMPLATE.parent)})


# ---------------------------------------------------------------- what pip recorded


@pytest.mark.parametrize(("record", "expected"), [
    ({"url": "https://example.org/org/robocore.git",
      "vcs_info": {"vcs": "git", "requested_revision": "v0.1.0", "commit_id": "0123abcd"}},
     origin.Installation(vcs_url="https://example.org/org/robocore.git", commit="0123abcd")),
    ({"url": "file:///home/me/my%20robocore", "dir_info": {"editable": True}},
     origin.Installation(folder=Path("/home/me/my robocore"))),
    ({"url": "file:///home/me/robocore", "dir_info": {}}, origin.Installation(folder=Path("/home/me/robocore"))),
    ({"url": "https://example.org/robocore-0.1.0-py3-none-any.whl", "archive_info": {"hashes": {}}},
     origin.Installation()),
    ({"url": "https://example.org/r", "vcs_info": {"vcs": "hg", "commit_id": "1"}}, origin.Installation()),
    ({"no": "url"}, origin.Installation()),
])
def test_direct_url_records(record: dict[str, Any], expected: origin.Installation) -> None:
    assert origin.parse_direct_url(json.dumps(record)) == expected


@pytest.mark.parametrize("text", [None, "", "not json", "[1, 2]"])
def test_direct_url_garbage_says_nothing(text: str | None) -> None:
    assert origin.parse_direct_url(text) == origin.Installation()


def test_installation_reads_the_distributions_direct_url(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.undo()  # the real origin.installation, not the hidden one
    info = tmp_path / "fake_robot_dist-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: fake-robot-dist\nVersion: 1.0\n")
    (info / "direct_url.json").write_text(json.dumps(
        {"url": "https://example.org/fake.git", "vcs_info": {"vcs": "git", "commit_id": "feed"}}))
    monkeypatch.syspath_prepend(str(tmp_path))
    assert origin.installation("fake-robot-dist") == origin.Installation(vcs_url="https://example.org/fake.git",
                                                                          commit="feed")
    assert origin.installation("no-such-distribution-here") == origin.Installation()


@pytest.mark.parametrize(("location", "url"), [
    ("https://example.org/org/robocore.git", "https://example.org/org/robocore.git"),
    ("git+https://example.org/org/robocore.git", "https://example.org/org/robocore.git"),
    ("gh:org/robocore", "https://github.com/org/robocore"),
    ("gl:org/robocore", "https://gitlab.com/org/robocore"),
    ("git@example.org:org/robocore.git", "ssh://git@example.org/org/robocore.git"),
    ("ssh://git@example.org/org/robocore.git", "ssh://git@example.org/org/robocore.git"),
    ("/srv/git/my robocore", "file:///srv/git/my%20robocore"),
    ("relative/path", None),
    ("https://example.org/robocore.git?ref=x y", None),  # nothing CI files could not hold
    ("https://example.org/$(id)", None),
])
def test_pip_url(location: str, url: str | None) -> None:
    assert origin.pip_url(location) == url


def test_source_checkout_is_this_repository_when_robocore_runs_from_it(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.undo()
    package_root = Path(robocore.__file__).resolve().parent.parent
    expected = package_root if (package_root / "copier.yml").is_file() else None
    assert origin.source_checkout() == expected


# ---------------------------------------------------------------- the choice


def test_a_git_url_source(monkeypatch: pytest.MonkeyPatch) -> None:
    choice = init.choose_template("https://example.org/org/robocore.git", "v0.3.0")
    assert (choice.location, choice.ref, choice.versioned) == ("git+https://example.org/org/robocore.git", "v0.3.0",
                                                               True)
    assert choice.data == {"robocore_repository": "https://example.org/org/robocore.git"}
    shortcut = init.choose_template("gh:org/robocore", None)
    assert (shortcut.location, shortcut.ref) == ("gh:org/robocore", None)
    assert shortcut.data == {"robocore_repository": "https://github.com/org/robocore"}


def test_the_environment_variable_is_a_source_too(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(copier_adapter.TEMPLATE_ENV, "https://example.org/r.git")
    assert init.choose_template(None, None).location == "git+https://example.org/r.git"
    assert init.choose_template("https://example.org/flag.git", None).location == "git+https://example.org/flag.git"


def test_a_local_repository_source_is_installed_in_ci_from_its_origin(repo: Path) -> None:
    choice = init.choose_template(str(repo), TAG)
    assert (choice.location, choice.ref, choice.versioned) == (str(repo), TAG, True)
    assert choice.data == {"robocore_repository": repo.as_uri()}  # its origin is a local path, of no use to CI
    git(repo, "remote", "set-url", "origin", "git@example.org:org/robocore.git")
    assert init.choose_template(str(repo), TAG).data == {
        "robocore_repository": "ssh://git@example.org/org/robocore.git"}
    git(repo, "remote", "remove", "origin")
    assert init.choose_template(str(repo), TAG).data == {"robocore_repository": repo.as_uri()}


def test_a_plain_folder_source_records_no_version(tmp_path: Path) -> None:
    choice = init.choose_template(str(TEMPLATE), None)
    assert (choice.location, choice.ref, choice.versioned, choice.data) == (str(TEMPLATE), None, False, {})
    assert "copier update will not work" in choice.note
    with pytest.raises(UsageError, match="not a git repository"):
        init.choose_template(str(TEMPLATE), "v0.1.0")


@pytest.mark.parametrize(("source", "ref", "message"), [
    (None, "-x", "--ref '-x': not a git tag"),
    (None, "v1 && id", "not a git tag"),
    ("--upload-pack=x", None, "not a path or git URL"),
    ("/no/such/folder/anywhere", None, "no such folder"),
    (None, "v9.9.9", "no git repository of robocore with it"),
])
def test_bad_sources_and_refs_are_usage_errors(source: str | None, ref: str | None, message: str) -> None:
    with pytest.raises(UsageError, match=message):
        init.choose_template(source, ref)


def test_robocores_own_checkout_at_its_version_tag(repo: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(origin, "source_checkout", lambda: repo)
    choice = init.choose_template(None, None)
    assert (choice.location, choice.ref, choice.versioned) == (str(repo), TAG, True)


def test_a_checkout_without_the_tag_falls_back_to_the_bundled_template(repo: Path,
                                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    git(repo, "tag", "-d", TAG)
    monkeypatch.setattr(origin, "source_checkout", lambda: repo)
    choice = init.choose_template(None, None)
    assert (choice.location, choice.ref, choice.versioned) == (str(copier_adapter.bundled_template()), None, False)
    assert choice.data == {"robocore_repository": "", "robocore_ref": TAG}
    assert f"_commit: {TAG}" in choice.note and "bundled template" in choice.note


def test_a_tag_without_the_template_is_not_used(repo: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """An old tag from before robocore's repository was a template would render the whole repository."""
    git(repo, "tag", "-d", TAG)
    git(repo, "rm", "-q", "copier.yml")
    commit_all(repo, "no root copier.yml", TAG)
    monkeypatch.setattr(origin, "source_checkout", lambda: repo)
    assert not init.choose_template(None, None).versioned


def test_the_git_url_pip_installed_from(repo: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    installed = origin.Installation(vcs_url=repo.as_uri(), commit="c0ffee")
    monkeypatch.setattr(origin, "installation", lambda distribution="robocore": installed)
    choice = init.choose_template(None, None)
    assert (choice.location, choice.ref, choice.versioned) == (f"git+{repo.as_uri()}", TAG, True)
    assert choice.data == {"robocore_repository": repo.as_uri()}


def test_an_unreachable_git_url_still_tells_ci_where_robocore_comes_from(tmp_path: Path,
                                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    gone = (tmp_path / "gone").as_uri()
    installed = origin.Installation(vcs_url=gone, commit="c0ffee")
    monkeypatch.setattr(origin, "installation", lambda distribution="robocore": installed)
    choice = init.choose_template(None, None)
    assert not choice.versioned
    assert choice.data == {"robocore_repository": gone, "robocore_ref": "c0ffee"}


def test_the_folder_pip_installed_from(repo: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(origin, "installation", lambda distribution="robocore": origin.Installation(folder=repo))
    assert init.choose_template(None, None).location == str(repo)


# ---------------------------------------------------------------- rendering from the repository


def test_copier_copy_of_the_repository_renders_the_same_files_as_the_template_folder(pristine: Path,
                                                                                      tmp_path: Path) -> None:
    copier = [sys.executable, "-m", "copier", "copy", "--defaults", "--quiet"]
    from_repo = run([*copier, "--vcs-ref", TAG, str(pristine), str(tmp_path / "a")], tmp_path)
    assert from_repo.returncode == 0, from_repo.stderr
    from_folder = run([*copier, str(pristine / "template"), str(tmp_path / "b")], tmp_path)
    assert from_folder.returncode == 0, from_folder.stderr

    def files(root: Path) -> set[str]:
        return {str(p.relative_to(root)) for p in root.rglob("*") if p.is_file()}

    assert files(tmp_path / "a") == files(tmp_path / "b")
    assert not {"copier.yml", "pyproject.toml", "setup.py"} & files(tmp_path / "a")
    assert (answers(tmp_path / "a")["_src_path"], answers(tmp_path / "a")["_commit"]) == (str(pristine), TAG)
    assert ci_requirement(tmp_path / "a") == f"robocore[testing] @ git+{pristine.as_uri()}@{TAG}"
    assert "_commit" not in answers(tmp_path / "b") and ci_requirement(tmp_path / "b") == ""


def test_an_untagged_commit_is_installed_by_its_hash(repo: Path, tmp_path: Path) -> None:
    (repo / "template" / "NOTES.md").write_text("after the tag\n")
    commit_all(repo, "one more commit")
    head = git(repo, "rev-parse", "HEAD").strip()
    done = run([sys.executable, "-m", "copier", "copy", "--defaults", "--quiet", "--vcs-ref", "HEAD", str(repo),
                str(tmp_path / "p")], tmp_path)
    assert done.returncode == 0, done.stderr
    assert answers(tmp_path / "p")["_commit"].startswith(f"{TAG}-1-g")
    assert ci_requirement(tmp_path / "p").endswith(f"@{head}")


def test_init_with_source_and_ref_on_the_command_line(repo: Path, tmp_path: Path) -> None:
    done = run([sys.executable, "-m", "robocore", "init", str(tmp_path / "bot"), "--defaults", "--source", str(repo),
                "--ref", TAG], tmp_path)
    assert done.returncode == 0, done.stderr
    assert f"template: {repo} at {TAG}; copier update brings later versions" in done.stderr
    assert (answers(tmp_path / "bot")["_src_path"], answers(tmp_path / "bot")["_commit"]) == (str(repo), TAG)
    assert answers(tmp_path / "bot")["robocore_repository"] == repo.as_uri()
    assert ci_requirement(tmp_path / "bot") == f"robocore[testing] @ git+{repo.as_uri()}@{TAG}"
    assert load_robot(tmp_path / "bot").components


def test_init_from_the_bundled_template_says_what_update_needs(tmp_path: Path) -> None:
    init.run(tmp_path / "b", defaults=True, distro=None, base=None, dry_run=False)
    recorded = answers(tmp_path / "b")
    assert "_commit" not in recorded and recorded["_src_path"] == str(copier_adapter.bundled_template())
    assert ci_requirement(tmp_path / "b") == ""
    with pytest.raises(copier_adapter.TemplateError):
        copier_adapter.update(tmp_path / "b")


# ---------------------------------------------------------------- copier update


def make_with_init(repo: Path, project: Path) -> None:
    init.run(project, defaults=True, distro=None, base="wheels", dry_run=False, source=str(repo), ref=TAG)


def make_with_copier(repo: Path, project: Path) -> None:
    done = run([sys.executable, "-m", "copier", "copy", "--defaults", "--quiet", "--vcs-ref", TAG,
                "--data", "base_kind=wheels", str(repo), str(project)], project.parent)
    assert done.returncode == 0, done.stderr


@pytest.mark.parametrize("make", [make_with_init, make_with_copier], ids=["robocore-init", "copier-copy"])
def test_copier_update_brings_a_new_version_and_keeps_the_users_edits(repo: Path, tmp_path: Path, make: Any) -> None:
    project = tmp_path / "bot"
    make(repo, project)
    assert answers(project)["_commit"] == TAG
    assert ci_requirement(project).endswith(f"@{TAG}")
    git(project, "init", "-q", "-b", "main")
    commit_all(project, "generated")
    robot_yaml = project / "robot.yaml"
    robot_yaml.write_text(robot_yaml.read_text().replace("ros_domain_id: 0", "ros_domain_id: 42"))
    with (project / "README.md").open("a") as readme:
        readme.write("\nOur robot's own notes.\n")
    commit_all(project, "my changes")

    with (repo / "template" / ".gitignore").open("a") as handle:
        handle.write("*.bag\n")
    (repo / "template" / "robot.yaml.jinja").write_text(
        (repo / "template" / "robot.yaml.jinja").read_text() + "# template v0.2.0\n")
    commit_all(repo, "template v0.2.0", "v0.2.0")

    copier_adapter.update(project, vcs_ref="v0.2.0")

    recorded = answers(project)
    assert (recorded["_commit"], recorded["base_kind"]) == ("v0.2.0", "wheels")
    text = robot_yaml.read_text()
    assert "# template v0.2.0" in text and "ros_domain_id: 42" in text and "<<<<<<<" not in text
    assert "*.bag" in (project / ".gitignore").read_text().splitlines()
    assert "Our robot's own notes." in (project / "README.md").read_text()
    assert ci_requirement(project).endswith("@v0.2.0")
    robot = load_robot(project)
    assert (robot.ros_domain_id, robot.base.kind.value) == (42, "wheels")



@pytest.mark.parametrize("source", ["file:///nonexistent/robocore.git", "git+file:///nonexistent/robocore.git"])
def test_a_git_source_that_git_cannot_read_is_one_line_and_writes_nothing(tmp_path: Path, source: str) -> None:
    done = run([sys.executable, "-m", "robocore", "init", "r", "--defaults", "--base", "wheels", "--source", source],
               cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr
    problems = [line for line in done.stderr.splitlines() if line.startswith("error:")]
    assert problems == [line for line in done.stderr.splitlines() if "git ls-remote failed: fatal:" in line]
    assert len(problems) == 1
    assert not (tmp_path / "r").exists()
