#!/usr/bin/env bash
# Generates worlds with `ftcbf gen`, then runs `ftcbf check` and
# `ftcbf batch --controller ft-cbf-clf` on each and prints one row per world and totals per
# sensor suite and per kind of scene (issue #36's measurement of the defaults).
#
# usage: scripts/gen_sweep.sh [SEED] [COUNT] [TRIALS] [OUT_DIR] [-- GEN_OPTIONS…]
#   defaults: seed 1, 40 worlds, 10 trials, gen_out/; GEN_OPTIONS go to `ftcbf gen`
#   (e.g. -- --kind doorway --robot waffle). FTCBF=path/to/ftcbf overrides the binary
#   (default target/release/ftcbf); run from the repository root (robots/ is read from there).
# Writes OUT_DIR/*.toml, OUT_DIR/sweep/NAME.check.txt and NAME.json (each batch's results),
# and OUT_DIR/sweep/summary.md: the same table as Markdown, stamped with the command, commit,
# date and machine (the book's results/generated-worlds.md is that file).
# REUSE=1 keeps the batch JSON already in OUT_DIR/sweep (a sweep stopped half-way resumes;
# check always runs again, so the prediction is the current binary's).
# Columns: verdict = Theorem 3 applies / no / ERROR (check failed); safe, entered, settled =
# trials of TRIALS; ω flips = mean % of control steps in which the commanded ω changes sign;
# infeas = % of control steps with no feasible input; liveness = check's prediction (live / stall),
# judged against "settled in >= 95 % of trials" in the closing lines; the worlds where it also
# predicts a safe stop on the way are counted apart there.
set -euo pipefail

