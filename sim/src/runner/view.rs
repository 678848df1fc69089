//! The per-step values a [`super::Simulation`] exposes through [`crate::observe::Frame`]:
//! readings before and after the attacks, the detector statistic, the estimates, and a readable
//! note on the policy's decision.

use std::fmt::Write as _;

use ftcbf_controller::policy::{DropReason, QpOutcome, Verdict};
use ftcbf_controller::{ControlOutput, EstimatorBank};

use super::errors::ErrorMeter;
use crate::observe::{ChannelView, EstimateView};
use crate::sensors::Sample;
use crate::state::TruthState;

/// Buffers refilled every control step (allocated once per run).
pub(super) struct StepView {
    pub(super) truth: TruthState,
    pub(super) channels: Vec<ChannelView>,
    pub(super) estimates: Vec<EstimateView>,
    pub(super) barrier_values: Vec<f64>,
    pub(super) v_values: Vec<f64>,
    pub(super) barrier_truth: Vec<f64>,
    pub(super) u: [f64; 2],
    pub(super) body_cmd: [f64; 2],
    /// The deciding policy stage; `None` for a law without a policy record.
    pub(super) decided_by: Option<&'static str>,
    pub(super) note: String,
    pub(super) attacks_active: Vec<bool>,
    pub(super) link_poses: Vec<(String, [f32; 3], [f32; 4])>,
    pub(super) events: Vec<String>,
    /// Contacts that began this step, with who moved.
    pub(super) contacts: Vec<crate::observe::Contact>,
}

impl StepView {
    /// Buffers for `sensors` channels, `filters` estimators, `barriers` and `attacks`.
    pub(super) fn new(sensors: usize, filters: usize, barriers: usize, attacks: usize) -> Self {
        let channel = ChannelView {
            clean: 0.0,
            received: 0.0,
            fresh: false,
            detector_z: f64::NAN,
            rejected: false,
        };
        let estimate = EstimateView {
            x: [0.0; 4],
            residue: 0.0,
            clf: 0.0,
            error_ratio: f64::NAN,
        };
        Self {
            truth: TruthState::default(),
            channels: vec![channel; sensors],
            estimates: vec![estimate; filters],
            barrier_values: Vec::new(),
            v_values: Vec::new(),
            barrier_truth: vec![0.0; barriers],
            u: [0.0; 2],
            body_cmd: [0.0; 2],
            decided_by: None,
            note: String::new(),
            attacks_active: vec![false; attacks],
            link_poses: Vec::new(),
            events: Vec::new(),
            contacts: Vec::new(),
        }
    }

    /// What arrived after the attacks, and the detector statistic of each fresh reading: the
    /// all-channel filter's normalised innovation before its update.
    pub(super) fn received(
        &mut self,
        samples: &[Sample],
        channel_of_sensor: &[Option<usize>],
        bank: Option<&EstimatorBank>,
    ) {
        for (si, (v, s)) in self.channels.iter_mut().zip(samples).enumerate() {
            v.received = s.value;
            v.fresh = s.fresh;
            v.detector_z = match (channel_of_sensor[si], bank) {
                (Some(c), Some(b)) if s.fresh => b
                    .predicted_measurement(b.baseline_index(), c)
                    .map_or(f64::NAN, |(mean, std)| (s.value - mean) / std),
                _ => f64::NAN,
            };
        }
    }

    /// Copies what the policy decided (or clears it for a law without a record); writes the
    /// decision's note only when `note` (a frame will show it).
    pub(super) fn decision(
        &mut self,
        record: Option<&ControlOutput>,
        filters: &[String],
        note: bool,
    ) {
        self.note.clear();
        self.barrier_values.clear();
        self.v_values.clear();
        self.decided_by = None;
        if let Some(out) = record {
            self.decided_by = Some(super::stage_name(&out.qp));
            self.barrier_values.extend_from_slice(&out.h_values);
            self.v_values.extend_from_slice(&out.v_values);
            if note {
                decision_note(&mut self.note, out, filters);
            }
        }
    }

