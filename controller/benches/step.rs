//! One full control step (bank predict + update of every filter, constraint rows, policy,
//! QP solves) for m = 2 (the paper's study: 2 single-drop filters, 1 pair filter, baseline)
//! and m = 3 (3 + 3 pair filters + baseline).
//!
//! Two scenarios per m, both with the paper's constant attack (+1 on y4):
//! * `static`: readings of a robot at rest at (0.5, 0); Step 1 decides (1 QP solve).
//! * `closed_loop`: the paper's study — the truth follows eq. 6.2 with process noise 1e-3·I
//!   (Euler–Maruyama, one step per control period) under the controller's input from
//!   x0 = (1, 0, 0, 0), measurements with variance 1e-3 (seeded ChaCha8), restarted every
//!   30 s; the stage mix, the clarabel solves per step (feasibility is decided by the
//!   geometric test of `feasibility.rs`, so one solve per step) and the solver failures /
//!   test–solver disagreements are printed before measuring. The time includes the
//!   simulation of truth and readings (a few hundred ns).
//!
//! `closed_loop_safety_filter`: the same closed loop in the safety-filter form (a path tracker
//! proposes u_nom; min ‖u − u_nom‖² over the CBF rows, no CLF rows).
//!
//! `step_m2_clutter_N` (issue #52): the m = 2 closed loop with N barriers, the floor half-plane
//! and N − 1 discs of radius 0.1 m at least 3 m from the path, δ = ∞ (every row imposed at
//! every step, as in a world without `delta`), the discs in an
//! [`ftcbf_controller::ellipse_index::EllipseIndex`] as a user of the library would put them:
//! a far obstacle should cost next to nothing. Target: N = 200 within 1.5× of N = 2.
//! `step_m2_clutter_200_unindexed`: the same 200 barriers without the index (every row built).
//!
//! Plus `feasibility_m3_infeasible`: the geometric test alone on an infeasible m = 3 set
//! (6 rows + box, every vertex enumerated: its worst case).

use std::hint::black_box;
use std::sync::Arc;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion};
use ftcbf_controller::barrier::{Barrier, EllipsoidOutside, HalfPlane};
use ftcbf_controller::constraints::HalfSpace;
use ftcbf_controller::ellipse_index::EllipseIndex;
use ftcbf_controller::feasibility::check_half_spaces;
use ftcbf_controller::params::FtParams;
use ftcbf_controller::{
    ClfConfig, Controller, ControllerConfig, Input, LinearModel, ProblemForm, QpOutcome,
    QuadraticClf, State, StateMatrix, TrackerConfig,
};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

const DT: f64 = 0.01;

fn controller(patterns: Vec<Vec<usize>>) -> Controller {
    controller_in(patterns, ProblemForm::Paper)
}

/// The same controller in the safety-filter form: a path tracker to the goal (the origin)
/// proposes u_nom, no CLF rows.
fn safety_filter(patterns: Vec<Vec<usize>>) -> Controller {
    let tracker = TrackerConfig::turtlebot([0.0, 0.0], 0.05, None);
    controller_in(
        patterns,
        ProblemForm::SafetyFilter {
            tracker,
            clf: false,
        },
    )
}

fn controller_in(patterns: Vec<Vec<usize>>, form: ProblemForm) -> Controller {
    let m = patterns.len();
    let model = LinearModel::paper_double_integrator(1e-3, 1e-3).expect("model");
    // V̄ as in tests/paper_study.rs: the largest level set inside the ball of radius d/2.
    let probe = QuadraticClf::new(
        &model.f,
        &model.g,
        State::zeros(),
        0.05,
        &ClfConfig::paper(0.0),
    )
    .expect("clf");
    Controller::new(
        ControllerConfig::builder(
            LinearModel::paper_double_integrator(1e-3, 1e-3).expect("model"),
            patterns,
            FtParams::uniform(m, 0.001, 0.045),
        )
        .barriers(vec![Arc::new(HalfPlane::new(
            "h",
            State::new(0.0, 1.0, 0.0, 0.2),
            -0.05,
        ))])
        .goal(State::zeros(), 0.05)
        .delta(1.0)
        .clf(ClfConfig::paper(probe.v_bar_inside_ball(0.025)))
        .input_limit(Input::new(2.0, 2.0))
        .start(
            State::new(1.0, 0.0, 0.0, 0.0),
            StateMatrix::identity() * 1e-3,
        )
        .form(form)
        .build(),
    )
    .expect("config")
}

