#!/usr/bin/env bash
# Build (once) and cache Debian chroots holding a distribution Blender:
#   trixie -> Blender 4.3 on Python 3.13,  sid -> Blender 5.x on Python 3.14.
# Usage: tests/blender/chroots.sh [trixie] [sid]
# Exit 0 when every requested chroot is ready; exit 3 with one line "SKIP: reason" when it cannot be
# built here (not root, no debootstrap, no network, not enough disk).
set -euo pipefail
CACHE="${BPY_PIPELINE_CHROOTS:-/var/cache/bpy_pipeline/chroots}"
MIRROR="${BPY_PIPELINE_DEBIAN_MIRROR:-http://deb.debian.org/debian}"
SUITES=("$@"); [ ${#SUITES[@]} -gt 0 ] || SUITES=(trixie sid)
PACKAGES="blender xvfb xauth xdotool imagemagick python3-pip python3-numpy python3-yaml libgl1-mesa-dri ca-certificates"
# Recommended by Debian's Blender 5.x, needed by its extension system (bl_pkg imports them at start-up).
EXTRAS="python3-cattr python3-requests"
IN_CHROOT=(env -i PATH=/usr/sbin:/usr/bin:/sbin:/bin HOME=/root LC_ALL=C DEBIAN_FRONTEND=noninteractive)
NEED_GB=6

skip() { echo "SKIP: $*"; exit 3; }

ready() { [ -x "$CACHE/$1/usr/bin/blender" ] && [ -f "$CACHE/$1/.bpy_pipeline_ready" ]; }

mount_chroot() {  # mount_chroot DIR: /proc, /dev, /dev/shm (idempotent)
  local d="$1"
  mountpoint -q "$d/proc" || mount -t proc proc "$d/proc"
  mountpoint -q "$d/dev" || mount --bind /dev "$d/dev"
  mountpoint -q "$d/dev/shm" || mount --bind /dev/shm "$d/dev/shm"
}
umount_chroot() {
  local d="$1"
  for m in dev/shm dev proc; do mountpoint -q "$d/$m" && umount -l "$d/$m" || true; done
}

all_ready=1
for s in "${SUITES[@]}"; do ready "$s" || all_ready=0; done
if [ $all_ready = 1 ]; then echo "chroots ready in $CACHE: ${SUITES[*]}"; exit 0; fi

[ "$(id -u)" = 0 ] || skip "building Blender chroots needs root (debootstrap, mount)"
command -v debootstrap >/dev/null || skip "debootstrap not installed (apt-get install debootstrap)"
mkdir -p "$CACHE"
avail_gb=$(( $(df -Pk "$CACHE" | awk 'NR==2 {print $4}') / 1024 / 1024 ))
[ "$avail_gb" -ge "$NEED_GB" ] || skip "only ${avail_gb} GB free under $CACHE, ${NEED_GB} GB needed"
curl -sfI --max-time 20 "$MIRROR/dists/sid/Release" >/dev/null 2>&1 \
  || wget -q --spider --timeout=20 "$MIRROR/dists/sid/Release" 2>/dev/null \
  || skip "Debian mirror $MIRROR unreachable"

for s in "${SUITES[@]}"; do
  ready "$s" && continue
  dir="$CACHE/$s"; part="$CACHE/$s.partial"
  echo "== building chroot $s in $dir"
  [ -d "$part" ] && { umount_chroot "$part"; rm -rf --one-file-system "$part"; }
  [ -d "$dir" ] && { umount_chroot "$dir"; rm -rf --one-file-system "$dir"; }
  debootstrap --variant=minbase "$s" "$part" "$MIRROR" >"$CACHE/$s.debootstrap.log" 2>&1 \
    || { tail -5 "$CACHE/$s.debootstrap.log"; skip "debootstrap $s failed (log: $CACHE/$s.debootstrap.log)"; }
  ln -sf /proc/self/mounts "$part/etc/mtab"
  cp /etc/resolv.conf "$part/etc/resolv.conf" 2>/dev/null || true
  # the mirror may serve a dated snapshot whose Release file is past its Valid-Until
  echo 'Acquire::Check-Valid-Until "false";' >"$part/etc/apt/apt.conf.d/99bpy-pipeline-snapshot"
  mount_chroot "$part"
  trap 'umount_chroot "$part"' EXIT
  chroot "$part" "${IN_CHROOT[@]}" sh -c \
    "apt-get update -q && apt-get install -y -q --no-install-recommends $PACKAGES && { apt-get install -y -q --no-install-recommends $EXTRAS || true; } && apt-get clean" >"$CACHE/$s.apt.log" 2>&1 \
    || { tail -5 "$CACHE/$s.apt.log"; umount_chroot "$part"; skip "apt-get install in $s failed (log: $CACHE/$s.apt.log)"; }
  # pip reaches PyPI through the same CA bundle as this machine (its /etc/pip.conf sets cert=).
  [ -f /etc/ssl/certs/ca-certificates.crt ] && cp /etc/ssl/certs/ca-certificates.crt "$part/etc/ssl/certs/ca-certificates.crt"
  mkdir -p "$part/etc"
  printf '[global]\ncert = /etc/ssl/certs/ca-certificates.crt\ndisable-pip-version-check = true\n' >"$part/etc/pip.conf"
  chroot "$part" "${IN_CHROOT[@]}" python3 -m pip install -q --break-system-packages --root-user-action=ignore embreex >"$CACHE/$s.pip.log" 2>&1 \
    || { tail -5 "$CACHE/$s.pip.log"; umount_chroot "$part"; skip "pip install embreex in $s failed (log: $CACHE/$s.pip.log)"; }
  chroot "$part" "${IN_CHROOT[@]}" python3 -c "import embreex, numpy, yaml" || { umount_chroot "$part"; skip "embreex/numpy/yaml not importable in $s"; }
  chroot "$part" "${IN_CHROOT[@]}" blender --version | head -1 >"$part/.bpy_pipeline_ready"
  umount_chroot "$part"
  trap - EXIT
  mv "$part" "$dir"
  echo "   $(cat "$dir/.bpy_pipeline_ready") in $dir"
done
