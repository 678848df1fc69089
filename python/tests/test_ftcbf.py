"""The Python package against the `ftcbf` command: the same world and seed give the same
summary bit for bit, a batch the same report and JSON, a bad world the same message."""

from __future__ import annotations

import math
import struct
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import ftcbf

LINEAR = "worlds/paper_linear.toml"
ROBOT = "worlds/paper_turtlebot_sf.toml"


def bits_equal(a, b, path="summary"):
    """Deep equality with floats compared by their bits (so -0.0 != 0.0 and NaN == NaN)."""
    assert type(a) is type(b), f"{path}: {type(a).__name__} vs {type(b).__name__}"
    if isinstance(a, dict):
        assert a.keys() == b.keys(), f"{path}: keys {sorted(a.keys() ^ b.keys())} differ"
        for k in a:
            bits_equal(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, list):
        assert len(a) == len(b), f"{path}: lengths {len(a)} and {len(b)}"
        for i, (x, y) in enumerate(zip(a, b)):
            bits_equal(x, y, f"{path}[{i}]")
    elif isinstance(a, float):
        assert struct.pack("<d", a) == struct.pack("<d", b), f"{path}: {a!r} vs {b!r}"
    else:
        assert a == b, f"{path}: {a!r} vs {b!r}"


class MedianPd:
    """A law in Python: per state component, the median of the fresh finite readings of the
    channels that measure it directly (held between samples), then a saturated PD law toward
    the goal (the Rust example examples/custom_controller.rs, in Python)."""

    name = "median-pd"
    steps = 0

    def __init__(self, config: ftcbf.LawConfig) -> None:
        c = config.c
        self.component = [
            int(np.flatnonzero(row == 1.0)[0])
            if np.count_nonzero(row == 1.0) == 1 and np.count_nonzero(row == 0.0) == 3
            else None
            for row in c
        ]
        self.goal = config.goal
        self.limit = config.input_limit if config.input_limit is not None else np.ones(2)
        self.x = np.full(4, np.nan)

    def step(self, r: ftcbf.Readings):
        MedianPd.steps += 1
        for i in range(4):
            vals = [
                y
                for y, fresh, ci in zip(r.y, r.fresh, self.component)
                if fresh and ci == i and math.isfinite(y)
            ]
            if vals:
                self.x[i] = float(np.median(vals))
        u = []
        for a in range(2):
            p, v = self.x[a], self.x[a + 2]
            v = v if math.isfinite(v) else 0.0
            raw = 0.6 * (self.goal[a] - p) - 1.2 * (v - self.goal[a + 2]) if math.isfinite(p) else 0.0
            u.append(min(max(raw, -self.limit[a]), self.limit[a]))
        return u


@pytest.mark.parametrize("world,seed", [(LINEAR, 7), (ROBOT, 3)])
def test_a_run_matches_the_cli_summary_bit_for_bit(cli_json, world, seed):
    expected = cli_json("run", world, "--seed", str(seed), "--json", "--no-record")
    w = ftcbf.World.load(world)
    bits_equal(ftcbf.Simulation(w, seed=seed).run(), expected)
    # Stepped from Python, the same run.
    sim = ftcbf.Simulation(w, seed=seed)
    frames = 0
    while (f := sim.step()) is not None:
        frames += 1
    assert frames == sim.progress[1] == expected["control_steps"]
    bits_equal(sim.summary(), expected)


def test_overrides_and_controller_match_the_cli(cli_json):
    expected = cli_json(
        "run", LINEAR, "--seed", "11", "--set", "attacks[0].value=0.5",
        "--controller", "baseline", "--json", "--no-record",
    )
    w = ftcbf.World.load(LINEAR, overrides={"attacks[0].value": 0.5})
    assert w.overrides == {"attacks[0].value": 0.5}
    got = ftcbf.Simulation(w, seed=11, controller="baseline").run()
    bits_equal(got, expected)
    # And the override changed the run.
    plain = ftcbf.Simulation(ftcbf.World.load(LINEAR), seed=11, controller="baseline").run()
    assert plain != got


def test_a_batch_matches_the_cli(cli, tmp_path):
    out = tmp_path / "cli.json"
    code, stdout, err = cli("batch", LINEAR, "--trials", "24", "--jobs", "2", "--out", str(out))
    assert code == 0, err
    res = ftcbf.batch(LINEAR, trials=24, jobs=2)
    assert res.report == stdout
    assert res.json == out.read_text()
    s = res.summary("ft-cbf-clf")
    assert s["trials"] == 24 and 0.0 <= s["safe_ci"]["lower"] <= s["safe_rate"] <= s["safe_ci"]["upper"]
    assert res.results[0]["paired"][0]["second"] == "baseline"


