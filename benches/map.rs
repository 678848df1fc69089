//! Issue #47 part B: what an occupancy map costs. On a synthetic 384 × 384 map of 5 cm cells
//! in the style of the TurtleBot3 world's nav2 map (a ring wall around a free room, nine round
//! pillars, unknown cells outside): building the distance field (two exact distance transforms
//! and the G/κ bounds), merging the blocked cells into the physics' boxes, and 10,000 field
//! lookups (what `check` reads from it), and tracing and simplifying the blocked cells' outline
//! into the controller's barrier pieces (once per world load).

use criterion::{criterion_group, criterion_main, Criterion};
use ftcbf_sim::environment::map::Cell;
use ftcbf_sim::environment::{MapField, OccupancyGrid};
use ftcbf_sim::world::UnknownCells;

fn tb3_like() -> OccupancyGrid {
    let (n, res) = (384usize, 0.05);
    let mut cells = vec![Cell::Unknown; n * n];
    for j in 0..n {
        for i in 0..n {
            let (x, y) = ((i as f64 + 0.5) * res - 9.6, (j as f64 + 0.5) * res - 9.6);
            let r = x.hypot(y);
            let pillar = [-1.1, 0.0, 1.1]
                .iter()
                .flat_map(|&a| [-1.1, 0.0, 1.1].map(|b| (a, b)))
                .any(|(a, b)| (x - a).hypot(y - b) < 0.15);
            cells[j * n + i] = if (2.45..2.6).contains(&r) || pillar {
                Cell::Occupied
            } else if r < 2.45 {
                Cell::Free
            } else {
                Cell::Unknown
            };
        }
    }
    OccupancyGrid {
        width: n,
        height: n,
        resolution: res,
        origin: [-9.6, -9.6, 0.0],
        cells,
    }
}

fn bench(c: &mut Criterion) {
    let grid = tb3_like();
    let mut g = c.benchmark_group("map_384x384");
    g.sample_size(10);
    g.bench_function("distance_field", |b| {
        b.iter(|| MapField::new(&grid, UnknownCells::Obstacle))
    });
    g.bench_function("outline_pieces", |b| {
        b.iter(|| {
            ftcbf_sim::environment::outline::outlines(
                &grid,
                UnknownCells::Obstacle,
                ftcbf_sim::environment::outline::DEFAULT_TOLERANCE_CELLS,
            )
        })
    });
    g.bench_function("physics_boxes", |b| {
        b.iter(|| grid.compound(UnknownCells::Obstacle))
    });
    let field = MapField::new(&grid, UnknownCells::Obstacle);
    g.bench_function("lookups_10000", |b| {
        b.iter(|| {
            let mut s = 0.0;
            for k in 0..10_000 {
                let t = k as f64 * 1e-3;
                s += field.signed_distance([2.0 * t.cos(), 2.0 * t.sin()]).0;
            }
            s
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
