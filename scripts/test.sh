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
echo "== numba kernels" >&2
# compiled into their on-disk cache (numba cache=True) before pytest, both halves side by side, as a
# build step: in a fresh clone ~30 s of CPU; with the cache warm each half only loads them (~2 s)
.venv/bin/python -m tests.numba_warm sim & sim=$!
.venv/bin/python -m tests.numba_warm vision || echo "numba warm-up (vision) failed: the tests compile as they go" >&2
wait "$sim" || echo "numba warm-up (sim) failed: the tests compile as they go" >&2
echo "== pytest" >&2
# one thread per numeric library in each worker: more workers than cores, and OpenBLAS's and
# OpenCV's second thread only contended with the other workers (vision tests: -10 % wall, -8 % CPU)
export OPENBLAS_NUM_THREADS="${OPENBLAS_NUM_THREADS:-1}" OMP_NUM_THREADS="${OMP_NUM_THREADS:-1}" \
  OPENCV_FOR_THREADS_NUM="${OPENCV_FOR_THREADS_NUM:-1}"
# three workers on the two cores: the whole-loop tests wait on run clocks, ptys, servers and chromium (two
# workers kept 1.3 of the 2 cores busy: 421 s of pytest on a quiet machine, three 359 s); they share one
# xdist group ("live"): one loop at a time. DRUMTWIN_TEST_WORKERS overrides the count.
exec .venv/bin/python -m pytest -n "${DRUMTWIN_TEST_WORKERS:-3}" --dist loadgroup "$@"
