//! `ftcbf regress`: the world catalogue as a regression suite.

use std::path::PathBuf;

use anyhow::Context;

use ftcbf_lab::regress;

use crate::bars::RunsBar;
use crate::exit::{invalid, Failure, EXIT_EXPECTATION};

/// `ftcbf regress`
#[derive(Debug, clap::Args)]
pub struct RegressArgs {
    /// World files or directories of world files [default: worlds/].
    pub paths: Vec<PathBuf>,
    /// Print every case (expectations, verdict, failures and each seed's summary) as JSON
    /// instead of the table.
    #[arg(long)]
    pub json: bool,
}

/// `ftcbf regress`.
pub fn command(a: &RegressArgs) -> Result<(), Failure> {
    let paths = if a.paths.is_empty() {
        vec![PathBuf::from("worlds")]
    } else {
        a.paths.clone()
    };
    let plan = regress::Plan::load(&paths).map_err(|e| match e {
        regress::RegressError::World(w) => invalid(w),
        other => Failure::from(anyhow::Error::new(other)),
    })?;
    for f in &plan.skipped {
        eprintln!("skipping {} (no [expect] table)", f.display());
    }
    let results = plan.run(&RunsBar::new()).context("regression run")?;
    if a.json {
        let text = serde_json::to_string_pretty(&results).context("serialising")?;
        println!("{text}");
    } else {
        println!("{}", regress::table_text(&results));
    }
    let failed = results.iter().filter(|r| !r.passed()).count();
    if failed > 0 {
        Err(Failure {
            code: EXIT_EXPECTATION,
            error: anyhow::anyhow!("{failed} regression case(s) failed"),
        })
    } else {
        Ok(())
    }
}
