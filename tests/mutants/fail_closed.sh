#!/usr/bin/env bash
# Issues #16, #29 and #30: each fail-closed fix has a test that fails without it. This script puts each
# fix's old behaviour back, one at a time, in a scratch copy of the tree, runs the tests that
# guard it, and checks that the named test fails. It exits 1 if any old behaviour passes the
# tests (or no longer compiles, or fails only other tests).
#
#   bash tests/mutants/fail_closed.sh            # every mutant
#   MUTANTS='exit|range' bash tests/mutants/...  # only those whose name matches the regex
#   MUTANTS_DRY=1 bash tests/mutants/fail_closed.sh  # only check that every fixed code is still
#                                                    # there exactly once (seconds; CI runs it)
#
# The first mutant builds the workspace in the scratch copy (CARGO_TARGET_DIR, default
# target/mutants: a copy of target/release there saves the dependencies' cold build); each
# one after it rebuilds the crate it changes and runs its tests: about 1–3 min per mutant on 2
# cores. Not part of CI; run it after touching the policy, the feasibility test, the estimator's
# update, the controller's X_t(δ), the run summary's verdict, check's hypotheses, world
# validation or the binary's exit codes.
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
mkdir -p "$work/tree"
tar -C "$root" --exclude=./target --exclude=./.git --exclude=./runs -cf - . | tar -C "$work/tree" -xf -
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$root/target/mutants}"
cd "$work/tree"
survivors=0
# name | file | the fixed code | the old behaviour | a test that must fail | cargo test arguments
# (default: the controller's tests). The #29 mutants of the binary's tests run only their own test:
# with validation off, other tests of the same file run worlds whose old behaviour hangs (a control
# rate of 1e-300 Hz), which is why each run also has a time limit (MUTANT_TIMEOUT, 1200 s).
mutant() {
  local name=$1 file=$2 new=$3 old=$4 test=$5
  shift 5
  local args=("$@")
  [ ${#args[@]} -eq 0 ] && args=(-p ftcbf-controller)
  if [ -n "${MUTANTS:-}" ] && ! [[ $name =~ $MUTANTS ]]; then
    return
  fi
  if [ -n "${MUTANTS_DRY:-}" ]; then
    if python3 - "$file" "$new" <<'PY'
import sys
f, new = sys.argv[1:]
sys.exit(0 if open(f).read().count(new) == 1 else 1)
PY
    then
      echo "applies  $name"
    else
      echo "MISSING  $name: the fixed code is not in $file exactly once: update the mutant"
      survivors=$((survivors + 1))
    fi
    return
  fi
  cp "$file" "$work/orig"
  python3 - "$file" "$new" "$old" <<'PY'
import sys
f, new, old = sys.argv[1:]
s = open(f).read()
if s.count(new) != 1:
    sys.exit(f"{f}: the fixed code is not there exactly once: {new!r}")
open(f, "w").write(s.replace(new, old))
PY
  local rc=0
  timeout "${MUTANT_TIMEOUT:-1200}" cargo test --release "${args[@]}" --no-fail-fast \
    >"$work/log" 2>&1 || rc=$?
  if [ "$rc" -eq 0 ]; then
    echo "SURVIVED $name: every test of \`cargo test ${args[*]}\` passes with the old behaviour"
    survivors=$((survivors + 1))
  elif [ "$rc" -eq 124 ]; then
    # Some old behaviours hang (that is why they were fixed): name a test that fails first.
    echo "SURVIVED $name: the tests did not end within ${MUTANT_TIMEOUT:-1200} s"
    survivors=$((survivors + 1))
  elif grep -q "^test .*$test .*FAILED" "$work/log"; then
    echo "killed   $name by $(grep -E '^test .* FAILED$' "$work/log" | sed 's/^test //; s/ \.\.\. FAILED//' | tr '\n' ' ')"
  else
    echo "SURVIVED $name: tests failed, but not $test"; survivors=$((survivors + 1))
  fi
  cp "$work/orig" "$file"
}
mutant "Step 2 may drop every unit with CBF rows" controller/src/policy.rs \
  'if had_cbf && !kept_cbf {' 'if false && had_cbf && !kept_cbf {' \
  step2_never_drops_the_last_unit_with_cbf_rows
mutant "a NaN normal with a finite offset >= 0 counts as satisfied" controller/src/feasibility.rs \
  '} else if finite && h.offset >= 0.0 {' '} else if h.offset.is_finite() && h.offset >= 0.0 {' \
  a_nan_normal_is_violated_and_the_fallback_brakes
mutant "the last-resort action coasts when only a dropped unit has a velocity" controller/src/policy.rs \
  '(None, Some(i)) => (velocity(i), BrakeVelocity::Dropped { unit: i }),' \
  '(None, Some(_)) => (Input::zeros(), BrakeVelocity::NoneFinite),' \
  brake_uses_the_best_finite_velocity_estimate
mutant "a non-finite innovation variance is skipped silently" controller/src/estimator.rs \
  $'                self.skipped += 1;\n                self.flagged = true;\n                continue;' \
  '                continue;' \
  non_finite_innovation_variance_is_counted_and_flags_the_filter
mutant "a NaN barrier value is left out of X_t(delta)" controller/src/controller.rs \
  'row.h_hat < self.delta || row.h_hat.is_nan();' 'row.h_hat < self.delta;' \
  a_nan_barrier_is_imposed_and_fails_closed_in_the_controller
# Issue #29: fail closed on non-finite results, validation by physical range, exit codes.
mutant "a run is SAFE with a non-finite barrier value" sim/src/runner/mod.rs \
  '&& non_finite.is_none()' \
  '&& true' \
  a_run_with_a_non_finite_barrier_value_is_unsafe_and_names_it \
  --test reliability a_run_with_a_non_finite_barrier_value_is_unsafe_and_names_it
mutant "the summary names NaN but not an infinite barrier minimum" sim/src/summary.rs \
  '.find(|b| !b.value.is_finite())' '.find(|b| b.value.is_nan())' \
  the_first_non_finite_quantity_is_named -p ftcbf-sim --lib
mutant "a check hypothesis that computed NaN or inf keeps its status" sim/src/analysis/check/report.rs \
  'if let Some(w) = shows_non_finite(&h.detail) {' 'if let Some(w) = None::<&str> {' \
  a_hypothesis_showing_nan_or_inf_fails_and_the_verdict_cannot_apply -p ftcbf-sim --lib
mutant "check does not test the start against the safe sets and obstacles" sim/src/analysis/check/safety.rs \
  'if !(h.is_finite() && h >= 0.0) {' 'if false {' \
  a_start_outside_the_safe_set_fails_theorem_3 \
  --test reliability a_start_outside_the_safe_set_fails_theorem_3
mutant "check is silent about a goal inside an obstacle" sim/src/analysis/check/safety.rs \
  'if !(h.is_finite() && h + f.goal.radius >= 0.0) {' 'if false {' \
  a_goal_inside_an_obstacle_fails \
  --test reliability a_goal_inside_an_obstacle_fails
mutant "no validation by physical range" sim/src/world/mod.rs \
  '        if r.contains(v) {' '        if true || r.contains(v) {' \
  the_issues_run_reproducers_are_refused_naming_the_key \
  --test reliability the_issues_run_reproducers_are_refused_naming_the_key
mutant "no caps on the sizes of lists" sim/src/world/mod.rs \
  'if n <= max {' 'if true {' \
  every_size_cap_is_a_clean_error_one_past_it \
  --test reliability every_size_cap_is_a_clean_error_one_past_it
mutant "no cap on a run's control steps" sim/src/world/mod.rs \
  'if steps > r::MAX_CONTROL_STEPS {' 'if false {' \
  every_size_cap_is_a_clean_error_one_past_it \
  --test reliability every_size_cap_is_a_clean_error_one_past_it
mutant "a noiseless linear plant gives its filters q = 0 (the fuzz's hang)" sim/src/world/mod.rs \
  'if l.process_noise == 0.0 && file.control.process_noise.is_none() {' 'if false {' \
  a_noiseless_linear_plant_needs_the_filters_own_process_noise \
  --test reliability a_noiseless_linear_plant_needs_the_filters_own_process_noise
mutant "loading skips the controller's structural check (check accepts what run refuses)" \
  sim/src/world/mod.rs \
  'structure::check_structure(&world).map_err(' \
  'Ok::<(), structure::StructureError>(()).map_err(' \
  every_invalid_world_is_rejected_with_a_helpful_message --test invalid_worlds
mutant "an error inside a kind-tagged table does not name its key" sim/src/spec/tagged.rs \
  'D::Error::custom(format!("`{key}`: {message}"))' 'D::Error::custom(message)' \
  errors_in_nested_tables_name_the_key_path_line_and_column --test invalid_worlds
mutant "a panic is not contained (Rust's exit 101)" src/main.rs \
  'std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| dispatch(cli.command)))' \
  'Ok::<_, Box<dyn std::any::Any + Send>>(dispatch(cli.command))' \
  a_contained_panic_exits_70_with_its_message_and_place \
  --test reliability a_contained_panic_exits_70_with_its_message_and_place
mutant "usage errors exit 2, like an invalid world" src/main.rs \
  'let code = if e.use_stderr() { EXIT_USAGE } else { 0 };' \
  'let code = if e.use_stderr() { exit::EXIT_INVALID } else { 0 };' \
  usage_errors_exit_64_and_a_negative_duration_is_a_range_error \
  --test reliability usage_errors_exit_64_and_a_negative_duration_is_a_range_error
mutant "a closed output pipe is reported as an internal error (exit 70)" src/main.rs \
  '    default_sigpipe();' '' \
  a_closed_output_pipe_ends_the_command_like_any_unix_tool \
  --test reliability a_closed_output_pipe_ends_the_command_like_any_unix_tool
# Issue #30: the controller's smaller fail-open paths, and a run past the parameters' horizon.
mutant "a solver failure on a set the exact test certified sends Step 3 dropping units" \
  controller/src/policy.rs \
  'let settled = settle(r, &s.lines, qp.input_limit(), witness, soft_clf);' \
  'let settled = if matches!(r, QpResult::Feasible { .. }) { settle(r, &s.lines, qp.input_limit(), witness, soft_clf) } else { Settled { result: r, witness_used: false } };' \
  a_certified_feasible_set_uses_the_witness_when_the_solver_fails
mutant "an AlmostSolved input is not rechecked against the hard rows" controller/src/policy.rs \
  'QpResult::Feasible { u, .. } if admits(hard, limit, u) => {' \
  'QpResult::Feasible { u: _, .. } => {' \
  a_solver_answer_that_violates_a_hard_row_is_replaced_by_the_witness
mutant "a non-finite chi-square term counts as 0 (most trustworthy)" controller/src/estimator.rs \
  'let nis = if nis.is_finite() { nis } else { f64::INFINITY };' \
  'let nis = if nis.is_finite() { nis } else { 0.0 };' \
  a_non_finite_innovation_ranks_the_filter_least_trustworthy
mutant "the increment history restarts when the control period changes" controller/src/controller.rs \
  '        self.steps += 1;' \
  '        let c = RESIDUE_WINDOW_MAX_STEPS; let t = |lag: usize| self.time[(self.head + c - lag) % c]; let changed = self.steps >= 2 && ((t(1) - t(2)) - (t(2) - t(3))).abs() > 1e-9; self.steps = if changed { 0 } else { self.steps + 1 };' \
  a_changed_period_keeps_the_increment_history
mutant "run --duration runs past the horizon gamma, theta, eta were computed for" sim/src/runner/mod.rs \
  'if duration > file.duration {' 'if false {' \
  a_run_past_the_horizon_of_gamma_theta_eta_is_refused \
  --test simulation a_run_past_the_horizon_of_gamma_theta_eta_is_refused
# Issue #30 item 4: γ, θ, η from the sensors as declared; biased filter channels fail check.
mutant "gamma, theta, eta ignore the filter channels' rates and dropouts" sim/src/model/setup.rs \
  '            &timing.schedule,' '            &ftcbf_controller::params::UpdateSchedule::every_step(),' \
  a_slow_lossy_receiver_widens_the_bounds_by_its_worst_gap \
  --test guarantees a_slow_lossy_receiver_widens_the_bounds_by_its_worst_gap
mutant "check ignores a declared bias on a filter channel" sim/src/analysis/check/mod.rs \
  '    check_white_noise(cx, &mut found); // 1d' '' \
  a_declared_bias_on_a_filter_channel_fails_the_white_noise_hypothesis \
  --test guarantees a_declared_bias_on_a_filter_channel_fails_the_white_noise_hypothesis
# Issue #36: a filter none of whose channels gave a reading for a whole χ² window ranks after
# every filter with evidence (it ranked first, and the tracker followed a dead-reckoning filter).
mutant "a filter with no reading in its window ranks first" controller/src/estimator.rs \
  '        } else if self.win_dof == 0 {' '        } else if false && self.win_dof == 0 {' \
  a_filter_silent_for_a_window_ranks_after_every_filter_with_evidence
# Issue #30 item 4: a heading held between slow samples without a gyro is stale by up to
# ω_max·age; R carries it.
mutant "a slow heading's staleness is left out of R" sim/src/world/structure.rs \
  '            h.noise_std.hypot(stale)' '            h.noise_std + 0.0 * stale' \
  a_slow_compass_without_a_gyro_puts_its_staleness_in_r_and_fails_white_noise \
  --test guarantees a_slow_compass_without_a_gyro_puts_its_staleness_in_r_and_fails_white_noise
if [ -n "${MUTANTS_DRY:-}" ]; then
  echo "$survivors mutant(s) no longer apply"
  [ "$survivors" -eq 0 ]
  exit
fi
echo "$survivors mutant(s) survived"
[ "$survivors" -eq 0 ]
