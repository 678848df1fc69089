#!/usr/bin/env python3
"""Reads an ftcbf recording back with the real rerun client (rerun-sdk 0.36.3 with the
`datafusion` extra) and checks what the viewer will show:

- the file carries a blueprint for the recording's own application id (`ftcbf-<world>-…`),
  with one 3D view, a text log and time-series views (barriers, sensors, residues, control);
- the 3D view's eye is set in the blueprint (`EyeControls3D`: position, look target, up = +z):
  it looks down at ≥ 45° on a target inside the ground, and no obstacle stands between the eye
  and the robot along ≥ 90 % of the true path (rays to the robot's middle, 0.1 m up, against
  each obstacle's bounding box);
- every `/world/estimates/<filter>` has *temporal* positions (no static position that would hide
  them) that change over time, and the robot's links move;
- h on the truth and on each estimate is plotted for every barrier, with the zero line;
- no value of a plotted series lies outside the documented plot range (|v| < 1e6).

Each moving obstacle (`/world/movers/<name>`) has a temporal translation that changes and its
trail under `/world/trails/movers/`. A tracked one (read through its `tracker`) also has its
estimate at `/world/mover_estimates/<name>`: temporal positions that change, each within 1 m
of the true mover, with temporal radii (its bound γ_p) > 0; an exactly read one has none.

With `--visual-meshes N`: at least N robot shapes are URDF visual meshes (`Mesh3D` entities
named `<link>_visual_<i>` under `/world/robot`).

Usage: rrd_check.py FILE.rrd WORLD [--visual-meshes N]
(exit status 1 with a message on the first failure)
"""

import math
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
    return eye_of_3d_view(table)


def first(table, name):
    """The first non-null value of a column (a list of instances), or None."""
    for v in table.column(name).to_pylist():
        if v:
            return v
    return None


def eye_of_3d_view(table):
    """(position, look_target) of the 3D view's EyeControls3D property in the blueprint."""
    view = None
    for name in columns(table, ":ViewBlueprint:class_identifier"):
        if first(table, name) == ["3D"]:
            view = name.split(":")[0]
    eye = {}
    for field in ("position", "look_target", "eye_up"):
        name = f"{view}/EyeControls3D:EyeControls3D:{field}"
        if name not in table.schema.names or first(table, name) is None:
            fail(f"the 3D view {view} has no EyeControls3D {field} in the blueprint")
        eye[field] = first(table, name)[0]
    if [round(x, 6) for x in eye["eye_up"]] != [0.0, 0.0, 1.0]:
        fail(f"eye_up is {eye['eye_up']}, not +z")
    pos, target = eye["position"], eye["look_target"]
    d = [pos[i] - target[i] for i in range(3)]
    elevation = math.degrees(math.atan2(d[2], math.hypot(d[0], d[1])))
    if elevation < 45.0:
        fail(f"the eye {pos} looks at {target} from only {elevation:.1f}° above the ground")
    print(f"rrd_check: 3D eye at {[round(x, 2) for x in pos]} looking at "
          f"{[round(x, 2) for x in target]}, {elevation:.1f}° above the ground")
    return pos, target


def rotate(q, v):
    """v turned by the unit quaternion q = (x, y, z, w)."""
    x, y, z, w = q
    tx, ty, tz = 2 * (y * v[2] - z * v[1]), 2 * (z * v[0] - x * v[2]), 2 * (x * v[1] - y * v[0])
    return [v[0] + w * tx + y * tz - z * ty, v[1] + w * ty + z * tx - x * tz, v[2] + w * tz + x * ty - y * tx]


