#!/usr/bin/env bash
# Regenerates book/src/development/speed.md (issue #52): every figure on the page is measured by
# this script in one run, on this machine, with the previous release's binary measured side by
# side, so a regression shows as a ratio and a slower machine does not pass for one.
#
#   scripts/speed.sh --base-bin PATH [--trials N] [--repeat R] [--out FILE]
#
#   --base-bin PATH  the previous release's `ftcbf` (build it in its own worktree and target:
#                    git worktree add ../ftcbf-base v0.X && (cd ../ftcbf-base && cargo build
#                    --release --workspace --all-targets --locked)); required
#   --trials N       trials of the batch rate (default 1000, the issue's figure)
#   --repeat R       runs per clutter point, the best kept (default 3)
#   --out FILE       where the page goes (default book/src/development/speed.md)
#
# Needs `cargo build --release --workspace --all-targets --locked` first (this tree's binary and
# its criterion bench executables in target/release/deps; they are run with `--bench`, so no
# bench-profile build is made). Times are whole processes: wall clock and CPU (user + system,
# from /usr/bin/time), best of R. On a shared machine read the CPU column.
#
# The sweep: 1, 16, 69 and 201 obstacles, the same world on a generated 384×384 map of 5 cm
# cells, and the 68-obstacle house of benches/worlds/house.toml.
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
base_bin=""
trials=1000
repeat=3
out="$root/book/src/development/speed.md"
while [[ $# -gt 0 ]]; do
  case "$1" in
    --base-bin) base_bin="$2"; shift 2 ;;
    --trials) trials="$2"; shift 2 ;;
    --repeat) repeat="$2"; shift 2 ;;
    --out) out="$2"; shift 2 ;;
    *) echo "speed.sh: unknown argument '$1' (see the header of $0)" >&2; exit 2 ;;
  esac
done
new_bin="$root/target/release/ftcbf"
[[ -x "$new_bin" ]] || { echo "speed.sh: $new_bin missing: cargo build --release --workspace --all-targets --locked" >&2; exit 2; }
[[ -n "$base_bin" && -x "$base_bin" ]] || { echo "speed.sh: --base-bin PATH (the previous release's ftcbf) is required" >&2; exit 2; }
[[ -x /usr/bin/time ]] || { echo "speed.sh: needs /usr/bin/time (GNU time)" >&2; exit 2; }

work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
# The start-up cache (q of the drive) is measured warm, like a user's second command.
export FTCBF_CACHE_DIR="$work/cache"

