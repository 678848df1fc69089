//! `ftcbf.World`: a world file loaded with overrides, and `check()`, `ftcbf check`'s report as
//! Python data.

use std::path::PathBuf;
use std::sync::Arc;

use ftcbf_sim::analysis::check::{self, CheckReport, CovarianceBound, Status};
use ftcbf_sim::analysis::liveness::rollout::ROLLOUTS;
use ftcbf_sim::analysis::liveness::{Blocked, LivenessReport};
use ftcbf_sim::runner::{preflight, CompiledWorld};
use ftcbf_sim::world::{Override, World as SimWorld};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::errors::{run_error, world_error};

/// A dict from `key: value` pairs (values converted with `IntoPyObject`).
macro_rules! pydict {
    ($py:expr, { $($k:literal : $v:expr),* $(,)? }) => {{
        let d = PyDict::new($py);
        $( d.set_item($k, $v)?; )*
        d
    }};
}
pub(crate) use pydict;

/// A world file, loaded and validated (with any overrides applied), ready to check, simulate
/// or certify.
#[pyclass(frozen, module = "ftcbf")]
pub struct World {
    pub(crate) inner: Arc<SimWorld>,
    /// The overrides it was loaded with, in order (a batch reloads the file with them).
    pub(crate) overrides: Vec<Override>,
}

#[pymethods]
impl World {
    /// Loads `path`; `overrides` maps world-file key paths (`"attacks[0].value"`,
    /// `"control.gamma"`) to numbers, applied in order as `ftcbf run --set KEY=VALUE` does.
    /// Raises `WorldError` with the file, key and expectation when the file is invalid.
    #[staticmethod]
    #[pyo3(signature = (path, overrides = None))]
    fn load(path: PathBuf, overrides: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        let mut list = Vec::new();
        for (k, v) in overrides.into_iter().flat_map(|d| d.iter()) {
            list.push(Override {
                key: k.extract()?,
                value: v.extract()?,
            });
        }
        let inner = SimWorld::load(&path, &list).map_err(world_error)?;
        Ok(Self {
            inner: Arc::new(inner),
            overrides: list,
        })
    }

    /// The world's name.
    #[getter]
    fn name(&self) -> &str {
        &self.inner.name
    }

    /// The file it was loaded from.
    #[getter]
    fn path(&self) -> PathBuf {
        self.inner.path.clone()
    }

    /// The world's own seed (the default of a run and the base seed of a batch).
    #[getter]
    fn seed(&self) -> u64 {
        self.inner.file.seed
    }

    /// Simulated duration [s].
    #[getter]
    fn duration(&self) -> f64 {
        self.inner.file.duration
    }

    /// Control period [s].
    #[getter]
    fn control_dt(&self) -> f64 {
        self.inner.control_dt()
    }

    /// The controller the world file names (`ft-cbf-clf`, `baseline` or `nominal`).
    #[getter]
    fn controller(&self) -> &'static str {
        self.inner.file.control.controller.name()
    }

    /// The overrides it was loaded with.
    #[getter]
    fn overrides<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for o in &self.overrides {
            d.set_item(&o.key, o.value)?;
        }
        Ok(d)
    }

    /// `ftcbf check` as data: every hypothesis of Theorem 3 with its numbers, the filters, the
    /// goal-holding margins, the Theorem 3 verdict, the liveness prediction, condition (4.4) per
    /// barrier at the start estimate, and `text`, the report as the CLI prints it. In a world
    /// with movers the liveness verdict is `rollouts` runs of the closed loop (`ftcbf check
    /// --rollouts`; 0: the search past the movers alone). Raises `WorldError` for what `ftcbf
    /// check` refuses (exit 2).
    #[pyo3(signature = (rollouts = ROLLOUTS))]
    fn check<'py>(&self, py: Python<'py>, rollouts: usize) -> PyResult<Bound<'py, PyDict>> {
        let world = self.inner.clone();
        let (report, setup) = py
            .detach(move || {
                let compiled = CompiledWorld::new((*world).clone())?;
                // Whatever `run` would refuse at its start, `check` refuses too.
                preflight(&compiled)?;
                let report = ftcbf_lab::trials::check_rolled_out(&compiled, rollouts);
                Ok((report, compiled.setup().clone()))
            })
            .map_err(run_error)?;
        let d = report_dict(py, &report)?;
        let mut c44 = Vec::new();
        for (name, v) in check::condition_4_4_at_start(&setup) {
            c44.push(pydict!(py, {
                "barrier": name,
                "holds": v.holds,
                "margin": v.margin,
                "spread": v.spread,
                "text": v.to_string(),
            }));
        }
        d.set_item("condition_4_4", c44)?;
        Ok(d)
    }

    fn __repr__(&self) -> String {
        format!(
            "World(name={:?}, path={:?}, overrides={})",
            self.inner.name,
            self.inner.path.display().to_string(),
            self.overrides.len()
        )
    }
}

