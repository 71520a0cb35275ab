#!/bin/sh
# robocore dev shell: runs as root when the dev container starts (POSIX sh, any distro).
# Makes a user matching the developer (ROBOCORE_UID/GID/USER/HOME), reusing or renaming an
# image user that already has that UID or name, gives it passwordless sudo when the image
# has sudo, writes the login environment, then keeps the container alive for `docker exec`.
set -u

uid="${ROBOCORE_UID:?}"
gid="${ROBOCORE_GID:?}"
want="${ROBOCORE_USER:-dev}"
home="${ROBOCORE_HOME:-/home/$want}"
state=/run/robocore
mkdir -p "$state"
rm -f "$state/ready"

say() { echo "robocore-shell: $*"; }

passwd_field() { # passwd_field KEY COLUMN FIELD: field FIELD of the passwd entry whose column COLUMN is KEY
    awk -F: -v k="$1" -v c="$2" -v f="$3" '$c == k { print $f; exit }' /etc/passwd
}
group_field() {
    awk -F: -v k="$1" -v c="$2" -v f="$3" '$c == k { print $f; exit }' /etc/group
}
have() { command -v "$1" >/dev/null 2>&1; }

# --- the primary group -------------------------------------------------------------------
group="$(group_field "$gid" 3 1)"
if [ -z "$group" ]; then
    group="$want"
    if [ -n "$(group_field "$group" 1 1)" ]; then group="robocore$gid"; fi
    if have groupadd; then groupadd -g "$gid" "$group"
    else echo "$group:x:$gid:" >>/etc/group; fi
fi

# --- the user ------------------------------------------------------------------------------
user=""
if [ "$uid" = 0 ]; then
    user=root
else
    by_uid="$(passwd_field "$uid" 3 1)"
    by_name_uid="$(passwd_field "$want" 1 3)"
    if [ -n "$by_uid" ]; then
        user="$by_uid"
        if [ "$by_uid" != "$want" ] && [ -z "$by_name_uid" ] && have usermod; then
            # e.g. Ubuntu 24.04's `ubuntu` at UID 1000: rename it to the developer's name
            usermod -l "$want" "$by_uid" && user="$want"
        fi
        if have usermod; then usermod -g "$gid" -d "$home" -s /bin/bash "$user"; fi
    elif [ -n "$by_name_uid" ]; then
        # the name exists with another UID: give it the developer's UID
        user="$want"
        if have usermod; then usermod -o -u "$uid" -g "$gid" -d "$home" -s /bin/bash "$user"
        else say "cannot change the UID of $user (no usermod)"; fi
    else
        user="$want"
        if have useradd; then useradd -o -M -u "$uid" -g "$gid" -d "$home" -s /bin/bash "$user"
        else echo "$user:x:$uid:$gid::$home:/bin/bash" >>/etc/passwd; fi
    fi
fi

# --- supplementary groups: hardware groups of the image and the host's device groups ------
extra=""
for g in dialout video render input plugdev audio; do
    if [ -n "$(group_field "$g" 1 1)" ]; then extra="$extra $g"; fi
done
for g in ${ROBOCORE_EXTRA_GIDS:-}; do
    name="$(group_field "$g" 3 1)"
    if [ -z "$name" ]; then
        name="robocore-dev$g"
        if have groupadd; then groupadd -g "$g" "$name"; else echo "$name:x:$g:" >>/etc/group; fi
    fi
    extra="$extra $name"
done
if [ "$user" != root ] && [ -n "$extra" ] && have usermod; then
    for g in $extra; do usermod -a -G "$g" "$user" 2>/dev/null || true; done
fi

# --- passwordless sudo ----------------------------------------------------------------------
if have sudo; then
    mkdir -p /etc/sudoers.d
    printf '%s ALL=(ALL) NOPASSWD:ALL\n' "$user" >/etc/sudoers.d/robocore-shell
    chmod 0440 /etc/sudoers.d/robocore-shell
    rm -f "$state/no-sudo"
else
    : >"$state/no-sudo"
fi

# --- home (persistent, on the dev machine) ------------------------------------------------
mkdir -p "$home"
chown "$uid:$gid" "$home"
if [ ! -e "$home/.bashrc" ]; then
    cat >"$home/.bashrc" <<'RC'
# robocore dev shell: shortcuts, prompt and ROS environment (do not remove this line)
[ -f /robocore/shell/bashrc ] && . /robocore/shell/bashrc
# your own settings below; this home folder is kept in the project's .robocore/home/
RC
    chown "$uid:$gid" "$home/.bashrc"
fi
if [ ! -e "$home/.profile" ] && [ ! -e "$home/.bash_profile" ] && [ ! -e "$home/.bash_login" ]; then
    printf '%s\n' '# login shells read ~/.bashrc too' '[ -n "${BASH_VERSION:-}" ] && [ -f "$HOME/.bashrc" ] && . "$HOME/.bashrc"' >"$home/.profile"
    chown "$uid:$gid" "$home/.profile"
fi

# --- Wayland runtime directory ------------------------------------------------------------
if [ -n "${ROBOCORE_XDG_RUNTIME_DIR:-}" ] && [ -d "$ROBOCORE_XDG_RUNTIME_DIR" ]; then
    chown "$uid:$gid" "$ROBOCORE_XDG_RUNTIME_DIR" 2>/dev/null || true
    chmod 0700 "$ROBOCORE_XDG_RUNTIME_DIR" 2>/dev/null || true
fi

# --- login environment: login shells reset PATH in /etc/profile; restore the image's ------
printf '%s\n' "$PATH" >"$state/path"
mkdir -p /etc/profile.d
printf '%s\n' '# robocore dev shell' '[ -f /robocore/shell/profile.sh ] && . /robocore/shell/profile.sh' \
    >/etc/profile.d/zz-robocore-shell.sh
printf '%s\n' "$user" >"$state/user"
if ! have bash; then say "this image has no bash: the shell needs it"; fi

: >"$state/ready"
say "ready (user $user, uid $uid, gid $gid, home $home)"
trap 'exit 0' TERM INT HUP
while :; do
    sleep 3600 &
    wait $!
done
