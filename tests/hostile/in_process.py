"""Running robocore's command line in the test's own process, as the hostile suites do for speed."""

from __future__ import annotations

import pytest

from robocore import cli


def run_main(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    """``robocore.cli.main(argv)``: its exit code (0 when it returns) and what it wrote to stdout and stderr."""
    try:
        cli.main(argv)
        code = 0
    except SystemExit as done:
        code = done.code if isinstance(done.code, int) else (0 if done.code is None else 1)
    out, err = capsys.readouterr()
    return code, out, err
