//! The QP leaves out the rows the input box satisfies when there are more than it was built
//! for (issue #52): the solution is that of the rows that can bind, and it grows only when
//! those do not fit.

use ftcbf_controller::constraints::HalfSpace;
use ftcbf_controller::qp::{QpResult, QpSolver, RowMode, COMPACT_CBF_ROWS, COMPACT_START_ROWS};
use ftcbf_controller::Input;
use nalgebra::Matrix2;

fn solver(capacity: usize) -> QpSolver {
    QpSolver::new(
        capacity,
        1,
        Matrix2::identity(),
        1e3,
        Some(Input::new(1.0, 1.0)),
    )
}

fn u_of(r: QpResult) -> Input {
    match r {
        QpResult::Feasible { u, .. } => u,
        other => panic!("not solved: {other:?}"),
    }
}

/// Rows `n·u ≤ o` with the reference (2, 0.5) outside them: the first two bind.
fn binding() -> Vec<HalfSpace> {
    vec![
        HalfSpace {
            normal: Input::new(1.0, 0.2),
            offset: 0.3,
        },
        HalfSpace {
            normal: Input::new(0.3, 1.0),
            offset: 0.2,
        },
    ]
}

/// A far obstacle's row: its offset beyond what the box |u| ≤ 1 reaches.
fn far(k: usize) -> HalfSpace {
    let a = 0.37 * k as f64;
    HalfSpace {
        normal: Input::new(a.cos(), a.sin()) * (1.0 + k as f64),
        offset: (1.0 + k as f64) * (1.5 + 0.01 * k as f64),
    }
}

#[test]
fn far_rows_are_left_out_and_change_nothing() {
    let n = 10 * COMPACT_CBF_ROWS;
    let mut big = solver(n);
    big.set_reference(Input::new(2.0, 0.5));
    let mut rows = binding();
    rows.extend((0..n - 2).map(far));
    assert!(rows[2..].iter().all(|h| big.box_satisfies(h)));
    assert!(!big.box_satisfies(&rows[0]) && !big.box_satisfies(&rows[1]));
    let u = u_of(big.solve(&rows, RowMode::Hard, &[], RowMode::Soft));
    // built once, for COMPACT_START_ROWS rows, not for n
    assert_eq!(big.counters(), (1, 1));
    assert_eq!(big.rows(), COMPACT_START_ROWS + 1 + 5);
    let mut small = solver(2);
    small.set_reference(Input::new(2.0, 0.5));
    let v = u_of(small.solve(&binding(), RowMode::Hard, &[], RowMode::Soft));
    // the same problem: the same solution within clarabel's tolerance (1e-8)
    assert!((u - v).norm() < 1e-6, "{u} vs {v}");
    for h in &rows {
        assert!(h.violation(&u) <= 1e-7, "row {h:?} violated at {u}");
    }
}

#[test]
fn rows_that_can_bind_make_the_solver_grow_and_are_all_imposed() {
    let n = 3 * COMPACT_CBF_ROWS;
    let mut qp = solver(n);
    qp.set_reference(Input::new(2.0, 2.0));
    // n rows tangent to the circle of radius 0.5: none is satisfied by the whole box
    let rows: Vec<HalfSpace> = (0..n)
        .map(|k| {
            let a = 0.8 * k as f64 / n as f64;
            HalfSpace {
                normal: Input::new(a.cos(), a.sin()),
                offset: 0.5,
            }
        })
        .collect();
    assert!(rows.iter().all(|h| !qp.box_satisfies(h)));
    let u = u_of(qp.solve(&rows, RowMode::Hard, &[], RowMode::Soft));
    assert!(qp.rows() >= n + 1 + 5, "solver holds {} rows", qp.rows());
    for h in &rows {
        assert!(h.violation(&u) <= 1e-7, "row {h:?} violated at {u}");
    }
    assert!(u.norm() > 0.45, "the reference's pull lost: {u}");
    // more rows than the limit are still refused
    let mut too_many = rows.clone();
    too_many.push(rows[0]);
    assert!(matches!(
        qp.solve(&too_many, RowMode::Hard, &[], RowMode::Soft),
        QpResult::TooManyRows { .. }
    ));
}

#[test]
fn a_row_is_never_left_out_without_a_box_or_when_not_finite() {
    let boxed = solver(4);
    let nan = HalfSpace {
        normal: Input::new(f64::NAN, 0.0),
        offset: 10.0,
    };
    let inf = HalfSpace {
        normal: Input::new(1.0, 0.0),
        offset: f64::INFINITY,
    };
    assert!(!boxed.box_satisfies(&nan));
    assert!(!boxed.box_satisfies(&inf));
    assert!(boxed.box_satisfies(&far(3)));
    let unboxed = QpSolver::new(4, 1, Matrix2::identity(), 1e3, None);
    assert!(!unboxed.box_satisfies(&far(3)));
    // on the box's corner exactly: kept (it could be active there)
    let corner = HalfSpace {
        normal: Input::new(1.0, 1.0),
        offset: 2.0,
    };
    assert!(!boxed.box_satisfies(&corner));
}

#[test]
fn a_solver_for_few_rows_holds_them_all() {
    // up to COMPACT_CBF_ROWS possible rows (every catalogue world): built for all of them, so
    // those worlds solve row for row as before compaction existed
    assert_eq!(solver(COMPACT_CBF_ROWS).rows(), COMPACT_CBF_ROWS + 1 + 5);
    assert_eq!(
        solver(COMPACT_CBF_ROWS + 1).rows(),
        COMPACT_START_ROWS + 1 + 5
    );
}