/// The m = 2 paper-form controller with the floor and `n − 1` far discs, δ = ∞, the discs in
/// an [`EllipseIndex`] when `indexed`.
fn clutter(patterns: Vec<Vec<usize>>, n: usize, indexed: bool) -> Controller {
    let m = patterns.len();
    let model = LinearModel::paper_double_integrator(1e-3, 1e-3).expect("model");
    let probe = QuadraticClf::new(
        &model.f,
        &model.g,
        State::zeros(),
        0.05,
        &ClfConfig::paper(0.0),
    )
    .expect("clf");
    let discs: Vec<EllipsoidOutside> = (0..n.saturating_sub(1))
        .map(|i| {
            let (col, row) = (i % 20, i / 20);
            let y = (3.5 + 0.5 * (row / 2) as f64) * if row % 2 == 0 { 1.0 } else { -1.0 };
            EllipsoidOutside::disc(format!("c{i}"), -2.0 + 0.4 * col as f64, y, 0.1)
        })
        .collect();
    // The floor first, then the discs at positions 1..n.
    let index = EllipseIndex::new(n, discs.iter().enumerate().map(|(i, d)| (i + 1, d)))
        .expect("planar discs");
    let mut barriers: Vec<Arc<dyn Barrier>> = vec![Arc::new(HalfPlane::new(
        "h",
        State::new(0.0, 1.0, 0.0, 0.2),
        -0.05,
    ))];
    barriers.extend(discs.into_iter().map(|d| Arc::new(d) as Arc<dyn Barrier>));
    let mut builder =
        ControllerConfig::builder(model, patterns, FtParams::uniform(m, 0.001, 0.045))
            .barriers(barriers);
    if indexed {
        builder = builder.barrier_index(Arc::new(index));
    }
    Controller::new(
        builder
            .goal(State::zeros(), 0.05)
            .clf(ClfConfig::paper(probe.v_bar_inside_ball(0.025)))
            .input_limit(Input::new(2.0, 2.0))
            .start(
                State::new(1.0, 0.0, 0.0, 0.0),
                StateMatrix::identity() * 1e-3,
            )
            .build(),
    )
    .expect("config")
}

/// Builds a controller for fault patterns.
type Make = fn(Vec<Vec<usize>>) -> Controller;

fn clutter_2(patterns: Vec<Vec<usize>>) -> Controller {
    clutter(patterns, 2, true)
}

fn clutter_200(patterns: Vec<Vec<usize>>) -> Controller {
    clutter(patterns, 200, true)
}

fn clutter_200_unindexed(patterns: Vec<Vec<usize>>) -> Controller {
    clutter(patterns, 200, false)
}

fn bench_clutter(c: &mut Criterion) {
    let make: [(&str, Make); 3] = [
        ("2", clutter_2),
        ("200", clutter_200),
        ("200_unindexed", clutter_200_unindexed),
    ];
    for (n, make) in make {
        let mut cl = ClosedLoop::new(vec![vec![1], vec![3]], make);
        for _ in 0..300 {
            cl.step();
        }
        c.bench_function(&format!("step_m2_clutter_{n}"), |b| {
            b.iter(|| black_box(cl.step().0))
        });
    }
}

/// Closed loop: truth + controller, restarted every 3000 steps.
struct ClosedLoop {
    model: LinearModel,
    patterns: Vec<Vec<usize>>,
    make: fn(Vec<Vec<usize>>) -> Controller,
    ctrl: Controller,
    x: State,
    k: usize,
    rng: ChaCha8Rng,
}

