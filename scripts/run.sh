#!/usr/bin/env bash
# The project's one entry point, used by people (README), CI (.ci/run) and the Dockerfile.
#
#   bash scripts/run.sh serve   set everything up, then start the service on 127.0.0.1:8000
#   bash scripts/run.sh test    set everything up, then run ruff, mypy and the whole test suite
#   bash scripts/run.sh setup   set everything up (the Dockerfile's step)
#
# Set-up is idempotent: a virtual environment in .venv (WAVECORE_VENV overrides it), the
# package installed into it with the extras that the command needs, re-done only when
# pyproject.toml changes.
set -euo pipefail
cd "$(dirname "$0")/.."

VENV=${WAVECORE_VENV:-.venv}
PYTHON=${PYTHON:-python3}

setup() {
    local extras=$1
    if [ ! -x "$VENV/bin/python" ]; then
        "$PYTHON" -m venv "$VENV"
    fi
    local stamp
    stamp="$VENV/.stamp-$(cat pyproject.toml | sha256sum | cut -c1-16)-${extras//,/-}"
    if [ ! -f "$stamp" ]; then
        "$VENV/bin/python" -m pip install --quiet --upgrade pip
        "$VENV/bin/python" -m pip install --quiet -e ".[$extras]"
        touch "$stamp"
    fi
}

cmd=${1:-help}
shift || true
case "$cmd" in
    setup)
        setup service
        ;;
    serve)
        setup service
        exec "$VENV/bin/python" -m wavecore.demo "$@"
        ;;
    test)
        setup service,figures,test
        "$VENV/bin/ruff" check .
        "$VENV/bin/ruff" format --check .
        "$VENV/bin/mypy"
        exec "$VENV/bin/python" -m pytest "$@"
        ;;
    *)
        sed -n '2,12p' "$0"
        exit 2
        ;;
esac
