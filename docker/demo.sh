#!/usr/bin/env bash
# Build and run the docker-compose demo, then copy the run out of the volume.
#
# Usage: docker/demo.sh [--offline] [--build-only] [--setup d|g | --routers] [--time-scale X]
#                       [--keep]
#   (default)       the base image is BASE_IMAGE if set, else the first of: python:3.11-slim
#                   if it is here, the local base eifp-swarm-base:bookworm if it is here,
#                   python:3.11-slim pulled from a registry, the local base built here as with
#                   --offline (root and debootstrap at hand); where none is possible it says
#                   in one line what it needs
#   --offline       no registry: build the local base image (docker/build-base-image.sh,
#                   reused when present) and download the wheels on the host
#                   (docker/fetch-wheels.sh); BASE_IMAGE defaults to eifp-swarm-base:bookworm
#   --build-only    build the image (EIFP_IMAGE, default eifp-swarm:latest) and stop: the
#                   image `python -m pytest tests` runs tests/docker against
#   --setup g       setup G with 16 robot containers (compose.setup-g.yaml); default d
#   --routers       setup D on two "hosts" joined through Zenoh routers
#                   (compose.routers.yaml: robots 2-3 behind a relay router)
#   --time-scale X  sim seconds per wall second (default 1)
#   --keep          leave the containers and the volume (default: `down -v` at the end)
# Environment: BASE_IMAGE (default python:3.11-slim, or the local base with --offline),
#   RUN_ID (default docker-<setup>-<time>), COMPOSE_PROJECT_NAME (default eifp-demo),
#   EIFP_IMAGE (default eifp-swarm:latest).
# The run directory is copied to runs/docker/<RUN_ID>/ (report.txt, metrics.json,
# trajectory.png, trajectory.csv, events.jsonl, ...). Exit status: the orchestrator's, i.e.
# the run's (0 every robot arrived with no contact, 1 not, 3 nothing to report).
set -euo pipefail
cd "$(dirname "$0")/.."

offline=0 setup=d keep=0 build_only=0
export TIME_SCALE=${TIME_SCALE:-1}
while [ "$#" -gt 0 ]; do
  case "$1" in
    --offline) offline=1 ;;
    --setup) setup=${2:?--setup needs d or g}; shift ;;
    --routers) setup=routers ;;
    --time-scale) TIME_SCALE=${2:?--time-scale needs a value}; shift ;;
    --keep) keep=1 ;;
    --build-only) build_only=1 ;;
    -h|--help) awk 'NR > 1 && /^#/ { sub(/^# ?/, ""); print; next } NR > 1 { exit }' "$0"; exit 0 ;;
    *) echo "demo: unknown argument $1" >&2; exit 2 ;;
  esac
  shift
done

files=(-f compose.yaml)
case "$setup" in
  d|setup_d) setup=d ;;
  g|setup_g) setup=g; files+=(-f compose.setup-g.yaml) ;;
  routers) files=(-f compose.routers.yaml) ;;
  *) echo "demo: --setup must be d or g, got $setup" >&2; exit 2 ;;
esac

if ! docker info >/dev/null 2>&1; then
  echo "demo: needs a running Docker Engine (docker info failed)" >&2
  exit 2
fi
if docker compose version >/dev/null 2>&1; then
  compose=(docker compose)
elif command -v docker-compose >/dev/null 2>&1; then
  compose=(docker-compose)
else
  echo "demo: neither 'docker compose' nor 'docker-compose' is available" >&2
  exit 2
fi

local_base=${LOCAL_BASE_IMAGE:-eifp-swarm-base:bookworm}
have_image() { docker image inspect "$1" >/dev/null 2>&1; }
can_debootstrap() {
  { [ "$(id -u)" = 0 ] || sudo -n true 2>/dev/null; } &&
    { command -v debootstrap >/dev/null 2>&1 || [ -x /usr/sbin/debootstrap ]; }
}
build_local_base() {
  docker/build-base-image.sh
  docker/fetch-wheels.sh
  export BASE_IMAGE=${BASE_IMAGE:-$local_base}
}
if [ "$offline" = 1 ]; then
  build_local_base
elif [ -z "${BASE_IMAGE:-}" ]; then
  # Offline where it can be: an image already here, a registry, or a base built here.
  if have_image python:3.11-slim; then
    export BASE_IMAGE=python:3.11-slim
  elif have_image "$local_base"; then
    export BASE_IMAGE=$local_base
    # Its containers may not reach PyPI: install from wheels downloaded on the host.
    docker/fetch-wheels.sh
  elif timeout 60 docker pull -q python:3.11-slim >/dev/null 2>&1; then
    export BASE_IMAGE=python:3.11-slim
  elif can_debootstrap; then
    echo "demo: no registry: building the local base image from Debian's mirror (--offline)"
    build_local_base
  else
    echo "demo: needs a base image with Python 3.11: a registry (python:3.11-slim), or root and debootstrap to build one (apt-get install debootstrap), or BASE_IMAGE=<local image>" >&2
    exit 2
  fi
fi
export RUN_ID=${RUN_ID:-docker-$setup-$(date +%Y%m%d-%H%M%S)}
export COMPOSE_PROJECT_NAME=${COMPOSE_PROJECT_NAME:-eifp-demo}
compose+=("${files[@]}")

cleanup() {
  if [ "$keep" = 0 ]; then
    "${compose[@]}" down --volumes --remove-orphans --timeout 20 >/dev/null 2>&1 || true
  fi
}
trap cleanup EXIT

echo "demo: setup $setup, run $RUN_ID, base image $BASE_IMAGE, ${compose[*]}"
"${compose[@]}" build world
if [ "$build_only" = 1 ]; then
  echo "demo: built ${EIFP_IMAGE:-eifp-swarm:latest} (base $BASE_IMAGE)"
  exit 0
fi
# Attached: every container's log, until the last one has exited (robots leave at the end of
# the run, the world after them, the orchestrator once the report is written).
"${compose[@]}" up --no-build || true

# By label (Compose v1 and v2 both set them; v2's `ps` leaves out exited containers).
orchestrator=$(docker ps -a -q --filter "label=com.docker.compose.project=$COMPOSE_PROJECT_NAME" \
  --filter label=com.docker.compose.service=orchestrator | head -n 1)
if [ -z "$orchestrator" ]; then
  echo "demo: no orchestrator container was created" >&2
  exit 3
fi
status=$(docker inspect -f '{{.State.ExitCode}}' "$orchestrator")
mkdir -p runs/docker
rm -rf "runs/docker/$RUN_ID"
if docker cp "$orchestrator:/runs/$RUN_ID" "runs/docker/$RUN_ID"; then
  echo "demo: the run is in runs/docker/$RUN_ID (report.txt, metrics.json, trajectory.png)"
fi
"${compose[@]}" ps -a
echo "demo: orchestrator exit status $status"
exit "$status"