def test_a_sweep_matches_the_cli(cli):
    code, stdout, err = cli(
        "batch", LINEAR, "--trials", "6", "--controller", "ft-cbf-clf",
        "--sweep", "attacks[0].value=0,1", "--seed", "5",
    )
    assert code == 0, err
    res = ftcbf.batch(LINEAR, trials=6, controllers=["ft-cbf-clf"], seed=5, sweep="attacks[0].value=0,1")
    assert res.report == stdout
    assert [r["plan"]["overrides"][0]["value"] for r in res.results] == [0.0, 1.0]


def test_a_worlds_overrides_apply_to_every_trial_of_its_batch():
    # The World's overrides go before a sweep point's: removing the attack's bias (1 in the
    # file) gives the trials of the sweep point attacks[0].value=0, but no sweep point in the plan.
    w = ftcbf.World.load(LINEAR, overrides={"attacks[0].value": 0.0})
    got = ftcbf.batch(w, trials=6, controllers=["baseline"], seed=5)
    swept = ftcbf.batch(LINEAR, trials=6, controllers=["baseline"], seed=5, sweep="attacks[0].value=0,1")
    assert got.results[0]["plan"]["overrides"] == []
    bits_equal(got.results[0]["records"], swept.results[0]["records"], "records")
    plain = ftcbf.batch(LINEAR, trials=6, controllers=["baseline"], seed=5)
    assert plain.results[0]["records"] != got.results[0]["records"]


def test_a_python_law_runs_through_a_batch():
    w = ftcbf.World.load(LINEAR)
    MedianPd.steps = 0
    res = ftcbf.batch(w, trials=8, controllers=["ft-cbf-clf", MedianPd], jobs=2)
    law = res.summary("median-pd")
    assert law["trials"] == 8
    assert MedianPd.steps == 8 * 2000  # 8 trials of 20 s at 100 Hz
    recs = res.results[0]["records"]
    assert [r["controller"] for r in recs[:2]] == ["ft-cbf-clf", "median-pd"]
    # A trial of the batch is the run of that seed.
    first = next(r for r in recs if r["controller"] == "median-pd")
    alone = ftcbf.Simulation(w, seed=first["seed"], controller=MedianPd).run()
    assert alone["controller"] == "median-pd"
    assert (alone["safe"], alone["goal_reached"]) == (first["safe"], first["goal_reached"])
    # paper_linear's attack spoofs one receiver: the median of the others resists it there,
    # the barrier-free PD law does not stay in the safe set as FT-CBF-CLF does.
    assert res.summary("ft-cbf-clf")["safe"] == 8
    assert res.results[0]["paired"][0]["second"] == "median-pd"


def test_a_python_law_sees_the_readings_and_drives_the_robot():
    seen = []

    class Hold:
        name = "hold"

        def __init__(self, config):
            seen.append(config)
            self.q = len(config.channels)

        def step(self, r):
            assert r.y.shape == (self.q,) and r.fresh.dtype == np.bool_
            return np.array([0.2, 0.0])

    sim = ftcbf.Simulation(ftcbf.World.load(LINEAR), controller=Hold)
    s = sim.run()
    cfg = seen[0]
    assert cfg.c.shape == (len(cfg.channels), 4) and cfg.dt == pytest.approx(0.01)
    assert cfg.goal.tolist() == [0.0, 0.0, 0.0, 0.0] and cfg.input_limit.tolist() == [2.0, 2.0]
    assert s["controller"] == "hold" and s["control_steps"] == 2000
    # The linear plant realises u: x = 1 + 0.2 t²/2 = 41 m after 20 s (process noise: σ ≈ 1.6 m).
    assert s["final_state"][0] == pytest.approx(41.0, abs=8.0)


def test_a_python_law_that_raises_surfaces_as_control_law_error():
    class Broken:
        name = "broken"

        def __init__(self, config):
            self.k = 0

        def step(self, r):
            self.k += 1
            if self.k == 5:
                raise ZeroDivisionError("law bug")
            return (0.0, 0.0)

    w = ftcbf.World.load(LINEAR)
    sim = ftcbf.Simulation(w, controller=Broken)
    with pytest.raises(ftcbf.ControlLawError, match="law bug") as e:
        for _ in range(10):
            sim.step()
    assert isinstance(e.value.__cause__, ZeroDivisionError)
    assert sim.progress[0] == 5
    with pytest.raises(ftcbf.ControlLawError) as e:
        ftcbf.batch(w, trials=3, controllers=["ft-cbf-clf", Broken], jobs=1)
    assert "trial 0" in str(e.value) and "controller broken" in str(e.value)
    assert isinstance(e.value.__cause__, ftcbf.ControlLawError)
    assert isinstance(e.value.__cause__.__cause__, ZeroDivisionError)

    class Wrong:
        def __init__(self, config):
            pass

        def step(self, r):
            return "fast"

    with pytest.raises(ftcbf.ControlLawError, match="not two numbers"):
        ftcbf.Simulation(w, controller=Wrong).run()
    with pytest.raises(ValueError, match="name of its own"):
        ftcbf.Simulation(w, controller=type("baseline", (), {}))


