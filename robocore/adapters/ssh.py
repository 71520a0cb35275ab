"""SSH to robot hosts: the OpenSSH client for commands, rsync and Docker connections.

All of them read the same OpenSSH client configuration: ``$ROBOCORE_SSH_CONFIG`` when set (an
``ssh_config`` file; the test suites use it to point at a throw-away key and known_hosts),
else the user's ``~/.ssh/config``. Authentication is key-based only (``BatchMode=yes``): robocore
never asks for or stores a password.

Remote commands are argv lists. OpenSSH sends one command string to the remote shell, so each
argument is quoted with :func:`shlex.quote` here, in one place, and never interpolated; the
destination follows ``--``.

Connections to a host are shared through control sockets in :func:`control_dir`, which is checked
before every ssh (:func:`ensure_control_dir`): a folder this user owns and no one else may enter,
never a symlink, so that no one can plant a socket robocore's ssh would connect through.
"""

from __future__ import annotations

import os
import selectors
import shlex
import stat
import subprocess
import tempfile
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

from robocore.errors import HostError, RobocoreError, ToolMissing, UnsafePath
from robocore.plan.addresses import bare

if TYPE_CHECKING:
    from robocore.config.model import Host

CONFIG_ENV = "ROBOCORE_SSH_CONFIG"
#: Seconds to wait for a TCP connection and for the SSH handshake before calling a host unreachable.
CONNECT_TIMEOUT = 6
#: Seconds an idle shared ssh connection stays open.
MULTIPLEX_SECONDS = 5


def config_file() -> Path | None:
    """The ssh_config file robocore passes to ssh (``-F``), or None for OpenSSH's default."""
    configured = os.environ.get(CONFIG_ENV)
    return Path(configured).expanduser() if configured else None


class Target(Protocol):
    """What ssh needs of a host: a robot.yaml :class:`~robocore.config.model.Host` or a recorded one.

    (This module imports no config model, so that a command can open connections before loading one.)
    """

    @property
    def user(self) -> str:
        """The ssh user."""

    @property
    def ip(self) -> str:
        """Address or name ssh connects to."""

    @property
    def ssh_port(self) -> int:
        """Port of the host's sshd."""


def destination(host: Target) -> str:
    """``user@ip`` of a host (an IPv6 address bare: ssh takes the destination on its own, after ``--``)."""
    return f"{host.user}@{bare(host.ip)}"


def ssh_options(host: Target, *, connect_timeout: int = CONNECT_TIMEOUT) -> list[str]:
    """The ssh options (no command) robocore uses for ``host``: config file, port, timeouts, batch mode."""
    argv: list[str] = []
    config = config_file()
    if config is not None:
        argv += ["-F", str(config)]
    argv += [
        "-p", str(host.ssh_port),
        "-o", "BatchMode=yes",
        "-o", f"ConnectTimeout={connect_timeout}",
        "-o", "ServerAliveInterval=4",
        "-o", "ServerAliveCountMax=2",
        # One connection per host shared by the steps of a command (prepare, rsync, finalize):
        # the master lingers MULTIPLEX_SECONDS after its last use, then exits.
        "-o", "ControlMaster=auto",
        "-o", f"ControlPath={control_dir()}/%C",
        "-o", f"ControlPersist={MULTIPLEX_SECONDS}",
    ]
    return argv


def control_dir() -> Path:
    """The folder of ssh's control sockets (short path: unix sockets are limited to 108 bytes); nothing
    is created here (:func:`ensure_control_dir` does that before ssh runs).

    ``$XDG_RUNTIME_DIR/robocore-ssh`` when the runtime folder is this user's own and private, else
    ``<tmp>/robocore-ssh-<uid>``.
    """
    runtime = os.environ.get("XDG_RUNTIME_DIR", "")
    if runtime.startswith("/") and _private_problem(Path(runtime)) is None:
        return Path(runtime) / "robocore-ssh"
    return _temp_root() / f"robocore-ssh-{os.getuid()}"


def _temp_root() -> Path:
    """The temp folder, as :func:`tempfile.gettempdir` would choose it but without its write test (a dry
    run writes nothing): ``tempfile.tempdir`` if set, ``$TMPDIR``/``$TEMP``/``$TMP``, else ``/tmp``."""
    if tempfile.tempdir:
        return Path(tempfile.tempdir)
    for name in ("TMPDIR", "TEMP", "TMP"):
        value = os.environ.get(name, "")
        if value.startswith("/") and os.path.isdir(value):
            return Path(value)
    return Path("/tmp")


