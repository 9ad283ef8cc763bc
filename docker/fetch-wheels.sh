#!/usr/bin/env bash
# Download, on the host, every wheel the image needs into docker/wheels/ (git-ignored), so
# `docker build` installs with `pip install --no-index --find-links` and no container needs
# the network. The wheels are for the image's Python (CPython 3.11, manylinux, x86_64, glibc
# <= TARGET_GLIBC): the project's runtime dependencies and its build requirements, both read
# from pyproject.toml. The project itself is built from source inside the image.
#
# Usage: docker/fetch-wheels.sh [--refresh]
#   --refresh   download again even if the wheels for this pyproject.toml are present
# Environment: PYTHON (host interpreter with pip, Python >= 3.11; default .venv/bin/python,
#   else python3), TARGET_GLIBC (default 2.36, Debian bookworm), WHEELS_DIR (default
#   docker/wheels).
set -euo pipefail
cd "$(dirname "$0")/.."

refresh=0
for arg in "$@"; do
  case "$arg" in
    --refresh) refresh=1 ;;
    -h|--help) awk 'NR > 1 && /^#/ { sub(/^# ?/, ""); print; next } NR > 1 { exit }' "$0"; exit 0 ;;
    *) echo "fetch-wheels: unknown argument $arg" >&2; exit 2 ;;
  esac
done

PYTHON=${PYTHON:-}
if [ -z "$PYTHON" ]; then
  if [ -x .venv/bin/python ]; then PYTHON=.venv/bin/python; else PYTHON=python3; fi
fi
TARGET_GLIBC=${TARGET_GLIBC:-2.36}
WHEELS_DIR=${WHEELS_DIR:-docker/wheels}
mkdir -p "$WHEELS_DIR"

# Requirements: [build-system].requires + [project].dependencies, one per line.
requirements=$("$PYTHON" - <<'PY'
import tomllib
with open("pyproject.toml", "rb") as f:
    meta = tomllib.load(f)
print("\n".join(meta["build-system"]["requires"] + meta["project"]["dependencies"]))
PY
)

platforms=(--platform manylinux2014_x86_64)
minor=${TARGET_GLIBC#2.}
for ((m = 17; m <= minor; m++)); do platforms+=(--platform "manylinux_2_${m}_x86_64"); done

stamp="$WHEELS_DIR/.fetched"
want=$(printf '%s\n%s\n' "$requirements" "${platforms[*]}" | sha256sum | cut -d' ' -f1)
if [ "$refresh" = 0 ] && [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ]; then
  echo "fetch-wheels: $WHEELS_DIR is up to date ($(ls "$WHEELS_DIR"/*.whl | wc -l) wheels)"
  exit 0
fi

reqfile=$(mktemp)
trap 'rm -f "$reqfile"' EXIT
printf '%s\n' "$requirements" > "$reqfile"
rm -f "$stamp"
"$PYTHON" -m pip download --quiet --disable-pip-version-check \
  --dest "$WHEELS_DIR" --only-binary=:all: \
  --implementation cp --python-version 3.11 --abi cp311 "${platforms[@]}" \
  -r "$reqfile"
echo "$want" > "$stamp"
echo "fetch-wheels: $(ls "$WHEELS_DIR"/*.whl | wc -l) wheels in $WHEELS_DIR ($(du -sh "$WHEELS_DIR" | cut -f1))"
