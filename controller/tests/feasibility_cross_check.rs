//! The geometric feasibility test of `feasibility.rs` against clarabel's own verdict, and the
//! policy that uses it against a reference cascade decided by clarabel's status alone (the
//! policy before the geometric test), on seeded random problems.

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
};
use ftcbf_controller::constraints::{CbfRow, ClfRow, HalfSpace};
use ftcbf_controller::feasibility::{check_half_spaces, Feasibility, Line, FEASIBILITY_TOL};
use ftcbf_controller::policy::{
    resolve, ConstraintKind, DecisionRecord, PolicyProblem, PolicyScratch, QpOutcome, Stage,
    Verdict,
};
use ftcbf_controller::qp::{QpResult, QpSolver, RowMode};
use ftcbf_controller::{Input, State};
use nalgebra::Matrix2;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Problems whose smallest achievable largest violation |φ| is below this (m/s²) are in the
/// boundary band, where either verdict is acceptable: clarabel's tolerances are 1e-8
/// (relative), the geometric test's [`FEASIBILITY_TOL`] = 1e-7 (relative), and on infeasible problems with φ up to ~4e-7
/// clarabel ends in InsufficientProgress (the policy's "not shown feasible").
const BAND: f64 = 1e-6;

/// A random row: unit-ish direction times a magnitude in [0.1, 10]; 25 % of the time parallel
/// or antiparallel to an earlier row.
fn random_row(rng: &mut ChaCha8Rng, earlier: &[HalfSpace]) -> HalfSpace {
    let mag = rng.random_range(0.1..10.0);
    let dir = if !earlier.is_empty() && rng.random_bool(0.25) {
        let e = earlier[rng.random_range(0..earlier.len())]
            .normal
            .normalize();
        if rng.random_bool(0.5) {
            e
        } else {
            -e
        }
    } else {
        let t: f64 = rng.random_range(0.0..std::f64::consts::TAU);
        Input::new(t.cos(), t.sin())
    };
    HalfSpace {
        normal: dir * mag,
        offset: rng.random_range(-3.0..3.0) * mag,
    }
}

/// φ = min over u (and the box, softened like the rows) of the largest scaled violation,
/// floored at −1: the LP `min s` s.t. `a_i·u − s ≤ b_i`, `±u_k − s ≤ L_k`, `s ≥ −1`.
fn phi(rows: &[HalfSpace], limit: Option<Input>) -> f64 {
    let mut a: Vec<[f64; 3]> = rows
        .iter()
        .map(|h| {
            let l = Line::from_half_space(h);
            [l.a[0], l.a[1], -1.0]
        })
        .collect();
    let mut b: Vec<f64> = rows.iter().map(|h| Line::from_half_space(h).b).collect();
    if let Some(l) = limit {
        for (row, lim) in [
            ([1.0, 0.0, -1.0], l[0]),
            ([-1.0, 0.0, -1.0], l[0]),
            ([0.0, 1.0, -1.0], l[1]),
            ([0.0, -1.0, -1.0], l[1]),
        ] {
            a.push(row);
            b.push(lim);
        }
    }
    a.push([0.0, 0.0, -1.0]);
    b.push(1.0);
    let m = a.len();
    let colptr: Vec<usize> = (0..=3).map(|c| c * m).collect();
    let rowval: Vec<usize> = (0..3).flat_map(|_| 0..m).collect();
    let nz: Vec<f64> = (0..3).flat_map(|c| a.iter().map(move |r| r[c])).collect();
    let amat = CscMatrix::new(m, 3, colptr, rowval, nz);
    let p = CscMatrix::new(3, 3, vec![0, 0, 0, 0], vec![], vec![]);
    let mut settings = DefaultSettingsBuilder::default()
        .build()
        .expect("default settings");
    settings.verbose = false;
    settings.presolve_enable = false;
    let mut s = DefaultSolver::new(
        &p,
        &[0.0, 0.0, 1.0],
        &amat,
        &b,
        &[SupportedConeT::NonnegativeConeT(m)],
        settings,
    )
    .expect("LP");
    s.solve();
    assert!(
        matches!(s.solution.status, SolverStatus::Solved),
        "φ LP: {:?}",
        s.solution.status
    );
    s.solution.x[2]
}

