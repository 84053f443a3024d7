#!/usr/bin/env bash
# Mutation testing of one pure core with mutmut (not in CI: minutes per module).
#   bash scripts/mutation.sh vision/mixing.py        # score + surviving mutants (with their diffs)
#   bash scripts/mutation.sh list                    # the modules and the tests that guard them
#   bash scripts/mutation.sh control/trend.py 'control.trend.x_moving_average*' ...
#                                                    # only the mutants matching these names (fnmatch; the
#                                                    # score then counts only those: for a busy machine)
# Runs in a throw-away clone of the committed tree (HEAD), so the work tree is never mutated; under
# `nice -n 19` with MUTMUT_CHILDREN=1 worker by default (a shared 2-core machine).
# Cost = tests run per mutant, so each module has a FAST guarding set (unit/rules/property tests only, no
# subprocess/CLI and no simulation-heavy tests), mutmut's own per-function test selection (its stats run
# records which tests call which function; a mutant runs only those), the tests of a mutant ordered fastest
# first (a kill usually comes from a millisecond test), hypothesis capped at DRUMTWIN_MUTATION_EXAMPLES
# (default 20) derandomised examples without shrinking. mutmut stops a mutant's tests after
# (t + 5 s) x MUTATION_TIMEOUT_MULTIPLIER (default 10) of wall time, t its tests' time in the stats run, and
# twice that of CPU time: a "timeout", counted as a kill but listed apart. The wall-clock limit is why the
# multiplier is large: at nice 19 on a loaded machine a test takes many times its stats-run time.
# The whole script is one block that bash parses before running it: an edit of this file during a run (bash
# otherwise reads a script as it goes) cannot change the run or lose its results.
{
set -euo pipefail
cd "$(dirname "$0")/.."
# The supervisor's pure core is four modules (control/supervisor.py and its settings, step records and
# segregation detector, split out of it): one guarding set for all four.
SUPERVISOR_TESTS="tests/control/test_supervisor.py tests/control/test_supervisor_props.py tests/control/test_supervisor_rules.py tests/control/test_supervisor_choice.py tests/control/test_supervisor_due.py tests/control/test_supervisor_ramps.py tests/control/test_supervisor_safe.py tests/control/test_supervisor_modes.py tests/control/test_objective_supervisor.py tests/control/test_endpoint_supervisor.py tests/control/test_auto_endpoint_rules.py"
SUPERVISOR_DESELECT="tests/control/test_objective_supervisor.py::test_run_options_objective_and_target_are_checked_in_one_line"
# The drive link's pure parts: their tests share files with pty/TCP tests, so their fast sets name tests
# (pytest node ids, FILE::TEST) beside the pure *_rules.py files.
M=tests/control/test_modbus.py
MODBUS_URL_TESTS="$M::test_modbus_urls_parse_and_bad_ones_name_the_key \
  $M::test_the_configs_drive_hz_per_rpm_goes_into_the_modbus_url_and_a_disagreeing_url_is_refused"
MODBUS_REPLY_TESTS="tests/control/test_modbus_replies.py::test_check_reply_takes_the_exact_answer_after_line_noise \
  tests/control/test_modbus_replies.py::test_check_reply_refuses_anything_else"
MODBUS_DRIVE_TESTS="$M::test_drive_model_trips_on_silence_not_on_reads_and_latches_until_reset \
  tests/control/test_modbus_book.py::test_the_drive_model_refuses_writes_by_the_book_and_applies_none_of_them \
  tests/control/test_modbus_book.py::test_the_status_word_says_decelerating_and_a_drive_fault_coasts"
MODBUS_PROFILE_TESTS="$M::test_every_shipped_profile_loads_and_names_its_comm_loss_parameter \
  $M::test_bad_profiles_are_one_line_errors $M::test_read_blocks_groups_near_registers \
  $M::test_comm_loss_problem_names_the_parameter_and_the_value_to_set"
# The calibration's pure core is three modules (sim/calibrate.py's decision path, its confirming runs in
# sim/calibrate_confirm.py, its slope statistic in sim/calibrate_slope.py): one set, every test on a known
# slope field (the twin patched out), none running the DEM.
S=tests/sim
CALIBRATE_TESTS="$S/test_calibrate_rules.py $S/test_calibrate_mutants.py $S/test_calibrate_plates.py \
  $S/test_calibrate_confirm.py $S/test_calibrate_confirm_rules.py"
# runs the DEM (14 s) for a refusal the known-field tests pin (test_calibrate_mutants.py's out-of-range ones)
CALIBRATE_DESELECT="$S/test_calibrate_rules.py::test_a_small_target_is_a_valid_angle_refused_only_by_the_range"
declare -A TESTS=(
  [vision/mixing.py]="tests/vision/test_mixing.py tests/vision/test_known_answers.py"
  [control/protocol.py]="tests/control/test_protocol.py tests/control/test_protocol_rules.py"
  [control/device.py]="tests/control/test_device.py tests/control/test_device_rules.py \
    tests/control/test_stop_never_gated.py::test_a_resent_stop_still_stops_a_motor_started_from_the_front_panel"
  [vision/moments.py]="tests/vision/test_moments_pure.py"
  [control/supervisor.py]="$SUPERVISOR_TESTS"
  [control/supervisor_config.py]="$SUPERVISOR_TESTS"
  [control/decision.py]="$SUPERVISOR_TESTS"
  [control/segregation.py]="$SUPERVISOR_TESTS"
  [control/trend.py]="tests/control/test_trend.py tests/control/test_trend_props.py tests/control/test_trend_settle.py tests/control/test_trend_rules.py tests/control/test_trend_mutants.py"
  [sim/calibrate.py]="$CALIBRATE_TESTS"
  [sim/calibrate_confirm.py]="$CALIBRATE_TESTS"
  [sim/calibrate_slope.py]="$CALIBRATE_TESTS"
  [control/endpoint.py]="tests/control/test_endpoint.py tests/control/test_endpoint_rules.py tests/control/test_endpoint_supervisor.py"
  [control/limits.py]="tests/control/test_limits.py tests/control/test_limits_rules.py"
  [control/objective.py]="tests/control/test_objective.py tests/control/test_objective_rules.py tests/control/test_objective_supervisor.py"
  [control/modbus/url.py]="$MODBUS_URL_TESTS tests/control/test_modbus_url_rules.py"
  [control/modbus/reply.py]="$MODBUS_REPLY_TESTS tests/control/test_modbus_reply_rules.py"
  [control/modbus/drive.py]="$MODBUS_DRIVE_TESTS tests/control/test_modbus_drive_rules.py"
  [control/modbus/profile.py]="$MODBUS_PROFILE_TESTS $MODBUS_DRIVE_TESTS tests/control/test_modbus_profile_rules.py"
  [control/motor.py]="tests/control/test_device.py tests/control/test_device_rules.py tests/control/test_motor_rules.py \
    tests/control/test_modbus_drive_rules.py"
  [control/errors.py]="tests/control/test_errors_rules.py tests/control/test_modbus_url_rules.py \
    tests/control/test_modbus_profile_rules.py"
)
# Tests of those files left out of the fast set (they run the CLI, in a subprocess or in process).
declare -A DESELECT=(
  [control/supervisor.py]="$SUPERVISOR_DESELECT"
  [control/supervisor_config.py]="$SUPERVISOR_DESELECT"
  [control/decision.py]="$SUPERVISOR_DESELECT"
  [control/segregation.py]="$SUPERVISOR_DESELECT"
  [control/objective.py]="$SUPERVISOR_DESELECT"
  [sim/calibrate.py]="$CALIBRATE_DESELECT"
  [sim/calibrate_confirm.py]="$CALIBRATE_DESELECT"
  [sim/calibrate_slope.py]="$CALIBRATE_DESELECT"
  [control/endpoint.py]="tests/control/test_endpoint.py::test_endpoint_options_reach_the_live_loop_and_mi_and_bad_ones_are_one_line_exit_2 \
    tests/control/test_endpoint.py::test_an_endpoint_table_in_the_config_is_read_under_the_options_and_a_bad_one_is_one_line_exit_2"
)
mod=${1:-}
if [ -z "$mod" ] || [ "$mod" = list ]; then
  for k in "${!TESTS[@]}"; do echo "$k: ${TESTS[$k]}${DESELECT[$k]:+ (not: ${DESELECT[$k]})}"; done | sort
  [ -n "$mod" ] || { echo "usage: bash scripts/mutation.sh MODULE.py (see 'list')" >&2; exit 2; }
  exit 0
fi
[ -n "${TESTS[$mod]:-}" ] || { echo "mutation: no test set for '$mod' (see 'bash scripts/mutation.sh list')" >&2; exit 2; }
# The venv with mutmut: $DRUMTWIN_VENV, else ./.venv (made by scripts/bootstrap.sh when missing).
venv=${DRUMTWIN_VENV:-$PWD/.venv}
[ -x "$venv/bin/mutmut" ] || { [ -z "${DRUMTWIN_VENV:-}" ] && bash scripts/bootstrap.sh >/dev/null; }
[ -x "$venv/bin/mutmut" ] || "$venv/bin/python" -m pip install -q -e '.[mutation]' >/dev/null
[ -x "$venv/bin/mutmut" ] || { echo "mutation: no mutmut in $venv (set DRUMTWIN_VENV)" >&2; exit 2; }
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
git clone -q . "$work/p"
cd "$work/p"
# Functions marked '# pragma: no cover - compiled' are numba kernels: mutmut's trampoline cannot be
# jitted (every mutant would "die" of a numba TypingError, a false kill), so they are not mutated:
# the pragma gets mutmut's 'no mutate block' on the function's header line (in this clone only).
perl -0pi -e 's/^(\s*def \w+\([^)]*\)(?:\s*->[^:]+)?:)([ \t]*# pragma: no cover - compiled)/$1$2, no mutate block/mg;
              s/^(\s*def \w+\([ \t]*# pragma: no cover - compiled\n[^)]*\)(?:\s*->[^:]+)?:)[ \t]*$/$1  # pragma: no mutate block/mg' "$mod"
# Not mutated (clone only), each for a reason given in docs/mutation.md: the twin's simulation, in
# sim/calibrate_slope.py since the noise-aware calibration (every mutant would run the DEM; the decision
# path and the slope statistic are tested on known slope fields and known frames).
if [ "$mod" = sim/calibrate_slope.py ]; then
  perl -0pi -e 's/^(def (?:_make|twin_frames|twin_surface|twin_slope_deg|twin_measure)\((?:[^()]|\([^()]*\))*\)[^:\n]*:)[ \t]*$/$1  # pragma: no mutate block/mg' "$mod"
  [ "$(grep -c 'no mutate block' "$mod")" = 5 ] || { echo "mutation: the twin's functions of $mod not all found" >&2; exit 2; }
fi
# The fast profile (clone only): hypothesis capped, derandomised, no shrinking (mutmut itself runs each
# mutant's tests fastest first, by the durations of its stats run).
cat >> tests/conftest.py <<'PY'


# --- appended by scripts/mutation.sh in its throw-away clone (never in the work tree) ---
import os as _mutation_os  # noqa: E402

if _mutation_os.environ.get("DRUMTWIN_MUTATION"):
    from hypothesis import Phase as _mutation_phase
    from hypothesis import settings as _mutation_settings

    _MUTATION_CAP = int(_mutation_os.environ.get("DRUMTWIN_MUTATION_EXAMPLES", "20"))
    # a failing example kills the mutant as it is: shrinking it (seconds to minutes) tells nothing more
    _NO_SHRINK = (_mutation_phase.explicit, _mutation_phase.reuse, _mutation_phase.generate)
    _mutation_settings.register_profile(
        "mutation", max_examples=_MUTATION_CAP, derandomize=True, database=None, deadline=None,
        phases=_NO_SHRINK,
    )
    _mutation_settings.load_profile("mutation")

    def pytest_collection_modifyitems(session, config, items):  # type: ignore[no-untyped-def]
        for item in items:
            fn = getattr(getattr(item, "obj", None), "__func__", getattr(item, "obj", None))
            own = getattr(fn, "_hypothesis_internal_use_settings", None)
            if own is not None:  # an explicit @settings(max_examples=...) beats a profile: cap it here
                fn._hypothesis_internal_use_settings = _mutation_settings(
                    own, max_examples=min(own.max_examples, _MUTATION_CAP), derandomize=True, database=None,
                    deadline=None, phases=_NO_SHRINK,
                )
PY
tests=""
# MUTATION_TESTS="a.py b.py" replaces the module's set (a subset kills no more than the whole set: its score
# is a lower bound of the set's)
for t in ${MUTATION_TESTS:-${TESTS[$mod]}}; do [ -e "${t%%::*}" ] && tests="$tests\"$t\", "; done
for t in ${DESELECT[$mod]:-}; do tests="$tests\"--deselect\", \"$t\", "; done
cat >> pyproject.toml <<TOML

[tool.mutmut]
source_paths = ["$mod"]
pytest_add_cli_args_test_selection = [${tests%, }]
pytest_add_cli_args = ["-p", "no:xdist", "-p", "no:randomly", "-q", "-o", "addopts=", "-x"]
timeout_multiplier = ${MUTATION_TIMEOUT_MULTIPLIER:-10}
timeout_constant = 5.0
also_copy = ["vision", "sim", "control", "twin", "tests", "configs", "docs", "README.md"]
TOML
echo "mutation: $mod against ${MUTATION_TESTS:-${TESTS[$mod]}}" >&2
shift
export DRUMTWIN_MUTATION=1
nice -n 19 "$venv/bin/mutmut" run --max-children "${MUTMUT_CHILDREN:-1}" "$@" >"$work/run.log" 2>&1 || { tail -20 "$work/run.log" >&2; exit 1; }
"$venv/bin/mutmut" results --all true >"$work/all.txt" 2>/dev/null || "$venv/bin/mutmut" results >"$work/all.txt"
if [ $# -gt 0 ]; then grep -v ': not checked' "$work/all.txt" >"$work/results.txt" || true; else cp "$work/all.txt" "$work/results.txt"; fi
total=$(grep -c ': ' "$work/results.txt" || true)
killed=$(grep -c ': killed' "$work/results.txt" || true)
timeouts=$(grep -c ': timeout' "$work/results.txt" || true)  # a mutant that hangs its tests: a kill too
killed=$((killed + timeouts))
survived=$(grep ': survived' "$work/results.txt" | awk -F: '{print $1}' | tr -d ' ' || true)
nsurv=$(echo -n "$survived" | grep -c . || true)
echo "module: $mod"
echo "tests: ${MUTATION_TESTS:-${TESTS[$mod]}}"
echo "date: $(date -u +%F)"
[ $# -eq 0 ] || echo "mutants matching: $*"
echo "mutants: $total  killed: $killed (of them timeouts: $timeouts)  survived: $nsurv  score: $(python3 -c "print(f'{100*$killed/max($total,1):.1f}%')")"
other=$(grep -v -E ': (killed|timeout|survived)$' "$work/results.txt" || true)
[ -z "$other" ] || { echo "not killed, not survived (no tests / suspicious / skipped):"; echo "$other"; }
[ "$timeouts" = 0 ] || { echo "timeouts (re-run them alone on a quieter machine to tell a hang from a slow test):"; grep ': timeout' "$work/results.txt"; }
for m in $survived; do
  echo "--- $m"
  "$venv/bin/mutmut" show "$m" 2>/dev/null | grep -E '^[-+][^-+]' || true
done
exit 0
}
