#!/bin/sh
# Entry point of the simulated robot host: sshd (key from $AUTHORIZED_KEY) plus dockerd.
set -eu
mkdir -p /run/sshd /root/.ssh
chmod 700 /root/.ssh
if [ -n "${AUTHORIZED_KEY:-}" ]; then
    printf '%s\n' "$AUTHORIZED_KEY" > /root/.ssh/authorized_keys
    chmod 600 /root/.ssh/authorized_keys
fi
ssh-keygen -A >/dev/null
/usr/sbin/sshd -e
exec dockerd --host unix:///var/run/docker.sock ${DOCKERD_ARGS:-}