# --- the clutter worlds: the README's world with its one box (the wall removed), the path held
# by two waypoints (no planning, so the planner's cost is not in the sweep), plus N − 1
# cylinders of radius 0.1 m at least 3.4 m from the path.
python3 - "$root" "$work" <<'EOF'
import sys, re
root, work = sys.argv[1], sys.argv[2]
base = open(f"{root}/worlds/quickstart.toml").read()
base = base.replace('urdf = "../robots/', f'urdf = "{root}/robots/')
base = base[: base.index("[expect]")]
wall = base.index('[[obstacles]]\nname = "wall"')
base = base[:wall] + base[base.index("[[sensors]]", wall):]
base = base.replace("radius = 0.15\n", "radius = 0.15\nplan = false\nwaypoints = [[1.0, 0.75], [2.0, 0.75]]\n", 1)
for n in (1, 16, 69, 201):
    s = base
    for i in range(n - 1):
        col, row = i % 20, i // 20
        y = (3.5 + 0.5 * (row // 2)) * (1 if row % 2 == 0 else -1)
        s += f'\n[[obstacles]]\nname = "c{i}"\nposition = [{-2.0 + 0.4 * col:.2f}, {y:.2f}, 0.3]\nshape = {{ kind = "cylinder", radius = 0.1, half_height = 0.3 }}\n'
    open(f"{work}/clutter_{n}.toml", "w").write(s)
# The map point: the one-obstacle world on a generated 384 x 384 map of 5 cm cells (19.2 m
# square, centred on the path): a border wall and 40 seeded blocks at least 2 m from the path.
import random
rng = random.Random(52)
N, res, org = 384, 0.05, -9.6
img = bytearray([254]) * (N * N)
def block(x0, y0, x1, y1):
    for j in range(max(0, int((y0 - org) / res)), min(N, int((y1 - org) / res) + 1)):
        for i in range(max(0, int((x0 - org) / res)), min(N, int((x1 - org) / res) + 1)):
            img[(N - 1 - j) * N + i] = 0
block(org, org, -org, org + 0.2); block(org, -org - 0.2, -org, -org)
block(org, org, org + 0.2, -org); block(-org - 0.2, org, -org, -org)
placed = 0
while placed < 40:
    x, y = rng.uniform(-9.0, 9.0), rng.uniform(-9.0, 9.0)
    w, h = rng.uniform(0.2, 1.0), rng.uniform(0.2, 1.0)
    if -2.5 < x < 5.5 + w and -2.0 - h < y < 2.75:
        continue
    block(x, y, x + w, y + h)
    placed += 1
open(f"{work}/map.pgm", "wb").write(f"P5\n{N} {N}\n255\n".encode() + bytes(img))
open(f"{work}/map.yaml", "w").write(f"image: map.pgm\nresolution: {res}\norigin: [{org}, {org}, 0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")
one = open(f"{work}/clutter_1.toml").read()
open(f"{work}/map_world.toml", "w").write(one.replace("[[obstacles]]", '[environment]\nmap = "map.yaml"\n\n[[obstacles]]', 1))
EOF
MAP_WORLD="$work/map_world.toml"   # the 384 x 384 map point

# best of $repeat: "wall cpu" in seconds
measure() {
  local best_w="" best_c=""
  for _ in $(seq "$repeat"); do
    /usr/bin/time -f "%e %U %S" -o "$work/t" "$@" > /dev/null 2>&1 || { echo "speed.sh: failed: $*" >&2; exit 1; }
    read -r w u s < "$work/t"
    c=$(python3 -c "print(f'{$u + $s:.2f}')")
    if [[ -z "$best_w" ]] || python3 -c "import sys; sys.exit(0 if $c < $best_c else 1)"; then best_w=$w; best_c=$c; fi
  done
  echo "$best_w $best_c"
}

rows="$work/rows"
: > "$rows"
clutter_row() { # label world
  local label="$1" w="$2"
  "$new_bin" run "$w" --no-record > /dev/null 2>&1 || true   # warm the q cache
  read -r nw nc < <(measure "$new_bin" run "$w" --no-record)
  # the previous release may not read every world (maps came later): then "-"
  if "$base_bin" run "$w" --no-record > /dev/null 2>&1; then
    read -r bw bc < <(measure "$base_bin" run "$w" --no-record)
  else
    bw="-"; bc="-"
  fi
  echo "clutter|$label|$nw|$nc|$bw|$bc" >> "$rows"
}
for n in 1 16 69 201; do clutter_row "$n" "$work/clutter_$n.toml"; done
if [[ -n "$MAP_WORLD" ]]; then clutter_row "384×384 map" "$MAP_WORLD"; fi

# the house (benches/worlds/house.toml, scripts/house_world.py): 68 obstacles, 90 s simulated
house="$root/benches/worlds/house.toml"
"$new_bin" run "$house" --no-record > /dev/null 2>&1 || true
read -r nw nc < <(measure "$new_bin" run "$house" --no-record)
read -r bw bc < <(measure "$base_bin" run "$house" --no-record)
echo "house|68|$nw|$nc|$bw|$bc" >> "$rows"

read -r nw nc < <(measure "$new_bin" check "$root/worlds/quickstart.toml")
read -r bw bc < <(measure "$base_bin" check "$root/worlds/quickstart.toml")
echo "check|quickstart|$nw|$nc|$bw|$bc" >> "$rows"

# batch rate: one run each (it is long), all cores
batch() { /usr/bin/time -f "%e %U %S" -o "$work/t" "$@" > /dev/null 2>&1; read -r w u s < "$work/t"; echo "$w $(python3 -c "print(f'{$u + $s:.1f}')")"; }
batch_row() { # label controller-args...: this tree, then the previous release, back to back
  local label="$1"; shift
  local cmd=(batch "$root/worlds/paper_turtlebot.toml" --trials "$trials" "$@")
  read -r nw nc < <(batch "$new_bin" "${cmd[@]}" --out "$work/new.csv")
  read -r bw bc < <(batch "$base_bin" "${cmd[@]}" --out "$work/base.csv")
  same=$(cmp -s "$work/new.csv" "$work/base.csv" && echo "identical" || echo "different")
  rates=$(python3 - "$work/new.csv" "$work/base.csv" <<'PY'
import csv, sys
def rate(f):
    rows = list(csv.DictReader(open(f)))
    ft = [r for r in rows if r["controller"] == "ft-cbf-clf"]
    return f"{sum(r['safe'] == 'true' for r in ft)}/{len(ft)}"
print(rate(sys.argv[1]), rate(sys.argv[2]))
PY
)
  echo "batch|$label|$trials|$nw|$nc|$bw|$bc|$same|$rates" >> "$rows"
}
batch_row "FT-CBF-CLF only (\`--controller ft-cbf-clf\`)" --controller ft-cbf-clf
batch_row "paired with the baseline (the default controllers)"

# criterion: the control step with 2 and 200 barriers (this tree only: the bench is new)
step_bench=$(ls -t "$root"/target/release/deps/step-* 2>/dev/null | grep -v '\.d$' | head -1 || true)
bench_txt=""
if [[ -n "$step_bench" ]]; then
  bench_txt=$("$step_bench" --bench clutter 2>/dev/null | grep -E '^step_m2_clutter|time:' || true)
fi

commit=$(git -C "$root" rev-parse --short HEAD)$(git -C "$root" diff --quiet HEAD || echo "+dirty")
cpu=$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ //')
python3 - "$rows" "$out" "$commit" "$cpu" "$(nproc)" "$(uname -sr)" "$base_bin" "$("$base_bin" --version 2>/dev/null || echo '?')" "$bench_txt" "$(cat /proc/loadavg | cut -d' ' -f1-3)" <<'EOF'
import os, sys, datetime
rows, out, commit, cpu, cores, kernel, base_bin, base_ver, bench, load = sys.argv[1:11]
R = [l.rstrip("\n").split("|") for l in open(rows) if l.strip()]
cl = [r for r in R if r[0] == "clutter"]
one_new, one_base = float(cl[0][3]), float(cl[0][5])
L = []
L.append("# Speed\n")
L.append("Generated by `scripts/speed.sh` (issue #52): every figure below was measured in one run, "
         "with the previous release's binary measured side by side on the same machine, so a "
         "regression shows as a ratio. Do not edit by hand; run the script again.\n")
L.append(f"- date: {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC; commit {commit}")
L.append(f"- machine: {cpu}, {cores} cores, {kernel}; load average at the end {load}")
L.append(f"- previous release: `{os.path.basename(base_bin)}` ({base_ver}), the binary given as `--base-bin`")
L.append("- times are whole processes, best of the script's `--repeat`; CPU = user + system. "
         "On a shared machine the CPU column is the one to compare.\n")
L.append("## Clutter: cost per obstacle\n")
L.append("The README's world (burger, two receivers, odometry, compass, one box; path held by two "
         "waypoints) plus cylinders at least 3.4 m from the path; `ftcbf run W --no-record`, 30 s "
         "simulated. Target (#52): 201 obstacles ≤ 1.3× the one-obstacle world.\n")
L.append("| obstacles | wall | CPU | × one obstacle (CPU) | real time (CPU) | previous: CPU | × one obstacle | this / previous |")
L.append("|---:|---:|---:|---:|---:|---:|---:|---:|")
for _, n, nw, nc, bw, bc in cl:
    nc = float(nc)
    if bc == "-":
        prev = "— (cannot read this world) | — | —"
    else:
        bc = float(bc)
        prev = f"{bc:.2f} s | {bc / one_base:.2f} | {nc / bc:.2f}"
    L.append(f"| {n} | {nw} s | {nc:.2f} s | {nc / one_new:.2f} | {30 / nc:.0f}× | {prev} |")
L.append("")
L.append("The map point is the one-obstacle world on a generated 384 × 384 map of 5 cm cells (a border "
         "wall and 40 seeded blocks at least 2 m from the path). Target (#52): ≤ 2× the one-obstacle world.\n")
for r in R:
    if r[0] == "house":
        _, n, nw, nc, bw, bc = r
        L.append(f"The house (`benches/worlds/house.toml`: {n} obstacles, walls as thin boxes, furniture; 90 s "
                 f"simulated, an 8.8 m path): {nw} s wall, {float(nc):.2f} s CPU, **{90 / float(nc):.0f}× real time** (CPU); "
                 f"previous release {float(bc):.2f} s CPU ({90 / float(bc):.0f}×). Target (#52): ≥ 100×.\n")
for r in R:
    if r[0] == "check":
        _, _, nw, nc, bw, bc = r
        L.append(f"`ftcbf check worlds/quickstart.toml` (q of the drive cached on disk, warm): {nw} s wall, {nc} s CPU; previous release {bw} s wall, {bc} s CPU. Target: ≤ 0.1 s.\n")

batches = [r for r in R if r[0] == "batch"]
if batches:
    L.append("## Batch rate\n")
    L.append(f"`ftcbf batch worlds/paper_turtlebot.toml --trials {batches[0][2]}`, all cores, one run each, "
             "this tree and the previous release back to back. Target (#52): ≥ 2.4× faster (CPU), single and paired.\n")
    L.append("| batch | wall | CPU | CPU per trial | previous: wall | previous: CPU | this / previous (CPU) | FT-CBF-CLF safe: this, previous | CSVs |")
    L.append("|---|---:|---:|---:|---:|---:|---:|---|---|")
    for _, label, n, nw, nc, bw, bc, same, rates in batches:
        per = 1000 * float(nc) / int(n)
        L.append(f"| {label} | {nw} s | {nc} s | {per:.1f} ms | {bw} s | {bc} s | {float(nc) / float(bc):.2f} ({float(bc) / float(nc):.2f}× faster) | {rates.replace(' ', ', ')} | {same} |")
    L.append("")
L.append("## Criterion: the control step with far barriers\n")
L.append("`target/release/deps/step-* --bench clutter` (controller/benches/step.rs): the m = 2 closed loop "
         "with the floor and 1 or 199 far discs, δ = ∞, the discs in the controller library's "
         "`EllipseIndex` (as a user of the library would put them); `200_unindexed`: the same "
         "200 barriers without the index. Target: 200 ≤ 1.5× 2.\n")
import re
unit = {"ns": 1e-3, "µs": 1.0, "us": 1.0, "ms": 1e3, "s": 1e6}
times, name = {}, None
for line in bench.splitlines():
    m = re.match(r"^(step_m2_clutter_\S+)", line)
    if m:
        name = m.group(1)
    t = re.search(r"time:\s+\[(\S+) (\S+) (\S+) (\S+) (\S+) (\S+)\]", line)
    if t and name:
        times[name] = [float(t.group(i)) * unit[t.group(i + 1)] for i in (1, 3, 5)]
        name = None
if times:
    L.append("| bench | time (criterion's interval) [µs] | × 2 barriers (medians) |")
    L.append("|---|---:|---:|")
    two = times.get("step_m2_clutter_2", [float("nan")] * 3)[1]
    for n, (lo, mid, hi) in times.items():
        L.append(f"| `{n}` | {lo:.1f} / **{mid:.1f}** / {hi:.1f} | {mid / two:.2f} |")
    L.append("")
else:
    L.append("(no bench executable found: build with --all-targets)\n")
L.append("## Other benches\n")
L.append("Not run by this script (run them for figures; the page keeps no hand-written numbers): "
         "`target/release/deps/step-* --bench` (every control-step bench: m = 2 and 3, static, "
         "closed loop, safety-filter form, the feasibility test), `target/release/deps/physics-* "
         "--bench` (one physics tick), `target/release/deps/run-* --bench` (a whole "
         "`paper_turtlebot` run, recording off and on), `target/release/deps/setup-* --bench` "
         "(starting trials from one `CompiledWorld`), after `cargo build --release --workspace "
         "--all-targets --locked`.\n")
L.append("A control step allocates nothing outside clarabel (checked by a counting allocator in "
         "`controller/tests/allocation.rs`); a QP that must grow for more binding rows than it "
         "holds (a world with more than 12 barrier rows, see `controller/src/qp.rs`) is rebuilt "
         "once, then reused.\n")
open(out, "w").write("\n".join(L))
EOF
echo "wrote $out"
