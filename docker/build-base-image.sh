#!/usr/bin/env bash
# Build a local base image for the demo where no registry can be reached: a Debian bookworm
# root filesystem from debootstrap (Debian's package mirror, not a registry) with python3
# (3.11) and its venv module, imported with `docker import`. The demo then builds with
# BASE_IMAGE set to it (docker/demo.sh --offline does all of this).
#
# Usage: docker/build-base-image.sh [--rebuild] [--install-debootstrap]
#   An existing image is reused; --rebuild runs debootstrap again and replaces it.
#   --install-debootstrap  install debootstrap with apt-get if it is missing (otherwise the
#                          script stops and says so: it never installs packages unasked)
# Environment: LOCAL_BASE_IMAGE (tag, default eifp-swarm-base:bookworm), ROOTFS_DIR (default
#   /var/tmp/eifp-base/rootfs), DEBIAN_MIRROR (default http://deb.debian.org/debian).
# Needs root (or password-less sudo) and debootstrap. Takes about a minute.
set -euo pipefail

IMAGE=${LOCAL_BASE_IMAGE:-eifp-swarm-base:bookworm}
ROOTFS=${ROOTFS_DIR:-/var/tmp/eifp-base/rootfs}
MIRROR=${DEBIAN_MIRROR:-http://deb.debian.org/debian}
SUITE=bookworm  # its python3 is 3.11, the version docker/fetch-wheels.sh downloads for

rebuild=0 install=0
for arg in "$@"; do
  case "$arg" in
    --rebuild) rebuild=1 ;;
    --install-debootstrap) install=1 ;;
    -h|--help) awk 'NR > 1 && /^#/ { sub(/^# ?/, ""); print; next } NR > 1 { exit }' "$0"; exit 0 ;;
    *) echo "build-base-image: unknown argument $arg" >&2; exit 2 ;;
  esac
done

if [ "$rebuild" = 0 ] && docker image inspect "$IMAGE" >/dev/null 2>&1; then
  echo "build-base-image: $IMAGE exists; reusing it (--rebuild to replace it)"
  exit 0
fi

as_root=()
if [ "$(id -u)" != 0 ]; then
  if command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null; then
    as_root=(sudo -n)
  else
    echo "build-base-image: debootstrap needs root (or password-less sudo)" >&2
    exit 1
  fi
fi
if ! command -v debootstrap >/dev/null 2>&1 && [ ! -x /usr/sbin/debootstrap ]; then
  # Debian's package mirror is reachable where a registry is not: install it from there,
  # when asked to.
  if [ "$install" = 0 ]; then
    echo "build-base-image: needs debootstrap (apt-get install debootstrap, or rerun with --install-debootstrap)" >&2
    exit 1
  elif command -v apt-get >/dev/null 2>&1; then
    echo "build-base-image: installing debootstrap (apt-get)"
    "${as_root[@]}" env DEBIAN_FRONTEND=noninteractive apt-get update -qq >/dev/null
    "${as_root[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq debootstrap >/dev/null
  else
    echo "build-base-image: debootstrap is missing and there is no apt-get to install it" >&2
    exit 1
  fi
fi

# A root filesystem from an earlier, complete debootstrap is reused unless --rebuild.
marker="$ROOTFS.complete"
if [ "$rebuild" = 1 ] || [ ! -f "$marker" ] || [ ! -x "$ROOTFS/usr/bin/python3" ]; then
  log=$(mktemp -t eifp-debootstrap.XXXXXX.log)
  echo "build-base-image: debootstrap $SUITE into $ROOTFS (log: $log)"
  "${as_root[@]}" rm -rf "$ROOTFS" "$marker"
  "${as_root[@]}" mkdir -p "$(dirname "$ROOTFS")"
  if ! "${as_root[@]}" env PATH="/usr/sbin:/sbin:$PATH" debootstrap --variant=minbase \
      --include=python3,python3-venv,python3-pip,ca-certificates "$SUITE" "$ROOTFS" "$MIRROR" \
      > "$log" 2>&1; then
    tail -n 20 "$log" >&2
    echo "build-base-image: debootstrap failed (full log: $log)" >&2
    exit 1
  fi
  rm -f "$log"
  # Package caches are of no use in the image.
  "${as_root[@]}" sh -c "rm -rf '$ROOTFS'/var/cache/apt/archives/*.deb '$ROOTFS'/var/lib/apt/lists/*"
  "${as_root[@]}" touch "$marker"
fi

echo "build-base-image: docker import -> $IMAGE"
"${as_root[@]}" tar -C "$ROOTFS" -c . \
  | docker import -c 'CMD ["/bin/bash"]' -c 'ENV LANG=C.UTF-8' - "$IMAGE" >/dev/null
docker run --rm "$IMAGE" python3 -c \
  'import sys, venv; assert sys.version_info[:2] == (3, 11), sys.version; print("python", sys.version.split()[0])'
echo "build-base-image: $IMAGE ready ($(docker image inspect -f '{{.Size}}' "$IMAGE" | awk '{printf "%d MB", $1 / 1e6}'))"
