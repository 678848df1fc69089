//! Human-readable tables of batch results (aligned columns, plain text).

use std::fmt::Write as _;

use super::{stats, BatchResult, LowerQuantiles, UpperQuantiles, Verdict};

/// Column alignment.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Align {
    /// Padded on the right.
    Left,
    /// Padded on the left (numbers).
    Right,
}

/// Render a table: a header row, a rule, then the rows; columns padded to their widest cell,
/// separated by two spaces, no trailing blanks (comfy-table without borders: the rule is its
/// header line, the gap its right padding).
/// Every plain-text table the tool prints (`batch`, `merge`, `regress`, `gen`) goes through here.
pub fn render(headers: &[&str], align: &[Align], rows: &[Vec<String>]) -> String {
    use comfy_table::{presets::NOTHING, CellAlignment, Table, TableComponent};
    let ncol = headers.len();
    let mut table = Table::new();
    table
        .load_preset(NOTHING)
        .set_style(TableComponent::HeaderLines, '-')
        .set_header(headers.to_vec());
    for row in rows {
        table.add_row(
            row.iter()
                .take(ncol)
                .map(String::as_str)
                .collect::<Vec<_>>(),
        );
    }
    for (i, column) in table.column_iter_mut().enumerate() {
        column.set_padding((0, if i + 1 < ncol { 2 } else { 0 }));
        column.set_cell_alignment(match align.get(i) {
            Some(Align::Right) => CellAlignment::Right,
            _ => CellAlignment::Left,
        });
    }
    let mut out = table.trim_fmt();
    out.push('\n');
    out
}

fn opt(x: Option<f64>, digits: usize) -> String {
    x.map_or_else(|| "-".to_string(), |v| format!("{v:.digits$}"))
}

fn three(x: Option<[f64; 3]>, digits: usize) -> String {
    x.map_or_else(
        || "-".to_string(),
        |[a, b, c]| format!("{a:.digits$} / {b:.digits$} / {c:.digits$}"),
    )
}

fn upper(q: Option<UpperQuantiles>, digits: usize) -> String {
    three(q.map(|q| [q.p50, q.p90, q.max]), digits)
}

fn lower(q: Option<LowerQuantiles>, digits: usize) -> String {
    three(q.map(|q| [q.min, q.p10, q.p50]), digits)
}

fn rate_ci(rate: f64, lower: f64, upper: f64) -> String {
    format!("{rate:.4} [{lower:.4}, {upper:.4}]")
}

fn verdict_cell(v: Verdict, outside: u64) -> String {
    if outside > 0 && v != Verdict::NoClaim {
        format!("{v} (*)")
    } else {
        v.to_string()
    }
}

