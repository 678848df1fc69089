#!/usr/bin/env bash
# Runs ftcbf on worlds robots already live in (issue #47), loaded as their packages ship them:
# the Gazebo SDF worlds of the ROBOTIS TurtleBot3 simulations (turtlebot3_world, turtlebot3_house,
# DQN stages 1-4; the stages' plugin-driven obstacles are dropped, so stages 3 and 4 run on their
# static parts) and the nav2 occupancy map of the TurtleBot3 world, all read by absolute path
# from ROBOTIS_DIR (never copied into the repository), plus the map fixture
# tests/worlds_map/office.yaml. For each start/goal pair it
# writes a world file (only `[environment]`, robot, start, goal, sensors, fault patterns and an
# attack), runs `ftcbf check` and `ftcbf batch --trials TRIALS --controller ft-cbf-clf`, and
# writes OUT/real-worlds.md: safe and settled with their 95 % Wilson intervals, check's verdict
# and liveness prediction against the outcome (live ⇔ settled in ≥ 95 % of trials). The book's
# results/real-worlds.md is that file.
#
# usage: scripts/real_worlds.sh ROBOTIS_DIR OUT [TRIALS]
#   ROBOTIS_DIR holds checkouts of github.com/ROBOTIS-GIT/turtlebot3_simulations
#   (turtlebot3_simulations/turtlebot3_gazebo/…) and github.com/ROBOTIS-GIT/turtlebot3
#   (turtlebot3/turtlebot3_navigation2/map/map.yaml). TRIALS defaults to 200.
#   FTCBF=path/to/ftcbf overrides the binary (default target/release/ftcbf); run from the
#   repository root. PAIRS="sdf:0 map:1 …" runs a subset (default: all).
set -euo pipefail

robotis=$(cd "${1:?usage: scripts/real_worlds.sh ROBOTIS_DIR OUT [TRIALS]}" && pwd)
out=${2:?usage: scripts/real_worlds.sh ROBOTIS_DIR OUT [TRIALS]}
trials=${3:-200}
ftcbf=${FTCBF:-target/release/ftcbf}
repo=$(pwd)
command -v jq >/dev/null || { echo "real_worlds.sh needs jq" >&2; exit 1; }
gazebo="$robotis/turtlebot3_simulations/turtlebot3_gazebo"
navmap="$robotis/turtlebot3/turtlebot3_navigation2/map/map.yaml"
for f in "$gazebo/worlds/turtlebot3_world.world" "$gazebo/worlds/turtlebot3_house.world" \
    "$gazebo"/worlds/turtlebot3_dqn_stage{1,2,3,4}.world "$navmap"; do
    [[ -f $f ]] || { echo "real_worlds.sh: $f not found (ROBOTIS_DIR = $robotis)" >&2; exit 1; }
done
mkdir -p "$out"
# the commit the run starts from (a page rewritten later still names it)
commit=$(git rev-parse --short HEAD)
dirty=$(git diff --quiet HEAD -- . ':!book/src/results' && echo "" || echo " (with local changes)")

sdf() { printf 'sdf = "%s"\\nmodel_paths = ["%s"]' "$gazebo/worlds/$1.world" "$gazebo/models"; }
# name | environment table | start x y θ | goal x y
pairs=(
    "map_world_0|map = \"$navmap\"|-2.0 -0.5 0.0|2.0 0.5"
    "sdf_world_0|sdf = \"$gazebo/worlds/turtlebot3_world.world\"\nmodel_paths = [\"$gazebo/models\"]|-2.0 -0.5 0.0|2.0 0.5"
    "map_office_1|map = \"$repo/tests/worlds_map/office.yaml\"|0.251 0.477 0.2|3.483 2.152"
    "map_world_1|map = \"$navmap\"|-2.0 0.5 0.0|0.6 -1.6"
    "sdf_world_1|sdf = \"$gazebo/worlds/turtlebot3_world.world\"\nmodel_paths = [\"$gazebo/models\"]|-1.6 0.5 0.0|1.6 -0.5"
    "map_office_0|map = \"$repo/tests/worlds_map/office.yaml\"|-1.815 3.119 0.2|2.635 3.817"
    # the house: through the doorway by the mailbox, the east doorway, the west doorway
    "house_0|$(sdf turtlebot3_house)|1.5 -2.0 1.57|-2.0 1.5"
    "house_1|$(sdf turtlebot3_house)|5.5 -1.2 1.57|4.0 1.5"
    "house_2|$(sdf turtlebot3_house)|-6.5 -1.0 1.57|-6.5 3.0"
    # the DQN stages: the empty square, its four pillars, and the static parts of stages 3-4
    "dqn1_0|$(sdf turtlebot3_dqn_stage1)|-1.5 -1.5 0.0|1.5 1.5"
    "dqn2_0|$(sdf turtlebot3_dqn_stage2)|-1.5 -1.5 0.0|1.5 1.5"
    "dqn3_0|$(sdf turtlebot3_dqn_stage3)|-1.5 1.5 0.0|1.5 -1.5"
    "dqn4_0|$(sdf turtlebot3_dqn_stage4)|-1.8 -0.8 0.0|1.8 1.0"
)

