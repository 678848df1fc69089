//! The report as text: the checked world's lines grouped by barrier, fail-closed on a
//! non-finite number, and [`CheckReport`]'s `Display`.

use super::*;

/// Whether `text` shows a non-finite number: a `NaN` or `inf` word (how Rust prints them).
pub(super) fn shows_non_finite(text: &str) -> Option<&str> {
    text.split(|c: char| !(c.is_alphanumeric() || c == '_'))
        .find(|w| *w == "NaN" || *w == "inf")
}

/// Fail closed: a hypothesis that computed NaN or ∞ is not verified, whatever its comparison
/// said (NaN compares false both ways); it FAILS with the number named, so the verdict can
/// never be "applies" with a non-finite number inside. A NaN in the description (parameters,
/// h̄_γ, P0; the world's free-text description excluded) fails the report the same way (∞
/// there is legitimate: δ = inf means always active).
pub(super) fn check_finite_report(context: &[String], found: &mut Findings) {
    for h in &mut found.hypotheses {
        if h.status == Status::Fails {
            continue;
        }
        if let Some(w) = shows_non_finite(&h.detail) {
            h.status = Status::Fails;
            let reason = format!(
                "{}: computed a non-finite number ({w}): {}",
                h.name, h.detail
            );
            h.detail = format!(
                "computed a non-finite number ({w}), so not verified: {}",
                h.detail
            );
            found.reasons.push(reason);
        }
    }
    for line in context {
        if line.starts_with("warning: ") {
            continue;
        }
        let nan = line
            .split(|c: char| !(c.is_alphanumeric() || c == '_'))
            .any(|w| w == "NaN");
        let h_bar_inf = line.starts_with("h̄_γ(") && shows_non_finite(line).is_some();
        let p0_inf = line.starts_with("filters:") && shows_non_finite(line).is_some();
        if nan || h_bar_inf || p0_inf {
            found.record(
                "finite derived numbers".into(),
                Status::Fails,
                format!("a derived number is not finite: {line}"),
            );
        }
    }
}

/// Lines that differ only in the one barrier they name, printed once with the barriers listed
/// (`obstacle:{wall_1, wall_2}`), in the order of their first line; every other line as it is.
/// A name counts where it stands as a whole word (`wall_1` is not found in `wall_10`), with or
/// without its `obstacle:` prefix.
pub fn group_by_barrier<I: IntoIterator<Item = String>>(lines: I, names: &[String]) -> Vec<String> {
    const MARK: &str = "\u{1}";
    let mut tokens: Vec<&str> = names
        .iter()
        .map(|n| n.strip_prefix("obstacle:").unwrap_or(n))
        .collect();
    // Longest first, so that a name that contains another is found whole.
    tokens.sort_by_key(|t| std::cmp::Reverse(t.len()));
    tokens.dedup();
    let word = |c: Option<char>| c.is_some_and(|c| c.is_alphanumeric() || c == '_');
    let find = |line: &str| -> Option<(String, String)> {
        let mut hit: Option<(&str, String)> = None;
        for t in &tokens {
            let mut out = String::new();
            let mut rest = line;
            let mut found = false;
            while let Some(i) = rest.find(t) {
                let before = rest[..i].chars().next_back();
                let after = rest[i + t.len()..].chars().next();
                out.push_str(&rest[..i]);
                if word(before) || word(after) {
                    out.push_str(t);
                } else {
                    out.push_str(MARK);
                    found = true;
                }
                rest = &rest[i + t.len()..];
            }
            out.push_str(rest);
            if found {
                if hit.is_some() {
                    return None; // two barriers in one line: leave it alone
                }
                hit = Some((t, out));
            }
        }
        hit.map(|(t, out)| (t.to_string(), out))
    };
    let mut order: Vec<(String, Vec<String>)> = Vec::new();
    for line in lines {
        match find(&line) {
            Some((name, template)) => match order
                .iter_mut()
                .find(|(t, n)| *t == template && !n.is_empty())
            {
                Some((_, n)) => n.push(name),
                None => order.push((template, vec![name])),
            },
            None => order.push((line, Vec::new())),
        }
    }
    order
        .into_iter()
        .map(|(t, n)| match n.len() {
            0 => t,
            1 => t.replace(MARK, &n[0]),
            k if k > MAX_LISTED => {
                let shown: Vec<&str> = n.iter().take(3).map(String::as_str).collect();
                t.replace(
                    MARK,
                    &format!("{{{} and {} more}}", shown.join(", "), k - shown.len()),
                )
            }
            _ => t.replace(MARK, &format!("{{{}}}", n.join(", "))),
        })
        .collect()
}

