# robocore's VNC desktop, run as `bash -c "<this text>" robocore-desktop` in a desktop component.
# An X server with a VNC server built in (TigerVNC's Xvnc), a small window manager when one is
# installed, and noVNC served by websockify. Every setting comes from the environment that robocore
# gives the container; nothing is interpolated into this text.
#
# X clients of other components reach the display through the socket folder, a volume shared with
# them (and, on host networking, through the X server's abstract socket); either way they need the
# cookie this script writes beside the socket.
set -eu
n=$ROBOCORE_DESKTOP_DISPLAY
sockets=/tmp/.X11-unix
auth=$ROBOCORE_DESKTOP_XAUTHORITY
log() { printf 'robocore-desktop: %s\n' "$*"; }

for tool in Xvnc xauth websockify; do
  command -v "$tool" >/dev/null || { log "$tool is missing: add tigervnc-standalone-server, novnc and websockify to apt_packages"; exit 127; }
done
web=${ROBOCORE_DESKTOP_WEB:-/usr/share/novnc}
[ -d "$web" ] || { log "no noVNC web folder at $web: add novnc to apt_packages"; exit 127; }

# A restarted container keeps /tmp and the socket volume: clear the previous server's lock and socket,
# and withdraw the clients' cookie: until the desktop is complete, clients are refused (their containers
# restart and try again). A window mapped while the window manager starts up can stay invisible.
rm -f -- "/tmp/.X$n-lock" "$sockets/X$n" "$auth"
mkdir -p -- "$sockets"
chmod 1777 -- "$sockets"

# A fresh cookie on every start, with the wildcard address family so that it matches any client's
# host name (clients on a bridge network have their own). The server reads its own copy.
umask 077
server_auth=/tmp/robocore-desktop.xauth
cookie=$(od -An -N16 -tx1 /dev/urandom | tr -d ' \n')
rm -f -- "$server_auth" "$server_auth.local"
: > "$server_auth.local"
: > "$server_auth"
xauth -q -f "$server_auth.local" add ":$n" MIT-MAGIC-COOKIE-1 "$cookie"
xauth -q -f "$server_auth.local" nlist ":$n" | sed -e 's/^..../ffff/' | xauth -q -f "$server_auth" nmerge -
rm -f -- "$server_auth.local"

# The project's VNC password, when robocore mounts one (every desktop but desktop.open: true): vncpasswd
# turns it into Xvnc's password file, readable by this container's user only. Never an argument, never
# in the environment.
security=(-SecurityTypes None)
rfbauth=/tmp/robocore-desktop.passwd
rm -f -- "$rfbauth"
if [ -n "${ROBOCORE_DESKTOP_PASSWORD_FILE:-}" ]; then
  command -v vncpasswd >/dev/null || { log "vncpasswd is missing: add tigervnc-tools to apt_packages"; exit 127; }
  [ -f "$ROBOCORE_DESKTOP_PASSWORD_FILE" ] && [ -s "$ROBOCORE_DESKTOP_PASSWORD_FILE" ] || {
    log "no VNC password at $ROBOCORE_DESKTOP_PASSWORD_FILE: run robocore stage (and sync for a robot)"; exit 1; }
  vncpasswd -f < "$ROBOCORE_DESKTOP_PASSWORD_FILE" > "$rfbauth"
  [ -s "$rfbauth" ] || { log "vncpasswd made no password file"; exit 1; }
  security=(-SecurityTypes VncAuth -PasswordFile "$rfbauth")
fi

pids=""
stop() { trap - TERM INT; [ -z "$pids" ] || kill $pids 2>/dev/null || true; wait || true; exit "${1:-0}"; }
trap 'stop 0' TERM INT

Xvnc ":$n" -auth "$server_auth" -geometry "$ROBOCORE_DESKTOP_SIZE" -depth 24 -nolisten tcp \
  -rfbport "$ROBOCORE_DESKTOP_VNC_PORT" -interface 127.0.0.1 "${security[@]}" -AlwaysShared \
  -desktop "${ROBOCORE_DESKTOP_NAME:-robocore}" &
xvnc=$!
pids="$xvnc"
tries=0
until [ -S "$sockets/X$n" ]; do
  if ! kill -0 "$xvnc" 2>/dev/null; then
    log "the X server of display :$n stopped; is display :$n or port $ROBOCORE_DESKTOP_VNC_PORT taken on this host? (desktop.display)"
    stop 1
  fi
  tries=$((tries + 1))
  [ "$tries" -lt 300 ] || { log "display :$n did not come up in 30 s"; stop 1; }
  sleep 0.1
done
export DISPLAY=":$n" XAUTHORITY="$server_auth"

# The window manager, when one is installed; openbox says when its start-up is over, the others get a second.
wm_ready=/tmp/robocore-desktop.wm-ready
rm -f -- "$wm_ready"
for wm in openbox fluxbox icewm twm; do
  command -v "$wm" >/dev/null || continue
  if [ "$wm" = openbox ]; then
    openbox --startup "touch $wm_ready" &
    pids="$pids $!"
  else
    "$wm" &
    pids="$pids $!"
    sleep 1
    touch "$wm_ready"
  fi
  tries=0
  until [ -e "$wm_ready" ] || [ "$tries" -ge 100 ]; do tries=$((tries + 1)); sleep 0.1; done
  break
done

websockify --web "$web" "$ROBOCORE_DESKTOP_LISTEN:$ROBOCORE_DESKTOP_WEB_PORT" "127.0.0.1:$ROBOCORE_DESKTOP_VNC_PORT" &
pids="$pids $!"
# The desktop is complete: hand the clients their cookie (made beside its name, then renamed over it).
umask 022
cp -- "$server_auth" "$auth.new"
chmod 0644 -- "$auth.new"
mv -f -- "$auth.new" "$auth"
log "display :$n ready (VNC security: ${security[1]}); noVNC on port $ROBOCORE_DESKTOP_WEB_PORT (/vnc.html), VNC on 127.0.0.1:$ROBOCORE_DESKTOP_VNC_PORT"

# The desktop lives as long as every part of it: the first to stop ends the container (its restart
# policy starts it again).
set +e
wait -n
code=$?
log "a part of the desktop stopped (exit $code)"
stop "$code"
