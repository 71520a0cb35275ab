# Sourced by scripts/demo and scripts/test: make .venv with robocore and its tools,
# and the few Debian tools robocore drives (mmdebstrap, rsync, ssh, Xvfb for the GUI tests).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$ROOT/.venv"

need_debs=()
command -v mmdebstrap >/dev/null || need_debs+=(mmdebstrap)
command -v rsync >/dev/null || need_debs+=(rsync)
command -v ssh >/dev/null || need_debs+=(openssh-client)
command -v git >/dev/null || need_debs+=(git)
if [ "${ROBOCORE_TEST_TOOLS:-0}" = 1 ]; then
  command -v Xvfb >/dev/null || need_debs+=(xvfb)
  command -v xauth >/dev/null || need_debs+=(xauth)
  command -v xwininfo >/dev/null || need_debs+=(x11-utils)
  command -v docker-compose >/dev/null || docker compose version >/dev/null 2>&1 || need_debs+=(docker-compose)
  command -v docker-registry >/dev/null || need_debs+=(docker-registry)
  command -v ssh-keygen >/dev/null || need_debs+=(openssh-client)
fi
install_debs() {
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    echo "installing ${need_debs[*]} with apt-get" >&2
    apt-get update -qq >/dev/null && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${need_debs[@]}" >/dev/null
  elif command -v sudo >/dev/null && command -v apt-get >/dev/null; then
    echo "installing ${need_debs[*]} with sudo apt-get" >&2
    sudo apt-get update -qq >/dev/null && sudo DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${need_debs[@]}" >/dev/null
  else
    echo "warning: please install ${need_debs[*]} (Debian/Ubuntu: apt-get install ${need_debs[*]})" >&2
  fi
}
# With ROBOCORE_PREFETCH_ROOT=1 (scripts/demo), a machine that has no Debian 12 image gets the root image of
# the wheels base as prepare-base would make it (robocore/adapters/rootfs.py: mmdebstrap, then docker import),
# here, while the venv is made, so that the two downloads overlap; prepare-base then finds it. On failure
# prepare-base tries again and says why.
prefetch_root() {
  command -v mmdebstrap >/dev/null && command -v docker >/dev/null || return 0
  docker image inspect robocore/debian:bookworm >/dev/null 2>&1 && return 0
  docker image inspect debian:bookworm >/dev/null 2>&1 && return 0
  local tmp
  tmp="$(mktemp -d)"
  echo "bootstrapping the Debian 12 root image (robocore/debian:bookworm) while the venv is made" >&2
  if mmdebstrap --variant=apt --include=python3,python3-venv,ca-certificates,procps bookworm "$tmp/root.tar" \
       "${ROBOCORE_DEBIAN_MIRROR:-http://deb.debian.org/debian}" >"$tmp/log" 2>&1; then
    docker import "$tmp/root.tar" robocore/debian:bookworm >/dev/null || true
  else
    echo "warning: bootstrapping the Debian root image ahead failed; prepare-base will try again" >&2
  fi
  rm -rf "$tmp"
}
# the Debian tools install (and the root image bootstraps) while the venv is made; the venv step waits for them
# at the end
background() {
  if [ ${#need_debs[@]} -gt 0 ]; then install_debs; fi
  if [ "${ROBOCORE_PREFETCH_ROOT:-0}" = 1 ]; then prefetch_root; fi
}
debs_pid=""
if [ ${#need_debs[@]} -gt 0 ] || [ "${ROBOCORE_PREFETCH_ROOT:-0}" = 1 ]; then
  background &
  debs_pid=$!
fi

command -v docker >/dev/null || { echo "error: docker is not installed; robocore needs a Docker Engine" >&2; exit 1; }
docker info >/dev/null 2>&1 || { echo "error: cannot reach the Docker daemon (is it running? may this user use it?)" >&2; exit 1; }

PY="${PYTHON:-python3}"
if [ ! -x "$VENV/bin/python" ]; then
  "$PY" -m venv "$VENV"
fi
stamp="$VENV/.robocore-installed"
if [ ! -f "$stamp" ] || [ "$ROOT/pyproject.toml" -nt "$stamp" ]; then
  # the same packages, installed by uv (from PyPI: downloads and installs side by side) when it can be had,
  # else by pip as before; ROBOCORE_INSTALLER=pip forces pip
  if [ "${ROBOCORE_INSTALLER:-uv}" = uv ] && "$VENV/bin/python" -m pip install -q --disable-pip-version-check uv \
       >/dev/null 2>&1 && "$VENV/bin/python" -m uv --version >/dev/null 2>&1; then
    "$VENV/bin/python" -m uv pip install -q --python "$VENV/bin/python" --upgrade pip -e "$ROOT[dev]"  # pip too: tests drive pip with git+file requirements
  else
    "$VENV/bin/python" -m pip install -q --upgrade pip >/dev/null
    "$VENV/bin/python" -m pip install -q -e "$ROOT[dev]"
  fi
  touch "$stamp"
fi
if [ -n "$debs_pid" ]; then
  wait "$debs_pid"
fi
export PATH="$VENV/bin:$PATH"
