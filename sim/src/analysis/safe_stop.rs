//! The second verdict of `ftcbf check` (issue #50): the safe stop's guarantee, next to
//! Theorem 3's. With `[control] fallback = "brake"` the policy never drops a unit by residue
//! without evidence; where Step 3 would have guessed, the robot brakes on its wheel encoders.
//! The claim (book/src/theory/safe-stop.md): Pr(safe) ≥ 1 − ε − N·m·α for any single fault
//! pattern, where N·m·α bounds the chance that an honest unit's residue ever looks like
//! evidence; the robot may stop short of its goal. Its hypotheses are Theorem 3's minus the two
//! the stop replaces (every pair filter certified, so Step 2 can isolate; every kept unit's rows
//! met by one input, case (i)), plus its own: braking inside the lift's margin, the honest unit
//! kept by Step 2, and static obstacles.

use crate::analysis::liveness::LivenessReport;
use crate::world::{Dynamics, FallbackSpec, World};
use ftcbf_controller::policy::DEFAULT_EVIDENCE_ALPHA;

/// Outcome of one of the safe stop's hypotheses (as `check`'s statuses).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Status {
    /// Verified from the world.
    Holds,
    /// Verified false: the safe stop's guarantee does not apply.
    Fails,
    /// Cannot be decided statically; stated as an assumption of the verdict.
    Assumed,
}

/// One hypothesis of the safe stop, with its numbers.
#[derive(Debug, Clone, PartialEq)]
pub struct Hypothesis {
    /// Short name.
    pub name: String,
    /// Outcome.
    pub status: Status,
    /// The numbers behind it.
    pub detail: String,
}

/// A hypothesis of Theorem 3 that `check` found false, by name and detail.
#[derive(Debug, Clone, PartialEq)]
pub struct Failed<'a> {
    /// Its name.
    pub name: &'a str,
    /// Its numbers.
    pub detail: &'a str,
}

/// The safe stop's verdict.
#[derive(Debug, Clone, PartialEq)]
pub struct SafeStopVerdict {
    /// `[control] fallback = "brake"` is in force.
    pub in_force: bool,
    /// The guarantee applies.
    pub applies: bool,
    /// The bound 1 − ε − N·m·α.
    pub bound: f64,
    /// Its own hypotheses (the ones Theorem 3's list does not have).
    pub hypotheses: Vec<Hypothesis>,
    /// Why not (empty when it applies).
    pub reasons: Vec<String>,
    /// Conditions it rests on that cannot be decided statically.
    pub assumptions: Vec<String>,
    /// Where the liveness walk predicts a stop (no input meets every kept unit's rows there).
    pub predicted_stop: Option<String>,
}

impl SafeStopVerdict {
    /// The verdict line.
    pub fn line(&self) -> String {
        if !self.in_force {
            return "safe-stop: not in force ([control] fallback = \"paper\": Step 3 drops the largest residue)".into();
        }
        if !self.applies {
            return format!("safe-stop does NOT apply: {}", self.reasons.join("; "));
        }
        let assuming = if self.assumptions.is_empty() {
            String::new()
        } else {
            format!(", assuming {}", self.assumptions.join("; "))
        };
        let stop = self
            .predicted_stop
            .as_ref()
            .map_or(String::new(), |s| format!("; {s}"));
        format!(
            "safe-stop applies{assuming}: Pr(safe) ≥ 1 − ε − N·m·α = {:.4} for any single fault pattern; the robot may stop short of its goal{stop}",
            self.bound
        )
    }
}

/// Whether a Theorem-3 hypothesis is one the safe stop does not need: the pair filters'
/// certification (Step 2's θ; the stop does not rely on Step 2 isolating) and case (i) (every
/// kept unit's rows met by one input: where they are not, the stop brakes).
fn replaced_by_the_stop(h: &Failed<'_>) -> bool {
    let pair_filter = h.name.contains(" ∪ ");
    (pair_filter && (h.name.starts_with("detectable") || h.name.starts_with("invertible")))
        || h.name.starts_with("case (i)")
}