#[test]
fn geometric_test_agrees_with_clarabel_outside_the_boundary_band() {
    let mut rng = ChaCha8Rng::seed_from_u64(2024);
    let mut lines = Vec::new();
    let (mut feasible, mut infeasible, mut band) = (0, 0, 0);
    let (mut band_changes, mut band_extra_solves) = (0, 0);
    let (mut boxed, mut near, mut band_failures) = (0, 0, 0);
    for case in 0..3000 {
        let k = rng.random_range(1..=7);
        let mut rows: Vec<HalfSpace> = Vec::new();
        for _ in 0..k {
            let r = random_row(&mut rng, &rows);
            rows.push(r);
        }
        let limit = if rng.random_bool(0.5) {
            boxed += 1;
            Some(Input::new(
                rng.random_range(0.5..3.0),
                rng.random_range(0.5..3.0),
            ))
        } else {
            None
        };
        // a third of the problems are pushed onto the boundary: shift every offset so that
        // φ becomes ±10^(−10 .. −3) (log-uniform), a thin margin on either side of it
        if rng.random_bool(0.33) {
            let f = phi(&rows, limit);
            if f > -1.0 {
                let target = 10f64.powf(rng.random_range(-10.0..-3.0))
                    * if rng.random_bool(0.5) { 1.0 } else { -1.0 };
                for h in rows.iter_mut() {
                    let n = h.normal.norm();
                    h.offset += (f - target) * n;
                }
                near += 1;
            }
        }
        let f = phi(&rows, limit);
        let geo = check_half_spaces(&rows, &[], limit, &mut lines);
        let mut qp = QpSolver::new(rows.len(), 0, Matrix2::identity(), 1e4, limit);
        // clarabel's verdict; None: neither solved nor certified infeasible
        let clar = match qp.solve(&rows, RowMode::Hard, &[], RowMode::Hard) {
            QpResult::Feasible { .. } => Some(true),
            QpResult::Infeasible { .. } => Some(false),
            QpResult::SolverFailure { .. } => None,
            other => panic!("case {case}: {other:?}"),
        };
        if let Feasibility::Feasible { witness } = geo {
            // a feasible answer is a certificate: every row holds to the stated tolerance
            let mut scale = rows
                .iter()
                .map(|h| Line::from_half_space(h).b.abs())
                .fold(1.0_f64, f64::max);
            if let Some(lim) = limit {
                scale = scale.max(lim.amax());
            }
            for h in &rows {
                let l = Line::from_half_space(h);
                let r = l.violation([witness[0], witness[1]]);
                assert!(r <= FEASIBILITY_TOL * scale + 1e-13, "case {case}: {r:e}");
            }
            if let Some(lim) = limit {
                assert!(witness[0].abs() <= lim[0] + 1e-9 && witness[1].abs() <= lim[1] + 1e-9);
            }
        }
        if f.abs() <= BAND {
            band += 1;
            // the policy before treated a failure as "not shown feasible"; the policy now
            // still solves when the test says feasible, so only (infeasible, Solved) changes
            // a decision
            match (geo.is_feasible(), clar) {
                (false, Some(true)) => band_changes += 1,
                (true, Some(false) | None) => band_extra_solves += 1,
                _ => {}
            }
            if clar.is_none() {
                band_failures += 1;
            }
            continue;
        }
        assert_eq!(
            Some(geo.is_feasible()),
            clar,
            "case {case}: φ = {f:e}, geometric {geo:?}, limit {limit:?}, rows {rows:?}"
        );
        assert_eq!(geo.is_feasible(), f < 0.0, "case {case}: φ = {f:e}");
        if geo.is_feasible() {
            feasible += 1;
        } else {
            infeasible += 1;
        }
    }
    eprintln!(
        "3000 problems ({boxed} boxed, {near} pushed to |φ| ≤ 1e-3): {feasible} feasible, \
         {infeasible} infeasible agree; {band} in the band |φ| ≤ {BAND:e} (clarabel failed on \
         {band_failures}; test infeasible / clarabel solved: {band_changes}; test feasible / \
         clarabel not: {band_extra_solves})"
    );
    assert!(
        feasible > 600 && infeasible > 600,
        "{feasible} / {infeasible}"
    );
    assert_eq!(feasible + infeasible + band, 3000);
    // the band was probed; inside it the test leans to "feasible" (its tolerance is 10×
    // clarabel's), so a decision can change only when clarabel solves a set the test
    // rejects, which must stay rare (0 of 202 with this seed); the other direction costs one
    // solve and reproduces the old decision
    assert!(band >= 100, "{band}");
    assert!(band_changes * 50 <= band, "{band_changes} of {band}");
}

