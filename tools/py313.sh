#!/usr/bin/env bash
# A Python 3.13 environment for the Blender 5.1 / 5.2 LTS leg: a Debian trixie root made with debootstrap,
# with a venv holding requirements-blender52.txt (bpy 5.2.3, numpy 2, scipy, scikit-fmm built from its sdist).
#
#   tools/py313.sh setup            build the root, or reuse it when its key matches
#   tools/py313.sh run CMD ARGS...  run CMD inside the root, in this repository (bind-mounted at the same
#                                   path), with the venv's bin/ first on PATH
#   tools/py313.sh check            exit 0 when this machine can build the root (root, debootstrap or apt-get)
#   tools/py313.sh ready            exit 0 when the root for the current key is built
#
# Needs root (debootstrap, mount, chroot) and Debian's package mirror; pip reaches PyPI with this machine's
# own pip configuration (config files, PIP_* variables, local file:// indexes and find-links), replicated
# inside the root. The root lives in $PY313_CACHE (default /var/cache/conformal-flatten/py313), one folder
# per key: a hash of requirements-blender52.txt and of how the root is built (suite, Debian packages,
# LAYOUT), so a change to either builds afresh and an unchanged key is reused across clones and worktrees
# (roots of older keys stay: remove them by hand). All mounts live in a private mount namespace
# (unshare -m), so they vanish with the command even when it is killed. The Debian mirror is the host's
# (its apt sources), or $DEBIAN_MIRROR.
set -euo pipefail
ROOT_DIR=$(cd "$(dirname "$0")/.." && pwd)
REQ="$ROOT_DIR/requirements-blender52.txt"
CACHE=${PY313_CACHE:-/var/cache/conformal-flatten/py313}
SUITE=trixie
host_mirror() {           # the first Debian (non-security) mirror in the host's apt sources
    cat /etc/apt/sources.list /etc/apt/sources.list.d/*.list /etc/apt/sources.list.d/*.sources 2>/dev/null \
        | grep -oE 'https?://[^ ]+/debian/?( |$)' | grep -v security | head -n 1 | tr -d ' ' || true
}
MIRROR=${DEBIAN_MIRROR:-$(host_mirror)}
MIRROR=${MIRROR:-http://deb.debian.org/debian}
# Python 3.13 with headers and a compiler (scikit-fmm's sdist), and the X11/GL libraries bpy links to
APT_PACKAGES="python3.13 python3.13-venv python3.13-dev build-essential ca-certificates \
libx11-6 libxext6 libxfixes3 libxi6 libxrender1 libxt6t64 libsm6 libice6 libxkbcommon0 libxxf86vm1 \
libgl1 libglx0 libopengl0 libegl1"
VENV=/opt/venv            # inside the root

LAYOUT=1                  # bump when the way the root is built changes
key=$( { printf '%s\n' "$SUITE" "$APT_PACKAGES" "$VENV" "$LAYOUT"; cat "$REQ"; } | sha256sum | cut -c1-16)
DIR="$CACHE/$SUITE-$key"
STAMP="$DIR/.ready"

log() { printf 'py313: %s\n' "$*" >&2; }
die() { log "$*"; exit 1; }

can_build() {
    [ "$(id -u)" = 0 ] || { log "needs root (debootstrap, mount, chroot)"; return 1; }
    command -v debootstrap >/dev/null || command -v apt-get >/dev/null \
        || { log "needs debootstrap, or apt-get to install it"; return 1; }
    command -v unshare >/dev/null && command -v chroot >/dev/null || { log "needs unshare and chroot"; return 1; }
}

# Local paths pip is configured with (file:// indexes, find-links, cert): bound read-only into the root.
pip_paths() {
    { python3 -m pip config list 2>/dev/null || true; env | grep '^PIP_' || true; } \
        | grep -oE "(file://)?/[^ '\"]+" | sed 's|^file://||' | while read -r p; do
            p=${p%/simple}; p=${p%/}
            [ -e "$p" ] && echo "$p"
        done | sort -u
}

pip_conf_files() {
    for f in /etc/pip.conf /etc/xdg/pip/pip.conf "$HOME/.config/pip/pip.conf" "$HOME/.pip/pip.conf" \
             ${PIP_CONFIG_FILE:-}; do
        [ -f "$f" ] && echo "$f"
    done
    return 0
}

# The body that runs inside a private mount namespace: mount, chroot, run "$@".
in_root() {
    local dir=$1; shift
    mount -t proc proc "$dir/proc"
    mount --rbind /dev "$dir/dev"
    mount --make-rslave "$dir/dev"
    mkdir -p "$dir/sys" && mount --rbind /sys "$dir/sys" && mount --make-rslave "$dir/sys"
    cp -L /etc/resolv.conf "$dir/etc/resolv.conf"
    [ -e "$dir/etc/mtab" ] || ln -s /proc/self/mounts "$dir/etc/mtab"
    local p
    for p in $(pip_paths); do
        if [ -d "$p" ]; then
            mkdir -p "$dir$p"; mount --bind "$p" "$dir$p"; mount -o remount,bind,ro "$dir$p"
        else                                 # a file (the CA bundle): copied, the root's packages may own it
            mkdir -p "$(dirname "$dir$p")"; cp -L "$p" "$dir$p"
        fi
    done
    for p in $(pip_conf_files); do mkdir -p "$(dirname "$dir$p")"; cp "$p" "$dir$p"; done
    mkdir -p "$dir$ROOT_DIR"
    mount --bind "$ROOT_DIR" "$dir$ROOT_DIR"
    RUN_TMP=$(mktemp -d "$dir/tmp/run.XXXXXX")
    trap 'rm -rf "$RUN_TMP"' EXIT
    chroot "$dir" /usr/bin/env -u PYTHONPATH -u VIRTUAL_ENV PATH="$VENV/bin:/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin" \
        HOME=/root TMPDIR="${RUN_TMP#"$dir"}" DEBIAN_FRONTEND=noninteractive LC_ALL=C.UTF-8 \
        /bin/bash -c 'cd "$1" && shift && exec "$@"' _ "$ROOT_DIR" "$@"
}

in_namespace() {     # in_namespace DIR CMD...
    local dir=$1; shift
    unshare -m --propagation private "$0" __inroot "$dir" "$@"
}

setup() {
    [ -f "$STAMP" ] && { log "reusing $DIR"; return 0; }
    can_build || die "cannot build the Python 3.13 root on this machine"
    mkdir -p "$CACHE"
    exec 9>"$CACHE/.lock"
    flock 9                                  # one builder at a time; the others then reuse its root
    [ -f "$STAMP" ] && { log "reusing $DIR"; return 0; }
    local t0=$SECONDS
    if ! command -v debootstrap >/dev/null; then
        log "installing debootstrap (apt-get)"
        apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq debootstrap >/dev/null
    fi
    local tmp="$DIR.tmp"
    rm -rf "$tmp"
    log "debootstrap $SUITE into $tmp"
    debootstrap --variant=minbase "$SUITE" "$tmp" "$MIRROR" >"$CACHE/debootstrap.log" 2>&1 \
        || { tail -20 "$CACHE/debootstrap.log" >&2; die "debootstrap failed (log: $CACHE/debootstrap.log)"; }
    log "apt-get install $APT_PACKAGES"
    in_namespace "$tmp" /bin/bash -c "apt-get update -qq && apt-get install -y -qq --no-install-recommends \
        $APT_PACKAGES >/dev/null && apt-get clean"
    log "venv and pip install -r $(basename "$REQ")"
    in_namespace "$tmp" /bin/bash -c "python3.13 -m venv $VENV && $VENV/bin/python -m pip install -q --upgrade pip \
        && { $VENV/bin/python -m pip install -q -r '$REQ' 2>&1 | grep -v 'is ignored: it is neither a file nor a directory' >&2; \
        test \${PIPESTATUS[0]} = 0; } && $VENV/bin/python -c 'import bpy, numpy, scipy, skfmm; \
print(\"bpy\", bpy.app.version_string, \"python\", __import__(\"sys\").version.split()[0], \"numpy\", numpy.__version__, \
\"scipy\", scipy.__version__)'"
    touch "$tmp/.ready"
    rm -rf "$DIR" && mv "$tmp" "$DIR"
    log "built $DIR in $((SECONDS - t0)) s"
}

case "${1:-}" in
    setup) setup ;;
    check) can_build ;;
    ready) [ -f "$STAMP" ] || die "no Python 3.13 root at $DIR (tools/py313.sh setup builds it)" ;;
    run) shift; [ -f "$STAMP" ] || die "no root at $DIR: run '$0 setup' first"; in_namespace "$DIR" "$@" ;;
    __inroot) shift; in_root "$@" ;;
    *) die "usage: $0 setup | run CMD... | check" ;;
esac
