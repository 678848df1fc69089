//! "No heap allocation per step outside clarabel": a counting global allocator (this test
//! binary only) measures the allocations of a bare clarabel solve through [`QpSolver`] and of
//! full control steps, and asserts that a step allocates exactly what its QP solves do.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use ftcbf_controller::constraints::HalfSpace;
use ftcbf_controller::qp::{QpSolver, RowMode};
use ftcbf_controller::{Controller, Input};
use nalgebra::Matrix2;

mod common;

struct Counting;
static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

// SAFETY: forwards to the system allocator unchanged; only counts calls.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn count() -> usize {
    ALLOCATIONS.load(Ordering::Relaxed)
}

#[test]
fn a_step_allocates_only_inside_clarabel() {
    // allocations of one reused clarabel solve
    let mut qp = QpSolver::new(2, 2, Matrix2::identity(), 1e4, Some(Input::new(2.0, 2.0)));
    let rows = [HalfSpace {
        normal: Input::new(0.0, -1.0),
        offset: -0.5,
    }];
    qp.solve(&rows, RowMode::Hard, &[], RowMode::Hard);
    let before = count();
    for _ in 0..100 {
        qp.solve(&rows, RowMode::Hard, &[], RowMode::Hard);
    }
    let per_solve = (count() - before) / 100;

    for attack in [0.0, 1.0] {
        let mut c = Controller::new(common::small_config()).expect("config");
        // a few rejected readings too: the rejection path must not allocate either
        let y = [0.5, 0.5, 0.0, attack, 0.0, f64::NAN];
        for _ in 0..300 {
            c.step(&y, &[true; 6], 0.01);
        }
        let before = count();
        let mut solves = 0usize;
        for _ in 0..200 {
            solves += c.step(&y, &[true; 6], 0.01).decision.qp_solves as usize;
        }
        let allocated = count() - before;
        assert_eq!(
            allocated,
            solves * per_solve,
            "attack {attack}: {allocated} allocations for {solves} QP solves ({per_solve} each)"
        );
    }
}