world_file() { # name env sx sy st gx gy
    cat <<EOF
name = "$1"
duration = 40.0
seed = 1
robot = { urdf = "$repo/robots/turtlebot3_burger.urdf", start = { x = $3, y = $4, theta = $5 } }
goal = { center = [$6, $7], radius = 0.15 }
sensors = [{ name = "a_x", measures = "x", noise_std = 0.03 }, { name = "a_y", measures = "y", noise_std = 0.03 },
  { name = "b_x", measures = "x", noise_std = 0.03 }, { name = "b_y", measures = "y", noise_std = 0.03 },
  { name = "odom", measures = "speed", noise_std = 0.01 }, { name = "compass", measures = "heading", noise_std = 0.01 }]
fault_patterns = [{ name = "a", channels = ["a_x", "a_y"] }, { name = "b", channels = ["b_x", "b_y"] }]
attacks = [{ kind = "bias", channels = ["b_y"], start = 3.0, value = 0.4 }]

[environment]
$(printf '%b' "$2")
EOF
}

# Wilson 95 % interval of k successes in n trials
wilson() {
    awk -v k="$1" -v n="$2" 'BEGIN { z = 1.959964; p = k / n; d = 1 + z * z / n;
        c = (p + z * z / (2 * n)) / d; h = z * sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d;
        lo = c - h; hi = c + h; if (lo < 0) lo = 0; if (hi > 1) hi = 1;
        printf "[%.3f, %.3f]", lo, hi }'
}

page() {
    {
        echo "# Worlds robots live in: SDF worlds and occupancy maps"
        echo
        echo "Written by \`scripts/real_worlds.sh ROBOTIS_DIR OUT_DIR $trials\` (do not edit by hand): the"
        echo "ROBOTIS TurtleBot3 worlds (\`turtlebot3_gazebo/worlds/\`: \`turtlebot3_world\`,"
        echo "\`turtlebot3_house\`, \`turtlebot3_dqn_stage1\`–\`4\`, with their \`models/\`; the"
        echo "obstacles stages 3 and 4 move by plugin are dropped, so those stages run on their static"
        echo "parts) and the nav2 map of the TurtleBot3 world (\`turtlebot3_navigation2/map/map.yaml\`), read"
        echo "unchanged from checkouts of ROBOTIS' repositories, and the map fixture"
        echo "\`tests/worlds_map/office.yaml\` (7 m × 5 m at 5 cm, origin turned 0.2 rad, a doorway, a"
        echo "pillar, a desk and a diagonal cabinet). Each world file holds only \`[environment]\`, the"
        echo "burger, start, goal, the quick start's sensors (two receivers, wheel odometry, compass) and"
        echo "attack (receiver b's y biased by 0.4 m from t = 3 s). \`ftcbf check\`, then"
        echo "\`ftcbf batch --trials $trials --controller ft-cbf-clf\`, each row at the commit it names"
        echo "(a PAIRS subset rerun keeps the other rows); $(uname -m), $(nproc) cores shared with other work."
        echo
        echo "Intervals are 95 % Wilson intervals. \`check\` predicts live when the rows leave a forward"
        echo "input along the planned path and hold the robot in its goal; the prediction matches when"
        echo "it said live and ≥ 95 % of trials settled, or said stall and fewer did."
        echo
        echo "| world | start → goal | Theorem 3 | safe | settled | check predicts | matches | batch time | commit |"
        echo "|---|---|---|---:|---:|---|---|---:|---|"
        while IFS=$'\t' read -r name verdict live safe settled n secs s g at; do
            if [[ $live == live ]]; then
                ok=$(awk -v k="$settled" -v n="$n" 'BEGIN { print (k >= 0.95 * n) ? "yes" : "no" }')
            else
                ok=$(awk -v k="$settled" -v n="$n" 'BEGIN { print (k < 0.95 * n) ? "yes" : "no" }')
            fi
            echo "| $name | ($s) → ($g) | $verdict | $safe/$n $(wilson "$safe" "$n") | $settled/$n $(wilson "$settled" "$n") | $live | $ok | ${secs} s | $at |"
        done <"$rows"
    } >"$out/real-worlds.md"
    readme_rows >"$out/readme-rows.md"
}

