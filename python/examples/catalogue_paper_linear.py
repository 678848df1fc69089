"""Reproduces the two `paper_linear` rows of the README's catalogue certification table
("Safety certification of the catalogue"): FT-CBF-CLF against the all-sensor baseline on the
same 1000 trial seeds, with the columns the batch itself measures.

    python python/examples/catalogue_paper_linear.py [TRIALS]    # from the repository root

The README's rows (1000 trials, measured 2026-11-25):

| paper_linear | paper | 1000 | no (input limit) | ft-cbf-clf | 1000 | 1.000 [0.9963, 1.0000] | supported | 0 | 1000 | 0 | 4.61 | 0.0 % | 9/1000 (1.08 γ) |
| paper_linear | paper | 1000 | no (input limit) | baseline   | 0    | 0.000 [0.0000, 0.0037] | refuted   | 0 | 0    | 0 | —    | 0.0 % | 10/1000 (1.08 γ) |

(the table's last two columns, the same world without its attack, are another batch.)
"""

from __future__ import annotations

import sys

import ftcbf


def honest_over_gamma(s: dict) -> str:
    """The honest filter that left its γ in the most trials: k/N and its worst ‖x − x̂‖/γ."""
    rows = [e for e in s["estimation"] if e["honest_trials"] > 0]
    if not rows:
        return "—"
    worst = max(rows, key=lambda e: (e["exceeded"], e["worst_ratio"] or 0.0))
    return f"{worst['exceeded']}/{worst['honest_trials']} ({worst['worst_ratio']:.2f} γ)"


def main() -> None:
    trials = int(sys.argv[1]) if len(sys.argv) > 1 else 1000
    world = ftcbf.World.load("worlds/paper_linear.toml")
    theorem3 = world.check()["theorem3"]
    res = ftcbf.batch(world, trials=trials, controllers=["ft-cbf-clf", "baseline"])
    print(f"Theorem 3 (check): {theorem3['line']}")
    print(
        "| world | trials | controller | safe | P(safe) [95 % CI] | vs 1 − ε | collisions "
        "| entered goal | settled | t_goal p50 [s] | fallback steps | honest filters over γ |"
    )
    for name in ("ft-cbf-clf", "baseline"):
        s = res.summary(name)
        ci = s["safe_ci"]
        t_goal = f"{s['time_to_goal']['p50']:.2f}" if s["time_to_goal"] else "—"
        fallback = 100.0 * s["steps"]["infeasible"] / s["control_steps"]
        print(
            f"| {world.name} | {s['trials']} | {name} | {s['safe']} "
            f"| {s['safe_rate']:.3f} [{ci['lower']:.4f}, {ci['upper']:.4f}] | {s['verdict']} "
            f"| {s['collisions']} | {s['goals']} | {s['settled']} | {t_goal} | {fallback:.1f} % "
            f"| {honest_over_gamma(s)} |"
        )
    p = res.results[0]["paired"][0]
    print(
        f"McNemar {p['first']} vs {p['second']}: only {p['first']} safe in {p['only_first_safe']}, "
        f"only {p['second']} safe in {p['only_second_safe']}, p = {p['p_value']:.3e}"
    )


if __name__ == "__main__":
    main()
