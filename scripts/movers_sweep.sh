#!/usr/bin/env bash
# Issue #51's measurement: generated worlds with moving obstacles, defaults only.
# Generates COUNT worlds of each moving kind (aisle_crossing, corridor_walker, room_people,
# dqn_loops) with `ftcbf gen --seed SEED`, keeps those that have a mover, runs `ftcbf check`
# and `ftcbf batch --controller ft-cbf-clf --trials TRIALS` on each, and prints one row per
# world (verdict, liveness prediction, safe/settled of TRIALS, collisions by who moved, the
# trials unsafe by the robot's own motion, the median over trials of the least clearance) and
# the totals: unsafe trials where check says Theorem 3 applies (all, and by the robot's own
# motion: a trial whose only contacts are movers walking into the stopped robot, which check
# says the guarantee does not cover, is not the robot's), settled where predicted live, and
# how often the prediction matched (live ⇔ settled in ≥ 95 % of trials).
# usage: scripts/movers_sweep.sh [SEED] [COUNT] [TRIALS] [OUT_DIR]   (needs jq)
set -euo pipefail
seed=${1:-51}; count=${2:-56}; trials=${3:-20}; out=${4:-movers_out}
ftcbf=${FTCBF:-target/release/ftcbf}
mkdir -p "$out/sweep"
for k in aisle_crossing corridor_walker room_people dqn_loops; do
    "$ftcbf" gen --seed "$seed" --count "$count" --out "$out" --kind "$k" >>"$out/sweep/gen.txt"
done
printf 'world\tverdict\tliveness\tsafe\tsettled\tstatic_hit\tmover_hit_moving\tmover_hit_stopped\town_unsafe\tclearance_p50\n'
for file in "$out"/*.toml; do
    grep -q '^motion' "$file" || continue
    name=$(basename "$file" .toml)
    if "$ftcbf" check "$file" >"$out/sweep/$name.check.txt" 2>&1; then
        grep -q '^verdict: Theorem 3 applies' "$out/sweep/$name.check.txt" && verdict=applies || verdict=no
    else
        verdict=ERROR
    fi
    grep -q '^liveness verdict: live' "$out/sweep/$name.check.txt" && live=live || live=stall
    json="$out/sweep/$name.json"
    if [[ ${REUSE:-0} == 1 && -s $json ]] || "$ftcbf" batch "$file" --trials "$trials" --controller ft-cbf-clf --out "$json" >"$out/sweep/$name.batch.txt" 2>&1; then
        stats=$(jq -r '.results[0] as $r | $r.summaries[0] as $s
            | ([$r.records[] | select(.controller == "ft-cbf-clf")]) as $t
            | ([$t[] | select(.safe | not)
                | select((.collisions.static_obstacles == 0 and .collisions.mover_robot_moving == 0
                          and .collisions.mover_robot_stopped > 0 and .first_violation_set == null) | not)]
               | length) as $own
            | ([$t[].min_clearance] | sort | .[(length / 2 | floor)]) as $c
            | [$s.safe, $s.settled, $s.static_collision_trials, $s.mover_hit_while_moving_trials,
               $s.mover_hit_while_stopped_trials, $own, $c] | @tsv' "$json")
    else
        stats=$'ERROR\tERROR\t-\t-\t-\t-\t-'
    fi
    printf '%s\t%s\t%s\t%s\n' "$name" "$verdict" "$live" "$stats"
done | tee "$out/sweep/rows.tsv"
awk -F'\t' -v n="$trials" '
    { worlds++; if ($2 == "applies") { ap++; unsafe_ap += n - $4; own_ap += $9 } else { unsafe_no += n - $4 }
      live_obs = ($5 >= 0.95 * n); if ($3 == "live") { pl++; settled_pl += $5; trials_pl += n }
      if (($3 == "live") == live_obs) agree++ }
    END { printf "worlds %d; check applies in %d: unsafe trials there %d of %d (by the robot'"'"'s own motion %d); unsafe elsewhere %d\n", worlds, ap, unsafe_ap, ap * n, own_ap, unsafe_no;
          printf "predicted live %d: settled %d of %d trials (%.3f); prediction matched in %d of %d worlds (%.3f)\n", pl, settled_pl, trials_pl, (trials_pl ? settled_pl / trials_pl : 0), agree, worlds, agree / worlds }' "$out/sweep/rows.tsv"
