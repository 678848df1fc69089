//! Active barriers (issue #52): the obstacle index's far-field bounds hold for the barriers it
//! covers, its `near` query finds every region within the radius, and a run with the index
//! follows the run without it (the rows it leaves out cannot bind).

use std::path::PathBuf;

use ftcbf_controller::reach::BarrierIndex;
use ftcbf_controller::{Barrier, ControlLaw, Controller, State};
use ftcbf_sim::active::ObstacleIndex;
use ftcbf_sim::obstacles::{BarrierConfig, Obstacle, ObstacleSpec, ShapeSpec};
use ftcbf_sim::runner::{RunOptions, Simulation};
use ftcbf_sim::world::World;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn obstacle(name: &str, position: [f64; 3], rpy: [f64; 3], shape: ShapeSpec) -> Obstacle {
    let spec = ObstacleSpec {
        name: name.into(),
        position,
        rpy,
        shape,
        motion: None,
        tracker: None,
    };
    Obstacle::from_spec(&spec, None).unwrap()
}

fn shapes() -> Vec<Obstacle> {
    vec![
        obstacle(
            "box",
            [1.0, 2.0, 0.15],
            [0.0, 0.0, 0.4],
            ShapeSpec::Cuboid {
                half_extents: [0.5, 0.1, 0.15],
            },
        ),
        obstacle(
            "pillar",
            [-1.0, 0.5, 0.3],
            [0.0; 3],
            ShapeSpec::Cylinder {
                radius: 0.2,
                half_height: 0.3,
            },
        ),
        obstacle(
            "ball",
            [0.0, -1.5, 0.1],
            [0.0; 3],
            ShapeSpec::Ball { radius: 0.25 },
        ),
        obstacle(
            "cone",
            [2.0, -1.0, 0.2],
            [0.0; 3],
            ShapeSpec::Cone {
                radius: 0.3,
                half_height: 0.2,
            },
        ),
        obstacle(
            "hull",
            [-2.0, -2.0, 0.0],
            [0.0; 3],
            ShapeSpec::ConvexHull {
                points: vec![
                    [0.0, 0.0, 0.0],
                    [0.6, 0.0, 0.0],
                    [0.0, 0.4, 0.0],
                    [0.1, 0.1, 0.5],
                ],
            },
        ),
    ]
}

fn cfg() -> BarrierConfig {
    BarrierConfig {
        robot_radius: 0.105,
        centre_height: 0.1,
        margin: 0.05,
        k: 0.5,
        v_max: 0.22,
        fd_step: 2e-3,
    }
}

#[test]
fn far_bounds_hold_for_every_covered_shape() {
    let obs = shapes();
    let cfg = cfg();
    let index = ObstacleIndex::new(&obs, 0, obs.len(), &cfg);
    // cone and hull are not covered (parry's iterative projection)
    assert_eq!(index.covered_count(), 3);
    assert!(!index.covers(3) && !index.covers(4));
    let mut rng = ChaCha8Rng::seed_from_u64(52);
    let mut checked = 0;
    for _ in 0..4000 {
        let p = [rng.random_range(-6.0..6.0), rng.random_range(-6.0..6.0)];
        let speed: f64 = rng.random_range(0.0..0.4);
        let a: f64 = rng.random_range(0.0..std::f64::consts::TAU);
        let x = State::new(p[0], p[1], speed * a.cos(), speed * a.sin());
        for (b, o) in obs.iter().enumerate().take(3) {
            let d = index.distance(b, p).unwrap();
            let fb = index.far_bounds(d, speed);
            if !fb.h_lower.is_finite() {
                continue;
            }
            let e = o.barrier(&cfg).eval(&x);
            assert!(
                e.value >= fb.h_lower,
                "{}: h = {} < bound {} at {p:?}",
                o.name,
                e.value,
                fb.h_lower
            );
            assert!(e.gradient.norm() <= fb.gradient, "{}: gradient", o.name);
            assert!(
                e.hessian.norm() <= fb.hessian,
                "{}: Hessian {} > {} at {p:?} d {d} s {speed}",
                o.name,
                e.hessian.norm(),
                fb.hessian
            );
            checked += 1;
        }
    }
    assert!(checked > 9_000, "{checked}");
}

#[test]
fn near_finds_every_region_within_the_radius() {
    let obs = shapes();
    let index = ObstacleIndex::new(&obs, 2, obs.len() + 2, &cfg());
    assert!(!index.covers(0) && !index.covers(1) && index.covers(2));
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let mut out = Vec::new();
    for _ in 0..2000 {
        let p = [rng.random_range(-5.0..5.0), rng.random_range(-5.0..5.0)];
        let r = rng.random_range(0.1..4.0);
        out.clear();
        index.near(p, r, &mut out);
        for b in 2..5 {
            if index.distance(b, p).unwrap() <= r {
                assert!(
                    out.contains(&b),
                    "barrier {b} within {r} of {p:?} not found"
                );
            }
        }
    }
}

/// The quick start's world (box, wall) plus 60 cylinders 3.5–5 m from its path.
fn cluttered() -> World {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../worlds");
    let text = std::fs::read_to_string(dir.join("quickstart.toml")).unwrap();
    let mut text = text[..text.find("[expect]").unwrap()].to_string();
    for i in 0..60 {
        let y = if i % 2 == 0 { 3.5 } else { -3.5 } + 0.05 * (i / 20) as f64;
        text.push_str(&format!(
            "\n[[obstacles]]\nname = \"c{i}\"\nposition = [{:.2}, {y:.2}, 0.3]\nshape = {{ kind = \"cylinder\", radius = 0.1, half_height = 0.3 }}\n",
            -2.0 + 0.25 * (i / 2) as f64
        ));
    }
    World::from_str(&text, &dir.join("cluttered.toml"), &[]).unwrap()
}

#[test]
fn a_run_with_the_index_follows_the_run_without_it() {
    let world = cluttered();
    let opts = RunOptions::default();
    let mut with = Simulation::new(&world, &opts).unwrap();
    assert!(with.setup().config.barrier_index.is_some());
    with.run_to_end();
    let mut without = Simulation::with_law(&world, &opts, |config| {
        let mut config = config.clone();
        config.barrier_index = None;
        Controller::new(config)
            .map(|c| Box::new(c) as Box<dyn ControlLaw>)
            .map_err(|e| e.to_string())
    })
    .unwrap();
    without.run_to_end();
    let (a, b) = (with.summary(), without.summary());
    assert_eq!(a.safe, b.safe);
    assert_eq!(a.goal_settled, b.goal_settled);
    // The QPs differ only in rows every input satisfies; clarabel's interior point (tolerance
    // 1e-8) lands a few ulps of its tolerance apart, and 1500 steps carry that to ~1e-5.
    for k in 0..4 {
        assert!(
            (a.final_state[k] - b.final_state[k]).abs() < 1e-4,
            "final state {:?} vs {:?}",
            a.final_state,
            b.final_state
        );
    }
    let (ca, cb) = (a.min_clearance.unwrap(), b.min_clearance.unwrap());
    assert!((ca - cb).abs() < 1e-4, "min clearance {ca} vs {cb}");
}
