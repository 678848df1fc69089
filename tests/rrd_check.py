#!/usr/bin/env python3
"""Reads an ftcbf recording back with the real rerun client (rerun-sdk 0.36.3 with the
`datafusion` extra) and checks what the viewer will show:

- the file carries a blueprint for the recording's own application id (`ftcbf-<world>-…`),
  with one 3D view, a text log and time-series views (barriers, sensors, residues, control);
- every `/world/estimates/<filter>` has *temporal* positions (no static position that would hide
  them) that change over time, and the robot's links move;
- h on the truth and on each estimate is plotted for every barrier, with the zero line;
- no value of a plotted series lies outside the documented plot range (|v| < 1e6).

Usage: rrd_check.py FILE.rrd WORLD   (exit status 1 with a message on the first failure)
"""

import sys

import pyarrow.compute as pc
from rerun.experimental import RrdReader


def fail(msg):
    print(f"rrd_check: FAIL: {msg}")
    sys.exit(1)


def columns(table, suffix):
    return {f.name: f for f in table.schema if f.name.endswith(suffix)}


def check_blueprint(reader, world):
    recs = reader.recordings()
    if len(recs) != 1:
        fail(f"expected one recording, found {len(recs)}")
    app = recs[0].application_id
    if not app.startswith(f"ftcbf-{world}-"):
        fail(f"application id {app!r} does not name the world {world!r}")
    bps = [b for b in reader.blueprints() if b.application_id == app]
    if not bps:
        fail(f"no blueprint for application id {app!r}")
    table = reader.store(store=bps[0]).stream().collect().reader("blueprint", contents=["/**"]).to_arrow_table()
    classes = []
    for name in columns(table, ":ViewBlueprint:class_identifier"):
        for v in table.column(name).to_pylist():
            if v:
                classes.extend(v)
    if classes.count("3D") != 1 or classes.count("TextLog") != 1 or classes.count("TimeSeries") < 5:
        fail(f"blueprint views are {sorted(classes)}")
    print(f"rrd_check: blueprint for {app}: {len(classes)} views ({classes.count('TimeSeries')} plots)")


def is_static(table, name):
    meta = table.schema.field(name).metadata or {}
    return meta.get(b"rerun:is_static") == b"true"


def distinct_positions(table, name):
    if is_static(table, name):
        fail(f"{name} is static: it would hide the positions over time")
    seen = set()
    for v in table.column(name).to_pylist():
        if v:
            seen.add(tuple(round(x, 4) for x in v[0]))
    return seen


def check_motion(reader):
    store = reader.store().stream().collect()
    table = store.reader("step", contents=["/world/**"]).to_arrow_table()
    est = columns(table, ":Points3D:positions")
    est = {n: f for n, f in est.items() if n.startswith("/world/estimates/")}
    if not est:
        fail("no /world/estimates/* positions")
    for name in est:
        seen = distinct_positions(table, name)
        if len(seen) < 10:
            fail(f"{name}: only {len(seen)} distinct positions over time")
        print(f"rrd_check: {name.split(':')[0]}: {len(seen)} distinct positions")
    links = columns(table, ":Transform3D:translation")
    links = [n for n in links if n.startswith("/world/robot/") and not is_static(table, n)]
    moving = [n for n in links if len(distinct_positions(table, n)) >= 10]
    if not moving:
        fail("no robot link moves")
    return store


def check_plots(store):
    table = store.reader("step", contents=["/barriers/**", "/sensors/**", "/clf/**", "/residues/**"]).to_arrow_table()
    scalars = columns(table, ":Scalars:scalars")
    truths = [n for n in scalars if n.startswith("/barriers/") and n.split(":")[0].endswith("/truth")]
    zeros = [n for n in scalars if n.startswith("/barriers/") and n.split(":")[0].endswith("/zero")]
    if not truths or len(zeros) != len(truths):
        fail(f"barrier plots: {len(truths)} truth series, {len(zeros)} zero lines")
    for name in scalars:
        col = pc.list_flatten(table.column(name))
        if len(col) == 0:
            continue
        worst = pc.max(pc.abs(col)).as_py()
        if worst is not None and worst >= 1e6:
            fail(f"{name}: |value| = {worst:g} is outside any plot range")
    print(f"rrd_check: {len(scalars)} plotted series within range, {len(truths)} barriers with zero lines")


def main():
    if len(sys.argv) != 3:
        fail("usage: rrd_check.py FILE.rrd WORLD")
    reader = RrdReader(sys.argv[1])
    check_blueprint(reader, sys.argv[2])
    store = check_motion(reader)
    check_plots(store)
    print("rrd_check: ok")


if __name__ == "__main__":
    main()
