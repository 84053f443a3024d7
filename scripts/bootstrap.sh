#!/usr/bin/env bash
# Create .venv (if missing) and install drumtwin with every extra, plus Debian's
# chromium for the dashboard's browser test, mbpoll (libmodbus) for the drive
# emulator's tests and postgresql for the run catalogue's server tests (apt, as root
# only). Idempotent; safe to run again.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  "$PY" -m venv .venv
fi
stamp=.venv/.drumtwin-installed
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
  .venv/bin/python -m pip install -q --upgrade pip
  .venv/bin/python -m pip install -q -e '.[test,bench,cluster,postgres]'
  touch "$stamp"
fi
# apt_install PACKAGE PRESENT WHAT: install a Debian package unless PRESENT (a command) succeeds;
# as root only (DRUMTWIN_NO_APT=1 skips it), otherwise say what to run.
apt_install() {
  if eval "$2" || [ "${DRUMTWIN_NO_APT:-}" = 1 ]; then
    return 0
  fi
  if [ "$(id -u)" = 0 ]; then
    echo "bootstrap: installing Debian $1 for $3 ..." >&2
    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "$1") >/dev/null 2>&1 \
      || echo "bootstrap: could not install $1 ($3 will fail)" >&2
  else
    echo "bootstrap: $1 missing; run 'sudo apt-get install $1' for $3" >&2
  fi
}
apt_install chromium '[ -x /usr/bin/chromium ]' "the browser test"
apt_install mbpoll 'command -v mbpoll >/dev/null 2>&1' "the drive emulator's tests (libmodbus's mbpoll)"
apt_install postgresql 'ls /usr/lib/postgresql/*/bin/initdb >/dev/null 2>&1' "the run catalogue's PostgreSQL tests"
