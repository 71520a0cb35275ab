"""Running rsync (over robocore's ssh settings) and reading what it moved."""

from __future__ import annotations

import shlex
import shutil
import subprocess
from collections.abc import Sequence

from robocore.adapters.ssh import ensure_control_dir
from robocore.config.model import Host
from robocore.errors import HostError, ToolMissing
from robocore.plan.sync import RsyncStats, parse_stats

#: rsync exit codes that mean "the other side is unreachable or has no rsync".
_UNREACHABLE = {255}
_NO_REMOTE_RSYNC = {12, 127}


def require_rsync() -> None:
    """Raise ToolMissing unless rsync is installed here."""
    if shutil.which("rsync") is None:
        raise ToolMissing("rsync is not installed on this machine", hint="apt-get install rsync")


def run(host: Host, argv: Sequence[str], *, timeout: float = 3600) -> RsyncStats:
    """Run an rsync argv (from :func:`robocore.plan.sync.rsync_argv`); return its stats or raise HostError."""
    require_rsync()
    ensure_control_dir()  # rsync's ssh shares robocore's connection to the host
    try:
        proc = subprocess.run(list(argv), capture_output=True, text=True, timeout=timeout, check=False)
    except subprocess.TimeoutExpired:
        raise HostError(f"host {host.name} ({host.ip}): rsync did not finish within {timeout:.0f} s",
                        hint="is the link to the host very slow? re-run: the next sync resumes") from None
    if proc.returncode != 0:
        lines = [line for line in proc.stderr.strip().splitlines() if line.strip()]
        last = lines[-1] if lines else "no output"
        if proc.returncode in _UNREACHABLE:
            hint = "check that `ssh USER@HOST` works with a key (robocore doctor)"
        elif proc.returncode in _NO_REMOTE_RSYNC or "command not found" in proc.stderr:
            hint = "install rsync on the host (apt-get install rsync)"
        else:
            hint = f"the command was: {shlex.join(argv)}"
        raise HostError(f"host {host.name} ({host.ip}): rsync exited {proc.returncode}: {last}", hint=hint)
    return parse_stats(proc.stdout)
