"""The cost of driving the simulation from Python, side by side with the Rust loop.

    FTCBF_BIN=target/release/ftcbf python python/benchmarks/step_overhead.py [WORLD] [REPEATS]

For one world and seed (default worlds/paper_turtlebot_sf.toml, seed 1), the median over
REPEATS (default 5) of:
  cli      `ftcbf run WORLD --no-record` wall time (process start, world load, run, print);
  run()    World.load + Simulation(...).run() in this process (the loop in Rust);
  step()   World.load + a `while sim.step()` loop in Python (a Frame per step);
  law      run() with the built-in law replaced by a Python law that returns (0, 0)
           (a Python call per step from inside the Rust loop).
and the per-step overhead of step() and of a Python law over the Rust loop.
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import time

import ftcbf


class Zero:
    name = "zero"

    def __init__(self, config):
        pass

    def step(self, readings):
        return (0.0, 0.0)


def timed(f, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        f()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main() -> None:
    world_path = sys.argv[1] if len(sys.argv) > 1 else "worlds/paper_turtlebot_sf.toml"
    repeats = int(sys.argv[2]) if len(sys.argv) > 2 else 5
    binary = os.environ.get("FTCBF_BIN", "target/release/ftcbf")
    seed = "1"

    def cli():
        subprocess.run([binary, "run", world_path, "--seed", seed, "--no-record"],
                       check=True, capture_output=True)

    def run():
        ftcbf.Simulation(ftcbf.World.load(world_path), seed=int(seed)).run()

    def step():
        sim = ftcbf.Simulation(ftcbf.World.load(world_path), seed=int(seed))
        while sim.step() is not None:
            pass

    def law():
        ftcbf.Simulation(ftcbf.World.load(world_path), seed=int(seed), controller=Zero).run()

    steps = ftcbf.Simulation(ftcbf.World.load(world_path)).progress[1]
    t = {name: timed(f, repeats) for name, f in
         [("cli", cli), ("run()", run), ("step()", step), ("law", law)]}
    print(f"{world_path}: {steps} control steps, median of {repeats}")
    for name, v in t.items():
        print(f"  {name:7s} {v * 1e3:9.1f} ms  {v / steps * 1e6:8.1f} µs/step")
    print(f"  run() / cli: {t['run()'] / t['cli']:.3f}")
    print(f"  step() overhead over run(): {(t['step()'] - t['run()']) / steps * 1e6:.1f} µs/step")


if __name__ == "__main__":
    main()
