#!/usr/bin/env python3
"""A seeded campaign against the real `ftcbf` binary (issue #46): mutated world files, mutated
URDFs, mutated shard and results files, and mutated flags and arguments for every subcommand.
Each invocation runs with a time bound; the campaign counts

* panics and aborts: exit 70 (the contained-panic path), 101, a signal, or "panicked at";
* hangs: an invocation still running at the time bound (killed);
* SAFE or "applies" next to a negative barrier, or next to NaN or inf;
* NaN or inf anywhere in the output of a command that succeeded;
* for every non-zero exit, whether the message names the file or the flag and what was
  expected (the classifier below).

The classifier (a heuristic, stated so the numbers can be judged):

* *names a place*: the message contains the path or the file name of an input or output the
  invocation gave (world, URDF, shard, results folder, --out target), or one of the flags or
  placeholders of its command line (`--trials`, `<WORLD>`, …), or the name of the subcommand's
  positional argument as clap prints it;
* *says what was expected*: the message contains one of the phrases in EXPECT_PHRASES (e.g.
  "expected", "must", "at least", "within", "possible values", "no such file", "not a
  directory", "did you mean").

A message counts as good when it does both. The report lists every message that does not, with
its command line, so each can be read.

Usage: scripts/cli_campaign.py [--bin target/release/ftcbf] [--n 2000] [--seed 1]
       [--timeout 60] [--jobs 1] [--json FILE] [--show-bad 20]
Exit status 0 always, unless --strict: then 1 when any panic, hang, SAFE/applies next to a
negative barrier, NaN or inf is found or fewer than --min-good of the error messages are good.
"""

import argparse
import concurrent.futures
import json
import os
import random
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

EXPECT_PHRASES = [
    "expected", "expect ", "must", "needs", "need ", "should", "at least", "at most", "within",
    "outside", "between", "range", "possible values", "one of", "did you mean",
    "not a directory", "not a file", "no such file", "does not exist", "required", "only ",
    "use ", "pass ", "add ", "give ", "set ", "refus", "too ", "exceed", "limit", "≤", "≥",
    "<=", ">=", "allowed", "accepts", "instead", "unknown", "missing", "not found", "no key",
    "duplicate", "unexpected", "invalid value", "is not ", "not a ", "cannot be used",
    "similar", "tip:", "not well-formed",
]

# Numbers a mutation puts in place of a number of the file.
EXTREMES = [
    "0", "-0.0", "-1", "1e308", "-1e308", "1e-308", "5e-324", "nan", "inf", "-inf",
    "99999999999999999999", "-9223372036854775809", "1e16", "0.5", "3", "-3.5", "1e6",
]
# Values of the wrong type.
WRONG_TYPES = ['"text"', "true", "[1.0, -1.0]", "{ a = 1 }", "[]", '""', "1979-05-27"]

NUMBER = re.compile(r"(?<![\w.\"])-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?(?![\w.\"])")
NEG_BARRIER = re.compile(r"h\([^)]*\)[^=\n]*=\s*-\d")
# A non-finite number as a value (`= NaN`, `[inf, 1]`, `: -inf`), not the word in a world's
# description ("gnss1 sends NaN for 2 s").
NON_FINITE = re.compile(r"(?:=|:|\[|,|\()\s*-?(?:inf|NaN|nan)(?![\w])")
SAFE = re.compile(r"(?<!UN)\bSAFE\b")
APPLIES = re.compile(r"Theorem 3 applies")


def base_worlds():
    out = sorted((ROOT / "worlds").glob("*.toml"))
    for sub in ["tests/worlds_user", "tests/worlds_check", "tests/worlds_threat"]:
        out += sorted((ROOT / sub).glob("*.toml"))
    return out