INVALID = sorted((Path(__file__).resolve().parents[2] / "tests" / "invalid_worlds").glob("*.toml"))


def test_bad_world_files_raise_the_cli_message(cli):
    assert len(INVALID) >= 25
    for path in INVALID:
        rel = str(path.relative_to(Path.cwd()))
        code, _, err = cli("check", rel)
        assert code == 2, f"{rel}: ftcbf check exited {code}"
        with pytest.raises(ftcbf.WorldError) as e:
            ftcbf.World.load(rel)
        assert f"error: {e.value}\n" == err, rel
        assert path.name in str(e.value)
    # A bad override names its key, as --set does.
    code, _, err = cli("run", LINEAR, "--set", "control.epsilon=7", "--no-record")
    assert code == 2
    with pytest.raises(ftcbf.WorldError) as e:
        ftcbf.World.load(LINEAR, overrides={"control.epsilon": 7})
    assert f"error: {e.value}\n" == err and "control.epsilon" in str(e.value)


def test_check_is_structured(cli):
    code, stdout, _ = cli("check", ROBOT)
    assert code == 0
    r = ftcbf.World.load(ROBOT).check()
    assert r["text"] in stdout and r["theorem3"]["line"] in stdout
    assert r["theorem3"]["applies"] is True and r["theorem3"]["reasons"] == []
    assert r["hypotheses"] and {h["status"] for h in r["hypotheses"]} <= {"holds", "fails", "assumed", "info"}
    assert all(h["status"] != "fails" for h in r["hypotheses"])
    assert r["liveness"]["live"] is True and r["liveness"]["line"] in stdout
    assert [c["barrier"] for c in r["condition_4_4"]] and all(c["text"] in stdout for c in r["condition_4_4"])
    lin = ftcbf.World.load(LINEAR).check()
    assert lin["theorem3"]["applies"] is False
    assert any(h["status"] == "fails" for h in lin["hypotheses"])


def test_check_rolls_out_a_world_with_movers(cli):
    # the ward's trolley paces the corridor and holds the robot out: no run settles
    ward = "tests/worlds_movers/ward_trolley.toml"
    code, stdout, _ = cli("check", ward)
    assert code == 0
    r = ftcbf.World.load(ward).check()
    ro = r["liveness"]["rollouts"]
    assert (ro["runs"], ro["settled"], ro["error"]) == (6, 0, None)
    assert r["liveness"]["live"] is False and r["liveness"]["line"] in stdout
    assert ftcbf.World.load(ward).check(rollouts=0)["liveness"]["rollouts"] is None
    assert ftcbf.World.load(ROBOT).check()["liveness"]["rollouts"] is None  # no movers


def test_frames_carry_the_step():
    w = ftcbf.World.load(ROBOT)
    sim = ftcbf.Simulation(w, seed=2, duration=1.0)
    n_f, n_b, n_s = len(sim.filters), len(sim.barriers), len(sim.sensors)
    frames = []
    while (f := sim.step()) is not None:
        frames.append(f)
    assert len(frames) == sim.progress[1] == round(1.0 / w.control_dt)
    f = frames[-1]
    assert f.estimates.shape == (n_f, 4) and f.h.shape == (n_f, n_b) and f.h_true.shape == (n_b,)
    assert f.received.shape == f.clean.shape == f.fresh.shape == (n_s,)
    assert f.stage in {"step1", "clf_relaxed", "step2", "step3", "infeasible"}
    assert [fr.step for fr in frames] == list(range(len(frames)))
    assert frames[1].t == pytest.approx(w.control_dt)
    assert set(f.truth) >= {"x", "y", "theta", "vx", "vy", "omega"}
    # the truth moved toward the goal and the true barrier values are positive (safe).
    assert (f.h_true > 0).all()
    assert sim.step() is None and sim.summary()["control_steps"] == len(frames)


def test_record_writes_an_rrd(tmp_path):
    sim = ftcbf.Simulation(ftcbf.World.load(LINEAR), duration=0.5)
    sim.record(tmp_path / "run.rrd")
    sim.run()
    data = (tmp_path / "run.rrd").read_bytes()
    assert data[:4] == b"RRF2" and len(data) > 10_000
    late = ftcbf.Simulation(ftcbf.World.load(LINEAR), duration=0.5)
    late.step()
    with pytest.raises(ftcbf.Error, match="before the first step"):
        late.record(tmp_path / "late.rrd")


def test_batch_releases_the_gil():
    w = ftcbf.World.load(LINEAR)
    done = threading.Event()
    t = threading.Thread(target=lambda: (ftcbf.batch(w, trials=16, jobs=1), done.set()))
    count = 0
    start = time.perf_counter()
    t.start()
    while not done.is_set():
        count += 1
    elapsed = time.perf_counter() - start
    t.join()
    # Holding the GIL, the batch would freeze this loop for its whole duration.
    assert elapsed > 0.05 and count > 10_000, (elapsed, count)
