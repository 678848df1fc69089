#!/usr/bin/env bash
# The scenario campaign of issue #31: `ftcbf falsify --scenario` on the catalogue (worlds/*.toml)
# and on worlds from `ftcbf gen`, then one row per world and the totals.
#
# usage: scripts/falsify_scenario_campaign.sh [GEN_SEED] [GEN_COUNT] [CATALOGUE_BUDGET] [GEN_BUDGET] [OUT_DIR]
#   defaults: gen seed 31, 40 generated worlds, budget 32 per catalogue world, 12 per generated
#   world, runs/scenario_campaign/. FTCBF=path/to/ftcbf overrides the binary (default
#   target/release/ftcbf); JOBS (default 2) the worker threads; run from the repository root.
# Writes OUT_DIR/gen/*.toml, OUT_DIR/json/NAME.json (each report), OUT_DIR/defects/NAME/ (a
# regression world per unsafe run where check says Theorem 3 applies) and OUT_DIR/worst/NAME.toml.
set -euo pipefail

gen_seed=${1:-31}
count=${2:-40}
cat_budget=${3:-32}
gen_budget=${4:-12}
out=${5:-runs/scenario_campaign}
ftcbf=${FTCBF:-target/release/ftcbf}
jobs=${JOBS:-2}
command -v jq >/dev/null || { echo "falsify_scenario_campaign.sh needs jq" >&2; exit 1; }

mkdir -p "$out/json" "$out/worst" "$out/defects"
"$ftcbf" gen --seed "$gen_seed" --count "$count" --out "$out/gen" >/dev/null

start=$(date +%s)
run() { # world budget
  local n
  n=$(basename "$1" .toml)
  "$ftcbf" falsify "$1" --scenario --controller ft-cbf-clf --budget "$2" --seed 1 --jobs "$jobs" \
    --json "$out/json/$n.json" --defects "$out/defects/$n" --out "$out/worst/$n.toml" >/dev/null
}
for w in worlds/*.toml; do run "$w" "$cat_budget"; done
for w in "$out"/gen/*.toml; do run "$w" "$gen_budget"; done
elapsed=$(($(date +%s) - start))

printf 'world\ttried\tinvalid\tT3_no\tnot_live\taccepted\truns\tunsafe\tunsafe_where_applies\tworst_rho\n'
jq -r '[.world, .variants_tried, .variants_invalid, .variants_not_applies, .variants_not_live,
        .variants_accepted, .runs, .unsafe_runs, .unsafe_where_applies,
        (if .worst then .worst.robustness.value else "-" end)] | @tsv' "$out"/json/*.json
jq -s '{worlds: length, tried: (map(.variants_tried) | add), accepted: (map(.variants_accepted) | add),
        runs: (map(.runs) | add), unsafe: (map(.unsafe_runs) | add),
        unsafe_where_applies: (map(.unsafe_where_applies) | add)}' "$out"/json/*.json
echo "wall time: $elapsed s"