    /// The estimators after the step (left as they were for a law without a bank).
    pub(super) fn estimates(&mut self, bank: Option<&EstimatorBank>, errors: &mut ErrorMeter) {
        let Some(bank) = bank else { return };
        let t = &self.truth;
        let truth = [t.x, t.y, t.vx, t.vy];
        for (i, f) in bank.filters().iter().enumerate() {
            let x = f.estimate();
            let x = [x[0], x[1], x[2], x[3]];
            self.estimates[i] = EstimateView {
                x,
                residue: f.residue_norm(),
                clf: self.v_values.get(i).copied().unwrap_or(f64::NAN),
                error_ratio: errors.observe(i, t.t, truth, x),
            };
        }
    }
}

/// Why constraints were dropped this step, and what was done when Step 3 did not help.
fn decision_note(note: &mut String, out: &ControlOutput, filters: &[String]) {
    let label = |i: usize| filters.get(i).map_or("?", |s| s.as_str());
    for d in &out.decision.decisions {
        let Verdict::Dropped { stage, reason } = d.verdict else {
            continue;
        };
        let who = label(d.unit);
        let why = match reason {
            DropReason::PairwiseDeviation {
                other,
                distance,
                theta,
                deviation_from_pair,
            } => format!(
                "‖x̂_{who} − x̂_{}‖ = {distance:.4} > θ = {theta:.4} and ‖x̂_{who} − x̂_pair‖ = {deviation_from_pair:.4} > θ/2",
                label(other)
            ),
            DropReason::SeparationIncrement {
                other,
                increment_distance,
                eta,
                increment_from_pair,
            } => format!(
                "over the last second ‖Δ(x̂_{who} − x̂_{})‖ = {increment_distance:.4} (conflict above η = {eta:.4}) and ‖Δ(x̂_{who} − x̂_pair)‖ = {increment_from_pair:.4} > η/2",
                label(other)
            ),
            DropReason::LargestResidue {
                residue,
                flagged,
                window_chi2,
                window_dof,
            } => format!(
                "largest residue score z = {residue:.3} (windowed χ² = {window_chi2:.2} on {window_dof} dof){}",
                if flagged { " (flagged: rejected reading)" } else { "" }
            ),
        };
        let _ = write!(note, "{who} dropped at {stage:?}: {why}; ");
    }
    if let Some(r) = out.decision.step2_retained {
        let _ = write!(
            note,
            "{} kept at Step2 although its pair test failed: it was the last estimator with barrier rows; ",
            label(r.unit)
        );
    }
    if let Some(u) = out.decision.step3_saturated {
        let _ = write!(
            note,
            "Step3 stopped: {}'s own barrier rows cannot be met within the input limit, so no estimator is dropped by residue (the fallback weighs them all); ",
            label(u)
        );
    }
    if out.decision.non_finite_rows > 0 {
        let _ = write!(
            note,
            "{} constraint row(s) not finite: treated as violated; ",
            out.decision.non_finite_rows
        );
    }
    if out.rejected.skipped_updates > 0 {
        let _ = write!(
            note,
            "{} reading(s) unusable (innovation variance not finite): filters flagged; ",
            out.rejected.skipped_updates
        );
    }
    if let QpOutcome::SafeStop { reason, .. } = &out.qp {
        let _ = write!(
            note,
            "safe stop: no evidence which estimator lies (scores {:.2} / {:.2} ≤ z = {:.2}), braking",
            reason.would_drop_key, reason.other_key, reason.evidence_z
        );
    }
    if let QpOutcome::InfeasibleAfterStep3 {
        action,
        max_cbf_violation,
    } = out.qp
    {
        let _ = write!(
            note,
            "infeasible after Step 3: safe action {action:?}, max CBF violation {max_cbf_violation:.4} m/s²"
        );
    }
}