# The README's table: the rows summed per world (name up to its last `_`), in the order the
# worlds first appear.
readme_rows() {
    echo "| world | pairs | Theorem 3 applies | safe | settled in the goal | \`check\` predicted live, matched |"
    echo "|---|---:|---:|---|---|---:|"
    local w
    for w in $(cut -f1 "$rows" | sed 's/_[^_]*$//' | awk '!seen[$0]++'); do
        read -r pairs applies safe settled n live matched < <(awk -F'\t' -v w="$w" '
            { g = $1; sub(/_[^_]*$/, "", g) }
            g == w { p++; a += ($2 == "applies"); s += $4; t += $5; n += $6
                if ($3 == "live") { l++; m += ($5 >= 0.95 * $6) } }
            END { print p, a, s, t, n, l + 0, m + 0 }' "$rows")
        local label
        case $w in
            sdf_world) label="SDF: \`turtlebot3_world.world\`" ;;
            map_world) label="nav2 map of turtlebot3_world" ;;
            map_office) label="map fixture \`tests/worlds_map/office.yaml\`" ;;
            house) label="SDF: \`turtlebot3_house.world\`" ;;
            dqn1) label="SDF: \`turtlebot3_dqn_stage1.world\`" ;;
            dqn2) label="SDF: \`turtlebot3_dqn_stage2.world\`" ;;
            dqn3 | dqn4) label="SDF: \`turtlebot3_${w/dqn/dqn_stage}.world\` (static parts)" ;;
            *) label=$w ;;
        esac
        echo "| $label | $pairs | $applies | $safe/$n $(wilson "$safe" "$n") | $settled/$n $(wilson "$settled" "$n") | $matched of $live |"
    done
}

rows="$out/rows.tsv"
touch "$rows"
for entry in "${pairs[@]}"; do
    IFS='|' read -r name env start goal <<<"$entry"
    if [[ -n ${PAIRS:-} && " $PAIRS " != *" $name "* ]]; then continue; fi
    read -r sx sy st <<<"$start"
    read -r gx gy <<<"$goal"
    world_file "$name" "$env" "$sx" "$sy" "$st" "$gx" "$gy" >"$out/$name.toml"
    "$ftcbf" check "$out/$name.toml" >"$out/$name.check.txt" 2>&1 || true
    if grep -q '^verdict: Theorem 3 applies' "$out/$name.check.txt"; then verdict=applies; else verdict=no; fi
    if grep -q '^liveness verdict: live' "$out/$name.check.txt"; then live=live; else live=stall; fi
    start_s=$(date +%s)
    "$ftcbf" batch "$out/$name.toml" --trials "$trials" --controller ft-cbf-clf -j 2 \
        --out "$out/$name.json" >"$out/$name.batch.txt" 2>&1
    secs=$(($(date +%s) - start_s))
    read -r safe settled n < <(jq -r '.results[0].summaries[0] | [.safe, .settled, .trials] | @tsv' "$out/$name.json")
    { grep -v "^$name"$'\t' "$rows" || true; } >"$rows.new"
    printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s %s\t%s %s\t%s\n' "$name" "$verdict" "$live" "$safe" "$settled" "$n" "$secs" \
        "$sx," "$sy" "$gx," "$gy" "$commit$dirty" >>"$rows.new"
    mv "$rows.new" "$rows"
    page # after each pair, so a run stopped half-way leaves the pairs it finished
done
page # also when no pair ran: PAIRS=none rewrites the page from OUT/rows.tsv
cat "$out/real-worlds.md"