def absolutise(text, base_dir):
    """Every quoted relative path the world names (URDF, STL, package folders) made absolute,
    so a mutated copy in a temporary folder still finds them."""

    def fix(m):
        s = m.group(1)
        if s.startswith("/") or ("/" not in s and "." not in s):
            return m.group(0)
        p = (base_dir / s).resolve()
        return '"%s"' % p if p.exists() else m.group(0)

    return re.sub(r'"([^"\n]+)"', fix, text)


def shorten(text):
    """Base worlds run for at most 4 s, so a campaign of thousands of runs stays short."""
    return re.sub(r"(?m)^duration\s*=\s*[\d.]+", "duration = 4.0", text, count=1)


def mutate_text(rng, text):
    """One or two text mutations of a TOML file; returns (text, description)."""
    lines = text.split("\n")
    done = []
    for _ in range(rng.choice([1, 1, 2])):
        kind = rng.choice([
            "number", "number", "number", "type", "delete", "duplicate", "truncate",
            "garbage", "header", "dotted", "swap_key", "empty_array", "deep",
        ])
        content = [i for i, l in enumerate(lines) if l.strip() and not l.lstrip().startswith("#")]
        if not content:
            break
        i = rng.choice(content)
        if kind == "number":
            nums = [(i, m) for i in content for m in NUMBER.finditer(lines[i])]
            if not nums:
                continue
            i, m = rng.choice(nums)
            v = rng.choice(EXTREMES)
            lines[i] = lines[i][: m.start()] + v + lines[i][m.end():]
            done.append(f"line {i + 1}: number -> {v}")
        elif kind == "type":
            if "=" not in lines[i]:
                continue
            k, _ = lines[i].split("=", 1)
            v = rng.choice(WRONG_TYPES)
            lines[i] = f"{k}= {v}"
            done.append(f"line {i + 1}: value -> {v}")
        elif kind == "delete":
            done.append(f"line {i + 1} deleted: {lines[i][:40]}")
            del lines[i]
        elif kind == "duplicate":
            lines.insert(i, lines[i])
            done.append(f"line {i + 1} duplicated")
        elif kind == "truncate":
            cut = rng.randrange(len("\n".join(lines)) + 1)
            lines = "\n".join(lines)[:cut].split("\n")
            done.append(f"truncated at byte {cut}")
        elif kind == "garbage":
            g = rng.choice(["[", "]", "=", '"', "{", "}", "\x00", "é", "[[", "= =", "\\"])
            pos = rng.randrange(len(lines[i]) + 1)
            lines[i] = lines[i][:pos] + g + lines[i][pos:]
            done.append(f"line {i + 1}: inserted {g!r}")
        elif kind == "header":
            h = rng.choice(["[control]", "[goal]", "[[sensors]]", "[[attacks]]", "[robot]",
                            "[[obstacles]]", "[[safe_sets]]", "[expect]", "[nonsense]"])
            lines.insert(i, h)
            done.append(f"line {i + 1}: inserted header {h}")
        elif kind == "dotted":
            n = rng.choice([50, 81, 100, 300])
            lines.insert(i, "[" + ".".join(["a"] * n) + "]")
            done.append(f"line {i + 1}: a header of {n} dotted parts")
        elif kind == "swap_key":
            if "=" not in lines[i]:
                continue
            _, v = lines[i].split("=", 1)
            k = rng.choice(["kind", "name", "measures", "channels", "start", "radius",
                            "controller", "dynamics", "urdf", "waypoints", "from_wheels",
                            "direction", "record_start", "dropout_prob", "rate_hz"])
            lines[i] = f"{k} ={v}"
            done.append(f"line {i + 1}: key -> {k}")
        elif kind == "empty_array":
            if "[" not in lines[i] or "=" not in lines[i]:
                continue
            k, _ = lines[i].split("=", 1)
            lines[i] = f"{k}= []"
            done.append(f"line {i + 1}: array emptied")
        elif kind == "deep":
            n = rng.choice([60, 90, 200])
            lines.insert(i, "deep = " + "[" * n + "]" * n)
            done.append(f"line {i + 1}: arrays nested {n} deep")
    return "\n".join(lines), "; ".join(done) or "unchanged"


