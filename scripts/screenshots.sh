#!/usr/bin/env bash
# Regenerates the book's and the README's viewer pictures from recordings of the current code
# (issue #48/#49): each world is run, its recording opened once in the real rerun viewer (as
# scripts/viewer_check.py does: fresh home, designed layout checked) and the window saved
# WAIT seconds after it showed. The viewer plays the run from its start, at real speed at most
# (slower on a loaded machine: 8.7 to 11.9 s of the quick start after 20 s of waiting, 2026-11-27): the
# time shown is in the picture's time panel, and the captions in book/src/guide/viewing.md and
# the README must be checked against the new pictures.
#
# Usage: scripts/screenshots.sh   (needs target/release/ftcbf, rerun-sdk[datafusion]==0.36.3,
# xvfb and mesa-vulkan-drivers; about 3 minutes)
set -euo pipefail
cd "$(dirname "$0")/.."
bin="${FTCBF:-target/release/ftcbf}"
out=book/src/images
tmp=$(mktemp -d)
trap 'kill "$xvfb" 2>/dev/null || true; rm -rf "$tmp"' EXIT
Xvfb :96 -screen 0 1600x1000x24 -nolisten tcp >/dev/null 2>&1 &
xvfb=$!
sleep 2
# world file | picture | WAIT [s]
while read -r world picture wait; do
  [ -z "$world" ] && continue
  name=$(basename "$world" .toml)
  "$bin" run "$world" --out "$tmp/$name.rrd" >/dev/null
  DISPLAY=:96 python3 scripts/viewer_check.py --opens 1 --wait "$wait" --shots "$tmp/shots" "$tmp/$name.rrd"
  cp "$tmp/shots/$name-1.png" "$out/$picture"
  echo "screenshots: $out/$picture (taken $wait s after the designed view showed)"
done <<'LIST'
worlds/quickstart.toml viewer-quickstart.png 20
worlds/corridor_spoof.toml viewer-corridor_spoof.png 12
worlds/stealthy_gnss.toml viewer-stealthy_gnss.png 12
worlds/doorway_clutter.toml viewer-doorway_clutter.png 12
worlds/turtlebot_realistic.toml viewer-turtlebot_realistic.png 8
tests/worlds_viewer/hex_arena.toml viewer-hex_arena.png 20
tests/worlds_user/user_living_room.toml viewer-user_living_room-estimation_error.png 20
LIST
