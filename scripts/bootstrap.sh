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
  command -v file >/dev/null || need_debs+=(file)
  # the fleet page's browser tests (integration/test_fleet_page.py): Debian's headless Chromium and its driver
  command -v chromium >/dev/null || need_debs+=(chromium)
  command -v chromedriver >/dev/null || need_debs+=(chromium-driver)
  # the arm64 suites run arm64 containers on amd64 through qemu (registered below)
  if [ "$(uname -m)" = x86_64 ]; then
    command -v qemu-aarch64-static >/dev/null || need_debs+=(qemu-user-static)
  fi
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
# the Debian tools install while the venv is made; the venv step waits for them
# at the end
background() {
  if [ ${#need_debs[@]} -gt 0 ]; then install_debs; fi
}
debs_pid=""
if [ ${#need_debs[@]} -gt 0 ]; then
  background &
  debs_pid=$!
fi

command -v docker >/dev/null || { echo "error: docker is not installed; robocore needs a Docker Engine" >&2; exit 1; }
docker info >/dev/null 2>&1 || { echo "error: cannot reach the Docker daemon (is it running? may this user use it?)" >&2; exit 1; }

PY="${PYTHON:-python3}"
installer="${ROBOCORE_INSTALLER:-uv}"
if [ ! -x "$VENV/bin/python" ]; then
  # with uv, the venv starts without pip (ensurepip costs seconds); uv installs pip into it below
  if [ "$installer" = uv ]; then "$PY" -m venv --without-pip "$VENV"; else "$PY" -m venv "$VENV"; fi
fi
# The pip wheel the interpreter bundles for ensurepip (Debian keeps it in /usr/share/python-wheels): pip runs
# from it without being installed, to fetch uv.
bundled_pip() {
  "$VENV/bin/python" - <<'PYCODE'
import glob, os
places = ["/usr/share/python-wheels"]
try:
    import ensurepip
    places.insert(0, os.path.join(os.path.dirname(ensurepip.__file__), "_bundled"))
except ImportError:
    pass
for place in places:
    found = sorted(glob.glob(os.path.join(place, "pip-*.whl")))
    if found:
        print(found[-1])
        break
PYCODE
}
# uv itself: the venv's own, else fetched into a scratch folder by the venv's pip or the bundled pip wheel
find_uv() {
  if [ -x "$VENV/bin/uv" ]; then echo "$VENV/bin/uv"; return 0; fi
  rm -rf "$VENV/.robocore-uv"
  local wheel pip=("$VENV/bin/python" -m pip)
  if ! "$VENV/bin/python" -m pip --version >/dev/null 2>&1; then
    wheel="$(bundled_pip)" && [ -n "$wheel" ] || return 1
    pip=("$VENV/bin/python" "$wheel/pip")
  fi
  "${pip[@]}" install -q --disable-pip-version-check --no-compile --target "$VENV/.robocore-uv" uv >/dev/null 2>&1 \
    && "$VENV/.robocore-uv/bin/uv" --version >/dev/null 2>&1 && echo "$VENV/.robocore-uv/bin/uv"
}
# ROBOCORE_EXTRAS: the extras installed with robocore (default dev: the test tools; scripts/demo asks for none,
# a quarter of the downloads). A venv that has the dev extras serves a demo too.
extras="${ROBOCORE_EXTRAS-dev}"
case "$extras" in
  dev) stamp="$VENV/.robocore-installed" ;;
  "") stamp="$VENV/.robocore-installed-core" ;;
  *) stamp="$VENV/.robocore-installed-${extras//[^a-z0-9-]/_}" ;;
esac
fresh() { [ -f "$1" ] && ! [ "$ROOT/pyproject.toml" -nt "$1" ]; }
if ! fresh "$stamp" && ! { [ -z "$extras" ] && fresh "$VENV/.robocore-installed"; }; then
  spec="$ROOT${extras:+[$extras]}"
  # the same packages, installed by uv (from PyPI: downloads and installs side by side) when it can be had,
  # else by pip as before; ROBOCORE_INSTALLER=pip forces pip
  if [ "$installer" = uv ] && uv="$(find_uv)"; then
    # pip too: tests drive pip with git+file requirements; uv too: the next install needs no fetch
    "$uv" pip install -q --python "$VENV/bin/python" --upgrade pip uv -e "$spec"
    rm -rf "$VENV/.robocore-uv"
  else
    "$VENV/bin/python" -m pip --version >/dev/null 2>&1 || "$VENV/bin/python" -m ensurepip -q
    "$VENV/bin/python" -m pip install -q --upgrade pip >/dev/null
    "$VENV/bin/python" -m pip install -q -e "$spec"
  fi
  # bytecode for every installed module, as pip writes at install time (uv does not): a Python started with
  # PYTHONDONTWRITEBYTECODE set (CI machines often set it) would otherwise compile robocore's imports from source
  # at every start, about 0.25 s of each robocore command
  # (a file that does not compile, such as a package's template, is left to Python as before)
  purelib="$("$VENV/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"
  "$VENV/bin/python" -m compileall -q -j0 "$purelib" >/dev/null 2>&1 || true
  touch "$stamp"
fi
# robocore's own modules (installed editable: their bytecode goes stale as the sources change)
"$VENV/bin/python" -m compileall -q -j0 "$ROOT/robocore" >/dev/null 2>&1 || true
if [ -n "$debs_pid" ]; then
  wait "$debs_pid"
fi
# arm64 on an amd64 test machine (docs/arm64.md): Debian's qemu-user-static puts qemu-aarch64.conf on disk
# but registers nothing where no init system runs. As root: mount binfmt_misc if needed, then write that line to
# its register file (flags POF: F opens the interpreter now, so arm64 binaries run in any container, Docker in
# Docker included). robocore itself never changes the kernel: without this it says what to run.
if [ "${ROBOCORE_TEST_TOOLS:-0}" = 1 ] && [ "$(uname -m)" = x86_64 ] && [ ! -e /proc/sys/fs/binfmt_misc/qemu-aarch64 ]; then
  conf=/usr/lib/binfmt.d/qemu-aarch64.conf
  if [ "$(id -u)" = 0 ] && [ -r "$conf" ]; then
    [ -e /proc/sys/fs/binfmt_misc/register ] || mount binfmt_misc -t binfmt_misc /proc/sys/fs/binfmt_misc
    grep -m1 '^:qemu-aarch64:' "$conf" > /proc/sys/fs/binfmt_misc/register
    echo "registered qemu-aarch64 with binfmt_misc" >&2
  else
    echo "warning: qemu-aarch64 is not registered with binfmt_misc: the arm64 suites will fail; as root:" \
      "apt-get install qemu-user-static && grep '^:qemu-aarch64:' $conf > /proc/sys/fs/binfmt_misc/register" >&2
  fi
fi
export PATH="$VENV/bin:$PATH"