/// The cascade of `policy.rs` with clarabel's status deciding every stage (the policy before
/// the geometric test). Returns (stage, u, per-unit drop stage, clf_relaxed, solves).
fn reference(
    p: &PolicyProblem,
    qp: &mut QpSolver,
) -> (Stage, Input, Vec<Option<Stage>>, bool, u32) {
    let units = p.units();
    let nb = p.barriers();
    let mut alive = vec![true; units];
    let mut dropped = vec![None; units];
    let rows = |alive: &[bool]| {
        let mut cbf = Vec::new();
        let mut clf = Vec::new();
        for i in (0..units).filter(|&i| alive[i]) {
            for b in 0..nb {
                if p.cbf_active[i * nb + b] {
                    cbf.push(p.cbf[i * nb + b].half_space());
                }
            }
            if p.use_clf && p.clf_active[i] {
                clf.push(p.clf[i].half_space());
            }
        }
        (cbf, clf)
    };
    let mut solves = 0;
    let (mut cbf, mut clf) = rows(&alive);
    let mut stage = Stage::Step1;
    let mut relaxed = false;
    solves += 1;
    let mut r = qp.solve(&cbf, RowMode::Hard, &clf, RowMode::Hard);
    let ok = |r: &QpResult| matches!(r, QpResult::Feasible { .. });
    if !ok(&r) && units > 1 {
        stage = Stage::Step2;
        let mut any = false;
        for i in 0..units {
            for j in (i + 1)..units {
                let theta = p.theta[(i, j)];
                let d = (p.estimates[i] - p.estimates[j]).norm();
                if d.is_nan() || d <= theta {
                    continue;
                }
                let pair = p.pair_estimates[(i, j)];
                for a in [i, j] {
                    if (p.estimates[a] - pair).norm() > theta / 2.0 && alive[a] {
                        alive[a] = false;
                        dropped[a] = Some(Stage::Step2);
                        any = true;
                    }
                }
            }
        }
        // Step 2 keeps the last unit with CBF rows (the one Step 3 would keep: smallest
        // residue key, then lowest index), as Step 3 does (issue 16).
        let has_cbf = |i: usize| (0..nb).any(|b| p.cbf_active[i * nb + b]);
        if (0..units).any(has_cbf) && !(0..units).any(|i| alive[i] && has_cbf(i)) {
            if let Some(k) = (0..units)
                .filter(|&i| has_cbf(i))
                .min_by(|&a, &b| p.residue_key[a].total_cmp(&p.residue_key[b]))
            {
                alive[k] = true;
                dropped[k] = None;
            }
        }
        if any {
            (cbf, clf) = rows(&alive);
            solves += 1;
            r = qp.solve(&cbf, RowMode::Hard, &clf, RowMode::Hard);
        }
    }
    if !ok(&r) && !clf.is_empty() {
        stage = Stage::ClfRelaxation;
        relaxed = true;
        solves += 1;
        r = qp.solve(&cbf, RowMode::Hard, &clf, RowMode::Soft);
    }
    if !ok(&r) && units > 1 {
        loop {
            let cands: Vec<usize> = (0..units)
                .filter(|&i| alive[i] && (0..nb).any(|b| p.cbf_active[i * nb + b]))
                .collect();
            if cands.len() <= 1 {
                break;
            }
            let mut w = cands[0];
            for &i in &cands[1..] {
                if p.residue_key[i] > p.residue_key[w] {
                    w = i;
                }
            }
            stage = Stage::Step3;
            alive[w] = false;
            dropped[w] = Some(Stage::Step3);
            (cbf, clf) = rows(&alive);
            relaxed = !clf.is_empty();
            solves += 1;
            r = qp.solve(&cbf, RowMode::Hard, &clf, RowMode::Soft);
            if ok(&r) {
                break;
            }
        }
    }
    let u = match r {
        QpResult::Feasible { u, .. } => u,
        _ => {
            stage = Stage::Fallback;
            solves += 1;
            match qp.solve(&cbf, RowMode::Soft, &[], RowMode::Hard) {
                QpResult::Feasible { u, .. } => u,
                other => panic!("reference fallback {other:?}"),
            }
        }
    };
    (stage, u, dropped, relaxed, solves)
}