def _private_problem(path: Path) -> str | None:
    """Why ``path`` is not a private folder of this user (None when it is one): a folder, not a symlink,
    owned by this user, that no other user may enter or write to."""
    try:
        info = os.lstat(path)
    except OSError as exc:
        return exc.strerror or "cannot be read"
    if stat.S_ISLNK(info.st_mode):
        return "is a symlink"
    if not stat.S_ISDIR(info.st_mode):
        return "is not a folder"
    if info.st_uid != os.getuid():
        return f"is owned by uid {info.st_uid}, not by this user (uid {os.getuid()})"
    if info.st_mode & 0o077:
        return f"has mode {stat.S_IMODE(info.st_mode):04o}: other users may use it"
    return None


def ensure_control_dir() -> Path:
    """Create :func:`control_dir` (mode 0700) unless it exists, then check that it is this user's private
    folder; raise UnsafePath otherwise, so that ssh never connects through a socket planted by someone
    else (a folder another user made beforehand, or a symlink to one)."""
    path = control_dir()
    try:
        path.mkdir(mode=0o700)
        os.chmod(path, 0o700)  # whatever the umask
    except FileExistsError:
        pass
    except OSError as exc:
        raise UnsafePath(f"{path}: cannot create the folder of robocore's ssh connections: {exc.strerror}",
                         hint="set XDG_RUNTIME_DIR or TMPDIR to a private folder") from None
    problem = _private_problem(path)
    if problem is not None:
        raise UnsafePath(f"{path}: {problem}; robocore keeps its ssh connection sockets there and will not use it",
                         hint=f"if you made it, remove it (rm -r {path}) and run again; "
                         "or set XDG_RUNTIME_DIR to a private folder")
    return path


def ssh_argv(host: Target, remote: Sequence[str], *, connect_timeout: int = CONNECT_TIMEOUT) -> list[str]:
    """The local argv that runs ``remote`` (an argv list) on ``host``, each argument quoted."""
    return ["ssh", *ssh_options(host, connect_timeout=connect_timeout), "--", destination(host), shlex.join(remote)]


def rsh_command(host: Host, *, connect_timeout: int = CONNECT_TIMEOUT) -> str:
    """The ``rsync -e`` value: ssh with robocore's options (rsync splits it into argv itself)."""
    return shlex.join(["ssh", *ssh_options(host, connect_timeout=connect_timeout)])


def require_ssh() -> None:
    """Raise ToolMissing unless the ssh client is installed."""
    from shutil import which

    if which("ssh") is None:
        raise ToolMissing("ssh (OpenSSH client) is not installed", hint="apt-get install openssh-client")


def warm(host: Target) -> None:
    """Open the shared connection to ``host`` in the background (nothing is waited for or reported).

    The commands that follow find it ready (``ControlMaster``) instead of each paying the handshake;
    if the host is unreachable, they say so themselves.
    """
    from shutil import which

    if which("ssh") is None:
        return
    try:
        ensure_control_dir()
    except UnsafePath:
        return  # the step that needs the host says why
    subprocess.Popen(ssh_argv(host, ["true"]), stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                     stderr=subprocess.DEVNULL, start_new_session=True)


def run(host: Host, remote: Sequence[str], *, timeout: float = 120, stdin: bytes | None = None,
        check: bool = True, connect_timeout: int = CONNECT_TIMEOUT) -> subprocess.CompletedProcess[bytes]:
    """Run ``remote`` on ``host`` over ssh; raise HostError naming the host on failure (``check``)
    or when it does not finish within ``timeout`` seconds."""
    require_ssh()
    ensure_control_dir()
    argv = ssh_argv(host, remote, connect_timeout=connect_timeout)
    try:
        proc = subprocess.run(argv, input=stdin, capture_output=True, timeout=timeout, check=False)
    except subprocess.TimeoutExpired:
        raise HostError(f"host {host.name} ({host.ip}): `{brief(remote)}` timed out after {timeout:.0f} s",
                        hint="is the host up and reachable over ssh?") from None
    if check and proc.returncode != 0:
        raise HostError(f"host {host.name} ({host.ip}): {describe_failure(proc, remote)}", hint=failure_hint(proc))
    return proc


