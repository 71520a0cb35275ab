"""How long `robocore shell --cmd true` takes: a fresh dev container vs joining a running one.

Side by side with plain Docker: `docker run --rm IMAGE true` (the floor for a new container)
and `docker exec CONTAINER true` (the floor for joining). Prints medians and ratios.
"""

from __future__ import annotations

import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from harness import Figure, record

#: Debian 12 images, the first one present is used (the Debian roots robocore makes for its bases come first).
CANDIDATES = ("robocore/amd64/debian:bookworm-wheels-jazzy", "robocore/amd64/debian:bookworm-wheels",
              "robocore/amd64/debian:bookworm-debian",
              "robocore/debian:bookworm", "debian:bookworm", "robocore-test/debian:bookworm")
ROUNDS = 5


def timed(argv: list[str], env: dict[str, str] | None = None) -> float:
    start = time.perf_counter()
    subprocess.run(argv, check=True, capture_output=True, env=env)
    return time.perf_counter() - start


def median(argv: list[str], env: dict[str, str] | None = None) -> float:
    return statistics.median(timed(argv, env) for _ in range(ROUNDS))


def main() -> int:
    image = next((ref for ref in CANDIDATES
                  if subprocess.run(["docker", "image", "inspect", ref], capture_output=True).returncode == 0), None)
    if image is None:
        print("no Debian 12 image present (run `robocore prepare-base` of a wheels project first)")
        return 1
    parent = Path(tempfile.mkdtemp(prefix="robocore-bench-shell-"))
    root = parent / "robocore-bench-shell"
    root.mkdir()
    (root / "robot.yaml").write_text(
        "ros_distro: jazzy\nhosts:\n  - name: dev\n    ip: 127.0.0.1\n"
        f"components:\n  - name: c\n    runs_on: dev\n    image: \"{image}\"\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "DISPLAY"}
    shell = [sys.executable, "-m", "robocore", "-p", str(root), "shell", "--component", "c", "--cmd"]
    holder = None
    try:
        docker_run = median(["docker", "run", "--rm", image, "true"])
        fresh = median([*shell, "true"], env)
        holder = subprocess.Popen([*shell, "while [ ! -e /tmp/stop ]; do sleep 0.1; done"], env=env,
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        name = "robocore-bench-shell-c-shell"
        deadline = time.monotonic() + 60
        while subprocess.run(["docker", "exec", name, "test", "-e", "/run/robocore/ready"],
                             capture_output=True).returncode != 0:
            if time.monotonic() > deadline:
                print("the holder shell never became ready")
                return 1
            time.sleep(0.1)
        docker_exec = median(["docker", "exec", name, "true"])
        join = median([*shell, "true"], env)
        subprocess.run([*shell, "touch /tmp/stop"], env=env, capture_output=True)
        holder.wait(timeout=60)
    finally:
        if holder is not None and holder.poll() is None:
            holder.kill()
        subprocess.run(["docker", "rm", "-f", "robocore-bench-shell-c-shell"], capture_output=True)
        shutil.rmtree(parent, ignore_errors=True)

    print(f"image: {image}; median of {ROUNDS} runs each")
    print(f"{'docker run --rm IMAGE true':<44}{docker_run:7.2f} s")
    print(f"{'robocore shell --cmd true (new container)':<44}{fresh:7.2f} s   x{fresh / docker_run:.1f} of docker run")
    print(f"{'docker exec CONTAINER true':<44}{docker_exec:7.2f} s")
    print(f"{'robocore shell --cmd true (join running)':<44}{join:7.2f} s   x{join / docker_exec:.1f} of docker exec")
    print(f"{'joining vs new container':<44}{'':7} x{fresh / join:.1f} faster")
    record("shell_start", [
        Figure("docker run --rm IMAGE true", docker_run, "s"),
        Figure("robocore shell --cmd true (new container)", fresh, "s", ratio=fresh / docker_run,
               ratio_of="x docker run"),
        Figure("docker exec CONTAINER true", docker_exec, "s"),
        Figure("robocore shell --cmd true (join running)", join, "s", ratio=join / docker_exec,
               ratio_of="x docker exec"),
        Figure("joining vs new container", fresh / join, "x faster"),
    ], notes=[f"image {image}; median of {ROUNDS} runs each"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