fn random_policy_problem(rng: &mut ChaCha8Rng) -> (PolicyProblem, Option<Input>) {
    let units = rng.random_range(2..=3);
    let nb = rng.random_range(1..=2);
    let mut p = PolicyProblem::new(units, nb);
    for k in 0..units * nb {
        let t: f64 = rng.random_range(0.0..std::f64::consts::TAU);
        let mag = rng.random_range(0.1..3.0);
        p.cbf[k] = CbfRow {
            lambda: Input::new(t.cos(), t.sin()) * mag,
            omega_bar: rng.random_range(-2.0..2.5) * mag,
            h: 0.0,
            h_hat: rng.random_range(0.0..1.0),
        };
        p.cbf_active[k] = rng.random_bool(0.8);
    }
    p.use_clf = rng.random_bool(0.7);
    for i in 0..units {
        let t: f64 = rng.random_range(0.0..std::f64::consts::TAU);
        let mag = rng.random_range(0.1..1e3);
        p.clf[i] = ClfRow {
            lg_v: Input::new(t.cos(), t.sin()) * mag,
            tau_bar: rng.random_range(-2.0..1.0) * mag,
            v: 1.0,
        };
        p.clf_active[i] = rng.random_bool(0.8);
        p.estimates[i] = State::new(
            rng.random_range(-0.1..0.1),
            rng.random_range(-0.1..0.1),
            0.0,
            0.0,
        );
        p.residue_key[i] = if rng.random_bool(0.1) {
            f64::INFINITY
        } else {
            rng.random_range(0.0..10.0)
        };
        p.flagged[i] = p.residue_key[i].is_infinite();
    }
    // Every ordered (i, j) draws an estimate and a θ, as when these were dense i·units + j
    // arrays (the same problems for the same seed): a pair keeps the estimate drawn at i < j
    // and the θ drawn at i > j, the last written there.
    for i in 0..units {
        for j in 0..units {
            let mid = (p.estimates[i] + p.estimates[j]) / 2.0;
            let pair = mid
                + State::new(
                    rng.random_range(-0.02..0.02),
                    rng.random_range(-0.02..0.02),
                    0.0,
                    0.0,
                );
            let t = rng.random_range(0.02..0.2);
            if i < j {
                p.pair_estimates[(i, j)] = pair;
            } else if i > j {
                p.theta[(i, j)] = t;
            }
        }
    }
    let limit = if rng.random_bool(0.6) {
        Some(Input::new(2.0, 2.0))
    } else {
        None
    };
    (p, limit)
}

#[test]
fn policy_decides_exactly_as_the_clarabel_only_cascade() {
    let mut rng = ChaCha8Rng::seed_from_u64(77);
    let mut stages = [0usize; 5];
    let (mut old_solves, mut new_solves) = (0u64, 0u64);
    for case in 0..2000 {
        let (p, limit) = random_policy_problem(&mut rng);
        let (units, nb) = (p.units(), p.barriers());
        let mut qp_ref = QpSolver::new(units * nb, units, Matrix2::identity(), 1e4, limit);
        let (stage, u_ref, dropped, relaxed, solves) = reference(&p, &mut qp_ref);
        let mut qp = QpSolver::new(units * nb, units, Matrix2::identity(), 1e4, limit);
        let mut s = PolicyScratch::new(units, nb);
        let mut rec = DecisionRecord::with_capacity(units * (nb + 1));
        let (u, outcome) = resolve(&p, &mut qp, &mut s, &mut rec);
        assert_eq!(rec.stage, stage, "case {case}");
        assert_eq!(rec.solver_failures, 0, "case {case}");
        assert_eq!(rec.feasibility_disagreements, 0, "case {case}");
        assert!(
            (u - u_ref).norm() <= 1e-9 * (1.0 + u_ref.norm()),
            "case {case}: {u} vs {u_ref}"
        );
        for (i, d) in dropped.iter().enumerate() {
            for dec in rec.decisions.iter().filter(|d| d.unit == i) {
                match (dec.verdict, d) {
                    (Verdict::Dropped { stage, .. }, Some(st)) => assert_eq!(stage, *st),
                    (Verdict::Dropped { .. }, None) => panic!("case {case}: unit {i} dropped"),
                    (Verdict::Inactive(_), _) => {}
                    (v, Some(_)) => panic!("case {case}: unit {i} should be dropped, {v:?}"),
                    (Verdict::Relaxed, None) => assert!(
                        stage == Stage::Fallback || (relaxed && dec.kind == ConstraintKind::Clf),
                        "case {case}"
                    ),
                    (Verdict::Kept, None) => assert!(
                        stage != Stage::Fallback && !(relaxed && dec.kind == ConstraintKind::Clf),
                        "case {case}"
                    ),
                }
            }
        }
        match outcome {
            QpOutcome::Feasible {
                stage: st,
                clf_relaxed,
                ..
            } => {
                assert_eq!(st, stage, "case {case}");
                assert_eq!(clf_relaxed, relaxed, "case {case}");
            }
            QpOutcome::InfeasibleAfterStep3 { .. } => assert_eq!(stage, Stage::Fallback),
            QpOutcome::SafeStop { .. } => panic!("case {case}: the paper's Step 3 never stops"),
        }
        // one clarabel solve per step: the deciding stage's (or the fallback's)
        assert!(rec.qp_solves <= solves, "case {case}");
        assert_eq!(rec.qp_solves, 1, "case {case}");
        stages[stage as usize] += 1;
        old_solves += solves as u64;
        new_solves += rec.qp_solves as u64;
    }
    eprintln!(
        "2000 policy problems: stages [Step1, Step2, ClfRelaxation, Step3, Fallback] = \
         {stages:?}; clarabel solves {old_solves} (status decides) → {new_solves} (geometric test decides)"
    );
    // every stage is exercised
    assert!(stages.iter().all(|&n| n >= 20), "{stages:?}");
    assert!(new_solves < old_solves);
}