class Case:
    def __init__(self, argv, places, what, tmp):
        self.argv = argv  # without the binary
        self.places = places  # strings a good message may name
        self.what = what
        self.tmp = tmp


def world_case(rng, tmp, worlds, idx):
    src = rng.choice(worlds)
    text = shorten(absolutise(src.read_text(), src.parent))
    text, what = mutate_text(rng, text)
    path = tmp / f"w{idx}_{src.stem}.toml"
    path.write_bytes(text.encode("utf-8", "surrogateescape"))
    cmd = rng.choice(["check", "check", "run", "run", "batch", "check --strict", "check --suggest"])
    argv = cmd.split() + [str(path)]
    if cmd == "run":
        argv += ["--no-record"]
    if cmd == "batch":
        argv += ["--trials", "2", "--jobs", "1"]
    return Case(argv, [str(path), path.name], f"{src.name}: {what}", tmp)


def urdf_case(rng, tmp, idx):
    urdf = ROOT / "robots" / rng.choice(["turtlebot3_burger.urdf", "turtlebot3_waffle.urdf"])
    text, what = mutate_text(rng, urdf.read_text())
    if rng.random() < 0.3:
        # a number of an origin or a size pushed to an extreme
        nums = list(NUMBER.finditer(text))
        if nums:
            m = rng.choice(nums)
            v = rng.choice(["1e9", "-1e9", "nan", "0", "1e-9", "-5"])
            text = text[: m.start()] + v + text[m.end():]
            what += f"; byte {m.start()}: number -> {v}"
    upath = tmp / f"r{idx}_{urdf.name}"
    upath.write_text(text)
    world = ROOT / "worlds" / "paper_turtlebot.toml"
    wtext = shorten(absolutise(world.read_text(), world.parent))
    wtext = re.sub(r'urdf = "[^"]*"', f'urdf = "{upath}"', wtext)
    wpath = tmp / f"r{idx}_world.toml"
    wpath.write_text(wtext)
    cmd = rng.choice(["check", "run"])
    argv = [cmd, str(wpath)] + (["--no-record"] if cmd == "run" else [])
    return Case(argv, [str(upath), upath.name, str(wpath), wpath.name], f"{urdf.name}: {what}", tmp)


