#!/usr/bin/env python3
"""Opens ftcbf recordings in the real rerun viewer and checks that they open with their
designed layout (issue #48).

For every FILE.rrd:

1. **Message order.** `rerun rrd print` lists the file's messages in order; the default
   blueprint's activation command must come before the recording's first message (its store
   info). A viewer that sees the recording first makes it active and fills an empty blueprint
   with its own heuristic layout; a default blueprint arriving later is stored, not shown.
2. **The layout, read back from the viewer.** The viewer (rerun-sdk's own binary, under the
   X display in `$DISPLAY`, Vulkan through Mesa's lavapipe) is started on the file `--opens`
   times, each time with a fresh home directory (a first-time user: no stored layout). Through
   its client API the script asks for a screenshot of the designed 3D view, by the view id the
   file's blueprint gives it. The viewer answers only if that view is in the layout it shows:
   in the heuristic layout the id does not exist and the request is never answered, so an
   open counts as *designed* when the view's screenshot arrives within `--timeout` seconds.
   A screenshot of the whole window is kept for every open (`--shots DIR`).

Exit status 0 when every file passes both checks on every open; 1 otherwise, with a line per
failure. Usage:

    DISPLAY=:98 scripts/viewer_check.py [--opens N] [--shots DIR] [--order-only] FILE.rrd…

Needs `rerun-sdk[datafusion]==0.36.3` (pip) and, for the viewer, `xvfb` and
`mesa-vulkan-drivers` (Debian); `.ci/run` installs them and starts `Xvfb`.
"""

import argparse
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time

from rerun.experimental import RrdReader

# The rerun CLI and viewer of the installed rerun-sdk, whatever is on PATH.
RERUN = [sys.executable, "-m", "rerun"]


def message_order(path):
    """(index of the activation command, index of the recording's first store info) in the
    file's message list; None where there is none."""
    out = subprocess.run(
        [*RERUN, "rrd", "print", path], capture_output=True, text=True, timeout=300, check=True
    ).stdout.splitlines()
    activation, recording, msg = None, None, -1
    for i, line in enumerate(out):
        if line.startswith(("StoreInfo {", "Chunk(", "BlueprintActivationCommand(")):
            msg += 1
        if line.startswith("BlueprintActivationCommand(") and activation is None:
            activation = msg
        if line.startswith("StoreInfo {") and recording is None:
            kind = next((l.strip().rstrip(",") for l in out[i + 1 : i + 6] if l.strip() in ("Recording,", "Blueprint,")), None)
            if kind == "Recording":
                recording = msg
    return activation, recording


def designed_view_ids(path):
    """{view id: class} of the blueprint the file carries for its recording's application."""
    reader = RrdReader(path)
    recs = reader.recordings()
    if len(recs) != 1:
        raise SystemExit(f"{path}: expected one recording, found {len(recs)}")
    app = recs[0].application_id
    bps = [b for b in reader.blueprints() if b.application_id == app]
    if not bps:
        raise SystemExit(f"{path}: no blueprint for application {app!r}")
    table = reader.store(store=bps[0]).stream().collect().reader("blueprint", contents=["/**"]).to_arrow_table()
    views = {}
    for name in table.schema.names:
        if name.endswith(":ViewBlueprint:class_identifier"):
            cls = next((v for v in table.column(name).to_pylist() if v), None)
            views[name.split(":")[0].rsplit("/", 1)[-1]] = cls[0] if cls else None
    return views


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


SHOT = """
import sys
from rerun.experimental import ViewerClient
c = ViewerClient.connect(sys.argv[1])
c.save_screenshot(sys.argv[2], view_id=(sys.argv[3] or None))
"""


