"""What a generated project brings to test itself: nox sessions, graph tests, CI files, and its README."""

from __future__ import annotations

import ast
import os
import re
import shutil
import stat
import subprocess
import sys
import types
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import yaml
from template_repo import TEMPLATE

from robocore.adapters import copier_adapter

REPOSITORY = "https://example.org/robots/robocore.git"
REQUIREMENT = f"robocore[testing] @ git+{REPOSITORY}@v0.1.0"
SESSIONS = ["validate", "build", "unit", "graph"]
BIN = Path(sys.executable).parent


def tool(name: str) -> str:
    found = shutil.which(name, path=str(BIN)) or shutil.which(name)
    assert found, f"{name} must be installed with robocore's test tools"
    return found


def render(dest: Path, **data: Any) -> Path:
    copier_adapter.copy(copier_adapter.CopyRequest(template=str(TEMPLATE), destination=dest, data=data,
                                                   defaults=True))
    return dest


@pytest.fixture(scope="module")
def rendered(tmp_path_factory: pytest.TempPathFactory) -> Callable[..., Path]:
    """``rendered(ci=..., known=True)``: a project from template/, robocore's repository and tag known or not."""
    cache: dict[tuple[str, bool], Path] = {}

    def get(ci: str = "both", known: bool = True) -> Path:
        if (ci, known) not in cache:
            data: dict[str, Any] = {"ci": ci}
            if known:
                data |= {"robocore_repository": REPOSITORY, "robocore_ref": "v0.1.0"}
            cache[ci, known] = render(tmp_path_factory.mktemp("ci") / f"{ci}-{known}", **data)
        return cache[ci, known]

    return get


def project_env() -> dict[str, str]:
    """This interpreter's tools first on PATH, and this checkout's robocore importable."""
    repo = str(TEMPLATE.parent)
    path = os.pathsep.join([str(BIN), os.environ.get("PATH", "")])
    pythonpath = os.pathsep.join(p for p in [repo, os.environ.get("PYTHONPATH", "")] if p)
    return {**os.environ, "PATH": path, "PYTHONPATH": pythonpath}


# ---------------------------------------------------------------- noxfile.py


def test_nox_lists_the_four_sessions_and_selects_them_all(rendered: Callable[..., Path]) -> None:
    project = rendered()
    done = subprocess.run([tool("nox"), "--no-venv", "-l", "-f", str(project / "noxfile.py")], capture_output=True,
                          text=True, timeout=60, cwd=project)
    assert done.returncode == 0, done.stderr
    listed = [re.match(r"([*-]) (\w+)", line) for line in done.stdout.splitlines() if " -> " in line]
    assert [m.group(2) for m in listed if m] == SESSIONS, done.stdout
    assert all(m and m.group(1) == "*" for m in listed), "every session runs by default"


def test_nox_validate_session_runs_robocore_in_the_project(rendered: Callable[..., Path]) -> None:
    project = rendered()
    done = subprocess.run([tool("nox"), "--no-venv", "-s", "validate"], capture_output=True, text=True,
                          timeout=120, cwd=project, env=project_env())
    assert done.returncode == 0, done.stdout + done.stderr
    assert f"{project / 'robot.yaml'}: ok" in done.stdout + done.stderr
    bad = project.parent / "broken"
    shutil.copytree(project, bad)
    (bad / "robot.yaml").write_text((bad / "robot.yaml").read_text().replace("runs_on: devmachine", "runs_on: nohost"))
    failed = subprocess.run([tool("nox"), "--no-venv", "-s", "validate"], capture_output=True, text=True,
                            timeout=120, cwd=bad, env=project_env())
    assert failed.returncode != 0
    assert "unknown host 'nohost'" in failed.stdout + failed.stderr


class FakeSession:
    """What the noxfile's sessions call on a nox session, recorded."""

    def __init__(self, backend: str, posargs: list[str]) -> None:
        self.venv_backend = backend
        self.posargs = posargs
        self.calls: list[tuple[str, ...]] = []

    def install(self, *args: str) -> None:
        self.calls.append(("install", *args))

    def run(self, *args: str) -> None:
        self.calls.append(("run", *args))

    def error(self, *args: Any) -> None:
        raise RuntimeError(" ".join(map(str, args)))


def load_noxfile(project: Path, monkeypatch: pytest.MonkeyPatch) -> Any:
    """The noxfile's names, loaded with a stand-in nox module (nox's own registry stays untouched)."""
    stub = types.ModuleType("nox")
    stub.session = lambda func: func  # type: ignore[attr-defined]
    stub.Session = FakeSession  # type: ignore[attr-defined]
    stub.options = types.SimpleNamespace()  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "nox", stub)
    namespace: dict[str, Any] = {"__name__": "noxfile"}
    exec(compile((project / "noxfile.py").read_text(), str(project / "noxfile.py"), "exec"), namespace)
    assert stub.options.sessions == SESSIONS  # type: ignore[attr-defined]
    return namespace