seed=${1:-1}
count=${2:-40}
trials=${3:-10}
out=${4:-gen_out}
shift $(($# < 4 ? $# : 4))
if [[ ${1:-} == "--" ]]; then shift; fi
ftcbf=${FTCBF:-target/release/ftcbf}
command -v jq >/dev/null || { echo "gen_sweep.sh needs jq" >&2; exit 1; }

mkdir -p "$out/sweep"
"$ftcbf" gen --seed "$seed" --count "$count" --out "$out" "$@" >"$out/sweep/gen.txt"

rows="$out/sweep/rows.tsv"
: >"$rows"
while read -r file kind robot suite attack; do
    name=$(basename "$file" .toml)
    if "$ftcbf" check "$file" >"$out/sweep/$name.check.txt" 2>&1; then
        if grep -q '^verdict: Theorem 3 applies' "$out/sweep/$name.check.txt"; then
            verdict=applies
        else
            verdict=no
        fi
    else
        verdict=ERROR
    fi
    # check's liveness prediction (issue #36), compared with the outcome below
    if grep -q '^liveness verdict: live' "$out/sweep/$name.check.txt"; then
        live=live
    else
        live=stall
    fi
    # a safe stop predicted on the way (a pause: live or stall is the walk's)
    if grep -q '^liveness verdict: .*the safe stop may brake near' "$out/sweep/$name.check.txt"; then
        stop=stop
    else
        stop=-
    fi
    json="$out/sweep/$name.json"
    if [[ ${REUSE:-0} == 1 && -s $json ]] \
        || "$ftcbf" batch "$file" --trials "$trials" --controller ft-cbf-clf --out "$json" \
            >"$out/sweep/$name.batch.txt" 2>&1; then
        stats=$(jq -r '.results[0].summaries[0] as $s
            | [$s.safe, $s.goals, $s.settled,
               (100 * $s.smoothness.omega_sign_change_fraction_mean),
               (100 * $s.steps.infeasible / ($s.control_steps | if . == 0 then 1 else . end))]
            | @tsv' "$json")
    else
        stats=$'-\t-\t-\t-\t-'
        verdict="$verdict/batch-ERROR"
    fi
    printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$name" "$kind" "$robot" "$suite" "$attack" \
        "$verdict" "$stats" "$live" "$stop" >>"$rows"
done < <(tail -n +3 "$out/sweep/gen.txt") # the listing's header and rule first

report="$out/sweep/report.txt"
awk -F'\t' -v n="$trials" '
function add(table, key) {
    worlds[table, key]++; keys[table, key] = 1
    if ($6 == "applies") applies[table, key]++
    if ($7 != "-") {
        safe[table, key] += $7; entered[table, key] += $8; settled[table, key] += $9
        flips[table, key] += $10; runs[table, key] += n; ran[table, key]++
    }
}
function totals(table, title, order,    i, m, names, k) {
    printf "\n%-18s %6s %8s %9s %9s %9s %9s\n", title, "worlds", "applies", "safe", "entered", "settled", "ω flips"
    m = split(order, names, " ")
    for (i = 1; i <= m; i++) {
        k = table SUBSEP names[i]
        if (!(k in keys)) continue
        printf "%-18s %6d %8d %9s %9s %9s %7.1f%%\n", names[i], worlds[k], applies[k],
            safe[k] "/" runs[k], entered[k] "/" runs[k], settled[k] "/" runs[k],
            (ran[k] ? flips[k] / ran[k] : 0)
    }
}
BEGIN {
    printf "%-22s %-8s %-6s %-17s %-30s %-8s %5s %7s %7s %7s %6s\n", "world", "kind", "robot", "suite",
        "attack", "verdict", "safe", "entered", "settled", "ω flips", "infeas", "liveness"
}
{
    printf "%-22s %-8s %-6s %-17s %-30s %-8s %5s %7s %7s %6.1f%% %5.1f%% %s\n", $1, $2, $3, $4, $5, $6,
        $7 "/" n, $8 "/" n, $9 "/" n, $10, $11, $12
    add("suite", $4); add("kind", $2); add("all", "all")
    if ($7 != "-") {
        judged++
        outcome = ($9 >= 0.95 * n) ? "live" : "stall"
        if ($12 == outcome) matched++
        if ($13 == "stop") { predicted_stop++; stop_trials += n; stop_trials_settled += $9 }
        if ($12 == "live") {
            predicted_live++; live_trials += n; live_trials_settled += $9
            if (outcome == "live") live_settled++
        }
        if ($6 == "applies") { applies_worlds++; if ($7 < n) unsafe_applies++ }
    }
}
END {
    totals("suite", "per suite", "two_receivers three_receivers odometry encoders receiver_velocity")
    totals("kind", "per kind", "room corridor doorway clutter l_turn")
    totals("all", "total", "all")
    printf "\nliveness: predicted live in %d of %d worlds, %d of them settled in >= 95 %% of trials; the prediction (live = settles in >= 95 %%) matches the outcome in %d of %d worlds\n", predicted_live, judged, live_settled, matched, judged
    printf "a safe stop predicted on the way in %d worlds: %d of %d trials settled\n", predicted_stop, stop_trials_settled, stop_trials
    printf "in the worlds predicted live, %d of %d trials settled (%.1f %%)\n", live_trials_settled, live_trials, live_trials ? 100 * live_trials_settled / live_trials : 0
    printf "Theorem 3 applies in %d worlds; unsafe trials in %d of them\n", applies_worlds, unsafe_applies
}
' "$rows" | tee "$report"

{
    echo "# Generated worlds: defaults only"
    echo
    echo "Written by \`scripts/gen_sweep.sh $seed $count $trials OUT_DIR\` (any output folder; do not edit by hand):"
    echo "$count worlds from \`ftcbf gen --seed $seed\`, every one with defaults only (no tuning key,"
    echo "no \`[control]\` table), \`ftcbf check\` on each, then \`ftcbf batch --trials $trials"
    echo "--controller ft-cbf-clf\`. Commit $(git rev-parse --short HEAD 2>/dev/null || echo unknown)$(git diff --quiet HEAD 2>/dev/null || echo ' (with local changes)'),"
    echo "$(date -u +%Y-%m-%d), $(uname -m), $(nproc) cores."
    if [[ ${REUSE:-0} == 1 ]]; then
        echo "Batch results reused from an earlier run (REUSE=1)${SWEEP_NOTE:+: $SWEEP_NOTE}; \`check\` ran again at this commit."
    fi
    echo
    echo "Columns: verdict = Theorem 3 applies / no; safe, entered, settled = trials of $trials;"
    echo "ω flips = mean % of control steps in which the commanded ω changes sign; infeas = % of"
    echo "control steps with no feasible input; liveness = \`check\`'s prediction, judged against"
    echo "\"settled in ≥ 95 % of trials\"."
    echo
    echo '```text'
    cat "$report"
    echo '```'
} >"$out/sweep/summary.md"
