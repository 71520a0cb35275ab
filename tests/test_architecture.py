"""robocore's import graph: no cycle, imports only downward in the layer order, no private names across modules.

Imports inside functions count (they are real dependencies, only deferred); imports under
``if TYPE_CHECKING:`` do not (they exist for annotations only).
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "robocore"
#: Layers from the top down: a module may import its own layer's modules and any layer below it.
#: The command line (cli, tasks) and the pytest plugin (testing) are the front ends; demo is one too.
#: commands.support holds what several task modules share: it sits below them, so it never imports a task
#: module (each module of robocore.commands outside support/ is a task, or a fleet verb).
LAYERS: tuple[tuple[str, ...], ...] = (
    ("robocore.cli", "robocore.__main__"),
    ("robocore.tasks", "robocore.testing", "robocore.demo"),
    ("robocore.commands",),
    ("robocore.commands.support",),
    ("robocore.adapters", "robocore.plan"),
    ("robocore.project",),
    ("robocore.config",),
    ("robocore.errors", "robocore.files", "robocore.ui", "robocore.resources", "robocore"),
)
MAX_LINES = 450


def module_name(path: Path, package: Path = PACKAGE) -> str:
    parts = path.relative_to(package.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def layer_of(module: str) -> int:
    best = None
    for index, layer in enumerate(LAYERS):
        for prefix in layer:
            inside = module == prefix or module.startswith(prefix + ".")
            if inside and (best is None or len(prefix) > len(best[1])):
                best = (index, prefix)
    assert best is not None, f"{module} is in no layer"
    return best[0]


def _type_checking_nodes(tree: ast.AST) -> set[int]:
    skipped: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING":
            for child in node.body:
                skipped.update(id(n) for n in ast.walk(child))
    return skipped


def imports(path: Path, package_root: Path = PACKAGE) -> Iterator[tuple[str, str | None, int]]:
    """(imported module, imported name or None, line) for every robocore import in ``path``."""
    tree = ast.parse(path.read_text())
    skipped = _type_checking_nodes(tree)
    here = module_name(path, package_root)
    known = {module_name(p, package_root) for p in package_root.rglob("*.py")}
    package = here if path.name == "__init__.py" else here.rsplit(".", 1)[0]
    for node in ast.walk(tree):
        if id(node) in skipped:
            continue
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith("robocore"):
                    yield alias.name, None, node.lineno
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*parent, base] if base else parent)
            if not base.startswith("robocore"):
                continue
            for alias in node.names:
                target = f"{base}.{alias.name}"
                if target in known:
                    yield target, None, node.lineno
                else:
                    yield base, alias.name, node.lineno


MODULES = sorted(PACKAGE.rglob("*.py"))


def graph(package: Path) -> dict[str, set[str]]:
    paths = sorted(package.rglob("*.py"))
    known = {module_name(p, package) for p in paths}
    edges: dict[str, set[str]] = {module_name(p, package): set() for p in paths}
    for path in paths:
        source = module_name(path, package)
        for target, _, _ in imports(path, package):
            while target not in known and "." in target:
                target = target.rsplit(".", 1)[0]
            if target != source and target in known:
                edges[source].add(target)
    return edges


def cycles_in(package: Path) -> list[list[str]]:
    """Every import cycle found by a depth-first walk of the package's import graph."""
    edges = graph(package)
    cycles: list[list[str]] = []
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(edges[node]):
            if state.get(nxt) == 1:
                cycles.append([*stack[stack.index(nxt):], nxt])
            elif nxt not in state:
                visit(nxt)
        stack.pop()
        state[node] = 2

    for node in sorted(edges):
        if node not in state:
            visit(node)
    return cycles


def upward_imports(package: Path) -> list[str]:
    """Imports of a module from a layer above its own."""
    wrong = []
    for path in sorted(package.rglob("*.py")):
        source = module_name(path, package)
        for target, _, line in imports(path, package):
            if layer_of(target) < layer_of(source):
                wrong.append(f"{path.relative_to(package.parent)}:{line}: {source} imports {target} (a layer above)")
    return wrong


def private_imports(package: Path) -> list[str]:
    """Imports of another module's ``_private`` name (or of a private module)."""
    wrong = []
    for path in sorted(package.rglob("*.py")):
        for target, name, line in imports(path, package):
            if name is not None and name.startswith("_") and not name.startswith("__"):
                wrong.append(f"{path.relative_to(package.parent)}:{line}: imports {target}.{name}")
            elif name is None and target.rsplit(".", 1)[-1].startswith("_") and not target.endswith("__"):
                wrong.append(f"{path.relative_to(package.parent)}:{line}: imports private module {target}")
    return wrong