@pytest.mark.parametrize(("session", "command"), [
    ("validate", ["robocore", "validate"]),
    ("build", ["robocore", "prepare-base", "stage", "build"]),
    ("unit", ["robocore", "test"]),
    ("graph", ["pytest", "tests/graph"]),
])
def test_each_session_runs_its_command_with_the_posargs(rendered: Callable[..., Path], session: str,
                                                        command: list[str], monkeypatch: pytest.MonkeyPatch) -> None:
    noxfile = load_noxfile(rendered(), monkeypatch)
    assert noxfile["ROBOCORE"] == REQUIREMENT
    passthrough = FakeSession("none", ["-x", "--flag"])
    noxfile[session](passthrough)
    assert passthrough.calls == [("run", *command, "-x", "--flag")]
    venv = FakeSession("virtualenv", [])
    noxfile[session](venv)
    assert venv.calls == [("install", REQUIREMENT), ("run", *command)]


def test_a_virtualenv_session_without_a_known_robocore_says_what_to_set(rendered: Callable[..., Path],
                                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    noxfile = load_noxfile(rendered(known=False), monkeypatch)
    assert noxfile["ROBOCORE"] == ""
    with pytest.raises(RuntimeError, match=r"ROBOCORE in noxfile\.py is empty"):
        noxfile["graph"](FakeSession("virtualenv", []))
    passthrough = FakeSession("none", [])
    noxfile["graph"](passthrough)  # with --no-venv the installed robocore is used
    assert passthrough.calls == [("run", "pytest", "tests/graph")]


# ---------------------------------------------------------------- CI files


@pytest.mark.parametrize(("ci", "github", "gitlab"), [
    ("github", True, False), ("gitlab", False, True), ("both", True, True), ("none", False, False)])
def test_the_ci_question_chooses_the_files(rendered: Callable[..., Path], ci: str, github: bool,
                                           gitlab: bool) -> None:
    project = rendered(ci)
    assert (project / ".github" / "workflows" / "robot.yml").is_file() == github
    assert (project / ".github").exists() == github
    assert (project / ".gitlab-ci.yml").is_file() == gitlab
    assert yaml.safe_load((project / ".copier-answers.yml").read_text())["ci"] == ci
    readme = (project / "README.md").read_text()
    assert ("GitHub Actions" in readme) == github and ("GitLab CI" in readme) == gitlab
    assert (project / "noxfile.py").is_file()


def test_an_unknown_ci_answer_is_refused(tmp_path: Path) -> None:
    with pytest.raises(copier_adapter.TemplateError, match="ci"):
        render(tmp_path / "x", ci="jenkins")
    assert not (tmp_path / "x").exists()


def check_jsonschema(schema: str, path: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([tool("check-jsonschema"), "--builtin-schema", schema, str(path)], capture_output=True,
                          text=True, timeout=120)


@pytest.mark.parametrize("known", [True, False])
def test_github_workflow_validates_against_the_workflow_schema(rendered: Callable[..., Path], known: bool,
                                                               tmp_path: Path) -> None:
    workflow = rendered("github", known) / ".github" / "workflows" / "robot.yml"
    done = check_jsonschema("vendor.github-workflows", workflow)
    assert done.returncode == 0, done.stdout + done.stderr
    broken = yaml.safe_load(workflow.read_text())
    del broken["jobs"]["robot"]["runs-on"]  # negative control: the schema does look at the jobs
    (tmp_path / "broken.yml").write_text(yaml.safe_dump(broken))
    assert check_jsonschema("vendor.github-workflows", tmp_path / "broken.yml").returncode != 0


@pytest.mark.parametrize("known", [True, False])
def test_gitlab_ci_validates_against_the_gitlab_schema(rendered: Callable[..., Path], known: bool,
                                                       tmp_path: Path) -> None:
    ci_file = rendered("gitlab", known) / ".gitlab-ci.yml"
    done = check_jsonschema("vendor.gitlab-ci", ci_file)
    assert done.returncode == 0, done.stdout + done.stderr
    broken = yaml.safe_load(ci_file.read_text())
    broken["robot"]["script"] = {"not": "a list"}  # negative control
    (tmp_path / "broken.yml").write_text(yaml.safe_dump(broken))
    assert check_jsonschema("vendor.gitlab-ci", tmp_path / "broken.yml").returncode != 0


def nox_commands(lines: list[str]) -> list[str]:
    return [line.removeprefix("nox --no-venv -s ") for line in lines if line.startswith("nox ")]


def test_github_workflow_runs_the_sessions_after_installing_robocore(rendered: Callable[..., Path]) -> None:
    workflow = yaml.safe_load((rendered("github") / ".github" / "workflows" / "robot.yml").read_text())
    assert workflow["env"]["ROBOCORE"] == REQUIREMENT
    job = workflow["jobs"]["robot"]
    assert job["runs-on"] == "ubuntu-latest"
    steps = job["steps"]
    uses = [step["uses"].split("@")[0] for step in steps if "uses" in step]
    assert uses == ["actions/checkout", "actions/setup-python"]
    python = next(step for step in steps if step.get("uses", "").startswith("actions/setup-python"))
    assert python["with"]["python-version"] in {"3.11", "3.12"}
    runs = [step["run"] for step in steps if "run" in step]
    assert "apt-get install" in runs[0] and "mmdebstrap" in runs[0]
    assert 'python -m pip install "$ROBOCORE" nox' in runs[1]
    assert nox_commands([line for run in runs for line in run.splitlines()]) == SESSIONS


def test_gitlab_job_runs_the_sessions_on_a_shell_runner(rendered: Callable[..., Path]) -> None:
    ci = yaml.safe_load((rendered("gitlab") / ".gitlab-ci.yml").read_text())
    assert ci["variables"]["ROBOCORE"] == REQUIREMENT
    job = ci["robot"]
    assert job["tags"] == ["robocore-docker"] and "image" not in job and "services" not in job
    assert 'python -m pip install "$ROBOCORE" nox' in job["script"]
    assert nox_commands(job["script"]) == SESSIONS


def fake_python(folder: Path) -> Path:
    """A ``python`` on PATH that records its arguments instead of installing anything."""
    folder.mkdir()
    script = folder / "python"
    script.write_text('#!/bin/sh\nprintf "%s\\n" "$@" > "$RECORD"\n')
    script.chmod(script.stat().st_mode | stat.S_IXUSR)
    return folder


@pytest.mark.parametrize("ci", ["github", "gitlab"])
def test_ci_install_step_passes_robocore_as_one_argument_or_stops_when_unknown(
        rendered: Callable[..., Path], tmp_path: Path, ci: str) -> None:
    def install_script(project: Path) -> tuple[str, str]:
        if ci == "github":
            doc = yaml.safe_load((project / ".github" / "workflows" / "robot.yml").read_text())
            step = next(s for s in doc["jobs"]["robot"]["steps"] if s.get("name") == "Install robocore")
            return doc["env"]["ROBOCORE"], step["run"]
        doc = yaml.safe_load((project / ".gitlab-ci.yml").read_text())
        script = doc["robot"]["script"]
        lines = [line for line in script if "ROBOCORE" in line]
        return doc["variables"]["ROBOCORE"], "\n".join(lines)

    record = tmp_path / "argv"
    env = {**os.environ, "PATH": f"{fake_python(tmp_path / 'bin')}{os.pathsep}{os.environ['PATH']}",
           "RECORD": str(record)}
    value, script = install_script(rendered(ci, True))
    ok = subprocess.run(["bash", "-e", "-c", script], env={**env, "ROBOCORE": value}, capture_output=True,
                        text=True, timeout=30)
    assert ok.returncode == 0, ok.stderr
    assert record.read_text().splitlines() == ["-m", "pip", "install", REQUIREMENT, "nox"]

    record.unlink()
    value, script = install_script(rendered(ci, False))
    assert value == ""
    stopped = subprocess.run(["bash", "-e", "-c", script], env={**env, "ROBOCORE": value}, capture_output=True,
                             text=True, timeout=30)
    assert stopped.returncode == 1
    assert "ROBOCORE" in stopped.stdout + stopped.stderr and "is empty" in stopped.stdout + stopped.stderr
    assert not record.exists()


@pytest.mark.parametrize(("key", "value"), [
    ("robocore_repository", "https://example.org/r.git; rm -rf ~"),
    ("robocore_repository", "https://example.org/$(id)"),
    ("robocore_repository", "--upload-pack=evil"),
    ("robocore_ref", "-x"),
    ("robocore_ref", "v1 && id"),
])
def test_repository_and_ref_answers_are_checked(tmp_path: Path, key: str, value: str) -> None:
    with pytest.raises(copier_adapter.TemplateError, match=key):
        render(tmp_path / "bad", **{key: value})
    assert not (tmp_path / "bad").exists()


# ---------------------------------------------------------------- README


def test_readme_says_how_to_run_the_tests_locally_and_in_ci(rendered: Callable[..., Path]) -> None:
    readme = (rendered("both") / "README.md").read_text()
    for text in ["nox --no-venv -s validate build unit graph", "nox -s graph", "tests/graph",
                 f'pip install "{REQUIREMENT}" nox', ".github/workflows/robot.yml", ".gitlab-ci.yml",
                 "--executor shell --tag-list robocore-docker", "copier update --defaults --vcs-ref"]:
        assert text in readme, text
    assert "{{" not in readme and "{%" not in readme
    unknown = (rendered("none", False) / "README.md").read_text()
    assert "No CI file was generated" in unknown and "GitHub Actions" not in unknown


def test_pytest_configuration_points_at_the_tests(rendered: Callable[..., Path]) -> None:
    import configparser

    config = configparser.ConfigParser()
    config.read(rendered() / "pytest.ini")
    assert config["pytest"]["testpaths"].split() == ["tests"]


def test_noxfile_parses_and_has_docstrings(rendered: Callable[..., Path]) -> None:
    tree = ast.parse((rendered() / "noxfile.py").read_text())
    sessions = [f for f in tree.body if isinstance(f, ast.FunctionDef)
                and any(ast.unparse(d) == "nox.session" for d in f.decorator_list)]
    assert [f.name for f in sessions] == SESSIONS
    assert all(ast.get_docstring(f) for f in sessions)