# Flags per subcommand: (flag, good values, bad values).
BAD_NUMBERS = ["-1", "0", "1e308", "nan", "abc", "", "18446744073709551616", "1.5", "-0"]
FLAGS = {
    "run": [("--seed", ["1", "7"], BAD_NUMBERS), ("--duration", ["1.0", "0.5"], BAD_NUMBERS + ["inf", "1e9"]),
            ("--controller", ["ft-cbf-clf", "baseline", "nominal"], ["x", "FT-CBF-CLF", ""]),
            ("--set", ["seed=3", "control.epsilon=0.1"], ["seed=-1e308", "seed=1.5", "x", "control.epsilon=nan",
                                                           "goal.radius=-1", "attacks[9].value=1", "=3",
                                                           "control..x=1", "seed=1e20", "duration=1e300"]),
            ("--out", ["OUTDIR/x.rrd"], ["/dev/null/x.rrd", "/", "OUTDIR"]),
            ("--json", None, None), ("--no-record", None, None)],
    "check": [("--strict", None, None), ("--suggest", None, None)],
    "batch": [("--trials", ["2", "3"], BAD_NUMBERS), ("--jobs", ["1"], BAD_NUMBERS),
              ("--seed", ["5"], BAD_NUMBERS), ("--controller", ["ft-cbf-clf", "baseline"], ["x", ""]),
              ("--out", ["OUTDIR/b.json", "OUTDIR/b.csv"], ["OUTDIR/b.txt", "/dev/null/b.json", "OUTDIR", "/"]),
              ("--sweep", ["control.epsilon=0.05,0.1"], ["x", "control.epsilon=", "seed=1.5,2", "a=1,,2",
                                                          "control.epsilon=nan", "goal.radius=-1,1"]),
              ("--shard", ["1/2", "2/2"], ["0/2", "3/2", "1/0", "x", "1/", "-1/2", "18446744073709551616/2"]),
              ("--fail-on", ["unsafe"], ["x", ""])],
    "falsify": [("--budget", ["24", "30"], BAD_NUMBERS + ["1000001", "2"]), ("--seed", ["2"], BAD_NUMBERS),
                ("--jobs", ["1"], BAD_NUMBERS), ("--controller", ["ft-cbf-clf"], ["nominal-x", ""]),
                ("--out", ["OUTDIR/worst.toml"], ["/dev/null/w.toml", "OUTDIR"]),
                ("--json", ["OUTDIR/f.json"], ["/dev/null/f.json", "OUTDIR"]),
                ("--no-record", None, None), ("--no-random", None, None)],
    "gen": [("--seed", ["1", "2"], BAD_NUMBERS), ("--count", ["1", "2"], BAD_NUMBERS + ["100001"]),
            ("--out", ["OUTDIR/gen"], ["/dev/null", "/dev/null/x", "/proc/x"]),
            ("--kind", ["room", "corridor", "doorway", "clutter", "l-turn"], ["x", ""]),
            ("--robot", ["burger", "waffle"], ["x"]),
            ("--suite", ["two-receivers", "odometry"], ["x"]),
            ("--robots", [str(ROOT / "robots")], ["/nonexistent", "/dev/null", "OUTDIR"])],
    "regress": [("--json", None, None)],
    "merge": [("--out", ["OUTDIR/m.json"], ["OUTDIR/m.txt", "/dev/null/m.json"]),
              ("--allow-incomplete", None, None)],
    "report": [("--results", ["RESULTS"], ["/nonexistent", "OUTDIR", "/dev/null"]),
               ("--out", ["OUTDIR/pages"], ["/dev/null", "/dev/null/x"]),
               ("--check", None, None)],
}
POSITIONAL = {"run": "<WORLD>", "check": "<WORLD>", "batch": "<WORLD>", "falsify": "<WORLD>",
              "regress": "[PATHS]", "merge": "<FILE.json>"}


