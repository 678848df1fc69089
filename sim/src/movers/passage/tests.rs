//! Tests of the search with movers ([`super`]).

use super::*;
use crate::obstacles::{MotionSpec, RepeatSpec};
use ftcbf_controller::{EllipsoidOutside, HalfPlane, MovingBarrier};
use std::sync::Arc;

/// A cart going up and down the robot's path between x = 1 and x = 4 at 0.1 m/s, kept
/// 0.3 m from (a disc barrier, γ = 0), with the robot's path along y = 0 from x = 0 to its
/// goal at x = 5.
fn cart() -> (ObstacleSpec, MovingBarrier) {
    let mut spec = crate::movers::fleet::tests::spec(MotionSpec::Waypoints {
        points: vec![[1.0, 0.0]],
        speed: 0.1,
        repeat: RepeatSpec::Reverse,
        start: 0.0,
    });
    spec.position = [4.0, 0.0, 0.2];
    let base = Arc::new(EllipsoidOutside::disc("cart", 4.0, 0.0, 0.3));
    (spec, MovingBarrier::new(base, 0))
}

fn inputs() -> PassInputs<'static> {
    PassInputs {
        statics: Vec::new(),
        rest: Rest {
            gamma: 0.0,
            rows: None,
        },
        n_movers: 1,
        v_max: 0.22,
        goal: ([5.0, 0.0], 0.1),
        duration: 90.0,
        robot_radius: 0.1,
    }
}

fn path() -> Vec<[f64; 2]> {
    (0..=100).map(|i| [i as f64 * 0.05, 0.0]).collect()
}

/// The search's view of the scripted mover `spec` with barrier `b` on `traj`.
fn scripted<'a>(
    b: &'a MovingBarrier,
    spec: &'a ObstacleSpec,
    traj: &'a Trajectory,
) -> PassMover<'a> {
    PassMover {
        b,
        spec,
        traj: Some(traj),
    }
}

/// With room beside its path (0.4 m, more than the cart's 0.3 m keep-out) the robot gets
/// past the cart coming down the path at it; kept to 0.2 m of the path it cannot: the cart
/// sweeps the whole stretch and turns back onto the robot that follows it.
#[test]
fn room_beside_the_path_lets_the_robot_past_a_mover_along_it() {
    let (spec, b) = cart();
    let traj = trajectory(&spec).expect("valid").expect("scripted");
    let m = scripted(&b, &spec, &traj);
    let i = inputs();
    let passes = |movers: &[PassMover<'_>], detour: f64| {
        Passage::new(&i, &path(), detour)
            .expect("a path and a time step")
            .passes(movers)
    };
    assert!(passes(std::slice::from_ref(&m), 0.4));
    assert!(!passes(std::slice::from_ref(&m), 0.2));
    // Without the cart the band alone is no obstacle.
    assert!(passes(&[], 0.2));
}

/// A cart standing on the goal at the end of the run: the robot cannot be inside the goal
/// through the last 2 s, however much room it has.
#[test]
fn a_mover_over_the_goal_at_the_end_blocks_it() {
    let (mut spec, b) = cart();
    spec.motion = Some(MotionSpec::Waypoints {
        points: vec![[5.0, 0.0]],
        speed: 0.1,
        repeat: RepeatSpec::Once,
        start: 0.0,
    });
    let traj = trajectory(&spec).expect("valid").expect("scripted");
    let m = scripted(&b, &spec, &traj);
    let i = inputs();
    let passage = Passage::new(&i, &path(), 1.0).expect("a path and a time step");
    assert!(!passage.passes(&[m]));
}

/// A cart coming down onto the goal (radius 0.1 m) from +y, 0.9 m in 90 s, ending the run
/// `gap` m from the goal's centre: within its 0.3 m disc the goal's centre is held at
/// 0.25 m, but the robot may settle on the disc's far side, 0.35 m from it; at 0.15 m the
/// whole disc is held and the cart blocks the robot for good.
#[test]
fn a_mover_over_the_goal_blocks_it_only_where_it_holds_the_whole_goal_disc() {
    let over = |gap: f64| {
        let (mut spec, _) = cart();
        spec.position = [5.0, gap + 0.9, 0.2];
        spec.motion = Some(MotionSpec::Waypoints {
            points: vec![[5.0, gap]],
            speed: 0.01,
            repeat: RepeatSpec::Reverse,
            start: 0.0,
        });
        let b = MovingBarrier::new(
            Arc::new(EllipsoidOutside::disc("cart", 5.0, gap + 0.9, 0.3)),
            0,
        );
        let traj = trajectory(&spec).expect("valid").expect("scripted");
        let live = LiveInputs {
            obstacles: &[],
            barriers: &[],
            rest: inputs().rest,
            duration: 90.0,
            goal: [5.0, 0.0],
            v_max: 0.22,
            goal_radius: 0.1,
            robot_radius: 0.1,
        };
        blocks_for_good(&live, &scripted(&b, &spec, &traj), "cart", &path(), 1)
    };
    assert_eq!(over(0.25), None);
    let line = over(0.15).expect("the whole disc is held");
    assert!(line.contains("is over the goal at t = 90.0 s"), "{line}");
}

