#!/bin/sh
# Entry point of the simulated robot host: sshd (key from $AUTHORIZED_KEY) plus dockerd
# (extra daemon flags from $DOCKERD_ARGS, e.g. a TLS or plain TCP listener).
set -eu
mkdir -p /run/sshd /root/.ssh
chmod 700 /root/.ssh
if [ -n "${AUTHORIZED_KEY:-}" ]; then
    printf '%s\n' "$AUTHORIZED_KEY" > /root/.ssh/authorized_keys
    chmod 600 /root/.ssh/authorized_keys
fi
ssh-keygen -A >/dev/null
# The kernel's binfmt_misc entries, readable as on a real machine (robocore's doctor and run read
# qemu-aarch64 there before running arm64 images on an amd64 daemon). Best effort.
if [ -d /proc/sys/fs/binfmt_misc ] && [ ! -e /proc/sys/fs/binfmt_misc/register ]; then
    mount -t binfmt_misc binfmt_misc /proc/sys/fs/binfmt_misc 2>/dev/null || true
fi
/usr/sbin/sshd -e
# Optional: wait for files put into the container after it started (e.g. TLS certificates for its address).
if [ -n "${DOCKERD_WAIT_FILE:-}" ]; then
    while [ ! -f "$DOCKERD_WAIT_FILE" ]; do sleep 0.2; done
fi
exec dockerd --host unix:///var/run/docker.sock ${DOCKERD_ARGS:-}
