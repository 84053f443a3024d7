#!/usr/bin/env bash
# Create .venv (if missing) and install drumtwin with every extra, plus Debian's
# chromium for the dashboard's browser test and mbpoll (libmodbus) for the drive
# emulator's tests (apt, as root only). Idempotent; safe to run again.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  "$PY" -m venv .venv
fi
stamp=.venv/.drumtwin-installed
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
  .venv/bin/python -m pip install -q --upgrade pip
  .venv/bin/python -m pip install -q -e '.[test,bench,cluster]'
  touch "$stamp"
fi
if [ ! -x /usr/bin/chromium ] && [ "${DRUMTWIN_NO_APT:-}" != 1 ]; then
  if [ "$(id -u)" = 0 ]; then
    echo "bootstrap: installing Debian chromium for the browser test ..." >&2
    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium) >/dev/null 2>&1 \
      || echo "bootstrap: could not install chromium (the browser test will fail)" >&2
  else
    echo "bootstrap: /usr/bin/chromium missing; run 'sudo apt-get install chromium' for the browser test" >&2
  fi
fi
if ! command -v mbpoll >/dev/null 2>&1 && [ "${DRUMTWIN_NO_APT:-}" != 1 ]; then
  if [ "$(id -u)" = 0 ]; then
    echo "bootstrap: installing Debian mbpoll (libmodbus) for the drive emulator's tests ..." >&2
    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq mbpoll) >/dev/null 2>&1 \
      || echo "bootstrap: could not install mbpoll (tests/control/test_modbus_book.py will fail)" >&2
  else
    echo "bootstrap: mbpoll missing; run 'sudo apt-get install mbpoll' for the drive emulator's tests" >&2
  fi
fi
