//! `ftcbf gen`: seeded world files, written and listed.

use std::path::PathBuf;

use anyhow::Context;

use ftcbf_sim::worldgen::{write_worlds, GenConfig, Generator, Kind, RobotModel, Suite};

use crate::parsers::{kind_parser, robot_parser, suite_parser, OneOrEvery};

/// `ftcbf gen`
#[derive(Debug, clap::Args)]
pub struct GenArgs {
    /// Seed of every draw.
    #[arg(long)]
    pub seed: u64,
    /// How many worlds to write (1 to 100000).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..=100_000))]
    pub count: u64,
    /// Directory to write the world files to (created when missing). The files' `urdf` keys
    /// are relative to it.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Kind of scene; `all` takes every kind in turn.
    #[arg(long, value_name = "KIND", value_parser = kind_parser(), default_value = "all")]
    pub kind: OneOrEvery<Kind>,
    /// Robot; `any` alternates the burger and the waffle.
    #[arg(long, value_name = "ROBOT", value_parser = robot_parser(), default_value = "any")]
    pub robot: OneOrEvery<RobotModel>,
    /// Sensor suite (book: Generating worlds); `any` takes every suite in turn.
    #[arg(long, value_name = "SUITE", value_parser = suite_parser(), default_value = "any")]
    pub suite: OneOrEvery<Suite>,
    /// Directory holding turtlebot3_burger.urdf and turtlebot3_waffle.urdf (the project's
    /// `robots/`).
    #[arg(long, value_name = "DIR", default_value = "robots")]
    pub robots: PathBuf,
    /// Draw every world on this occupancy map (map_server YAML) instead of a drawn scene: a
    /// start and a goal 1 to 5 m apart in its free cells that the planner joins, the map
    /// referenced as `[environment] map` (relative to --out). Leave --kind at `all`.
    #[arg(long, value_name = "FILE.yaml")]
    pub map: Option<PathBuf>,
}

/// `ftcbf gen`: the library generates (`ftcbf_sim::worldgen`); this writes and lists.
pub fn command(a: &GenArgs) -> anyhow::Result<()> {
    if a.out.exists() && !a.out.is_dir() {
        anyhow::bail!(
            "--out `{}` is not a directory; expected a directory to write the generated worlds \
             into (it is created when missing)",
            a.out.display()
        );
    }
    let out_flag = || {
        format!(
            "--out `{}`: expected a directory the generated worlds can be written into",
            a.out.display()
        )
    };
    let generator = Generator::new(GenConfig {
        seed: a.seed,
        kind: a.kind,
        robot: a.robot,
        suite: a.suite,
        robots_dir: a.robots.clone(),
        out_dir: a.out.clone(),
        map: a.map.clone(),
    })
    .map_err(|e| match e {
        ftcbf_sim::worldgen::GenError::Io { .. } => anyhow::Error::new(e).context(out_flag()),
        e => anyhow::Error::new(e),
    })?;
    let count = usize::try_from(a.count).context("--count")?;
    let worlds = generator.worlds(count)?;
    let paths = write_worlds(&a.out, &worlds).with_context(out_flag)?;
    let rows: Vec<Vec<String>> = worlds
        .iter()
        .zip(&paths)
        .map(|(w, p)| {
            vec![
                p.display().to_string(),
                w.kind.name().to_string(),
                w.robot.name().to_string(),
                w.suite.name().to_string(),
                w.attack_label(),
            ]
        })
        .collect();
    print!(
        "{}",
        ftcbf_lab::batch::render_table(
            &["file", "kind", "robot", "suite", "attack"],
            &[ftcbf_lab::batch::Align::Left; 5],
            &rows
        )
    );
    Ok(())
}