def private_uses(paths: list[Path], package: Path = PACKAGE) -> list[str]:
    """Uses of a robocore module's ``_private`` name from another file: ``from robocore.m import _name``, and
    ``m._name`` where ``m`` is a robocore module imported by name (``from robocore.commands import run``)."""
    known = {module_name(p, package) for p in package.rglob("*.py")}
    wrong = []
    for path in paths:
        tree = ast.parse(path.read_text())
        where = path.relative_to(package.parent)
        modules = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                modules.update(a.asname for a in node.names if a.name.startswith("robocore") and a.asname)
            elif isinstance(node, ast.ImportFrom) and not node.level and (node.module or "").startswith("robocore"):
                for alias in node.names:
                    if f"{node.module}.{alias.name}" in known:
                        modules.add(alias.asname or alias.name)
                    elif alias.name.startswith("_") and not alias.name.startswith("__"):
                        wrong.append(f"{where}:{node.lineno}: imports {node.module}.{alias.name}")
        wrong += [f"{where}:{node.lineno}: uses {node.value.id}.{node.attr}" for node in ast.walk(tree)
                  if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
                  and node.value.id in modules and node.attr.startswith("_") and not node.attr.startswith("__")]
    return wrong


def test_there_is_no_import_cycle() -> None:
    cycles = cycles_in(PACKAGE)
    assert cycles == [], "import cycles:\n" + "\n".join(" -> ".join(c) for c in cycles)


def test_imports_go_down_the_layers() -> None:
    wrong = upward_imports(PACKAGE)
    assert wrong == [], "\n".join(wrong)


def test_no_module_imports_another_modules_private_name() -> None:
    wrong = private_imports(PACKAGE)
    assert wrong == [], "\n".join(wrong)


def test_no_test_suite_or_benchmark_reaches_into_a_private_name() -> None:
    folders = [PACKAGE.parent / name for name in ("robocore", "tests", "integration", "bench")]
    files = [path for folder in folders for path in sorted(folder.rglob("*.py"))]
    wrong = private_uses(files)
    assert wrong == [], "\n".join(wrong)


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(PACKAGE.parent)))
def test_modules_stay_small(path: Path) -> None:
    lines = len(path.read_text().splitlines())
    assert lines <= MAX_LINES, f"{path.relative_to(PACKAGE.parent)} has {lines} lines (at most {MAX_LINES})"


def test_the_checks_see_a_planted_cycle_an_upward_import_and_a_private_name(tmp_path: Path) -> None:
    """Negative control: each check fails on a package that breaks its rule."""
    fake = tmp_path / "robocore"
    (fake / "plan").mkdir(parents=True)
    (fake / "commands").mkdir()
    for init in (fake / "__init__.py", fake / "plan" / "__init__.py", fake / "commands" / "__init__.py"):
        init.write_text("")
    (fake / "plan" / "a.py").write_text("def f():\n    from robocore.commands import b\n")
    (fake / "commands" / "b.py").write_text("from robocore.plan.a import _hidden\n")
    (fake / "commands" / "c.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
                                            "    from robocore.plan.a import _typing_only\n")
    assert cycles_in(fake) == [["robocore.commands.b", "robocore.plan.a", "robocore.commands.b"]]
    assert upward_imports(fake) == ["robocore/plan/a.py:2: robocore.plan.a imports robocore.commands.b (a layer above)"]
    assert private_imports(fake) == ["robocore/commands/b.py:1: imports robocore.plan.a._hidden"]
    (fake / "commands" / "d.py").write_text("from robocore.plan import a\na._hidden()\na.public()\n")
    assert private_uses([fake / "commands" / "b.py", fake / "commands" / "d.py"], fake) == [
        "robocore/commands/b.py:1: imports robocore.plan.a._hidden", "robocore/commands/d.py:2: uses a._hidden"]


def test_a_support_module_that_imports_a_task_module_is_caught(tmp_path: Path) -> None:
    """Negative control of the support/task split: a shared helper that imports a task module, at the top or
    inside a function, is an upward import; a task module importing a support module is not."""
    fake = tmp_path / "robocore"
    support = fake / "commands" / "support"
    support.mkdir(parents=True)
    for init in (fake / "__init__.py", fake / "commands" / "__init__.py", support / "__init__.py"):
        init.write_text("")
    (fake / "commands" / "build.py").write_text("from robocore.commands.support import helper\n")
    (fake / "commands" / "stage.py").write_text("from robocore.commands.support.helper import shared\n")
    (support / "helper.py").write_text("from robocore.commands import build\n\n\n"
                                       "def shared():\n    from robocore.commands.stage import plan\n")
    assert upward_imports(fake) == [
        "robocore/commands/support/helper.py:1: robocore.commands.support.helper imports robocore.commands.build "
        "(a layer above)",
        "robocore/commands/support/helper.py:5: robocore.commands.support.helper imports robocore.commands.stage "
        "(a layer above)",
    ]


#: Tasks with no module in robocore/commands/: ``schema`` prints a pure function of the config model
#: (:func:`robocore.config.schema.schema_json`); it loads no project and executes nothing.
NO_COMMAND_MODULE = {"schema"}


def test_each_task_has_a_module_named_after_it() -> None:
    """What a user types is where its code is: ``robocore prepare-base`` -> robocore/commands/prepare_base.py."""
    from robocore.tasks import cli_namespace

    names = sorted(set(cli_namespace.task_names) - NO_COMMAND_MODULE)
    missing = [n for n in names if not (PACKAGE / "commands" / f"{n.replace('-', '_')}.py").is_file()]
    assert {"prepare-base", "desktop-password", "down"} <= set(names)  # the collection was read
    assert missing == [], f"tasks with no robocore/commands/<task>.py: {missing}"