def obstacle_boxes(store):
    """World-frame axis-aligned bounding boxes (lo, hi) of every obstacle as drawn."""
    # Static-only entities yield no rows on their own: read them with the moving robot.
    table = store.reader("step", contents=["/world/**"]).to_arrow_table()
    names = {n.split(":")[0] for n in table.schema.names if n.startswith(("/world/obstacles/", "/world/ground"))}
    boxes, ground = [], None
    for ent in sorted(names):
        col = lambda c: first(table, f"{ent}:{c}") if f"{ent}:{c}" in table.schema.names else None
        if ent == "/world/ground":
            c, h = col("Boxes3D:centers")[0], col("Boxes3D:half_sizes")[0]
            ground = ([c[0] - h[0], c[1] - h[1]], [c[0] + h[0], c[1] + h[1]])
            continue
        local = None
        if col("Boxes3D:half_sizes"):
            h = col("Boxes3D:half_sizes")[0]
            local = [[s * h[0], t * h[1], u * h[2]] for s in (-1, 1) for t in (-1, 1) for u in (-1, 1)]
        elif col("Ellipsoids3D:half_sizes"):
            h = col("Ellipsoids3D:half_sizes")[0]
            local = [[s * h[0], t * h[1], u * h[2]] for s in (-1, 1) for t in (-1, 1) for u in (-1, 1)]
        elif col("Cylinders3D:radii"):
            r, ln = col("Cylinders3D:radii")[0], col("Cylinders3D:lengths")[0]
            local = [[s * r, t * r, u * ln / 2] for s in (-1, 1) for t in (-1, 1) for u in (-1, 1)]
        elif col("Capsules3D:radii"):
            r, ln = col("Capsules3D:radii")[0], col("Capsules3D:lengths")[0]
            local = [[s * r, t * r, u * (ln / 2 + r)] for s in (-1, 1) for t in (-1, 1) for u in (-1, 1)]
        elif col("Mesh3D:vertex_positions"):
            local = col("Mesh3D:vertex_positions")
        if local is None:
            continue
        # An obstacle drawn see-through (alpha < 255: a mesh around the robot, such as an
        # arena's wall) hides nothing.
        colour = col("Mesh3D:albedo_factor") or col("Boxes3D:colors") or col("Cylinders3D:colors") \
            or col("Ellipsoids3D:colors") or col("Capsules3D:colors")
        if colour and (colour[0] & 0xFF) < 255:
            print(f"rrd_check: {ent} is drawn see-through (alpha {colour[0] & 0xFF})")
            continue
        tr = col("Transform3D:translation") or [[0.0, 0.0, 0.0]]
        q = col("Transform3D:quaternion") or [[0.0, 0.0, 0.0, 1.0]]
        pts = [[a + b for a, b in zip(rotate(q[0], p), tr[0])] for p in local]
        boxes.append((ent, [min(p[i] for p in pts) for i in range(3)], [max(p[i] for p in pts) for i in range(3)]))
    if ground is None:
        fail("no /world/ground")
    return boxes, ground


def hits(a, b, lo, hi):
    """Whether the segment a–b passes through the box [lo, hi] (slab test)."""
    t0, t1 = 0.0, 1.0
    for k in range(3):
        d = b[k] - a[k]
        if abs(d) < 1e-12:
            if a[k] < lo[k] or a[k] > hi[k]:
                return False
            continue
        u, v = (lo[k] - a[k]) / d, (hi[k] - a[k]) / d
        t0, t1 = max(t0, min(u, v)), min(t1, max(u, v))
        if t0 > t1:
            return False
    return True


def check_view(store, eye):
    """The eye's target lies on the ground, and obstacles hide the robot along < 10 % of its path."""
    pos, target = eye
    boxes, (glo, ghi) = obstacle_boxes(store)
    if not (glo[0] <= target[0] <= ghi[0] and glo[1] <= target[1] <= ghi[1]):
        fail(f"the eye looks at {target}, outside the ground {glo}–{ghi}")
    table = store.reader("step", contents=["/world/trails/truth"]).to_arrow_table()
    name = "/world/trails/truth:LineStrips3D:strips"
    path = [v for v in table.column(name).to_pylist() if v][-1][0]
    hidden = {}
    for p in path:
        robot = [p[0], p[1], 0.1]
        for ent, lo, hi in boxes:
            if hits(pos, robot, lo, hi):
                hidden[ent] = hidden.get(ent, 0) + 1
                break
    share = sum(hidden.values()) / len(path)
    if share > 0.1:
        fail(f"obstacles hide the robot from the eye along {share:.0%} of its path: {hidden}")
    print(f"rrd_check: the robot is in sight along {1 - share:.0%} of its path ({len(path)} points)")