/// A person pacing the robot's path head-on between x = 1 and x = 4 (legs ending 0.3 m
/// short), kept 0.3 m off the robot's centre, with the robot kept to 0.2 m of its path: in
/// a corridor 1.2 m wide she stands aside and the robot passes; in one 0.56 m wide (she
/// is 0.4 m across, the robot 0.2 m) there is no room to, and the robot never gets past.
/// Read as a script (a cart on the same beat), she blocks it in the wide one too.
#[test]
fn a_walker_stands_aside_where_the_corridor_has_room_for_both() {
    let mut person = crate::movers::fleet::tests::spec(MotionSpec::Walker {
        goals: vec![[1.0, 0.0], [4.0, 0.0]],
        speed: 0.1,
    });
    person.position = [4.0, 0.0, 0.85];
    person.shape = crate::obstacles::ShapeSpec::Cylinder {
        radius: 0.2,
        half_height: 0.85,
    };
    let b = MovingBarrier::new(Arc::new(EllipsoidOutside::disc("person", 4.0, 0.0, 0.3)), 0);
    // Walls at y = ±w as the robot's barriers (h = its clearance, radius 0.1 m).
    let passes = |w: f64, m: PassMover<'_>| {
        let walls = [
            HalfPlane::new("left", State::new(0.0, -1.0, 0.0, 0.0), -(w - 0.1)),
            HalfPlane::new("right", State::new(0.0, 1.0, 0.0, 0.0), -(w - 0.1)),
        ];
        let i = PassInputs {
            statics: walls.iter().map(|b| b as &dyn Barrier).collect(),
            ..inputs()
        };
        Passage::new(&i, &path(), 0.2)
            .expect("a path and a time step")
            .passes(&[m])
    };
    let walker = || PassMover {
        b: &b,
        spec: &person,
        traj: None,
    };
    assert!(passes(0.6, walker()));
    assert!(!passes(0.28, walker()));
    let (cart, _) = cart();
    let traj = trajectory(&cart).expect("valid").expect("scripted");
    assert!(!passes(0.6, scripted(&b, &cart, &traj)));
}

/// The first point out from the cart's centre along +x (1 cm steps) where `held` no
/// longer holds the robot out \[m from the centre\].
fn edge(held: impl Fn([f64; 2]) -> bool) -> f64 {
    (1..=300)
        .map(|k| k as f64 * 0.01)
        .find(|&r| !held([4.0 + r, 0.0]))
        .expect("the cart's hold ends within 3 m")
}

/// With a unit's rows (κ = 1, γ = 0.05, K c̄ = I) the robot at rest stands only where u = 0
/// meets the row, κ(h − h̄) ≥ γ‖∇h‖: farther out than h = h̄ alone; and running at the
/// cart at 0.2 m/s it is held out farther still (the drift of its own velocity).
#[test]
fn the_rows_hold_the_robot_farther_out_than_h_bar_and_farther_still_running_at_it() {
    let (_, b) = cart();
    let model = LinearModel::new(
        LinearModel::double_integrator_f(),
        LinearModel::double_integrator_g(),
        vec![nalgebra::RowVector4::new(1.0, 0.0, 0.0, 0.0)],
        StateMatrix::zeros(),
        vec![1.0],
    )
    .expect("a valid model");
    let units = [UnitGains {
        m: StateMatrix::identity(),
        n: StateMatrix::zeros(),
        gamma: 0.05,
    }];
    let bare = Rest {
        gamma: 0.05,
        rows: None,
    };
    let rows = Rest {
        gamma: 0.05,
        rows: Some((&model, &units, 1.0)),
    };
    let b = &b;
    let at_rest = |rest: &Rest<'_>| {
        edge(|p| keeps_out_going(b, rest, p, [0.0, 0.0], MoverState::default(), 1))
    };
    let running = edge(|p| keeps_out_going(b, &rows, p, [-0.2, 0.0], MoverState::default(), 1));
    let (h_bar_edge, rest_edge) = (at_rest(&bare), at_rest(&rows));
    assert!(
        rest_edge > h_bar_edge + 0.02,
        "rows {rest_edge} m, h̄ alone {h_bar_edge} m"
    );
    assert!(
        running > rest_edge + 0.02,
        "running {running} m, at rest {rest_edge} m"
    );
    // Going away from the cart, the robot is held out no farther than at rest.
    let leaving = edge(|p| keeps_out_going(b, &rows, p, [0.2, 0.0], MoverState::default(), 1));
    assert!(
        leaving <= rest_edge,
        "leaving {leaving} m, at rest {rest_edge} m"
    );
}