impl fmt::Display for CheckReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let names = &self.barrier_names;
        if !self.environment.is_empty() {
            writeln!(f, "environment:")?;
            for line in &self.environment {
                writeln!(f, "  {line}")?;
            }
        }
        for line in group_by_barrier(self.context.iter().cloned(), names) {
            writeln!(f, "  {line}")?;
        }
        writeln!(f, "hypotheses of Theorem 3:")?;
        let hyps = self
            .hypotheses
            .iter()
            .map(|h| format!("[{}] {}: {}", h.status.tag(), h.name, h.detail));
        for line in group_by_barrier(hyps, names) {
            writeln!(f, "  {line}")?;
        }
        if !self.verdict.assumptions.is_empty() {
            writeln!(f, "assumed, not checkable from the world file:")?;
            for a in group_by_barrier(self.verdict.assumptions.iter().cloned(), names) {
                writeln!(f, "  - {a}")?;
            }
        }
        writeln!(f, "{}", self.liveness)?;
        if self.safe_stop.in_force {
            writeln!(f, "hypotheses of the safe stop (besides Theorem 3's, less the pair filters' certification and case (i)):")?;
            for h in &self.safe_stop.hypotheses {
                let status = match h.status {
                    crate::analysis::safe_stop::Status::Holds => Status::Holds,
                    crate::analysis::safe_stop::Status::Fails => Status::Fails,
                    crate::analysis::safe_stop::Status::Assumed => Status::Assumed,
                };
                writeln!(f, "  [{}] {}: {}", status.tag(), h.name, h.detail)?;
            }
        }
        writeln!(f, "{}", self.safe_stop.line())?;
        write!(f, "verdict: {}", self.verdict.line())
    }
}

#[cfg(test)]
mod non_finite_tests {
    use super::*;

    #[test]
    fn a_suggestion_with_nothing_to_try_says_so_instead_of_counting_zero_worlds() {
        let none = Suggestion {
            changes: Vec::new(),
            already: false,
            verdict: "verdict: Theorem 3 does NOT apply: …".into(),
            liveness: "live".into(),
            tried: 0,
        };
        let text = none.to_string();
        assert!(text.starts_with("suggest: nothing to try"), "{text}");
        assert!(!text.contains("0 worlds checked"), "{text}");
        let searched = Suggestion { tried: 7, ..none };
        assert!(searched.to_string().contains("(7 worlds checked)"));
    }

    #[test]
    fn a_hypothesis_showing_nan_or_inf_fails_and_the_verdict_cannot_apply() {
        assert_eq!(shows_non_finite("λ̄ = NaN"), Some("NaN"));
        assert_eq!(shows_non_finite("needs inf × the box"), Some("inf"));
        assert_eq!(shows_non_finite("the infimum is 0.3; info"), None);
        let mut found = Findings::default();
        found.record("Prop. 1".into(), Status::Holds, "λ̄ = NaN".into());
        found.record("Thm. 5".into(), Status::Info, "bound 0.2".into());
        check_finite_report(&["in force: δ = inf".to_string()], &mut found);
        assert_eq!(found.hypotheses[0].status, Status::Fails);
        assert!(found.hypotheses[0]
            .detail
            .contains("non-finite number (NaN)"));
        assert_eq!(found.hypotheses[1].status, Status::Info);
        // δ = inf is legitimate (always active); only the NaN hypothesis is a reason.
        assert_eq!(found.reasons.len(), 1, "{:?}", found.reasons);
        let mut found = Findings::default();
        check_finite_report(
            &["h̄_γ(floor) per fault-pattern filter = [inf]".to_string()],
            &mut found,
        );
        assert_eq!(found.reasons.len(), 1);
    }
}

#[cfg(test)]
mod grouping_tests {
    use super::group_by_barrier;

    #[test]
    fn lines_that_differ_only_in_the_barrier_are_printed_once() {
        let names: Vec<String> = [
            "obstacle:wall_1",
            "obstacle:wall_10",
            "obstacle:post",
            "floor",
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        let lines = [
            "condition 1 for obstacle:wall_1: needs 0.490 × the box",
            "condition 1 for obstacle:wall_10: needs 0.490 × the box",
            "condition 1 for obstacle:post: needs 0.700 × the box",
            "condition 1 for obstacle:floor_x: needs 0.490 × the box",
            "curvature of wall_1 is assumed",
            "curvature of post is assumed",
            "wall_1 and post touch",
        ]
        .map(String::from);
        let out = group_by_barrier(lines, &names);
        assert_eq!(
            out,
            vec![
                "condition 1 for obstacle:{wall_1, wall_10}: needs 0.490 × the box",
                "condition 1 for obstacle:post: needs 0.700 × the box",
                // `floor` inside `floor_x` is not a barrier's name
                "condition 1 for obstacle:floor_x: needs 0.490 × the box",
                "curvature of {wall_1, post} is assumed",
                // two barriers in one line: as it is
                "wall_1 and post touch",
            ]
        );
    }
}
