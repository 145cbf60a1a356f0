#!/usr/bin/env bash
# graphnav's two set-up commands (fresh Debian, Python >= 3.11):
#   ./dev.sh demo   create .venv, install everything, run the main job on the embedded data
#   ./dev.sh test   create .venv, install everything, run the test suite
# Also: ./dev.sh lint | bench | lock | shell CMD...   (PYTHON=python3.12 ./dev.sh ... picks another interpreter)
# Installs are locked: requirements.lock pins every package with its hashes (what CI tested);
# `./dev.sh lock` re-resolves it from pyproject.toml (uv, universal markers) after a dependency change.
# The lock holds graphnav[all] (open3d, dask, ros, fast) and the dev tools: both commands install all of it.
set -euo pipefail
cd "$(dirname "$0")"
PYTHON=${PYTHON:-python3}
VENV=${VENV:-.venv}
OUT=${OUT:-out/demo}

need_root_or_say() {  # $@ = Debian packages
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    echo "dev.sh: installing system packages: $*" >&2
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq >&2 && apt-get install -y -qq --no-install-recommends "$@" >/dev/null
  else
    echo "dev.sh: error: missing system packages: $*" >&2
    echo "dev.sh: run:   sudo apt-get update && sudo apt-get install -y $*" >&2
    exit 1
  fi
}

setup() {
  command -v "$PYTHON" >/dev/null || need_root_or_say python3 python3-venv
  "$PYTHON" -c 'import sys; sys.exit(sys.version_info < (3, 11))' || {
    echo "dev.sh: error: graphnav needs Python >= 3.11; $("$PYTHON" --version 2>&1) found (set PYTHON=...)" >&2; exit 1; }
  "$PYTHON" -c 'import venv, ensurepip' 2>/dev/null || need_root_or_say python3-venv
  bash tools/sysdeps.sh
  if [ ! -x "$VENV/bin/python" ]; then "$PYTHON" -m venv "$VENV"; fi
  local stamp="$VENV/.installed"
  if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ] || [ requirements.lock -nt "$stamp" ]; then
    echo "dev.sh: installing graphnav and its locked dependencies into $VENV (first time: a few minutes)" >&2
    local pip=("$VENV/bin/python" -m pip --quiet --disable-pip-version-check)
    "${pip[@]}" install --require-hashes --no-deps -r requirements.lock
    "${pip[@]}" install --no-deps --no-build-isolation -e .
    "$VENV/bin/python" -m pip check >&2 || { echo "dev.sh: error: requirements.lock is out of step with pyproject.toml; run ./dev.sh lock" >&2; exit 1; }
    touch "$stamp"
  fi
}

cmd=${1:-}
shift || true
case "$cmd" in
  demo)  setup; exec "$VENV/bin/graphnav" demo --out "$OUT" "$@" ;;
  test)  setup; exec "$VENV/bin/python" -m pytest -q -p no:cacheprovider "$@" ;;
  lint)  setup; exec "$VENV/bin/ruff" check graphnav factors tests benchmarks examples ;;
  lock)  [ -x "$VENV/bin/python" ] || "$PYTHON" -m venv "$VENV"   # no setup: the old lock may not satisfy pyproject
         "$VENV/bin/python" -m pip install --quiet --disable-pip-version-check 'uv>=0.9'
         exec "$VENV/bin/uv" pip compile pyproject.toml --extra all --extra dev --universal --python-version 3.11 \
           --generate-hashes --custom-compile-command './dev.sh lock' --quiet -o requirements.lock ;;
  bench) setup; for b in benchmarks/*.py; do "$VENV/bin/python" "$b"; done ;;
  shell) setup; exec "$VENV/bin/$1" "${@:2}" ;;
  *) echo "usage: ./dev.sh demo | test | lint | bench | lock | shell CMD..." >&2; exit 2 ;;
esac
