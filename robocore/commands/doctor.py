"""doctor: check every host and say what to fix.

Per host: its Docker daemon is reachable (within the connect timeout) and recent enough, its
CPU architecture is the one robot.yaml says, the file system of ``mount_root`` has free space,
and, for remote hosts, ssh works and rsync is installed. One line per problem with a hint;
the exit code is non-zero when there is any problem.
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass, field
from typing import Any, ClassVar

from robocore.adapters import ssh
from robocore.adapters.docker_hosts import client_for, describe
from robocore.commands.support.arch_checks import host_arch
from robocore.commands.support.context import Options
from robocore.commands.support.hosts import for_each_host, select_hosts
from robocore.config.model import DockerAccess, Host
from robocore.errors import GroupError, HostError, RobocoreError
from robocore.project import Project

#: Below this much free space on mount_root's file system, doctor complains.
MIN_FREE_BYTES = 2 * 1024**3
MIN_DOCKER = (20, 10)

# $1 = mount_root: df of its deepest existing ancestor (POSIX df -P, 1K blocks).
_DF_SCRIPT = """\
d=$1
while [ ! -e "$d" ]; do d=$(dirname -- "$d"); done
df -P -k -- "$d"
"""


@dataclass(frozen=True)
class Finding:
    """A problem doctor found, and how to fix it."""

    problem: str
    hint: str


@dataclass
class HostReport:
    """What doctor found on one host."""

    kind: ClassVar[str] = "host_check"
    host: str
    facts: list[str] = field(default_factory=list)
    problems: list[Finding] = field(default_factory=list)

    def found(self, problem: str, hint: str) -> None:
        """Record a problem and its hint."""
        self.problems.append(Finding(problem, hint))


class DoctorProblems(HostError):
    """doctor found problems: one line per problem, each followed by its hint."""

    def __init__(self, reports: list[HostReport]) -> None:
        self.reports = reports
        count = sum(len(r.problems) for r in reports)
        super().__init__(f"{count} problem(s) found")

    def lines(self) -> list[str]:
        """``host: problem`` then ``hint: ...`` for each problem."""
        out = []
        for report in self.reports:
            for finding in report.problems:
                out.append(f"{report.host}: {finding.problem}")
                out.append(f"hint: {finding.hint}")
        return out


def doctor(options: Options, *, host: str | None) -> None:
    """Check hosts; print what was found; raise DoctorProblems when anything needs fixing."""
    from rich.markup import escape

    project = options.load()
    hosts = select_hosts(project, host)
    results, failures = for_each_host(hosts, lambda h: check_host(project, h))
    if failures:  # check_host collects problems; anything raised is not a finding about the host
        raise GroupError(failures, list(results))
    reports = [results[h.name] for h in hosts]
    if any(not h.is_local for h in hosts):
        local = HostReport("this machine")
        for tool, package in (("rsync", "rsync"), ("ssh", "openssh-client")):
            if shutil.which(tool) is None:
                local.found(f"{tool} is not installed (sync needs it)", f"apt-get install {package}")
        if local.problems:
            reports.append(local)
    options.report.add(*reports)
    for report in reports:
        mark = "[green]ok[/]" if not report.problems else f"[red]{len(report.problems)} problem(s)[/]"
        options.report.info(f"{report.host}: {mark}  " + escape(", ".join(report.facts)), markup=True)
    if any(r.problems for r in reports):
        raise DoctorProblems([r for r in reports if r.problems])


def check_host(project: Project, host: Host) -> HostReport:
    """Every check of one host; problems are collected, never raised."""
    report = HostReport(host.name)
    report.facts.append(describe(host))
    try:
        client = client_for(host, timeout=20, project_root=project.root)
    except RobocoreError as exc:
        report.found(exc.message, f"is {host.name} powered and on the network? "
                     f"try `ssh -p {host.ssh_port} {ssh.destination(host)} docker version`")
        if not host.is_local and host.access is not DockerAccess.ssh:
            _check_ssh(host, report)  # sync still needs ssh when Docker is reached over TLS/TCP
        return report
    try:
        _check_docker(host, client, report)
    finally:
        client.close()
    if host.is_local:
        _check_local_disk(project, report)
    else:
        _check_ssh(host, report)
    return report


def _check_docker(host: Host, client: Any, report: HostReport) -> None:
    version = client.version()
    text = str(version.get("Version", "?"))
    report.facts.append(f"docker {text}")
    if _version_tuple(text) < MIN_DOCKER:
        report.found(f"Docker {text} is older than {'.'.join(map(str, MIN_DOCKER))}",
                     "upgrade docker (Debian/Ubuntu: apt-get install docker.io)")
    found = host_arch(host, str(client.info().get("Architecture", "?")))
    report.facts.append(found.describe())
    if found.problem:
        report.found(found.problem, found.hint or "")


def _check_ssh(host: Host, report: HostReport) -> None:
    try:
        proc = ssh.run(host, ["sh", "-c", _DF_SCRIPT, "sh", host.deploy_root], timeout=20)
    except RobocoreError as exc:
        report.found(f"ssh: {exc.message}", exc.hint or "check ssh access")
        return
    _disk_fact(host.deploy_root, _parse_df(proc.stdout.decode()), report)
    rsync = ssh.run(host, ["sh", "-c", "command -v rsync && rsync --version | head -n 1"], timeout=20, check=False)
    if rsync.returncode != 0:
        report.found("rsync is not installed on the host (sync needs it)",
                     f"on {host.name}: apt-get install rsync")
    else:
        words = rsync.stdout.decode().splitlines()[-1].split()
        report.facts.append(f"rsync {words[2] if len(words) > 2 else '?'}")


def _check_local_disk(project: Project, report: HostReport) -> None:
    usage = shutil.disk_usage(project.root)
    _disk_fact(str(project.root), usage.free, report)


def _disk_fact(where: str, free: int | None, report: HostReport) -> None:
    if free is None:
        report.found(f"could not read free disk space for {where}", "run `df -P` on the host")
        return
    report.facts.append(f"{free / 1024**3:.1f} GiB free at {where}")
    if free < MIN_FREE_BYTES:
        report.found(f"only {free / 1024**2:.0f} MiB free on the file system of {where}",
                     "free space (docker image prune, old releases) or set mount_root elsewhere")


def _parse_df(text: str) -> int | None:
    lines = [line for line in text.splitlines() if line.strip()]
    if len(lines) < 2:
        return None
    parts = lines[-1].split()
    try:
        return int(parts[3]) * 1024
    except (IndexError, ValueError):
        return None


def _version_tuple(text: str) -> tuple[int, ...]:
    nums = []
    for piece in text.split("+")[0].split("-")[0].split(".")[:2]:
        try:
            nums.append(int(piece))
        except ValueError:
            nums.append(0)
    return tuple(nums)
