"""What robocore prints never carries a terminal control sequence from robot.yaml, a host or a container
(log lines keep their colours), and text from those places is never read as rich markup."""

from __future__ import annotations

import pytest

from robocore import ui
from robocore.commands import logs
from robocore.commands.support import status_table
from robocore.commands.support.reporting import Reporter
from robocore.errors import HostError

TITLE = "\x1b]0;pwned\x07"
CLEAR = "\x1b[2J\x1b[H"
RED = "\x1b[31m"


@pytest.mark.parametrize("text, expected", [
    ("plain text\twith a tab\nand a newline", "plain text\twith a tab\nand a newline"),
    (f"ip {TITLE}", "ip \\x1b]0;pwned\\x07"),
    (f"a{CLEAR}b", "a\\x1b[2J\\x1b[Hb"),
    ("over\rwrite", "over\\x0dwrite"),
    ("\u202etxt.exe", "\\u202etxt.exe"),
    ("c1 \x9b31m", "c1 \\x9b31m"),
    (f"{RED}red", "\\x1b[31mred"),  # colours too, unless kept
])
def test_clean_escapes_every_control_character(text: str, expected: str) -> None:
    assert ui.clean(text) == expected


def test_log_lines_keep_their_colours_and_nothing_else() -> None:
    assert ui.clean(f"{RED}[ERROR]\x1b[0m plain", keep_sgr=True) == f"{RED}[ERROR]\x1b[0m plain\x1b[0m"
    assert ui.clean(f"{RED}x{TITLE}{CLEAR}", keep_sgr=True) == f"{RED}x\\x1b]0;pwned\\x07\\x1b[2J\\x1b[H\x1b[0m"
    assert ui.clean("no colour", keep_sgr=True) == "no colour"


def test_logs_print_the_containers_colours_but_escape_the_rest(capsys: pytest.CaptureFixture[str]) -> None:
    logs.emit_line(Reporter(), logs.LogLine(f"talk{TITLE}er", "rpi", f"{RED}hello\x1b[0m{CLEAR}"), 8, stream=True)
    out = capsys.readouterr().out
    assert out == f"talk\\x1b]0;pwned\\x07er | {RED}hello\x1b[0m\\x1b[2J\\x1b[H\x1b[0m\n"


def test_the_status_table_escapes_what_hosts_report(capsys: pytest.CaptureFixture[str]) -> None:
    rows = [status_table.Row(component=f"[/bold]x{TITLE}", host="rpi", state=f"running{CLEAR}", uptime="1s", restarts=0,
                        image="[red]img")]
    failures = {"other": HostError(f"host other: {TITLE}[/]")}
    status_table.print_status(rows, failures, [f"/node{TITLE}", "/[/x]"], f"via {TITLE}")  # rich markup would raise
    out = capsys.readouterr().out
    assert "\x1b" not in out and "\x07" not in out
    assert "[/bold]x\\x1b]0;pwned\\x07" in out and "[red]img" in out and "/[/x]" in out


def test_the_consoles_escape_every_string_they_render(capsys: pytest.CaptureFixture[str]) -> None:
    from rich.table import Table

    table = Table(title=f"t{TITLE}")
    table.add_column(f"c{CLEAR}")
    table.add_row(f"cell{TITLE}")
    ui.make_console(width=120, force_terminal=False).print(table)
    ui.console().print(f"message {TITLE}", markup=False)
    out, err = capsys.readouterr()
    assert "\x1b" not in out + err and "\x07" not in out + err
    assert "cell\\x1b]0;pwned\\x07" in out and "message \\x1b]0;pwned\\x07" in err


def test_a_key_path_from_a_files_own_keys_forges_no_line() -> None:
    from robocore.errors import Problem

    forged = Problem("v1.json", None, "components.talker.amd64\nerror: forged", "outside the fleet's registry")
    assert str(forged) == "v1.json: components.talker.amd64\\nerror: forged: outside the fleet's registry"
    assert str(Problem("robot.yaml", 3, "hosts[0].ip", "bad")) == "robot.yaml:3: hosts[0].ip: bad"  # control
