#!/usr/bin/env bash
# Build and run the docker-compose demo, then copy the run out of the volume.
#
# Usage: docker/demo.sh [--offline] [--setup d|g | --routers] [--time-scale X] [--keep]
#   --offline       no registry: build the local base image (docker/build-base-image.sh,
#                   reused when present) and download the wheels on the host
#                   (docker/fetch-wheels.sh); BASE_IMAGE defaults to eifp-swarm-base:bookworm
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

offline=0 setup=d keep=0
export TIME_SCALE=${TIME_SCALE:-1}
while [ "$#" -gt 0 ]; do
  case "$1" in
    --offline) offline=1 ;;
    --setup) setup=${2:?--setup needs d or g}; shift ;;
    --routers) setup=routers ;;
    --time-scale) TIME_SCALE=${2:?--time-scale needs a value}; shift ;;
    --keep) keep=1 ;;
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

if docker compose version >/dev/null 2>&1; then
  compose=(docker compose)
elif command -v docker-compose >/dev/null 2>&1; then
  compose=(docker-compose)
else
  echo "demo: neither 'docker compose' nor 'docker-compose' is available" >&2
  exit 2
fi

if [ "$offline" = 1 ]; then
  docker/build-base-image.sh
  docker/fetch-wheels.sh
  export BASE_IMAGE=${BASE_IMAGE:-${LOCAL_BASE_IMAGE:-eifp-swarm-base:bookworm}}
fi
export BASE_IMAGE=${BASE_IMAGE:-python:3.11-slim}
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