fn status(s: Status) -> &'static str {
    match s {
        Status::Holds => "holds",
        Status::Fails => "fails",
        Status::Assumed => "assumed",
        Status::Info => "info",
    }
}

fn report_dict<'py>(py: Python<'py>, r: &CheckReport) -> PyResult<Bound<'py, PyDict>> {
    let mut hypotheses = Vec::new();
    for h in &r.hypotheses {
        hypotheses.push(pydict!(py, {
            "name": &h.name, "status": status(h.status), "detail": &h.detail,
        }));
    }
    let mut filters = Vec::new();
    for f in &r.filters {
        let (bound, seconds) = match f.bound {
            CovarianceBound::SteadyState => ("steady_state", None),
            CovarianceBound::FiniteHorizon { seconds } => ("finite_horizon", Some(seconds)),
            CovarianceBound::OpenLoop { seconds } => ("open_loop", Some(seconds)),
        };
        filters.push(pydict!(py, {
            "label": &f.label,
            "channels": &f.channels,
            "r_bar_min": f.r_bar_min,
            "detectable": f.detectability.detectable,
            "unobservable": &f.detectability.unobservable,
            "bound": bound,
            "horizon": seconds,
            "gamma": f.gamma,
        }));
    }
    let mut goal = Vec::new();
    for g in &r.goal {
        goal.push(pydict!(py, {
            "barrier": &g.barrier,
            "filter": &g.filter,
            "needed_h": g.needed_h,
            "max_h_in_goal": g.max_h_in_goal,
            "holds": g.holds(),
        }));
    }
    let v = &r.verdict;
    let theorem3 = pydict!(py, {
        "applies": v.applies,
        "epsilon": v.epsilon,
        "reasons": &v.reasons,
        "assumptions": &v.assumptions,
        "horizon": v.horizon,
        "line": v.line(),
    });
    Ok(pydict!(py, {
        "world": &r.world,
        "context": &r.context,
        "hypotheses": hypotheses,
        "filters": filters,
        "goal": goal,
        "theorem3": theorem3,
        "liveness": liveness_dict(py, &r.liveness)?,
        "text": r.to_string(),
    }))
}

fn liveness_dict<'py>(py: Python<'py>, l: &LivenessReport) -> PyResult<Bound<'py, PyDict>> {
    let mut cases = Vec::new();
    for c in &l.cases {
        let stall = match &c.stall {
            None => None,
            Some(s) => {
                let (blocked, acceleration) = match s.blocked {
                    Blocked::Infeasible => ("infeasible", None),
                    Blocked::NoProgress(a) => ("no_progress", Some(a)),
                };
                Some(pydict!(py, {
                    "at": s.at,
                    "along": s.along,
                    "blocked": blocked,
                    "acceleration": acceleration,
                    "binding": &s.binding,
                    "offset": s.offset,
                }))
            }
        };
        cases.push(pydict!(py, {
            "name": &c.name,
            "live": c.live(),
            "reach": c.reach,
            "stall": stall,
            "least_progress": c.least_progress.0,
            "least_progress_at": c.least_progress.1,
            "goal_holds": c.goal_holds,
        }));
    }
    let fix = match &l.fix {
        Some(f) => Some(pydict!(py, { "key": &f.key, "value": f.value })),
        None => None,
    };
    Ok(pydict!(py, {
        "live": l.live(),
        "line": l.line(),
        "kappa": l.kappa,
        "path_length": l.path_length,
        "samples": l.samples,
        "cases": cases,
        "fix": fix,
        "structural": &l.structural,
        "skipped": &l.skipped,
        "safe_stop": &l.safe_stop,
        "rollouts": match &l.rollouts {
            Some(r) => Some(pydict!(py, {
                "runs": r.runs,
                "settled": r.settled,
                "base_seed": r.base_seed,
                "first_miss_seed": r.first_miss.map(|m| m.0),
                "error": &r.error,
            })),
            None => None,
        },
    }))
}
