#!/usr/bin/env bash
# Installs what the integration tests need beyond cargo: Debian's chromium (headless viewer tests)
# and iproute2 (network namespaces), a Python virtual environment at .venv with the pinned
# readers of python/requirements-test.txt, and Foxglove's WebSocket client for Node
# (tests/foxglove, pinned by its package-lock.json). Idempotent: a second run only checks.
set -euo pipefail
cd "$(dirname "$0")/.."

need_apt=()
command -v chromium >/dev/null 2>&1 || need_apt+=(chromium)
command -v ip >/dev/null 2>&1 || need_apt+=(iproute2)
command -v unshare >/dev/null 2>&1 || need_apt+=(util-linux)
python3 -c 'import venv, ensurepip' >/dev/null 2>&1 || need_apt+=(python3-venv)
command -v npm >/dev/null 2>&1 || need_apt+=(nodejs npm)
if [ ${#need_apt[@]} -gt 0 ]; then
  if [ "$(id -u)" -ne 0 ]; then
    echo "test-deps: missing ${need_apt[*]}; install them as root (apt-get install ${need_apt[*]})" >&2
    exit 2
  fi
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -q
  apt-get install -y -q "${need_apt[@]}"
fi

req=python/requirements-test.txt
stamp=.venv/.requirements.sha256
want=$(sha256sum "$req" | cut -d' ' -f1)
if [ ! -x .venv/bin/python ] || [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
  python3 -m venv .venv
  .venv/bin/python -m pip install -q --disable-pip-version-check -r "$req"
  echo "$want" > "$stamp"
fi
# The Foxglove client of tests/tests/view/foxglove.rs: exactly the lock file's packages.
lock=tests/foxglove/package-lock.json
npm_stamp=tests/foxglove/node_modules/.lock.sha256
want=$(sha256sum "$lock" | cut -d' ' -f1)
if [ "$(cat "$npm_stamp" 2>/dev/null)" != "$want" ]; then
  npm ci --prefix tests/foxglove --no-audit --no-fund --loglevel=error
  echo "$want" > "$npm_stamp"
fi
echo "test-deps: chromium, iproute2, the Foxglove client and .venv ($(.venv/bin/python --version)) ready" >&2
