"""Build hook: the wheel carries the project template as ``robocore/resources/template``.

The template stays a top-level ``template/`` folder in the repository (``copier copy
path/to/robocore`` renders it through the root ``copier.yml``). An installed, non-editable
robocore has no repository next to it, so ``robocore init`` renders this bundled copy
(``robocore.adapters.copier_adapter.bundled_template``). Editable installs use ``template/``
in place and copy nothing. Everything else about the package is in pyproject.toml.
"""

from __future__ import annotations

import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

TEMPLATE = Path(__file__).resolve().parent / "template"
BUNDLED = ("robocore", "resources", "template")


class BuildWithTemplate(build_py):
    """build_py that also copies template/ into the built package."""

    def run(self) -> None:
        super().run()
        if self.editable_mode:
            return
        if not (TEMPLATE / "copier.yml").is_file():
            raise FileNotFoundError(f"{TEMPLATE / 'copier.yml'}: the project template is missing from the source tree")
        target = Path(self.build_lib, *BUNDLED)
        shutil.rmtree(target, ignore_errors=True)
        shutil.copytree(TEMPLATE, target, ignore=shutil.ignore_patterns("__pycache__", "*.py[co]", ".pytest_cache"))


setup(cmdclass={"build_py": BuildWithTemplate})