def screenshot(url, out, view_id, timeout):
    """True when the viewer saved the screenshot within `timeout` seconds."""
    try:
        r = subprocess.run([sys.executable, "-c", SHOT, url, out, view_id or ""], capture_output=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return False
    return r.returncode == 0 and os.path.exists(out)


def wait_listening(port, proc, timeout):
    end = time.time() + timeout
    while time.time() < end and proc.poll() is None:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return True
        time.sleep(0.5)
    return False


def open_once(path, view3d, shot, timeout, wait=0.0, starts=3):
    """Opens `path` in a new viewer with a fresh home; True when it shows the designed layout.
    The window's screenshot is taken `wait` seconds after the 3D view answered (the viewer plays
    the run from its start at real speed, so that is about the simulated time shown). A viewer
    that exits before it listens (it is started up to `starts` times) is reported with its log;
    that is a failure to start, not a layout."""
    for attempt in range(starts):
        home = tempfile.mkdtemp(prefix="ftcbf-viewer-home-")
        port = free_port()
        env = dict(os.environ, HOME=home, XDG_DATA_HOME=os.path.join(home, ".local/share"),
                   XDG_CONFIG_HOME=os.path.join(home, ".config"), WGPU_BACKEND="vulkan")
        log_path = os.path.join(home, "viewer.log")
        log = open(log_path, "w")
        proc = subprocess.Popen([*RERUN, "--bind", "127.0.0.1", "--port", str(port), path],
                                env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
        try:
            url = f"rerun+http://127.0.0.1:{port}/proxy"
            if not wait_listening(port, proc, 60):
                log.flush()
                kept = shot + f".viewer-{attempt + 1}.log"
                shutil.copy(log_path, kept)
                print(f"viewer_check: {path}: the viewer did not start (exit {proc.poll()}, log {kept})")
                continue
            ok = screenshot(url, shot + ".3d.png", view3d, timeout)
            time.sleep(wait)
            # The whole window as the user sees it (the artefact), taken after the 3D view
            # answered (or gave up), so the data has loaded.
            screenshot(url, shot, None, timeout)
            return ok
        finally:
            try:
                os.killpg(proc.pid, signal.SIGTERM)
                proc.wait(10)
            except ProcessLookupError:
                pass
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
            log.close()
            shutil.rmtree(home, ignore_errors=True)
    return False


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("files", nargs="+", metavar="FILE.rrd")
    ap.add_argument("--opens", type=int, default=3, help="viewer opens per file (default 3)")
    ap.add_argument("--shots", default="target/ci/viewer", help="folder for the screenshots")
    ap.add_argument("--timeout", type=float, default=45.0,
                    help="seconds the designed 3D view may take to answer (default 45)")
    ap.add_argument("--order-only", action="store_true", help="check the message order only")
    ap.add_argument("--wait", type=float, default=0.0,
                    help="seconds between the 3D view's answer and the window's screenshot")
    args = ap.parse_args()
    os.makedirs(args.shots, exist_ok=True)
    failures = 0
    for path in args.files:
        name = os.path.basename(path).removesuffix(".rrd")
        activation, recording = message_order(path)
        if activation is None or recording is None or activation > recording:
            print(f"viewer_check: FAIL {path}: blueprint activation at message {activation}, "
                  f"recording starts at message {recording}: the blueprint must come first")
            failures += 1
        else:
            print(f"viewer_check: {path}: blueprint activation at message {activation}, "
                  f"before the recording's first message ({recording})")
        if args.order_only:
            continue
        views = designed_view_ids(path)
        view3d = next((v for v, cls in views.items() if cls == "3D"), None)
        if view3d is None:
            print(f"viewer_check: FAIL {path}: the blueprint has no 3D view")
            failures += 1
            continue
        designed = 0
        for i in range(args.opens):
            t0 = time.time()
            ok = open_once(path, view3d, os.path.join(args.shots, f"{name}-{i + 1}.png"),
                           args.timeout, args.wait)
            designed += ok
            print(f"viewer_check: {name} open {i + 1}: {'designed layout' if ok else 'NOT the designed layout'}"
                  f" ({time.time() - t0:.1f} s)", flush=True)
        if designed < args.opens:
            failures += 1
        print(f"viewer_check: {path}: designed layout in {designed} of {args.opens} opens")
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
