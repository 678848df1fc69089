//! The safe stops of a run ([`QpOutcome::SafeStop`]): how many, when, and why, in words a user
//! can act on.

use ftcbf_controller::policy::{QpOutcome, StopReason};

use crate::summary::SafeStopReport;

/// Counts the safe-stop steps and episodes (maximal runs of consecutive stop steps) and keeps
/// the first episode's reason.
#[derive(Debug, Clone, Default)]
pub(super) struct StopMeter {
    steps: u64,
    episodes: u64,
    stopping: bool,
    first: Option<(f64, String)>,
    last_start: Option<f64>,
}

impl StopMeter {
    /// One control step at time `t` \[s\] with the policy's outcome; `patterns` names the fault
    /// patterns (unit i drops pattern i). Returns the event line when a stop begins.
    pub(super) fn observe(
        &mut self,
        t: f64,
        qp: &QpOutcome,
        patterns: &[String],
    ) -> Option<String> {
        let QpOutcome::SafeStop { reason, .. } = qp else {
            self.stopping = false;
            return None;
        };
        self.steps += 1;
        if self.stopping {
            return None;
        }
        self.stopping = true;
        self.episodes += 1;
        self.last_start = Some(t);
        let why = explain(reason, patterns);
        if self.first.is_none() {
            self.first = Some((t, why.clone()));
        }
        Some(format!("safe stop: stopped at t = {t:.2} s: {why}"))
    }

    /// The report (None when the run never stopped).
    pub(super) fn report(&self) -> Option<SafeStopReport> {
        let (t, reason) = self.first.clone()?;
        Some(SafeStopReport {
            first_t: t,
            reason,
            episodes: self.episodes,
            steps: self.steps,
            last_start: self.last_start.unwrap_or(t),
            stopped_at_end: self.stopping,
        })
    }
}

/// "cannot tell whether gnss1 or gnss2 lies (…); add …": unit i is the filter that drops
/// pattern i, so the two units Step 3 would have chosen between stand for their patterns.
pub(super) fn explain(r: &StopReason, patterns: &[String]) -> String {
    let name = |i: usize| {
        patterns
            .get(i)
            .cloned()
            .unwrap_or_else(|| format!("r{}", i + 1))
    };
    let (a, b) = (
        name(r.would_drop.min(r.other)),
        name(r.would_drop.max(r.other)),
    );
    let isolation = if r.step2_isolated {
        "Step 2 isolated another source, not these".to_string()
    } else if r.theta.is_finite() {
        format!("Step 2 isolates only beyond θ = {:.2}", r.theta)
    } else {
        "Step 2 cannot isolate either".to_string()
    };
    let third = if patterns.len() <= 2 {
        "; no third source"
    } else {
        ""
    };
    format!(
        "cannot tell whether {a} or {b} lies ({:.2} m apart, {isolation}; residue scores {:.2} and {:.2}, evidence needs > {:.2}{third}); add a channel the pair filters share: odometry or a third receiver",
        r.separation,
        r.would_drop_key.max(r.other_key),
        r.would_drop_key.min(r.other_key),
        r.evidence_z
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use ftcbf_controller::policy::BrakeVelocity;

    fn stop(separation: f64) -> QpOutcome {
        QpOutcome::SafeStop {
            reason: StopReason {
                would_drop: 1,
                would_drop_key: 1.3,
                other: 0,
                other_key: 0.8,
                separation,
                theta: 55.0,
                evidence_z: 4.75,
                step2_isolated: false,
            },
            velocity: BrakeVelocity::Remaining { unit: 0 },
            max_cbf_violation: 0.1,
            evades_movers: false,
        }
    }

    #[test]
    fn a_stop_is_reported_once_per_episode_with_the_sources_it_cannot_tell_apart() {
        let names = vec!["gnss1".to_string(), "gnss2".to_string()];
        let feasible = QpOutcome::Feasible {
            stage: ftcbf_controller::Stage::Step1,
            clf_relaxed: false,
            clf_slack: 0.0,
            iterations: 3,
        };
        let mut m = StopMeter::default();
        assert!(m.observe(14.0, &feasible, &names).is_none());
        let line = m.observe(14.2, &stop(1.2), &names).expect("a stop begins");
        assert_eq!(
            line,
            "safe stop: stopped at t = 14.20 s: cannot tell whether gnss1 or gnss2 lies (1.20 m apart, Step 2 isolates only beyond θ = 55.00; residue scores 1.30 and 0.80, evidence needs > 4.75; no third source); add a channel the pair filters share: odometry or a third receiver"
        );
        assert!(
            m.observe(14.22, &stop(1.3), &names).is_none(),
            "the same episode"
        );
        assert!(m.observe(14.24, &feasible, &names).is_none());
        assert!(
            m.observe(15.0, &stop(1.4), &names).is_some(),
            "a second episode"
        );
        let r = m.report().expect("it stopped");
        assert_eq!((r.episodes, r.steps), (2, 3));
        assert_eq!(r.first_t, 14.2);
        assert_eq!(r.last_start, 15.0);
        assert!(r.stopped_at_end);
        assert!(
            r.reason.contains("1.20 m apart"),
            "the first episode's reason: {}",
            r.reason
        );
    }
}