class Session:
    """A remote command kept running by :func:`hold`: the lines it printed before it was ready, and
    :meth:`finish` to hand it its last instruction."""

    def __init__(self, host: Host, remote: Sequence[str], proc: subprocess.Popen[bytes]) -> None:
        self._host = host
        self._remote = list(remote)
        self._proc = proc
        self._buffer = b""
        #: True once the command's output has ended (it exited, or its connection dropped).
        self.ended = False
        #: What the command printed before its ``ready`` line.
        self.greeting: list[str] = []

    def read_until(self, marker: str, timeout: float) -> list[str] | None:
        """The lines printed before ``marker`` (which is consumed); None if the command ended first or
        printed nothing for ``timeout`` seconds."""
        assert self._proc.stdout is not None
        fd = self._proc.stdout.fileno()
        lines: list[str] = []
        with selectors.DefaultSelector() as selector:
            selector.register(fd, selectors.EVENT_READ)
            while True:
                while b"\n" in self._buffer:
                    raw, self._buffer = self._buffer.split(b"\n", 1)
                    line = raw.decode(errors="replace").rstrip("\r")
                    if line.strip() == marker:
                        return lines
                    lines.append(line)
                if not selector.select(timeout):
                    return None
                chunk = os.read(fd, 65536)
                if not chunk:
                    self.ended = True
                    return None
                self._buffer += chunk

    def finish(self, line: str, *, done: str, what: str, timeout: float = 120) -> list[str]:
        """Send ``line`` to the command and wait for it to print ``done``; return the lines before it.

        Raises HostError (with the command's last error line) if it ends or goes quiet first.
        """
        assert self._proc.stdin is not None
        try:
            self._proc.stdin.write(line.encode() + b"\n")
            self._proc.stdin.flush()
        except OSError:
            pass  # it ended already: read_until finds out and says why
        out = self.read_until(done, timeout)
        if out is None:
            raise self.failure(what, timeout)
        return out

    def failure(self, what: str, timeout: float, refused: Callable[[int, str], RobocoreError | None] | None = None,
                ) -> RobocoreError:
        """The error to raise when the command ended, or stopped answering for ``timeout`` seconds, before
        it should have; ``refused(exit code, stderr)`` may name a specific reason for an exit."""
        host = self._host
        assert self._proc.stderr is not None
        no_answer = HostError(f"host {host.name} ({host.ip}): {what}: no answer within {timeout:.0f} s",
                              hint="is the host up and reachable over ssh?")
        if not self.ended:
            return no_answer
        try:
            code = self._proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            return no_answer
        err = self._proc.stderr.read().decode(errors="replace")
        error = refused(code, err) if refused else None
        ended = subprocess.CompletedProcess(self._proc.args, code, b"", err.encode())
        return error or HostError(f"host {host.name} ({host.ip}): {what}: {describe_failure(ended, self._remote)}",
                                  hint=failure_hint(ended))


@contextmanager
def hold(host: Host, remote: Sequence[str], *, ready: str, what: str, timeout: float = 3 * CONNECT_TIMEOUT,
         refused: Callable[[int, str], RobocoreError | None] | None = None) -> Iterator[Session]:
    """Keep ``remote`` running on ``host`` for the duration of the block (a lock held over ssh).

    ``remote`` prints ``ready`` once it holds what it holds (the lines before it are the session's
    ``greeting``), and keeps it until its stdin closes, which happens when the block ends, or when
    robocore dies, however it dies; :meth:`Session.finish` may hand it a last instruction first.
    ``what`` names it in messages. If it exits before ``ready``, ``refused(exit code, stderr)`` may
    turn that into a specific error; otherwise a HostError.
    """
    require_ssh()
    ensure_control_dir()
    proc = subprocess.Popen(ssh_argv(host, remote), stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    assert proc.stdin is not None and proc.stdout is not None and proc.stderr is not None
    session = Session(host, remote, proc)
    try:
        greeting = session.read_until(ready, timeout)
        if greeting is None:
            raise session.failure(what, timeout, refused)
        session.greeting = greeting
        yield session
    finally:
        if proc.poll() is None:
            proc.stdin.close()
            try:
                proc.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        for stream in (proc.stdin, proc.stdout, proc.stderr):
            stream.close()


def describe_failure(proc: subprocess.CompletedProcess[bytes], remote: Sequence[str]) -> str:
    """One line: what ran, its exit code and the last line it printed on stderr."""
    err = proc.stderr.decode(errors="replace").strip().splitlines()
    last = err[-1] if err else "no output"
    if proc.returncode == 255:
        return f"ssh failed: {last}"
    return f"`{brief(remote)}` exited {proc.returncode}: {last}"


def brief(remote: Sequence[str], width: int = 80) -> str:
    """A remote command for a one-line message: its first line, at most ``width`` characters (a
    robocore script would otherwise fill the screen)."""
    text = shlex.join(remote)
    first = text.splitlines()[0] if text else ""
    return first if first == text and len(first) <= width else first[: width - 3] + "..."


def failure_hint(proc: subprocess.CompletedProcess[bytes]) -> str:
    """What to check after a failed ssh command (authentication, host key, reachability)."""
    if proc.returncode != 255:
        return "run the command on the host by hand to see the full output"
    text = proc.stderr.decode(errors="replace")
    if "Permission denied" in text:
        return "robocore uses key-based ssh only: add your public key to the host's authorized_keys (ssh-copy-id)"
    if "Host key verification failed" in text:
        return "add the host's key to known_hosts (ssh-keyscan HOST >> ~/.ssh/known_hosts) after checking it"
    config = config_file() or "~/.ssh/config"
    return f"check that the host is up and that `ssh -p PORT USER@HOST` works (config: {config})"