def check_visual_meshes(store, n):
    table = store.reader("step", contents=["/world/robot/**"]).to_arrow_table()
    meshes = [c for c in columns(table, ":Mesh3D:vertex_positions") if "_visual_" in c.split(":")[0]]
    if len(meshes) < n:
        fail(f"{len(meshes)} robot visual meshes, expected at least {n}")
    print(f"rrd_check: {len(meshes)} robot links drawn from URDF visual meshes")


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
    check_movers(table)
    return store


def check_movers(table):
    """Each moving obstacle (issue #51) drawn at `/world/movers/<name>` moves: its translation
    is temporal and takes >= 10 distinct values, and its trail `/world/trails/movers/<name>`
    is drawn. A world without movers has no `/world/movers/` entity."""
    movers = [n for n in columns(table, ":Transform3D:translation")
              if n.startswith("/world/movers/") and n.split(":")[0].count("/") == 3]
    strips = columns(table, ":LineStrips3D:strips")
    for name in movers:
        entity = name.split(":")[0]
        seen = distinct_positions(table, name)
        if len(seen) < 10:
            fail(f"{entity}: only {len(seen)} distinct translations over time")
        trail = "/world/trails/movers/" + entity.rsplit("/", 1)[1] + ":LineStrips3D:strips"
        if trail not in strips:
            fail(f"{entity}: no trail {trail.split(':')[0]}")
        print(f"rrd_check: {entity}: {len(seen)} distinct translations, trail drawn")
    check_mover_estimates(table, movers)


def check_mover_estimates(table, movers):
    """A tracked mover's estimate (issue #51) is drawn beside it: temporal positions at
    `/world/mover_estimates/<name>` of a mover that exists, >= 10 distinct, each within 1 m of
    the mover's true centre at the same step (its start plus its translation), with radii > 0."""
    names = {n.split(":")[0].rsplit("/", 1)[1]: n for n in movers}
    est = [n for n in columns(table, ":Points3D:positions") if n.startswith("/world/mover_estimates/")]
    for name in est:
        entity = name.split(":")[0]
        mover = entity.rsplit("/", 1)[1]
        if mover not in names:
            fail(f"{entity}: no mover `{mover}` drawn at /world/movers/")
        seen = distinct_positions(table, name)
        if len(seen) < 10:
            fail(f"{entity}: only {len(seen)} distinct positions over time")
        radii = entity + ":Points3D:radii"
        if radii not in columns(table, ":Points3D:radii") or is_static(table, radii):
            fail(f"{entity}: no temporal radii (its bound)")
        if any(r is not None and not (r and r[0] > 0) for r in table.column(radii).to_pylist()):
            fail(f"{entity}: a radius (its bound) is not > 0")
        start = mover_start(table, mover)
        worst = 0.0
        for p, d in zip(table.column(name).to_pylist(), table.column(names[mover]).to_pylist()):
            if p and d and start is not None:
                true = (start[0] + d[0][0], start[1] + d[0][1])
                worst = max(worst, math.hypot(p[0][0] - true[0], p[0][1] - true[1]))
        if worst > 1.0:
            fail(f"{entity}: {worst:.3f} m from the mover it tracks")
        print(f"rrd_check: {entity}: {len(seen)} distinct positions, at most {worst:.3f} m from the mover")


def mover_start(table, mover):
    """The mover's start in the plane: the first point of its trail."""
    trail = "/world/trails/movers/" + mover + ":LineStrips3D:strips"
    if trail not in columns(table, ":LineStrips3D:strips"):
        return None
    for v in table.column(trail).to_pylist():
        if v and v[0]:
            return v[0][0]
    return None


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
    args = sys.argv[1:]
    meshes = 0
    if len(args) == 4 and args[2] == "--visual-meshes" and args[3].isdigit():
        meshes = int(args[3])
        args = args[:2]
    if len(args) != 2:
        fail("usage: rrd_check.py FILE.rrd WORLD [--visual-meshes N]")
    reader = RrdReader(args[0])
    eye = check_blueprint(reader, args[1])
    store = check_motion(reader)
    check_view(store, eye)
    check_plots(store)
    if meshes:
        check_visual_meshes(store, meshes)
    print("rrd_check: ok")


if __name__ == "__main__":
    main()