def flags_case(rng, tmp, worlds, shards, results, idx):
    cmd = rng.choice(list(FLAGS))
    out = tmp / f"o{idx}"
    out.mkdir()
    argv = [cmd]
    places = [f"--{cmd}", POSITIONAL.get(cmd, "@@")]
    whats = []
    world = rng.choice(worlds[:16])  # the catalogue
    if cmd in ("run", "check", "batch", "falsify"):
        text = shorten(absolutise(world.read_text(), world.parent))
        wpath = tmp / f"f{idx}_{world.stem}.toml"
        wpath.write_text(text)
        r = rng.random()
        if r < 0.08:
            p = rng.choice(["/nonexistent.toml", str(tmp), "/dev/null", str(ROOT / "README.md")])
            argv.append(p)
            places += [p, Path(p).name]
            whats.append(f"world {p}")
        elif r < 0.12:
            whats.append("no world")
        else:
            argv.append(str(wpath))
            places += [str(wpath), wpath.name]
        if cmd == "batch":
            argv += ["--trials", "2", "--jobs", "1"]
        if cmd == "falsify":
            argv += ["--budget", "24", "--jobs", "1", "--no-record"]
        if cmd == "run":
            argv += ["--no-record"]
    elif cmd == "merge":
        files = rng.sample(shards, rng.randint(1, len(shards)))
        for f in files:
            if rng.random() < 0.35:
                t = f.read_text()
                mt, what = mutate_text(rng, t) if rng.random() < 0.5 else mutate_json(rng, t)
                p = tmp / f"m{idx}_{f.name}"
                p.write_text(mt)
                whats.append(f"{f.name}: {what}")
                f = p
            argv.append(str(f))
            places += [str(f), f.name]
        if rng.random() < 0.1:
            argv.append("/nonexistent.json")
            places.append("/nonexistent.json")
    elif cmd == "report":
        copy = tmp / f"res{idx}"
        shutil.copytree(results, copy)
        pages = tmp / f"pages{idx}"
        shutil.copytree(ROOT / "book/src/results", pages)
        if rng.random() < 0.6:
            target = rng.choice([copy / "stamp.toml"] + sorted(copy.rglob("*.json")))
            t = target.read_text()
            mt, what = mutate_text(rng, t) if target.suffix == ".toml" or rng.random() < 0.5 else mutate_json(rng, t)
            target.write_text(mt)
            whats.append(f"{target.name}: {what}")
            places += [target.name]
        argv += ["--results", str(copy), "--out", str(pages), "--check"]
        places += [str(copy), str(pages)]
    elif cmd == "regress":
        w = rng.choice(worlds[:16])
        argv.append(str(w))
        places += [str(w), w.name]
    # flags: some good, one or two mutated
    for _ in range(rng.randint(1, 3)):
        flag, good, bad = rng.choice(FLAGS[cmd])
        places.append(flag)
        r = rng.random()
        if good is None:
            argv.append(flag)
            if r < 0.15:
                argv.append(flag)
                whats.append(f"{flag} twice")
            continue
        if r < 0.45:
            v = rng.choice(bad)
            whats.append(f"{flag} {v!r}")
        elif r < 0.55:
            argv.append(flag)
            whats.append(f"{flag} without a value")
            continue
        else:
            v = rng.choice(good)
        v = v.replace("OUTDIR", str(out)).replace("RESULTS", str(results))
        argv += [flag, v]
        places.append(v)
    if rng.random() < 0.08:
        u = rng.choice(["--frobnicate", "-x", "--seed=1=2", "extra_positional"])
        argv.append(u)
        places.append(u)
        whats.append(f"unknown {u}")
    if rng.random() < 0.05:
        argv = [rng.choice(["runn", "chek", "", "help", "--version", "-h"])] + argv[1:]
        whats.append(f"subcommand {argv[0]!r}")
    places.append(argv[0] if argv else "@@")
    return Case(argv, places, f"{cmd}: " + ("; ".join(whats) or "valid flags"), tmp)


