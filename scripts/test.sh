#!/usr/bin/env bash
# The whole test suite, from a clean clone: sets up .venv, lints (ruff), type-checks
# (mypy), then runs pytest on two workers (pytest-xdist). Arguments go to pytest (e.g. -m "not slow and not browser").
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/bootstrap.sh
echo "== ruff check" >&2
.venv/bin/ruff check .
echo "== mypy" >&2
.venv/bin/mypy
echo "== pytest" >&2
# two workers on the two cores; the whole-loop tests share one xdist group ("live"): one loop at a time
exec .venv/bin/python -m pytest -n 2 --dist loadgroup "$@"
