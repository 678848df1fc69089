//! One physics tick of the burger among 20 obstacles (and the per-tick queries the runner makes).

use std::path::PathBuf;

use criterion::{criterion_group, criterion_main, Criterion};
use ftcbf_controller::{Barrier, State};
use ftcbf_sim::obstacles::{BarrierConfig, Obstacle, ObstacleSpec, ShapeSpec};
use ftcbf_sim::physics::{PhysicsConfig, PhysicsWorld, Pose2};
use ftcbf_sim::robot::{LoadOptions, RobotDescription};

fn obstacles() -> Vec<Obstacle> {
    let mut specs = Vec::new();
    for i in 0..20 {
        let a = i as f64 * 0.314;
        let r = 1.0 + 0.1 * i as f64;
        let position = [r * a.cos(), r * a.sin(), 0.2];
        let shape = match i % 5 {
            0 => ShapeSpec::Cuboid {
                half_extents: [0.2, 0.1, 0.2],
            },
            1 => ShapeSpec::Cylinder {
                radius: 0.1,
                half_height: 0.2,
            },
            2 => ShapeSpec::Ball { radius: 0.15 },
            3 => ShapeSpec::Capsule {
                radius: 0.1,
                half_height: 0.1,
            },
            _ => ShapeSpec::ConvexHull {
                points: vec![
                    [0.0, 0.0, -0.2],
                    [0.3, 0.0, -0.2],
                    [0.0, 0.3, -0.2],
                    [0.1, 0.1, 0.2],
                ],
            },
        };
        specs.push(ObstacleSpec {
            name: format!("o{i}"),
            position,
            rpy: [0.0, 0.0, a],
            shape,
            motion: None,
            tracker: None,
        });
    }
    Obstacle::from_specs(&specs, None).expect("valid obstacles")
}

fn bench(c: &mut Criterion) {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../robots/turtlebot3_burger.urdf");
    let robot = RobotDescription::from_file(path, &LoadOptions::default()).expect("burger loads");
    let obs = obstacles();
    let mut world = PhysicsWorld::new(&robot, Pose2::default(), &obs, &PhysicsConfig::default())
        .expect("world");
    world.set_wheel_speeds(2.0, 2.5);
    c.bench_function("physics_step_burger_20_obstacles", |b| {
        b.iter(|| {
            world.step();
            std::hint::black_box(world.contacts().count());
        })
    });
    let mut buf = Vec::with_capacity(obs.len());
    c.bench_function("clearances_20_obstacles", |b| {
        b.iter(|| {
            world.clearances(&mut buf);
            std::hint::black_box(buf[0]);
        })
    });
    let bcfg = BarrierConfig::for_robot(&robot, 0.05, 0.5);
    let barriers: Vec<_> = obs.iter().map(|o| o.barrier(&bcfg)).collect();
    let x = State::new(0.1, 0.2, 0.15, 0.05);
    c.bench_function("barrier_eval_20_obstacles", |b| {
        b.iter(|| {
            let s: f64 = barriers
                .iter()
                .map(|br| br.eval(std::hint::black_box(&x)).value)
                .sum();
            std::hint::black_box(s)
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
