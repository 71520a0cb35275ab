"""The script a Fast DDS discovery server container runs before the server: the restart hold, its profile, and
a supervision that tells a clean stop from an unclean end (:data:`DISCOVERY_SCRIPT`)."""

from __future__ import annotations

from robocore.plan.naming import INIT_SIGNALS_GROUP

#: In a discovery server container: the state volume (markers that the server ran before) and its profile.
DISCOVERY_STATE = "/robocore/discovery"
DISCOVERY_PROFILE = "/tmp/robocore-discovery.xml"
#: Seconds between a supervised server's heartbeats (the mtime of ``alive`` in the state volume).
HEARTBEAT_SECONDS = 1
#: The discovery container's command (argv: this script, then ``fastdds discovery ...``); fixed text, values come
#: from the environment.
#:
#: * **The restart hold** (:func:`restart_hold_seconds`) is for a server that ended without a goodbye (a crash, a
#:   SIGKILL, a power cut) less than a lease ago: its clients still hold its previous instance. ``started`` in the
#:   state volume says the server ran and did not end cleanly; ``alive`` is touched every
#:   :data:`HEARTBEAT_SECONDS` while it serves (not during a hold: it says when its clients last heard from it), so
#:   the hold is only what is left of ROBOCORE_DS_HOLD since a heartbeat after its last sign of life (all of it
#:   when the clock is behind that). A server that ran before this script kept heartbeats (``started`` alone)
#:   holds in full.
#: * **A clean stop** (exit 0) removes both markers: the server unregistered itself from its clients, which drop
#:   it at once, so its next start (``docker restart``, a host's shutdown and boot, ``run``'s replace) serves
#:   without a hold.
#: * **Signals.** Under Docker's init with ROBOCORE's INIT_SIGNALS_GROUP set, SIGTERM reaches the whole group; the
#:   script and the ``fastdds`` tool's wrappers ignore it and wait for the server's own clean stop
#:   (docs/design-notes.md, "A graceful stop: Docker's init"); the hold's sleep still ends on it. Without that
#:   init (a Kubernetes pod), the script ``exec``\s the server, which then gets the signal itself, and keeps no
#:   heartbeat.
#: The script's statements, one per line as written here; each ends so that they can be joined into one line
#: (``;``, ``then``, ``&``): the container's command stays one line, as compose files and pods write it.
DISCOVERY_SCRIPT_LINES = (
    f'state="{DISCOVERY_STATE}"; hold="${{ROBOCORE_DS_HOLD:-0}}";',
    'if [ -e "$state/started" ] && [ "$hold" -gt 0 ]; then',
    '  left="$hold";',
    '  if [ -e "$state/alive" ]; then',
    '    now=$(date +%s); last=$(date -r "$state/alive" +%s 2>/dev/null || echo "$now");',
    f'    late=$((last + {HEARTBEAT_SECONDS} + hold - now));',
    '    if [ "$now" -gt "$last" ] && [ "$late" -lt "$hold" ]; then left="$late"; fi;',
    '  fi;',
    '  if [ "$left" -gt 0 ]; then',
    '    echo "robocore: discovery server restarted; silent for $left s so that clients drop the previous instance";',
    '    sleep "$left";',
    '  fi;',
    'fi;',
    'touch "$state/started";',
    f'printf "%s\\n" "$ROBOCORE_DS_XML" > {DISCOVERY_PROFILE};',
    f'if [ -z "${{{INIT_SIGNALS_GROUP}:-}}" ]; then rm -f "$state/alive"; exec "$@"; fi;',
    'trap "" TERM;',
    'touch "$state/alive";',
    '"$@" &',
    'server=$!;',
    # the beat writes with the shell's own redirection (no child that could outlive it and touch a removed marker),
    # on a regular builtin, whose failed redirection does not end the loop
    f'(while kill -0 "$server" 2>/dev/null; do true 2>/dev/null > "$state/alive"; sleep {HEARTBEAT_SECONDS}; done) &',
    'beat=$!;',
    'wait "$server"; code=$?;',
    'kill -KILL "$beat" 2>/dev/null; wait "$beat" 2>/dev/null;',
    'if [ "$code" -eq 0 ]; then rm -f "$state/started" "$state/alive"; fi;',
    'exit "$code"',
)
DISCOVERY_SCRIPT = " ".join(line.strip() for line in DISCOVERY_SCRIPT_LINES)