fn point_label(res: &BatchResult) -> String {
    res.plan
        .overrides
        .iter()
        .map(|o| format!("{}={}", o.key, o.value))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The full report of one batch: header, safety table, policy-step table, worst trials, paired
/// comparisons, warnings.
pub fn summary_text(res: &BatchResult) -> String {
    let mut out = String::new();
    plan_header(res, &mut out);
    safety_table(res, &mut out);
    steps_table(res, &mut out);
    stops_table(res, &mut out);
    smoothness_table(res, &mut out);
    gamma_table(res, &mut out);
    worst_table(res, &mut out);
    paired_and_warnings(res, &mut out);
    out
}

/// World, trials, seed, shard and the claim under test.
fn plan_header(res: &BatchResult, out: &mut String) {
    let p = &res.plan;
    let _ = write!(out, "World `{}` ({})", p.world, p.world_file);
    let point = point_label(res);
    if !point.is_empty() {
        let _ = write!(out, ", {point}");
    }
    let _ = write!(out, "\n{} trials, base seed {}", p.trials, p.base_seed);
    if let Some(s) = p.shard {
        let _ = write!(out, ", shard {s} ({} trials run)", res.trials_covered);
    } else if res.trials_covered != p.trials {
        let _ = write!(out, " ({} trials present)", res.trials_covered);
    }
    match (p.claimed_safety(), p.epsilon) {
        (Some(c), Some(e)) => {
            let _ = write!(out, "; claim Pr(safe for all t) >= {c} (epsilon = {e})");
            if let Some(n) = stats::min_trials_to_support(c, p.confidence) {
                let _ = write!(out, "; supporting it takes at least {n} trials");
            }
            out.push('\n');
        }
        _ => out.push_str("; the world states no claim (no epsilon)\n"),
    }
    if let Some(v) = &p.theorem3 {
        let _ = writeln!(out, "check: {v}");
    }
    if let Some(v) = &p.liveness {
        let _ = writeln!(out, "liveness: {v}");
    }
    out.push('\n');
}

/// Safety, verdict, collisions, goals per controller.
fn safety_table(res: &BatchResult, out: &mut String) {
    let p = &res.plan;
    let conf = format!("P(safe) [{:.0}% CI]", p.confidence * 100.0);
    let headers = [
        "controller",
        "n",
        "safe",
        conf.as_str(),
        "verdict",
        "collided",
        "violated",
        "entered goal",
        "settled",
        "final dist p50 [m]",
        "t_goal p50/p90/max [s]",
        "clearance min/p10/p50 [m]",
    ];
    use Align::{Left, Right};
    let align = [
        Left, Right, Right, Right, Left, Right, Right, Right, Right, Right, Right, Right,
    ];
    let rows: Vec<Vec<String>> = res
        .summaries
        .iter()
        .map(|s| {
            vec![
                s.controller.clone(),
                s.trials.to_string(),
                s.safe.to_string(),
                rate_ci(s.safe_rate, s.safe_ci.lower, s.safe_ci.upper),
                verdict_cell(s.verdict, s.outside_fault_pattern_trials),
                format!("{} ({:.3})", s.collisions, s.collision_rate),
                s.violations.to_string(),
                format!("{} ({:.3})", s.goals, s.goal_rate),
                format!("{} ({:.3})", s.settled, s.settled_rate),
                format!("{:.3}", s.final_goal_distance_p50),
                upper(s.time_to_goal, 2),
                lower(s.min_clearance, 3),
            ]
        })
        .collect();
    out.push_str(&render(&headers, &align, &rows));
    if res
        .summaries
        .iter()
        .any(|s| s.outside_fault_pattern_trials > 0)
    {
        out.push_str("(*) some attacks lie outside the declared fault patterns: the claim does not cover them\n");
    }
    // Moving obstacles (issue #51): which collisions were with movers, and who moved.
    for s in &res.summaries {
        let movers = s.mover_hit_while_moving_trials + s.mover_hit_while_stopped_trials;
        if movers > 0 {
            out.push_str(&format!(
                "{}: trials with a collision — static obstacle {}, a mover the robot moved into {}, a mover into the robot at rest or moving away {} (a walker: {})\n",
                s.controller,
                s.static_collision_trials,
                s.mover_hit_while_moving_trials,
                s.mover_hit_while_stopped_trials,
                s.walker_hit_while_stopped_trials
            ));
        }
    }
}

/// Which policy step decided, summed over trials.
fn steps_table(res: &BatchResult, out: &mut String) {
    use Align::{Left, Right};
    out.push_str("\nPolicy steps (control steps, summed over trials)\n");
    let headers = [
        "controller",
        "step1",
        "clf_relaxed",
        "step2",
        "step3",
        "infeasible",
        "infeasible trials",
        "rejected readings (trials)",
        "min barrier min/p10/p50",
    ];
    let align = [Left, Right, Right, Right, Right, Right, Right, Right, Right];
    let rows: Vec<Vec<String>> = res
        .summaries
        .iter()
        .map(|s| {
            vec![
                s.controller.clone(),
                s.steps.step1.to_string(),
                s.steps.clf_relaxed.to_string(),
                s.steps.step2.to_string(),
                s.steps.step3.to_string(),
                s.steps.infeasible.to_string(),
                s.infeasible_trials.to_string(),
                format!("{} ({})", s.rejected_readings, s.rejected_trials),
                lower(s.min_barrier, 4),
            ]
        })
        .collect();
    out.push_str(&render(&headers, &align, &rows));
}

/// What `check`'s liveness line says when it predicts a safe stop
/// (`ftcbf_sim::analysis::safe_stop::predicted_stop_line`).
const PREDICTED_STOP: &str = "the safe stop may brake near";

/// The safe stops (`[control] fallback = "brake"`), per controller: how many trials stopped, the
/// braking steps, whether liveness predicted a stop and how many trials settled, and the first
/// stopped trial's reason (nothing when no trial stopped and none was predicted).
fn stops_table(res: &BatchResult, out: &mut String) {
    let predicted = res
        .plan
        .liveness
        .as_deref()
        .is_some_and(|l| l.contains(PREDICTED_STOP));
    if !predicted && res.records.iter().all(|r| r.first_stop_t.is_none()) {
        return;
    }
    out.push_str(
        "\nSafe stops (no evidence which source lies: the robot braked instead of guessing)\n",
    );
    for s in &res.summaries {
        let mine = || res.records.iter().filter(|r| r.controller == s.controller);
        let n = mine().count();
        let stopped = mine().filter(|r| r.first_stop_t.is_some()).count();
        let _ = writeln!(
            out,
            "{}: {stopped} of {n} trials stopped, {} braking steps in all; {}",
            s.controller,
            s.steps.safe_stop,
            if predicted {
                format!(
                    "liveness predicted a stop: {} of {n} trials settled",
                    s.settled
                )
            } else {
                "liveness predicted no stop".to_string()
            }
        );
        if let Some(r) = mine().find(|r| r.first_stop_t.is_some()) {
            let _ = writeln!(
                out,
                "  e.g. trial {}: stopped at t = {:.1} s: {}",
                r.trial,
                r.first_stop_t.unwrap_or(f64::NAN),
                r.stop_reason.as_deref().unwrap_or("?")
            );
        }
    }
}

/// Smoothness of the commanded (v, ω): per-trial fractions and means, averaged and at worst.
fn smoothness_table(res: &BatchResult, out: &mut String) {
    use Align::{Left, Right};
    out.push_str(
        "\nControl smoothness (commanded ω per control step; mean over trials / worst trial)\n",
    );
    let headers = [
        "controller",
        "ω sign changes [% of steps]",
        "mean |Δω| [rad/s per step]",
        "trials with a stall",
    ];
    let align = [Left, Right, Right, Right];
    let rows: Vec<Vec<String>> = res
        .summaries
        .iter()
        .map(|s| {
            let m = &s.smoothness;
            vec![
                s.controller.clone(),
                format!(
                    "{:.2} / {:.2}",
                    100.0 * m.omega_sign_change_fraction_mean,
                    100.0 * m.omega_sign_change_fraction_max
                ),
                format!(
                    "{:.4} / {:.4}",
                    m.mean_abs_domega_mean, m.mean_abs_domega_max
                ),
                m.stalled_trials.to_string(),
            ]
        })
        .collect();
    out.push_str(&render(&headers, &align, &rows));
}

/// Theorem 1's hypothesis measured: per filter, the share of the trials in which it read no
/// attacked channel whose estimation error ‖x − x̂‖ left γ, against ε.
fn gamma_table(res: &BatchResult, out: &mut String) {
    use Align::{Left, Right};
    let rows: Vec<Vec<String>> = res
        .summaries
        .iter()
        .flat_map(|s| {
            s.estimation
                .iter()
                .filter(|g| g.honest_trials > 0)
                .map(|g| {
                    vec![
                        s.controller.clone(),
                        g.filter.clone(),
                        format!("{} / {}", g.exceeded, g.honest_trials),
                        g.exceeded_ci.map_or("—".into(), |ci| {
                            format!("[{:.4}, {:.4}]", ci.lower, ci.upper)
                        }),
                        g.worst_ratio.map_or("—".into(), |r| format!("{r:.3}")),
                        if g.refuted {
                            "REFUTED (lower bound > ε)".into()
                        } else {
                            String::new()
                        },
                    ]
                })
        })
        .collect();
    if rows.is_empty() {
        return;
    }
    out.push_str(&format!(
        "\nEstimation error against γ (honest filters: those reading no attacked channel; Theorem 1 asks Pr(over γ) ≤ ε{})\n",
        res.plan
            .epsilon
            .map_or(String::new(), |e| format!(" = {e}"))
    ));
    let headers = [
        "controller",
        "filter",
        "trials over γ",
        "95 % interval",
        "worst ‖x − x̂‖/γ",
        "",
    ];
    let align = [Left, Left, Right, Right, Right, Left];
    out.push_str(&render(&headers, &align, &rows));
}

/// The worst trials, with their seeds for re-running.
fn worst_table(res: &BatchResult, out: &mut String) {
    use Align::{Left, Right};
    out.push_str("\nWorst trials (unsafe first, then smallest barrier value; re-run with `ftcbf run --seed SEED`)\n");
    let headers = [
        "controller",
        "trial",
        "seed",
        "safe",
        "min barrier",
        "at",
        "min clearance [m]",
    ];
    let align = [Left, Right, Right, Left, Right, Left, Right];
    let rows: Vec<Vec<String>> = res
        .summaries
        .iter()
        .flat_map(|s| {
            s.worst.iter().map(move |w| {
                vec![
                    s.controller.clone(),
                    w.trial.to_string(),
                    w.seed.to_string(),
                    if w.safe { "yes" } else { "NO" }.to_string(),
                    opt(w.min_barrier, 4),
                    w.min_barrier_name.clone().unwrap_or_else(|| "-".into()),
                    opt(w.min_clearance, 4),
                ]
            })
        })
        .collect();
    out.push_str(&render(&headers, &align, &rows));
}

/// The McNemar comparisons and any warnings.
fn paired_and_warnings(res: &BatchResult, out: &mut String) {
    if !res.paired.is_empty() {
        out.push_str("\nPaired comparison on the same seeds (exact McNemar test)\n");
        for c in &res.paired {
            let _ = writeln!(
                out,
                "{} vs {}: both safe {}, only {} safe {}, only {} safe {}, neither {}; p = {:.3e}",
                c.first,
                c.second,
                c.both_safe,
                c.first,
                c.only_first_safe,
                c.second,
                c.only_second_safe,
                c.neither_safe,
                c.p_value
            );
        }
    }
    for w in &res.warnings {
        let _ = writeln!(out, "\nwarning: {w}");
    }
}

/// One table for a sweep: rows = sweep value × controller.
pub fn sweep_text(results: &[BatchResult]) -> String {
    let key = results
        .first()
        .and_then(|r| r.plan.overrides.first())
        .map_or_else(|| "value".to_string(), |o| o.key.clone());
    let conf = results.first().map_or(95.0, |r| r.plan.confidence * 100.0);
    let ci = format!("P(safe) [{conf:.0}% CI]");
    let headers = [
        key.as_str(),
        "controller",
        "n",
        ci.as_str(),
        "verdict",
        "collision rate",
        "entered goal",
        "settled",
        "t_goal p50 [s]",
    ];
    use Align::{Left, Right};
    let align = [Right, Left, Right, Right, Left, Right, Right, Right, Right];
    let mut rows = Vec::new();
    for r in results {
        let value = r
            .plan
            .overrides
            .first()
            .map_or_else(|| "-".to_string(), |o| o.value.to_string());
        for s in &r.summaries {
            rows.push(vec![
                value.clone(),
                s.controller.clone(),
                s.trials.to_string(),
                rate_ci(s.safe_rate, s.safe_ci.lower, s.safe_ci.upper),
                verdict_cell(s.verdict, s.outside_fault_pattern_trials),
                format!("{:.3}", s.collision_rate),
                format!("{:.3}", s.goal_rate),
                format!("{:.3}", s.settled_rate),
                opt(s.time_to_goal.map(|t| t.p50), 2),
            ]);
        }
    }
    let mut out = String::new();
    if let Some(r) = results.first() {
        let claim = r.plan.claimed_safety().map_or_else(
            || "no claim".to_string(),
            |c| format!("claim Pr(safe) >= {c}"),
        );
        let _ = writeln!(
            out,
            "Sweep of {key} on world `{}` ({} trials per point, {claim})\n",
            r.plan.world, r.plan.trials
        );
    }
    out.push_str(&render(&headers, &align, &rows));
    for r in results {
        for w in &r.warnings {
            let _ = writeln!(out, "warning ({}): {w}", point_label(r));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::super::testutil::*;
    use super::super::*;
    use super::*;

    #[test]
    fn render_aligns_columns() {
        let t = render(
            &["name", "n"],
            &[Align::Left, Align::Right],
            &[
                vec!["ε-long".into(), "5".into()],
                vec!["b".into(), "1234".into()],
            ],
        );
        let lines: Vec<&str> = t.lines().collect();
        assert_eq!(
            lines,
            vec![
                "name       n",
                "------------",
                "ε-long     5",
                "b       1234"
            ]
        );
    }

    /// Widths are terminal columns: x̂ (x and a combining circumflex) takes one, as γ does, so
    /// the estimation-error table's last column lines up under its header (counted in chars, the
    /// header was one wider than it looks and its numbers stood one column right of it).
    #[test]
    fn render_measures_cells_in_terminal_columns() {
        let t = render(
            &["f", "‖x − x̂‖/γ"],
            &[Align::Left, Align::Right],
            &[vec!["a".into(), "0.384".into()]],
        );
        let lines: Vec<&str> = t.lines().collect();
        assert_eq!(lines, vec!["f  ‖x − x̂‖/γ", "------------", "a      0.384"]);
    }

    #[test]
    fn summary_shows_interval_verdict_and_worst_seeds() {
        let runner = Synthetic {
            p_safe: 0.9,
            fail_seed: None,
        };
        let res = run_batch(&runner, &plan(100, None), SERIAL).expect("batch");
        let text = summary_text(&res);
        let s = &res.summaries[1];
        let cell = format!(
            "{:.4} [{:.4}, {:.4}]",
            s.safe_rate, s.safe_ci.lower, s.safe_ci.upper
        );
        assert!(text.contains(&cell), "{text}");
        assert!(text.contains("refuted"), "{text}");
        assert!(text.contains(&res.summaries[0].worst[0].seed.to_string()));
        assert!(text.contains("epsilon = 0.1"));
        assert!(
            text.contains("supporting it takes at least 36 trials"),
            "{text}"
        );
        // Every row of the first table has its verdict column starting at the same offset.
        let table: Vec<&str> = text.lines().skip(3).take(4).collect();
        let col = table[0].find("verdict").expect("header");
        for row in &table[2..] {
            let rest = &row[col..];
            assert!(
                rest.starts_with("refuted")
                    || rest.starts_with("unresolved")
                    || rest.starts_with("supported"),
                "{row}"
            );
        }
    }

    #[test]
    fn sweep_table_has_a_row_per_value_and_controller() {
        let runner = Synthetic {
            p_safe: 0.9,
            fail_seed: None,
        };
        let results: Vec<BatchResult> = [0.25, 4.0]
            .iter()
            .map(|&v| {
                let mut p = plan(30, None);
                p.overrides = vec![Override {
                    key: "sensors[1].noise".into(),
                    value: v,
                }];
                run_batch(&runner, &p, SERIAL).expect("point")
            })
            .collect();
        let text = sweep_text(&results);
        let rows: Vec<&str> = text
            .lines()
            .skip_while(|l| !l.starts_with('-'))
            .skip(1)
            .collect();
        assert_eq!(rows.len(), 4, "{text}");
        assert!(rows[0].trim_start().starts_with("0.25") && rows[0].contains("ft-cbf-clf"));
        assert!(rows[3].trim_start().starts_with('4') && rows[3].contains("baseline"));
        assert!(text.contains("sensors[1].noise"));
    }
}