impl ClosedLoop {
    fn new(patterns: Vec<Vec<usize>>, make: fn(Vec<Vec<usize>>) -> Controller) -> Self {
        Self {
            model: LinearModel::paper_double_integrator(1e-3, 1e-3).expect("model"),
            ctrl: make(patterns.clone()),
            patterns,
            make,
            x: State::new(1.0, 0.0, 0.0, 0.0),
            k: 0,
            rng: ChaCha8Rng::seed_from_u64(5),
        }
    }
    fn readings(&mut self) -> [f64; 6] {
        let mut y = [0.0; 6];
        for (c, yc) in y.iter_mut().enumerate() {
            let v: f64 = StandardNormal.sample(&mut self.rng);
            *yc = self.model.measure(c, &self.x) + 1e-3f64.sqrt() * v;
        }
        y[3] += 1.0;
        y
    }
    fn step(&mut self) -> (Input, QpOutcome, [u32; 3]) {
        self.k += 1;
        if self.k.is_multiple_of(3000) {
            self.ctrl = (self.make)(self.patterns.clone());
            self.x = State::new(1.0, 0.0, 0.0, 0.0);
        }
        let y = self.readings();
        let out = self.ctrl.step(&y, &[true; 6], DT);
        let d = &out.decision;
        let (u, qp) = (out.u, out.qp);
        let counts = [d.qp_solves, d.solver_failures, d.feasibility_disagreements];
        self.x = self
            .model
            .euler_maruyama_step(&self.x, &u, DT, &State::zeros());
        (u, qp, counts)
    }
}

fn bench_step(c: &mut Criterion) {
    for (m, patterns) in [
        (2, vec![vec![1], vec![3]]),
        (3, vec![vec![1], vec![3], vec![5]]),
    ] {
        let mut ctrl = controller(patterns.clone());
        let y = [0.5, 0.5, 0.0, 1.0, 0.0, 0.0];
        for _ in 0..300 {
            ctrl.step(&y, &[true; 6], DT);
        }
        c.bench_function(&format!("step_m{m}_static"), |b| {
            b.iter(|| black_box(ctrl.step(black_box(&y), &[true; 6], DT).u))
        });

        let mut cl = ClosedLoop::new(patterns.clone(), controller);
        let mut mix = [0usize; 5];
        let mut counts = [0u64; 3];
        for _ in 0..3000 {
            let (_, qp, s) = cl.step();
            for (c, v) in counts.iter_mut().zip(s) {
                *c += v as u64;
            }
            let i = match qp {
                QpOutcome::Feasible { stage, .. } => stage as usize,
                QpOutcome::InfeasibleAfterStep3 { .. } | QpOutcome::SafeStop { .. } => 4,
            };
            mix[i] += 1;
        }
        eprintln!(
            "m = {m} closed loop, 3000 steps: stages [Step1, Step2, ClfRelaxation, Step3, Fallback] = {mix:?}, {:.2} clarabel solves/step, {} solver failures, {} disagreements",
            counts[0] as f64 / 3000.0,
            counts[1],
            counts[2]
        );
        c.bench_function(&format!("step_m{m}_closed_loop"), |b| {
            b.iter(|| black_box(cl.step().0))
        });
        // The safety-filter form (issue #11: ≤ 40 µs for m = 2): tracker + QP with a reference.
        let mut sf = ClosedLoop::new(patterns, safety_filter);
        let mut solves = 0u64;
        for _ in 0..3000 {
            solves += u64::from(sf.step().2[0]);
        }
        eprintln!(
            "m = {m} closed loop, safety-filter form: {:.2} clarabel solves/step",
            solves as f64 / 3000.0
        );
        c.bench_function(&format!("step_m{m}_closed_loop_safety_filter"), |b| {
            b.iter(|| black_box(sf.step().0))
        });
    }
}

fn bench_feasibility(c: &mut Criterion) {
    // three units' CBF rows u_y ≥ 0.5 − 0.1k tilted, CLF rows pulling u_y ≤ −1: infeasible
    let mut rows = Vec::new();
    for k in 0..3 {
        let t = 0.1 * k as f64;
        rows.push(HalfSpace {
            normal: Input::new(t.sin(), -t.cos()),
            offset: -(0.5 - 0.1 * k as f64),
        });
    }
    let clf: Vec<HalfSpace> = (0..3)
        .map(|k| HalfSpace {
            normal: Input::new(0.05 * k as f64, 1.0) * 1e3,
            offset: -1e3,
        })
        .collect();
    let mut lines = Vec::with_capacity(6);
    let limit = Some(Input::new(2.0, 2.0));
    assert!(!check_half_spaces(&rows, &clf, limit, &mut lines).is_feasible());
    c.bench_function("feasibility_m3_infeasible", |b| {
        b.iter(|| {
            black_box(check_half_spaces(
                black_box(&rows),
                black_box(&clf),
                limit,
                &mut lines,
            ))
        })
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().measurement_time(Duration::from_secs(3)).warm_up_time(Duration::from_secs(1));
    targets = bench_step, bench_clutter, bench_feasibility
}
criterion_main!(benches);
