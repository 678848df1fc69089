#!/usr/bin/env python3
"""Writes benches/worlds/house.toml (issue #52): a house as a transcription of one reads —
walls as thin boxes with door gaps, furniture as boxes and cylinders — 68 obstacles, the
README's burger and sensors, an ~8.8 m path through two doors. Seeded (random.Random(52)), so
the file is the same on every run: python3 scripts/house_world.py > benches/worlds/house.toml"""
import math
import random

rng = random.Random(52)
T = 0.05  # half thickness of a wall [m]
H = 0.4   # half height of a wall [m]
walls = [
    # outer walls of a 10 m x 6 m house
    ("wall_south", 5.0, -T, 5.0 + T, T),
    ("wall_north", 5.0, 6.0 + T, 5.0 + T, T),
    ("wall_west", -T, 3.0, T, 3.0),
    ("wall_east", 10.0 + T, 3.0, T, 3.0),
    # x = 4 with a door at y in [2.0, 3.0]
    ("wall_4_low", 4.0, 1.0, T, 1.0),
    ("wall_4_high", 4.0, 4.5, T, 1.5),
    # x = 7 with a door at y in [3.5, 4.5]
    ("wall_7_low", 7.0, 1.75, T, 1.75),
    ("wall_7_high", 7.0, 5.25, T, 0.75),
    # y = 4 in the west room with a door at x in [1.5, 2.5]
    ("wall_y4_west", 0.75, 4.0, 0.75, T),
    ("wall_y4_east", 3.25, 4.0, 0.75, T),
]
path = [(1.0, 1.0), (4.0, 2.5), (7.0, 4.0), (9.0, 4.5)]

def seg_dist(p, a, b):
    ax, ay = a; bx, by = b; px, py = p
    dx, dy = bx - ax, by - ay
    t = max(0.0, min(1.0, ((px - ax) * dx + (py - ay) * dy) / (dx * dx + dy * dy)))
    return math.hypot(px - ax - t * dx, py - ay - t * dy)

def clear_of_path(x, y, r):
    return all(seg_dist((x, y), path[i], path[i + 1]) > r + 0.6 for i in range(len(path) - 1))

def inside_wall(x, y, r):
    for _, cx, cy, hx, hy in walls:
        if abs(x - cx) < hx + r + 0.05 and abs(y - cy) < hy + r + 0.05:
            return True
    return False

items = []
while len(walls) + len(items) < 68:
    kind = rng.choice(["box", "box", "cyl"])
    x, y = rng.uniform(0.3, 9.7), rng.uniform(0.3, 5.7)
    if kind == "box":
        hx, hy, hz = rng.uniform(0.1, 0.4), rng.uniform(0.1, 0.4), rng.uniform(0.2, 0.4)
        r = math.hypot(hx, hy)
    else:
        rad, hz = rng.uniform(0.05, 0.2), rng.uniform(0.2, 0.5)
        r = rad
    if not clear_of_path(x, y, r) or inside_wall(x, y, r):
        continue
    if any(math.hypot(x - o[1], y - o[2]) < r + o[3] + 0.05 for o in items):
        continue
    items.append((kind, x, y, r, (hx, hy, hz) if kind == "box" else (rad, hz)))

print("# A house (issue #52's speed target: >= 100x real time with 68 obstacles), written by")
print("# scripts/house_world.py (seeded): walls as thin boxes with door gaps, furniture as boxes and")
print("# cylinders, the README's burger and sensors, a path of ~8.8 m through two doors.")
print('name = "house"')
print('description = "Burger crosses a 10 m x 6 m house through two doors; 68 obstacles."')
print("duration = 90.0\nseed = 1\n")
print('[robot]\nurdf = "../../robots/turtlebot3_burger.urdf"\nstart = { x = 1.0, y = 1.0, theta = 0.46 }\n')
print("[control]\ninput_limit = 1.0\n")
print("[goal]\ncenter = [9.0, 4.5]\nradius = 0.15\nplan = false")
print("waypoints = [[4.0, 2.5], [7.0, 4.0]]\n")
for name, cx, cy, hx, hy in walls:
    print(f'[[obstacles]]\nname = "{name}"\nposition = [{cx:.3f}, {cy:.3f}, {H}]')
    print(f'shape = {{ kind = "cuboid", half_extents = [{hx:.3f}, {hy:.3f}, {H}] }}\n')
for i, (kind, x, y, r, dims) in enumerate(items):
    if kind == "box":
        hx, hy, hz = dims
        yaw = rng.uniform(-0.5, 0.5)
        print(f'[[obstacles]]\nname = "furniture_{i}"\nposition = [{x:.3f}, {y:.3f}, {hz:.3f}]\nrpy = [0.0, 0.0, {yaw:.3f}]')
        print(f'shape = {{ kind = "cuboid", half_extents = [{hx:.3f}, {hy:.3f}, {hz:.3f}] }}\n')
    else:
        rad, hz = dims
        print(f'[[obstacles]]\nname = "furniture_{i}"\nposition = [{x:.3f}, {y:.3f}, {hz:.3f}]')
        print(f'shape = {{ kind = "cylinder", radius = {rad:.3f}, half_height = {hz:.3f} }}\n')
for s in [("a_x", "x", 0.03), ("a_y", "y", 0.03), ("b_x", "x", 0.03), ("b_y", "y", 0.03),
          ("odom", "speed", 0.01), ("compass", "heading", 0.01)]:
    print(f'[[sensors]]\nname = "{s[0]}"\nmeasures = "{s[1]}"\nnoise_std = {s[2]}\n')
print('[[fault_patterns]]\nname = "a"\nchannels = ["a_x", "a_y"]\n')
print('[[fault_patterns]]\nname = "b"\nchannels = ["b_x", "b_y"]')