def mutate_json(rng, text):
    """A JSON mutation: a number to an extreme, a key removed, a value retyped, truncation."""
    try:
        doc = json.loads(text)
    except ValueError:
        return text[: len(text) // 2], "truncated (not JSON)"
    paths = []

    def walk(v, path):
        paths.append(path)
        if isinstance(v, dict):
            for k, x in v.items():
                walk(x, path + [k])
        elif isinstance(v, list):
            for i, x in enumerate(v[:3]):
                walk(x, path + [i])

    walk(doc, [])
    path = rng.choice(paths[1:] or [[]])
    parent = doc
    for p in path[:-1]:
        parent = parent[p]
    key = path[-1] if path else None
    kind = rng.choice(["number", "delete", "type", "truncate"])
    if key is None or kind == "truncate":
        cut = rng.randrange(len(text) + 1)
        return text[:cut], f"truncated at byte {cut}"
    if kind == "number":
        parent[key] = rng.choice([-1, 0, 1e308, -1e308, 2**64, 0.5, 1e-300, "NaN"])
    elif kind == "delete" and isinstance(parent, dict):
        del parent[key]
    else:
        parent[key] = rng.choice(["x", None, [], {}, True])
    return json.dumps(doc), f"{kind} at {'/'.join(map(str, path))}"


def classify_error(msg, places):
    low = msg.lower()
    named = any(p and p in msg for p in places)
    expected = any(ph in low for ph in EXPECT_PHRASES)
    return named, expected


def invoke(binary, case, timeout):
    t0 = time.time()
    try:
        p = subprocess.run([binary] + case.argv, capture_output=True, timeout=timeout,
                           cwd=case.tmp, stdin=subprocess.DEVNULL)
        out = p.stdout.decode("utf-8", "replace")
        err = p.stderr.decode("utf-8", "replace")
        return p.returncode, out, err, time.time() - t0
    except subprocess.TimeoutExpired as e:
        out = (e.stdout or b"").decode("utf-8", "replace")
        err = (e.stderr or b"").decode("utf-8", "replace")
        return None, out, err, time.time() - t0


def setup_shards(binary, tmp):
    """Two shards and one unsharded result of a small batch, for `merge` to be given."""
    world = ROOT / "worlds" / "paper_linear.toml"
    text = shorten(absolutise(world.read_text(), world.parent))
    wpath = tmp / "shard_world.toml"
    wpath.write_text(text)
    out = []
    for shard in ["1/2", "2/2"]:
        p = tmp / f"shard{shard[0]}.json"
        subprocess.run([binary, "batch", str(wpath), "--trials", "4", "--jobs", "1",
                        "--shard", shard, "--out", str(p)], capture_output=True, check=True, cwd=tmp)
        out.append(p)
    p = tmp / "whole.json"
    subprocess.run([binary, "batch", str(wpath), "--trials", "4", "--jobs", "1", "--out", str(p)],
                   capture_output=True, check=True, cwd=tmp)
    out.append(p)
    return out


DESCRIPTION = re.compile(r'^\s*description\s*=\s*"(.*)"\s*$', re.M)


def without_echo(case, out):
    """`out` without the world files' own `description` text, which `check` and `run` echo: a
    number mutated to nan or inf inside that string is the input repeated, not a value the
    program computed."""
    for arg in case.argv:
        if arg.endswith(".toml") and os.path.isfile(arg):
            try:
                text = open(arg, encoding="utf-8", errors="replace").read()
            except OSError:
                continue
            for d in DESCRIPTION.findall(text):
                if d.strip():
                    out = out.replace(d, "")
    return out


def judge(case, code, out, err):
    """The findings of one invocation, as a dict of counters and notes."""
    out = without_echo(case, out)
    text = out + err
    f = {"panic": False, "hang": code is None, "safe_negative": False, "safe_nonfinite": False,
         "nonfinite_ok": False, "error": False, "named": False, "expected": False}
    if code is not None and (code in (70, 101) or code < 0 or "panicked at" in text):
        f["panic"] = True
    verdict = SAFE.search(out) or APPLIES.search(out)
    if verdict and NEG_BARRIER.search(out):
        f["safe_negative"] = True
    if verdict and NON_FINITE.search(out):
        f["safe_nonfinite"] = True
    if code == 0 and NON_FINITE.search(out):
        f["nonfinite_ok"] = True
    if code not in (0, None) and not f["panic"]:
        f["error"] = True
        msg = err.strip() or out.strip()
        f["named"], f["expected"] = classify_error(msg, case.places)
    return f


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bin", default=str(ROOT / "target/release/ftcbf"))
    ap.add_argument("--n", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--timeout", type=float, default=60.0)
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--json", help="write every invocation and its findings here")
    ap.add_argument("--show-bad", type=int, default=20)
    ap.add_argument("--strict", action="store_true")
    ap.add_argument("--min-good", type=float, default=0.95)
    a = ap.parse_args()
    binary = str(Path(a.bin).resolve())
    rng = random.Random(a.seed)
    worlds = base_worlds()
    tmp = Path(tempfile.mkdtemp(prefix="ftcbf-campaign-"))
    try:
        shards = setup_shards(binary, tmp)
        results = ROOT / "results"
        cases = []
        for i in range(a.n):
            r = rng.random()
            if r < 0.45:
                cases.append(world_case(rng, tmp, worlds, i))
            elif r < 0.55:
                cases.append(urdf_case(rng, tmp, i))
            else:
                cases.append(flags_case(rng, tmp, worlds, shards, results, i))
        t0 = time.time()
        with concurrent.futures.ThreadPoolExecutor(a.jobs) as pool:
            runs = list(pool.map(lambda c: invoke(binary, c, a.timeout), cases))
        wall = time.time() - t0
        rows = []
        for c, (code, out, err, secs) in zip(cases, runs):
            f = judge(c, code, out, err)
            rows.append({"argv": c.argv, "what": c.what, "code": code, "seconds": round(secs, 3),
                         "stderr": err[-2000:], "stdout_tail": out[-600:], **f})
        report(rows, a, wall)
        if a.json:
            Path(a.json).write_text(json.dumps(rows, indent=1))
        counts = summarise(rows)
        print("COUNTS " + json.dumps(counts, sort_keys=True))
        if a.strict:
            bad = counts["panics"] + counts["hangs"] + counts["safe_negative"] + counts["safe_nonfinite"]
            if bad or counts["good_fraction"] < a.min_good:
                return 1
        return 0
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def summarise(rows):
    errors = [r for r in rows if r["error"]]
    good = [r for r in errors if r["named"] and r["expected"]]
    return {
        "invocations": len(rows),
        "exit_0": sum(1 for r in rows if r["code"] == 0),
        "errors": len(errors),
        "panics": sum(r["panic"] for r in rows),
        "hangs": sum(r["hang"] for r in rows),
        "safe_negative": sum(r["safe_negative"] for r in rows),
        "safe_nonfinite": sum(r["safe_nonfinite"] for r in rows),
        "nonfinite_in_success": sum(r["nonfinite_ok"] for r in rows),
        "errors_named": sum(r["named"] for r in errors),
        "errors_expected": sum(r["expected"] for r in errors),
        "errors_good": len(good),
        "good_fraction": len(good) / len(errors) if errors else 1.0,
    }


def report(rows, a, wall):
    c = summarise(rows)
    codes = {}
    for r in rows:
        codes[str(r["code"])] = codes.get(str(r["code"]), 0) + 1
    print(f"campaign: {c['invocations']} invocations, seed {a.seed}, time bound {a.timeout:.0f} s, "
          f"{wall:.0f} s wall")
    print(f"  exit codes: {dict(sorted(codes.items()))}")
    print(f"  panics/aborts: {c['panics']}  hangs: {c['hangs']}")
    print(f"  SAFE/applies next to a negative barrier: {c['safe_negative']}  "
          f"next to NaN/inf: {c['safe_nonfinite']}  NaN/inf in a successful output: "
          f"{c['nonfinite_in_success']}")
    e = max(c["errors"], 1)
    print(f"  error messages: {c['errors']}; naming the file or flag {c['errors_named']} "
          f"({100 * c['errors_named'] / e:.1f} %), saying what was expected {c['errors_expected']} "
          f"({100 * c['errors_expected'] / e:.1f} %), both {c['errors_good']} "
          f"({100 * c['good_fraction']:.1f} %)")
    flagged = [r for r in rows if r["panic"] or r["hang"] or r["safe_negative"] or r["safe_nonfinite"]]
    bad = [r for r in rows if r["error"] and not (r["named"] and r["expected"])]
    for r in flagged[: a.show_bad]:
        print(f"FLAGGED {r['code']} {' '.join(r['argv'])}  [{r['what']}]\n    {r['stderr'][-300:]!r}")
    for r in bad[: a.show_bad]:
        first = (r["stderr"].strip() or r["stdout_tail"].strip())[:300]
        print(f"BAD-MESSAGE exit {r['code']} named={r['named']} expected={r['expected']}: "
              f"ftcbf {' '.join(r['argv'])}  [{r['what']}]\n    {first!r}")


if __name__ == "__main__":
    sys.exit(main())