/// The safe stop's verdict for `world`, from Theorem 3's hypotheses and the liveness walk.
pub fn verdict(
    world: &World,
    theorem3: &[Failed<'_>],
    liveness: &LivenessReport,
) -> SafeStopVerdict {
    let f = &world.file;
    let steps = (f.duration * f.control.rate_hz).round();
    let units = world.file.fault_patterns.len() as f64;
    let false_alarm = steps * units * DEFAULT_EVIDENCE_ALPHA;
    let mut v = SafeStopVerdict {
        in_force: f.control.fallback == FallbackSpec::Brake,
        applies: false,
        bound: 1.0 - f.control.epsilon - false_alarm,
        hypotheses: Vec::new(),
        reasons: Vec::new(),
        assumptions: Vec::new(),
        predicted_stop: None,
    };
    if !v.in_force {
        return v;
    }
    for h in theorem3 {
        if !replaced_by_the_stop(h) {
            v.reasons.push(format!("{}: {}", h.name, h.detail));
        }
    }
    let mut record = |name: &str, status: Status, detail: String| {
        match status {
            Status::Fails => v.reasons.push(format!("{name}: {detail}")),
            Status::Assumed => v.assumptions.push(name.to_string()),
            Status::Holds => {}
        }
        v.hypotheses.push(Hypothesis {
            name: name.to_string(),
            status,
            detail,
        });
    };
    braking(world, &mut record);
    let open_pairs: Vec<&str> = theorem3
        .iter()
        .filter(|h| replaced_by_the_stop(h) && h.name.contains(" ∪ "))
        .map(|h| h.name)
        .collect();
    if open_pairs.is_empty() {
        record(
            "the honest unit kept in Z_t by Step 2",
            Status::Holds,
            "every pair filter is certified: under (4.5) Step 2 never drops the honest unit (Theorem 3's case (iii))".into(),
        );
    } else {
        record(
            "the honest unit kept in Z_t by Step 2",
            Status::Assumed,
            format!(
                "Step 2 drops the honest unit i only if ‖x̂_i − x̂_ij‖ > θ_ij/2; nothing measured bounds the pair filter's error ({}), so this rests on the assumed process noise",
                open_pairs.join("; ")
            ),
        );
    }
    record(
        "no honest unit dropped on false evidence",
        Status::Holds,
        format!(
            "Step 3 drops a unit only when its windowed χ² score exceeds z_α (α = {DEFAULT_EVIDENCE_ALPHA:e} per unit and step) or a reading of it was rejected: over N = {steps} steps and m = {units} units the union bound is N·m·α = {false_alarm:.4}, spent from the bound"
        ),
    );
    let movers: Vec<&str> = world
        .obstacles
        .iter()
        .filter(|o| o.spec.motion.is_some())
        .map(|o| o.name.as_str())
        .collect();
    if movers.is_empty() {
        record(
            "static obstacles",
            Status::Holds,
            "the world declares no moving obstacle: a robot at rest cannot hit one".into(),
        );
    } else {
        record(
            "static obstacles",
            Status::Fails,
            format!(
                "{} move ({}): the stopped robot steps aside for them only where one input meets every kept estimator's rows of the movers (their estimates may disagree by up to θ), and brakes where none does; a mover that does not avoid it can hit it then, so the safe stop is not a safe state",
                movers.len(),
                crate::environment::name_list(&movers, 3)
            ),
        );
    }
    v.applies = v.reasons.is_empty();
    v.predicted_stop = predicted_stop(liveness);
    v
}

/// Braking distance inside the lift's margin: with the lifted barrier H = d + k·ḋ ≥ 0 when the
/// stop begins, the robot at speed v towards a wall is at least k·v from it; braking at a after
/// one control period Δt travels at most v·Δt + v²/(2a), inside k·v when k ≥ Δt + v/(2a).
fn braking(world: &World, record: &mut impl FnMut(&str, Status, String)) {
    let name = "braking distance inside the margin the rows keep";
    let f = &world.file;
    let (Dynamics::Rapier, Some(robot)) = (f.dynamics, world.robot.as_ref()) else {
        record(
            name,
            Status::Assumed,
            "the linear plant brakes with the controller's u = −v̂/τ_s (no encoders): its stopping distance is assumed inside h̄_γ".into(),
        );
        return;
    };
    let v = robot.limits.v_max;
    let a = world.brake_deceleration();
    let dt = world.control_dt();
    let k = f.control.obstacle_lift;
    let need = dt + v / (2.0 * a);
    let detail = format!(
        "from v_max = {v:.3} m/s at a = {a:.3} m/s² after one period Δt = {dt:.3} s the robot travels ≤ v·Δt + v²/(2a) = {:.4} m; the lift H = d + k·ḋ with k = {k:.3} s keeps k·v = {:.4} m when the stop begins (needs k ≥ Δt + v/(2a) = {need:.3} s)",
        v * dt + v * v / (2.0 * a),
        k * v
    );
    let status = if !world.obstacles.is_empty() && k < need {
        Status::Fails
    } else if f.safe_sets.is_empty() {
        Status::Holds
    } else {
        // Safe sets carry their own lift (not obstacle_lift): not decided here.
        Status::Assumed
    };
    record(name, status, detail);
}

/// "under the declared attack the robot may stop near (x, y), s m along its path": the first
/// point where the liveness walk finds no input meeting every kept unit's rows.
fn predicted_stop(liveness: &LivenessReport) -> Option<String> {
    liveness.cases.iter().find_map(|c| {
        c.joint_infeasible.as_ref().map(|st| {
            format!(
                "predicted: {} it may stop near ({:.2}, {:.2}), {:.2} m along its path (no input meets every kept unit's rows there; it resumes when they agree)",
                c.name, st.at[0], st.at[1], st.along
            )
        })
    })
}

/// `A` and `B` of a Theorem-3 hypothesis about the pair filter that drops them, named
/// "… x̂_12 (drops A ∪ B)".
fn pair_of(name: &str) -> Option<(&str, &str)> {
    let inside = name.rsplit_once("(drops ")?.1;
    let inside = inside.strip_suffix(')').unwrap_or(inside);
    inside.split_once(" ∪ ")
}

/// The liveness line's prediction of a safe stop (issue #50): with `[control] fallback =
/// "brake"`, where a case of the liveness walk finds a point at which no input meets every kept
/// unit's rows and a pair filter Theorem 3 could not certify leaves two sources that nothing
/// tells apart, the robot brakes there instead of guessing. The stop is a pause: the walk says
/// whether the robot goes on (it waits for the rows to agree) or stops short there (a stall).
/// Names the pair and the channel that would resolve it, as a run's stop reason does. `None`
/// when no such point or pair exists, or the stop is not in force.
pub fn predicted_stop_line(
    world: &World,
    theorem3: &[Failed<'_>],
    liveness: &LivenessReport,
) -> Option<String> {
    if world.file.control.fallback != FallbackSpec::Brake {
        return None;
    }
    let (case, st) = liveness
        .cases
        .iter()
        .find_map(|c| c.joint_infeasible.as_ref().map(|st| (c, st)))?;
    let (a, b) = theorem3
        .iter()
        .filter(|h| replaced_by_the_stop(h))
        .find_map(|h| pair_of(h.name))?;
    let third = if world.file.fault_patterns.len() <= 2 {
        "; no third source"
    } else {
        ""
    };
    let after = match (&case.stall, case.waited) {
        (Some(_), _) => "; the walk does not get past it".to_string(),
        (None, Some((w, _))) => {
            format!("; the walk waits {w:.1} s for the rows to agree, then goes on")
        }
        (None, None) => String::new(),
    };
    Some(format!(
        "{}, the safe stop may brake near ({:.2}, {:.2}), {:.2} m along its path: no input meets every kept unit's rows there and nothing tells whether {a} or {b} lies (their pair filter is not certified, so Step 2 cannot isolate either{third}); it brakes instead of guessing and resumes when the rows agree{after}; to resolve it, add a channel the pair filters share: odometry or a third receiver",
        case.name, st.at[0], st.at[1], st.along
    ))
}
