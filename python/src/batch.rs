//! `ftcbf.batch`: `ftcbf batch` from Python — the same plan, trial seeds, runner, statistics and
//! report — with control laws written in Python among the controllers.

use std::sync::{Arc, Mutex};

use ftcbf_lab::batch::{self as engine, BatchSpec, PreparedWorld, TrialRunner};
use ftcbf_lab::trials::{world_info, WorldRunner};
use ftcbf_sim::summary::RunSummary;
use ftcbf_sim::world::Override;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::errors::chain_error;
use crate::law::{Factory, LawError};
use crate::sim::{start, Choice};
use crate::world::World;

/// The exceptions Python laws raised in a batch, by (seed, law name).
type Raised = Mutex<Vec<(u64, String, PyErr)>>;

/// Runs trials of one world: built-in controllers as `ftcbf batch` does, Python laws by name.
struct Runner {
    builtin: WorldRunner,
    laws: Arc<Vec<Factory>>,
    raised: Arc<Raised>,
}

impl TrialRunner for Runner {
    fn run_trial(&self, controller: &str, seed: u64) -> anyhow::Result<RunSummary> {
        let Some(law) = self.laws.iter().find(|f| f.name == controller) else {
            return self.builtin.run_trial(controller, seed);
        };
        let world = &self.builtin.0;
        let error = LawError::default();
        let choice = Choice::Python(law.clone());
        let started = start(world, Some(seed), None, Some(&choice), &error);
        let failure = |context: &str| {
            let e = error.take(context)?;
            let text = Python::attach(|py| e.value(py).to_string());
            if let Ok(mut r) = self.raised.lock() {
                r.push((seed, controller.to_string(), e));
            }
            Some(anyhow::anyhow!(text))
        };
        let mut sim = match started {
            Ok(sim) => sim,
            Err(e) => {
                return Err(failure(&format!("building the control law `{controller}`"))
                    .unwrap_or_else(|| e.into()))
            }
        };
        while sim.step().is_some() {
            if let Some(e) = failure(&format!("control law `{controller}` raised")) {
                return Err(e);
            }
        }
        Ok(sim.summary())
    }
}

/// `ftcbf batch WORLD --trials N --controller C … [--seed S] [--jobs J] [--sweep K=V1,V2]
/// [--shard K/N]`, with the GIL released while trials run. `controllers` holds built-in names
/// and Python law factories (see `Simulation`). Returns `(json, report)`: the text of the
/// `--out FILE.json` file and the report the command prints.
#[pyfunction]
#[pyo3(signature = (world, trials = 100, controllers = None, jobs = None, seed = None, sweep = None, shard = None))]
#[allow(clippy::too_many_arguments)] // the command's options, one argument each
pub fn batch(
    py: Python<'_>,
    world: &World,
    trials: u64,
    controllers: Option<Vec<Bound<'_, PyAny>>>,
    jobs: Option<u64>,
    seed: Option<u64>,
    sweep: Option<&str>,
    shard: Option<&str>,
) -> PyResult<(String, String)> {
    let mut names = Vec::new();
    let mut laws = Vec::new();
    for c in controllers.unwrap_or_default() {
        match Choice::from_py(Some(&c))? {
            Some(Choice::Python(f)) => {
                names.push(f.name.clone());
                laws.push(f);
            }
            _ => names.push(c.extract::<String>()?),
        }
    }
    let mut spec = BatchSpec::new(world.inner.path.clone());
    if !names.is_empty() {
        spec.controllers = names;
    }
    if trials == 0 || jobs == Some(0) {
        return Err(PyValueError::new_err("trials and jobs must be at least 1"));
    }
    let bad = |e: engine::ArgError| PyValueError::new_err(e.to_string());
    spec.trials = trials;
    spec.seed = seed;
    spec.jobs = jobs
        .map(usize::try_from)
        .transpose()
        .map_err(|_| PyValueError::new_err("jobs is too large for this machine"))?;
    spec.sweep = sweep.map(str::parse).transpose().map_err(bad)?;
    spec.shard = shard.map(str::parse).transpose().map_err(bad)?;
    spec.overrides = world.overrides.clone();
    let raised = Arc::new(Raised::default());
    let laws = Arc::new(laws);
    let outcome = py.detach(|| {
        let prepare = |overrides: &[Override]| -> anyhow::Result<PreparedWorld> {
            let builtin = WorldRunner::new(ftcbf_sim::world::World::load(&spec.world, overrides)?)?;
            Ok(PreparedWorld {
                info: world_info(&builtin.0),
                runner: Box::new(Runner {
                    builtin,
                    laws: laws.clone(),
                    raised: raised.clone(),
                }),
            })
        };
        let run = spec.run(&prepare, &ftcbf_lab::progress::Silent)?;
        Ok::<_, anyhow::Error>((engine::to_json(&run.results)?, run.report))
    });
    outcome.map_err(|e| {
        let text = format!("{e:#}");
        let cause = raised.lock().ok().and_then(|mut r| {
            let i = r
                .iter()
                .position(|(s, c, _)| text.contains(&format!("(seed {s}, controller {c})")))?;
            Some(r.swap_remove(i))
        });
        match cause {
            Some((_, _, err)) => {
                let e = crate::errors::ControlLawError::new_err(text);
                e.set_cause(py, Some(err));
                e
            }
            None => chain_error(&e),
        }
    })
}
