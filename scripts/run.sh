#!/usr/bin/env bash
# The project's one entry point, used by people (README), CI (.ci/run) and the Dockerfile.
#
#   bash scripts/run.sh serve   set everything up, then start the service on 127.0.0.1:8000
#   bash scripts/run.sh test    set everything up, then run ruff, mypy and the test suite
#                               (without the `long` tests: `test -m long` runs only those)
#   bash scripts/run.sh setup   set everything up and compile every kernel (the Dockerfile's step)
#
# Set-up is idempotent: a virtual environment in .venv (WAVECORE_VENV overrides it), the
# package installed into it with the extras that the command needs (serve: `service`; test:
# `service,figures,test`, and Debian's Chromium via apt when run as root), re-done only when
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

# The browser tests (tests/browser) drive Debian's Chromium through Playwright; Playwright's own
# browser download is never used. Installed only when missing and only as root (CI, Docker).
ensure_chromium() {
    if [ -x /usr/bin/chromium ] && command -v chromedriver >/dev/null 2>&1; then
        return
    fi
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
        echo "installing chromium from Debian for the browser tests" >&2
        export DEBIAN_FRONTEND=noninteractive
        apt-get update -qq >/dev/null
        apt-get install -y -qq chromium chromium-driver >/dev/null </dev/null
    else
        echo "note: /usr/bin/chromium is missing (not root, not installing it)" >&2
    fi
}

cmd=${1:-help}
shift || true
case "$cmd" in
    setup)
        setup service
        # Compile every numba kernel into the on-disk cache, with a progress line per step.
        "$VENV/bin/python" -m wavecore.warmup
        ;;
    serve)
        setup service
        # The `wavecore` console script (service/cli.py); WAVECORE_* variables set the limits.
        # It warms the kernels up (compiling them the first time) before it reports ready.
        exec "$VENV/bin/wavecore" serve --host 127.0.0.1 --port 8000 "$@"
        ;;
    test)
        setup service,figures,test
        ensure_chromium
        "$VENV/bin/ruff" check .
        "$VENV/bin/ruff" format --check .
        "$VENV/bin/mypy"
        # pytest's exit status 5 is "no tests collected": a selection that matches nothing
        # (say `-m long -k something`) is not a failure of the code.
        status=0
        "$VENV/bin/python" -m pytest "$@" || status=$?
        if [ "$status" = 5 ]; then
            echo "pytest collected no tests for this selection" >&2
            status=0
        fi
        exit "$status"
        ;;
    *)
        sed -n '2,12p' "$0"
        exit 2
        ;;
esac
