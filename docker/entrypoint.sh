#!/bin/sh
# Entry point of the eifp-swarm image: the first argument is the container's role.
#
#   certs         the run's CA and certificates (`orchestrator compose certs`): one
#                 directory per service under TLS_ROOT (each a volume of that service
#                 alone); runs once, as root, before every other service
#   world         resolve the setup into <RUNS_DIR>/<RUN_ID>/scenario.input.yaml, then run
#                 `python -m world`: a Zenoh router listening on LISTEN (mutual TLS, the
#                 run's access control), recording the run into <RUNS_DIR>/<RUN_ID>; it
#                 starts once every robot is alive
#   robot         `python -m agent` for robot ROBOT_ID, a client of the router at CONNECT
#   router        `python -m world.router`: a relay router on another "host" for the robots
#                 ROUTER_ROBOTS, certificate router-ROUTER_NAME, listening on LISTEN and
#                 dialling the world's router at CONNECT (compose.routers.yaml); it leaves
#                 once the run is over
#   orchestrator  with no argument, or only options (compose.yaml, compose.live.yaml):
#                 `orchestrator compose await`: waits for every robot, follows the run,
#                 writes metrics.json, trajectory.png, report.txt and run.json into the run
#                 directory and exits with the run's status (README, "Exit codes");
#                 with a subcommand (`docker run IMAGE orchestrator list`): the CLI itself
#   anything else is run as a command (e.g. `bash`, `orchestrator list`)
#
# Environment (defaults in brackets): RUN_ID [demo], SETUP [setup_d], ROBOTS (robot services
# in the compose file; the setup must have as many robots) [not checked], AGENTS, PLANNER,
# SEED [0], ROBOT_ID (robot), CONNECT [tls/world:7447], LISTEN [tls/0.0.0.0:7447],
# RUNS_DIR [/runs], TIME_SCALE [1], STARTUP_TIMEOUT_S [300], TLS_DIR (this service's
# certificate, key and the run's CA) [/tls], TLS_ROOT (certs) [/tls], RELAYS (certs, world:
# the relay routers and their robots, e.g. "b=2,3 c=4-7") [none], WORLD_ZID (world: its
# Zenoh id; robot: the world's, needed behind a relay) [random / the router dialled],
# ROUTER_NAME and ROUTER_ROBOTS (router). Extra arguments go to the role's command.
set -eu

role=${1:-help}
[ "$#" -gt 0 ] && shift

RUN_ID=${RUN_ID:-demo}
SETUP=${SETUP:-setup_d}
RUNS_DIR=${RUNS_DIR:-/runs}
CONNECT=${CONNECT:-tls/world:7447}
LISTEN=${LISTEN:-tls/0.0.0.0:7447}
TLS_DIR=${TLS_DIR:-/tls}
TIME_SCALE=${TIME_SCALE:-1}
STARTUP_TIMEOUT_S=${STARTUP_TIMEOUT_S:-300}

# Setup options, the same in the world's and the orchestrator's container.
setup_args() {
  printf '%s\n' --setup "$SETUP" --run "$RUN_ID" --runs-dir "$RUNS_DIR" --seed "${SEED:-0}"
  [ -n "${ROBOTS:-}" ] && printf '%s\n' --robots "$ROBOTS"
  [ -n "${AGENTS:-}" ] && printf '%s\n' --agents "$AGENTS"
  [ -n "${PLANNER:-}" ] && printf '%s\n' --planner "$PLANNER"
  return 0
}

# Wait (up to STARTUP_TIMEOUT_S) for this service's certificate: the certs service writes it.
await_certs() {
  waited=0
  while [ ! -r "$TLS_DIR/ca.pem" ] || [ ! -r "$TLS_DIR/$1.key" ]; do
    if [ "$waited" -ge "$STARTUP_TIMEOUT_S" ]; then
      echo "eifp-entrypoint: no certificate $TLS_DIR/$1.pem after $STARTUP_TIMEOUT_S s" >&2
      exit 6
    fi
    sleep 1
    waited=$((waited + 1))
  done
}

case "$role" in
  certs)
    if [ -z "${ROBOTS:-}" ]; then
      echo "eifp-entrypoint: the certs role needs ROBOTS in the environment" >&2
      exit 2
    fi
    for relay in ${RELAYS:-}; do
      set -- "$@" --relay "${relay%%=*}"
    done
    exec orchestrator compose certs --run "$RUN_ID" --robots "$ROBOTS" \
      --out "${TLS_ROOT:-/tls}" "$@"
    ;;
  world)
    # One argument per line (no value here contains a newline).
    IFS='
'
    # shellcheck disable=SC2046
    orchestrator compose scenario $(setup_args)
    unset IFS
    await_certs world
    for relay in ${RELAYS:-}; do
      set -- "$@" --relay "$relay"
    done
    [ -n "${WORLD_ZID:-}" ] && set -- "$@" --zid "$WORLD_ZID"
    exec python -m world --run "$RUN_ID" \
      --scenario "$RUNS_DIR/$RUN_ID/scenario.input.yaml" --out "$RUNS_DIR/$RUN_ID" \
      --listen "$LISTEN" --time-scale "$TIME_SCALE" --wait-robots-s "$STARTUP_TIMEOUT_S" \
      --tls "$TLS_DIR" "$@"
    ;;
  robot)
    if [ -z "${ROBOT_ID:-}" ]; then
      echo "eifp-entrypoint: the robot role needs ROBOT_ID in the environment" >&2
      exit 2
    fi
    await_certs "robot-$ROBOT_ID"
    [ -n "${WORLD_ZID:-}" ] && set -- "$@" --world-zid "$WORLD_ZID"
    exec python -m agent --run "$RUN_ID" --id "$ROBOT_ID" --connect "$CONNECT" \
      --startup-timeout-s "$STARTUP_TIMEOUT_S" --tls "$TLS_DIR" "$@"
    ;;
  router)
    if [ -z "${ROUTER_NAME:-}" ] || [ -z "${ROUTER_ROBOTS:-}" ]; then
      echo "eifp-entrypoint: the router role needs ROUTER_NAME and ROUTER_ROBOTS" >&2
      exit 2
    fi
    await_certs "router-$ROUTER_NAME"
    exec python -m world.router --run "$RUN_ID" --name "$ROUTER_NAME" \
      --robots "$ROUTER_ROBOTS" --listen "$LISTEN" --connect "$CONNECT" --tls "$TLS_DIR" \
      --wait-world-s "$STARTUP_TIMEOUT_S" "$@"
    ;;
  orchestrator)
    case "${1:-}" in
      ""|-*) ;;                          # the demo's role: follow the run (below)
      *) exec orchestrator "$@" ;;       # a subcommand: run the CLI as given
    esac
    IFS='
'
    # shellcheck disable=SC2046
    set -- $(setup_args) --connect "$CONNECT" --time-scale "$TIME_SCALE" \
      --startup-timeout-s "$STARTUP_TIMEOUT_S" --tls "$TLS_DIR" "$@"
    unset IFS
    await_certs orchestrator
    exec orchestrator compose await "$@"
    ;;
  help|-h|--help)
    awk 'NR > 1 && /^#/ { sub(/^# ?/, ""); print; next } NR > 1 { exit }' "$0"
    ;;
  *)
    exec "$role" "$@"
    ;;
esac
