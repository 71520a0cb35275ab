"""The README and docs/ as a newcomer meets them.

Every command of the README's shell blocks runs here, in a fresh folder with no Docker daemon reachable: the
tasks that need Docker or a robot run as the dry run each of them has (a dry run contacts no daemon and no
host). The README's robot.yaml example validates in the project its commands made; its Python block compiles;
its task table names exactly the tasks of the ``robocore`` command. Every relative link in README.md,
CONTRIBUTING.md, CHANGELOG.md and docs/*.md resolves to a file, and a link with an anchor to a heading of it; every
section the code cites by title (``docs/design-notes.md, "Discovery timing: 20 ms"``) is a heading of that page.
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
import stat
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"

#: Tasks that need a Docker daemon or a robot host: the README's lines with them run with ``--dry-run``.
NEEDS_DOCKER = frozenset({"prepare-base", "stage", "build", "test", "dev", "sync", "run", "down", "status", "logs",
                          "shell", "connect", "release", "rollback", "export", "fleet"})
#: The two set-up commands: they install Debian tools and run the Docker suites, so they are checked, not run.
SETUP_SCRIPTS = ("./scripts/demo", "./scripts/test")

FENCE = re.compile(r"^```([\w-]*)\n(.*?)^```$", re.M | re.S)
LINK = re.compile(r"\[([^\]]*)\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
HEADING = re.compile(r"^(#{1,6})\s+(.*?)\s*#*\s*$", re.M)


def code_blocks(text: str, language: str) -> list[str]:
    """The fenced code blocks of ``language`` in a Markdown text, in order."""
    return [body for lang, body in FENCE.findall(text) if lang == language]


def shell_line(line: str) -> str | None:
    """The shell line the doc test runs for one line of a README shell block, or None when it runs nothing.

    Comments go; ``source .venv/bin/activate`` is the test's own interpreter (put first on PATH); a robocore
    line with a task that needs Docker or a robot gets ``--dry-run``. Any other line is an error, so that a
    command added to the README is either run here or deliberately handled.
    """
    command = re.sub(r"(^|\s)#.*$", "", line).strip()
    if not command or command.startswith("source .venv/bin/activate"):
        return None
    if command in SETUP_SCRIPTS:
        return None
    words = command.split()
    if words[0] == "cd":
        return command
    if words[0] == "robocore":
        return f"{command} --dry-run" if NEEDS_DOCKER & set(words[1:]) else command
    raise ValueError(f"the doc test does not know how to run this README line: {line!r}")


def slug(heading: str) -> str:
    """The anchor GitHub gives a heading: links to their text, code marks dropped, lower case, punctuation
    removed, each space a hyphen."""
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading).replace("`", "").lower()
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(text: str) -> set[str]:
    """Every heading anchor of a Markdown text (repeated headings get -1, -2, ... as on GitHub)."""
    seen: dict[str, int] = {}
    found = set()
    for _, title in HEADING.findall(FENCE.sub("", text)):
        base = slug(title)
        count = seen.get(base, 0)
        seen[base] = count + 1
        found.add(base if count == 0 else f"{base}-{count}")
    return found


def broken_links(path: Path) -> list[str]:
    """One line per relative link of a Markdown file that does not resolve: a missing file, or an anchor
    that is no heading of its target. Links with a scheme (https:, mailto:) are not followed."""
    text = path.read_text(encoding="utf-8")
    prose = re.sub(r"`[^`\n]*`", "", FENCE.sub("", text))
    problems = []
    for _, target in LINK.findall(prose):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target):
            continue
        file_part, _, anchor = target.partition("#")
        resolved = (path.parent / file_part).resolve() if file_part else path
        if not resolved.exists():
            problems.append(f"{path.name}: {target}: no such file")
        elif anchor and resolved.suffix == ".md" and anchor not in anchors(resolved.read_text(encoding="utf-8")):
            problems.append(f"{path.name}: {target}: no heading with anchor #{anchor}")
    return problems


#: A page of docs/ cited by a section's title in code or comments: ``docs/x.md, "Title"`` (the title may be the
#: start of the heading's text).
CITATION = re.compile(r'docs/([\w-]+\.md)[,:]?\s+"([^"]+)"')


def headings(text: str) -> list[str]:
    """The text of every heading of a Markdown text, code marks dropped (fenced blocks are no headings)."""
    return [title.replace("`", "") for _, title in HEADING.findall(FENCE.sub("", text))]


def broken_citations(text: str, docs: Path) -> list[str]:
    """One line per page of docs/ named in ``text`` that does not exist, and per citation of a section by title
    that is no heading of its page.
    Comment markers at line starts are read through, so a citation may wrap across comment lines."""
    flat = re.sub(r"\n\s*(?:#:?|//)?\s*", " ", text)
    problems = [f"docs/{page}: no such page" for page in dict.fromkeys(re.findall(r"\bdocs/([\w-]+\.md)", flat))
                if not (docs / page).is_file()]
    for page, title in CITATION.findall(flat):
        target = docs / page
        if target.is_file() and not any(h.startswith(title) for h in headings(target.read_text(encoding="utf-8"))):
            problems.append(f'docs/{page}, "{title}": no such heading')
    return problems


def documents() -> list[Path]:
    """The Markdown files of the repository a reader follows links through."""
    top = [ROOT / name for name in ("README.md", "CONTRIBUTING.md", "CHANGELOG.md") if (ROOT / name).exists()]
    return top + sorted((ROOT / "docs").glob("*.md"))


# ---------------------------------------------------------------- the link checker itself


def test_the_link_checker_finds_a_missing_file_and_a_missing_anchor(tmp_path: Path) -> None:
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "b.md").write_text("# B\n\n## Real heading (`x.y`)\n\n```\n# not a heading\n```\n")
    page = tmp_path / "a.md"
    page.write_text(
        "# Local part\n"
        "[gone](docs/missing.md) [wrong anchor](docs/b.md#nope) [fenced](docs/b.md#not-a-heading)\n"
        "[good](docs/b.md#real-heading-xy) [file](docs/b.md) [here](#local-part) [web](https://example.com/x)\n"
        "`[in code](docs/also-missing.md)`\n"
    )
    assert broken_links(page) == [
        "a.md: docs/missing.md: no such file",
        "a.md: docs/b.md#nope: no heading with anchor #nope",
        "a.md: docs/b.md#not-a-heading: no heading with anchor #not-a-heading",
    ]
    page.write_text("[good](docs/b.md#real-heading-xy) [file](docs/b.md) [b](docs/b.md#b)\n")
    assert broken_links(page) == []


def test_anchors_follow_github() -> None:
    text = "# Builds on a robot host (`builds_here`)\n## The no-op memo (`.robocore/noop/`)\n## Same\n## Same\n"
    assert anchors(text) == {"builds-on-a-robot-host-builds_here", "the-no-op-memo-robocorenoop", "same", "same-1"}


def test_a_citation_of_a_missing_section_is_found(tmp_path: Path) -> None:
    (tmp_path / "notes.md").write_text("# Notes\n\n## Discovery timing: 20 ms\n")
    code = ('#: the measurements: docs/notes.md, "Discovery timing: 20 ms".\n'
            '#: and docs/notes.md,\n#: "Discovery timing"; docs/notes.md, "Discovery over UDP"; docs/gone.md, "X"\n')
    assert broken_citations(code, tmp_path) == ["docs/gone.md: no such page",
                                                'docs/notes.md, "Discovery over UDP": no such heading']
    assert broken_citations("see docs/notes.md and docs/notes.md", tmp_path) == []
    assert broken_citations("see docs/old-name.md", tmp_path) == ["docs/old-name.md: no such page"]


def test_a_readme_line_the_doc_test_cannot_run_is_refused() -> None:
    assert shell_line("robocore build sync run   # deploy") == "robocore build sync run --dry-run"
    assert shell_line("robocore validate") == "robocore validate"
    assert shell_line("source .venv/bin/activate   # the venv") is None
    with pytest.raises(ValueError, match="does not know how to run"):
        shell_line("docker compose up")


# ---------------------------------------------------------------- the repository's documents


@pytest.mark.parametrize("path", documents(), ids=lambda p: str(p.relative_to(ROOT)))
def test_every_relative_link_resolves(path: Path) -> None:
    assert broken_links(path) == []


def test_every_section_cited_in_the_code_exists() -> None:
    listed = subprocess.run(["git", "ls-files", "robocore", "tests", "integration", "bench", "scripts", "template",
                             "tasks.py", "noxfile.py"], cwd=ROOT, capture_output=True, text=True, check=True)
    problems = []
    for name in listed.stdout.split():
        path = ROOT / name
        if path.suffix in {".py", ".sh", ".jinja", ".yaml", ".yml", ".md", ""} and path.is_file() and (
                path != Path(__file__).resolve()):  # this file's own examples of citations
            problems += [f"{name}: {p}" for p in broken_citations(path.read_text(encoding="utf-8"), ROOT / "docs")]
    assert problems == []


#: A reference to a document that is not in the repository: a numbered seed or an issue number.
OUTSIDE_REFERENCE = re.compile(r"seed 00\d|\bissue #?\d+", re.I)


def outside_references(text: str) -> list[str]:
    """The references in ``text`` to documents the repository does not hold (a reader cannot follow them)."""
    return [match.group(0) for match in OUTSIDE_REFERENCE.finditer(text)]


def test_a_reference_to_an_outside_document_is_found() -> None:
    assert outside_references("the goal (Issue 37) of seed 002; see issue #12") == ["Issue 37", "seed 002", "issue #12"]
    assert outside_references("an issue with 3 hosts; the seed examples") == []


def test_no_file_refers_to_documents_outside_the_repository() -> None:
    listed = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True)
    found = []
    for name in listed.stdout.split():
        path = ROOT / name
        if path == Path(__file__).resolve() or not path.is_file():
            continue
        try:
            text = path.read_text(encoding="utf-8")
        except UnicodeDecodeError:  # binary files
            continue
        found += [f"{name}: {ref}" for ref in outside_references(text)]
    assert found == []


def test_the_readme_stays_short() -> None:
    assert len(README.read_text(encoding="utf-8").splitlines()) < 250


@pytest.fixture(scope="module")
def readme_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, subprocess.CompletedProcess[str]]:
    """The README's shell blocks run as one bash script, each block from the same fresh folder, with no Docker
    daemon reachable."""
    folder = tmp_path_factory.mktemp("readme")
    script = "set -euo pipefail\n"
    for block in code_blocks(README.read_text(encoding="utf-8"), "bash"):  # each block from the fresh folder
        lines = [shell_line(line) for line in block.splitlines()]
        script += f"cd {shlex.quote(str(folder))}\n" + "".join(f"{line}\n" for line in lines if line is not None)
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}",
           "DOCKER_HOST": f"unix://{folder}/no-docker.sock"}
    done = subprocess.run(["bash", "-c", script], cwd=folder, env=env, capture_output=True, text=True,
                          timeout=600, check=False)
    return folder, done


def test_the_readme_commands_run(readme_run: tuple[Path, subprocess.CompletedProcess[str]]) -> None:
    folder, done = readme_run
    assert done.returncode == 0, done.stdout + done.stderr
    assert "robot.yaml: ok" in done.stdout + done.stderr  # validate ran on the project init made
    made = re.findall(r"^robocore init (\S+)", "\n".join(code_blocks(README.read_text(encoding="utf-8"), "bash")),
                      re.M)
    assert made and all((folder / name / "robot.yaml").is_file() for name in made), made


def test_the_two_set_up_commands_are_what_ci_runs() -> None:
    blocks = "\n".join(code_blocks(README.read_text(encoding="utf-8"), "bash"))
    for script in SETUP_SCRIPTS:
        assert re.search(rf"^{re.escape(script)}\s", blocks, re.M), script
        assert (ROOT / script).stat().st_mode & stat.S_IXUSR, script
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    assert re.search(r"^[^#\n]*\./scripts/test\b", ci, re.M)
    test_script = (ROOT / "scripts" / "test").read_text(encoding="utf-8")
    assert "nox --no-venv -s lint typecheck tests integration" in test_script
    assert "`nox --no-venv -s lint typecheck tests integration`" in README.read_text(encoding="utf-8")


def robot_yaml_example(path: Path) -> str:
    """The robot.yaml example of a document: its first YAML block that names a ROS distribution."""
    return next(block for block in code_blocks(path.read_text(encoding="utf-8"), "yaml") if "ros_distro:" in block)


@pytest.mark.parametrize("path", [README, ROOT / "docs" / "robot-yaml.md"], ids=lambda p: p.name)
def test_the_robot_yaml_example_validates(path: Path, readme_run: tuple[Path, subprocess.CompletedProcess[str]],
                                          tmp_path: Path) -> None:
    folder, done = readme_run
    assert done.returncode == 0, done.stderr
    project = shutil.copytree(folder / "myrobot", tmp_path / "myrobot")
    text = robot_yaml_example(path)
    (project / "robot.yaml").write_text(text, encoding="utf-8")
    doc = yaml.safe_load(text)
    for entry in [*doc.get("components", []), *doc.get("common_packages", [])]:  # the example's own folders
        if "folder" in entry:
            (project / entry["folder"]).mkdir(parents=True, exist_ok=True)
    checked = subprocess.run([sys.executable, "-m", "robocore", "-p", str(project), "validate"],
                             capture_output=True, text=True, timeout=300, check=False)
    assert checked.returncode == 0, checked.stdout + checked.stderr


def test_the_readme_python_block_compiles() -> None:
    for block in code_blocks(README.read_text(encoding="utf-8"), "python"):
        compile(block, "README.md", "exec")


def test_the_task_table_lists_every_task_of_the_command() -> None:
    from robocore.tasks import cli_namespace

    text = README.read_text(encoding="utf-8")
    table = text[text.index("## Tasks"):].split("\n\n")[1]
    listed = {row.split("`")[1].split()[0] for row in table.splitlines() if row.startswith("| `")}
    assert listed == set(cli_namespace.task_names)
