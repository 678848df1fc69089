//! Text of the event log: what the policy decided, and when attacks start and end.

use crate::observe::{Frame, Scene};

/// The policy's state this step as (key, line). The key (stage and who was dropped at which
/// stage, without the changing numbers) decides when a new line is logged; repeated clauses
/// are written once; an infeasible step names the tightest constraint.
pub(super) fn policy_line(scene: &Scene, f: &Frame<'_>) -> (String, String) {
    let mut clauses: Vec<&str> = Vec::new();
    for c in f.decision_note.split("; ").map(str::trim) {
        if !c.is_empty() && !clauses.contains(&c) {
            clauses.push(c);
        }
    }
    let mut key = f.decided_by.to_string();
    for c in &clauses {
        key.push('|');
        key.push_str(c.split(':').next().unwrap_or(c));
    }
    let mut line = format!("policy stage {}", f.decided_by);
    if f.decided_by == "infeasible" {
        line.push_str(&tightest(scene, f));
    }
    if clauses.is_empty() {
        line.push_str(": all estimators' constraints kept");
    } else {
        line.push_str(": ");
        line.push_str(&clauses.join("; "));
    }
    (key, line)
}

/// ", tightest constraint h_<barrier> = <v> on <estimator>": the barrier with the smallest
/// h(x̂) over the estimators (empty when no value is finite).
fn tightest(scene: &Scene, f: &Frame<'_>) -> String {
    let nb = scene.barriers.len();
    let mut best: Option<(f64, usize, usize)> = None;
    for (k, &h) in f.barrier_values.iter().enumerate() {
        if nb > 0 && h.is_finite() && best.is_none_or(|(b, _, _)| h < b) {
            best = Some((h, k % nb, k / nb));
        }
    }
    match best {
        Some((h, j, i)) => format!(
            " (no input satisfies every kept constraint; tightest: h_{} = {h:.4} on estimate {})",
            scene.barriers[j],
            scene.filters.get(i).map_or("?", String::as_str)
        ),
        None => " (no input satisfies every kept constraint)".into(),
    }
}

/// "attack <label> on <channels> starts/ends at t = … s".
pub(super) fn attack_line(scene: &Scene, a: usize, on: bool, t: f64) -> String {
    let label = scene.attacks.get(a).map_or("?", String::as_str);
    let channels = scene
        .attack_channels
        .get(a)
        .map(|c| c.join(", "))
        .unwrap_or_default();
    let what = if on { "starts" } else { "ends" };
    format!("attack {label} on [{channels}] {what} at t = {t:.2} s")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::state::TruthState;

    fn frame<'a>(truth: &'a TruthState, note: &'a str, stage: &'a str, h: &'a [f64]) -> Frame<'a> {
        Frame {
            t: 1.0,
            step: 50,
            truth,
            channels: &[],
            estimates: &[],
            barrier_values: h,
            barrier_truth: &[],
            u: [0.0; 2],
            body_cmd: [0.0; 2],
            decided_by: stage,
            decision_note: note,
            attacks_active: &[],
            link_poses: &[],
            events: &[],
            movers: &[],
            mover_readings: &[],
            contacts: &[],
        }
    }

    #[test]
    fn repeated_clauses_are_written_once_and_numbers_do_not_change_the_key() {
        let scene = Scene::default();
        let truth = TruthState::default();
        let a = "gps dropped at Step2: d = 1.0; gps dropped at Step2: d = 1.0; ";
        let b = "gps dropped at Step2: d = 2.0; ";
        let (ka, la) = policy_line(&scene, &frame(&truth, a, "step2", &[]));
        let (kb, _) = policy_line(&scene, &frame(&truth, b, "step2", &[]));
        assert_eq!(ka, kb);
        assert_eq!(la.matches("gps dropped").count(), 1, "{la}");
    }

    #[test]
    fn an_infeasible_step_names_the_tightest_constraint() {
        let scene = Scene {
            barriers: vec!["corridor_left".into(), "pillar".into()],
            filters: vec!["all".into(), "no_gps".into()],
            ..Scene::default()
        };
        let truth = TruthState::default();
        // Rows are estimators, columns barriers: the tightest is pillar on no_gps.
        let h = [0.5, 0.2, 0.4, -0.1];
        let (_, line) = policy_line(&scene, &frame(&truth, "", "infeasible", &h));
        assert!(
            line.contains("h_pillar = -0.1000 on estimate no_gps"),
            "{line}"
        );
    }
}
