#!/usr/bin/env bash
# Regenerates the JSON behind the book's results pages, then the pages themselves.
#
# usage: scripts/results.sh [TRIALS] [BUDGET] [FALSIFY_WORLD…]
#   TRIALS: trials per world for `ftcbf batch` (default 1000, the full measurement)
#   BUDGET: runs per search method for `ftcbf falsify` (default 400)
#   FALSIFY_WORLD…: names of catalogue worlds to falsify (default: every catalogue world)
#   FTCBF=path/to/ftcbf overrides the binary (default target/release/ftcbf, built by
#   `cargo build --release --workspace --all-targets --locked`); JOBS=N the worker threads (default
#   all cores); RESUME=1 keeps results/stamp.toml and skips every command already in it (to
#   finish an interrupted measurement, or to measure a world added to the catalogue since: its
#   commands then record the commit they ran at). Run from the repository root.
#
# Also searches the safe stop's worlds (tests/worlds_safe_stop/) with `--family fallback`.
# Writes results/batch/*.json, results/falsify/*.json and results/stamp.toml (the invocation,
# commit, date, machine and every command exactly as run, with its wall time), then runs
# `ftcbf report`, which renders book/src/results/ from them. `ftcbf report --check` (CI)
# re-renders and fails if the committed pages differ. The full measurement,
# `scripts/results.sh`, takes hours on 2 cores: each command's time is in the stamp.
set -euo pipefail
cd "$(dirname "$0")/.."

invocation="scripts/results.sh $*"
trials=${1:-1000}
budget=${2:-400}
shift $(($# < 2 ? $# : 2))
ftcbf=${FTCBF:-target/release/ftcbf}
jobs=${JOBS:-$(nproc)}

# The catalogue: every world in worlds/, paired FT-CBF-CLF vs the all-sensor baseline.
catalogue=(quickstart paper_linear paper_turtlebot paper_turtlebot_sf paper_turtlebot_receivers
    corridor_spoof field_replay elliptic_arena_drift three_gnss stealthy_gnss outside_model
    waffle_pillars doorway_clutter turtlebot_realistic turtlebot_odometry_bias
    turtlebot_encoders turtlebot_gyro_compass)
# FT-CBF-CLF alone: the attacks that refuted the claim before the #10/#16 work, and worlds
# written as a user would (no tuning key).
alone=(tests/worlds_guarantees/paper_turtlebot_receivers_garbage
    tests/worlds_guarantees/paper_turtlebot_receivers_stealthy
    tests/worlds_user/user_living_room tests/worlds_user/user_l_corridor
    tests/worlds_user/user_clutter_waffle tests/worlds_user/user_crate_corridor)
if [[ $# -gt 0 ]]; then falsify=("$@"); else falsify=("${catalogue[@]}"); fi
# The safe stop's worlds (issue #50: two sources nothing can tell apart), FT-CBF-CLF searched
# with the attacks aimed at the safe stop (`--family fallback`).
safe_stop=(pair_ramp_corridor gen3_066_corridor user_pair_doorway)

stamp=results/stamp.toml
if [[ ${RESUME:-0} != 1 || ! -f $stamp ]]; then
    # The tree is judged before the old results are removed: their removal is not a change
    # to the code that measures.
    commit=$(git rev-parse HEAD)
    if [[ -n $(git status --porcelain --untracked-files=no) ]]; then
        commit="$commit (uncommitted changes)"
    fi
    rm -rf results/batch results/falsify
    cpu=$(sed -n 's/^model name[[:space:]]*: //p' /proc/cpuinfo | head -n 1)
    mkdir -p results
    {
        echo "# Written by scripts/results.sh; read by \`ftcbf report\`. Do not edit by hand."
        echo "script = '$invocation'"
        echo "commit = \"$commit\""
        echo "date = \"$(date -u +%Y-%m-%dT%H:%M:%SZ)\""
        echo "machine = \"$(uname -sm), ${cpu:-unknown CPU}, $(nproc) cores, load average $(cut -d' ' -f1 /proc/loadavg) at the start\""
        echo "toolchain = \"$(rustc --version)\""
    } >"$stamp"
fi
mkdir -p results/batch results/falsify runs/falsify
# A command run at another commit than the stamp's (RESUME=1 after a world was added) records
# its own, and the pages say so.
head=$(git rev-parse HEAD)
if [[ -n $(git status --porcelain --untracked-files=no) ]]; then
    head="$head (uncommitted changes)"
fi
stamp_commit=$(sed -n 's/^commit = "\(.*\)"$/\1/p' "$stamp" | head -n 1)

# run JSON COMMAND...: runs COMMAND (unless the stamp lists JSON already), then appends it (as
# typed, with `ftcbf` for the binary) and its wall time to the stamp.
run() {
    local json=$1
    shift
    if grep -qF "json = \"$json\"" "$stamp"; then
        echo "already measured: $json"
        return
    fi
    local t0=$SECONDS
    "$ftcbf" "$@" >/dev/null
    local shown="ftcbf $*"
    [[ $shown != *"'"* ]] || { echo "a quote in a command: $shown" >&2; exit 1; }
    printf "\n[[run]]\njson = \"%s\"\ncommand = '%s'\nseconds = %d\n" \
        "$json" "$shown" $((SECONDS - t0)) >>"$stamp"
    if [[ $head != "$stamp_commit" ]]; then
        printf 'commit = "%s"\n' "$head" >>"$stamp"
    fi
    echo "$shown ($((SECONDS - t0)) s)"
}

for w in "${catalogue[@]}"; do
    run "results/batch/$w.json" batch "worlds/$w.toml" --trials "$trials" --jobs "$jobs" \
        --out "results/batch/$w.json"
done
for path in "${alone[@]}"; do
    w=$(basename "$path")
    run "results/batch/$w.json" batch "$path.toml" --trials "$trials" \
        --controller ft-cbf-clf --jobs "$jobs" --out "results/batch/$w.json"
done
# `batch` draws its figure next to each JSON file; the report draws the same figures into the
# book from the JSON, so these copies are not kept.
rm -f results/batch/*.svg
for w in "${falsify[@]}"; do
    run "results/falsify/$w.json" falsify "worlds/$w.toml" --controller ft-cbf-clf \
        --budget "$budget" --jobs "$jobs" --no-record --out "runs/falsify/$w.toml" \
        --json "results/falsify/$w.json"
done
for w in "${safe_stop[@]}"; do
    run "results/falsify/fallback_$w.json" falsify "tests/worlds_safe_stop/$w.toml" \
        --controller ft-cbf-clf --family fallback --budget "$budget" --jobs "$jobs" --no-record \
        --out "runs/falsify/fallback_$w.toml" --json "results/falsify/fallback_$w.json"
done

"$ftcbf" report
