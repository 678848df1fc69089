//! One full `paper_turtlebot` run (20 s simulated: 4000 physics ticks at 200 Hz, 1000 control
//! steps at 50 Hz), with recording off and on. Real-time factor = 20 s / median.

use std::path::PathBuf;

use criterion::{criterion_group, criterion_main, Criterion};
use ftcbf_sim::record::{Recorder, RecordingName};
use ftcbf_sim::runner::{run, run_observed, RunOptions};
use ftcbf_sim::world::World;

fn bench(c: &mut Criterion) {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("worlds/paper_turtlebot.toml");
    let world = World::load(&path, &[]).expect("world loads");
    let opts = RunOptions::default();
    let mut g = c.benchmark_group("paper_turtlebot_20s");
    g.sample_size(20);
    g.bench_function("record_off", |b| {
        b.iter(|| run(&world, &opts).expect("runs"))
    });
    let out = std::env::temp_dir().join("ftcbf-bench.rrd");
    g.bench_function("record_on", |b| {
        b.iter(|| {
            let mut rec = Recorder::create(
                &out,
                &RecordingName {
                    world: "bench".into(),
                    controller: "ft-cbf-clf".into(),
                    seed: 0,
                },
            )
            .expect("recording");
            let s = run_observed(&world, &opts, Some(&mut rec)).expect("runs");
            rec.finish().expect("flushed");
            s
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
