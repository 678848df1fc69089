#!/usr/bin/env python3
"""Can a tied pair of the paired campaign be won at all? (issue #31)

usage: scripts/falsify_pool.py CAMPAIGN_DIR [OTHER_DIR ...]

CAMPAIGN_DIR holds the JSON reports of `scripts/falsify_paired.sh` (NAME-sS.json). For every
pair there whose paired verdict is a tie, every finalist of every report of the same pair in
CAMPAIGN_DIR and the OTHER_DIRs (other search designs, other budgets: the held-out seeds of a
base seed are the same at any budget, a larger budget only adds seeds after them) is played
against random search's best attack of CAMPAIGN_DIR on the first 20 held-out seeds, seed by seed,
as the paired verdict counts them. A pair where no known attack is worse than random search's
best on significantly many seeds (exact two-sided sign test, 5 %) is one no search has been able
to win; one where some attack is, is winnable.

Also prints the attack-free reference of the campaign report (mean ρ without attacks on the same
seeds), when it has one: how much room the attacks had at all.
"""

import glob
import json
import os
import sys
from math import comb


def sign_p(a, b):
    n = a + b
    if n == 0:
        return 1.0
    k = min(a, b)
    return min(1.0, 2 * sum(comb(n, i) for i in range(k + 1)) / 2**n)


def key(run):
    """Order of the paired verdict: a collision is worse than any run without one."""
    r = run["robustness"]
    value = r["value"] if r["value"] is not None else float("-inf")
    return (0 if r["collided"] else 1, value)


def same_seed(a, b):
    # Reports that went through jq 1.6 carry seeds rounded to doubles.
    return a == b or abs(a - b) <= 1e-15 * max(abs(a), abs(b))


def main(argv):
    if len(argv) < 2:
        sys.exit(__doc__)
    campaign, others = argv[1], argv[2:]
    wins = unwon = 0
    for path in sorted(glob.glob(os.path.join(campaign, "*-s[0-9]*.json"))):
        name = os.path.basename(path)
        report = json.load(open(path))
        paired = report.get("paired")
        if paired is None or paired["p"] < 0.05:
            continue
        reference = report["methods"][1]["finalists"][0]["runs"]
        n = len(reference)
        attacks, searches, best = 0, 0, None
        for d in [campaign] + others:
            other = os.path.join(d, name)
            if not os.path.exists(other):
                continue
            searches += 1
            for method in json.load(open(other))["methods"]:
                for fin in method["finalists"]:
                    runs = fin["runs"][:n]
                    if len(runs) < n or not all(
                        same_seed(x["seed"], y["seed"]) for x, y in zip(runs, reference)
                    ):
                        continue
                    attacks += 1
                    worse = sum(key(x) < key(y) for x, y in zip(runs, reference))
                    better = sum(key(x) > key(y) for x, y in zip(runs, reference))
                    mean = sum(key(x)[1] for x in runs) / n
                    if best is None or worse - better > best[0] - best[1]:
                        best = (worse, better, mean, d, method["method"], fin["description"])
        free = report.get("attack_free")
        free_text = f"no attack {free['mean']:.4f}; " if free else ""
        random_mean = sum(key(x)[1] for x in reference) / n
        p = sign_p(best[0], best[1])
        winnable = p < 0.05 and best[0] > best[1]
        wins += winnable
        unwon += not winnable
        print(
            f"{name[:-5]}: {free_text}random search's best {random_mean:.4f}; {attacks} attacks "
            f"from {searches} searches; the most damaging against it: {best[0]} : {best[1]} "
            f"(p = {p:.3f}, mean {best[2]:.4f}, {best[4]} in {best[3]}): {best[5]} -> "
            f"{'WINNABLE' if winnable else 'no known attack wins it'}"
        )
    print(f"tied pairs: {wins + unwon}; winnable by a known attack: {wins}; by none: {unwon}")


if __name__ == "__main__":
    main(sys.argv)
