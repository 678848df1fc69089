//! A control law written in Python, driven as a Rust `ControlLaw`: the same simulation loop,
//! summary and batch as the built-in controllers.
//!
//! A *law factory* is a callable (usually a class) `factory(config: LawConfig)` returning an
//! object with `step(readings: Readings) -> (a_x, a_y)`. Its name (in summaries and batch
//! tables) is the factory's `name` attribute when that is a string, else its `__name__`.

use std::sync::{Arc, Mutex};

use ftcbf_sim::ftcbf_controller::{
    ControlLaw, ControllerConfig, Decision, Input, Readings as RustReadings,
};
use ftcbf_sim::model::setup::ControlSetup;
use ftcbf_sim::world::structure::Conversion;
use ftcbf_sim::world::World;
use numpy::{PyArray1, PyArray2, PyArrayMethods};
use pyo3::prelude::*;

use crate::errors::ControlLawError;

/// What a Python law is built from: the controller configuration the world implies.
#[pyclass(frozen, get_all, module = "ftcbf")]
pub struct LawConfig {
    /// Channel names, in the order of `Readings.y` (a `speed` sensor turned into world-frame
    /// velocity gives two channels, `name→vx` and `name→vy`).
    channels: Vec<String>,
    /// The output matrix C of the linear model: one row per channel over the state
    /// (p_x, p_y, v_x, v_y).
    c: Py<PyArray2<f64>>,
    /// Goal state x_g = (p_x, p_y, v_x, v_y).
    goal: Py<PyArray1<f64>>,
    /// Goal radius [m].
    goal_radius: f64,
    /// Box bound |a_k| ≤ limit_k [m/s²], or None.
    input_limit: Option<Py<PyArray1<f64>>>,
    /// Control period [s].
    dt: f64,
    /// Fault patterns as channel indices.
    fault_patterns: Vec<Vec<usize>>,
    /// Barrier names (safe sets, then obstacles).
    barriers: Vec<String>,
    /// The run's seed (for a law that draws random numbers: seed them from it).
    seed: u64,
}

/// The readings of one control step, as the law receives them (after any attack).
#[pyclass(frozen, get_all, module = "ftcbf")]
pub struct Readings {
    /// Time at the start of the step [s].
    t: f64,
    /// Control period [s].
    dt: f64,
    /// One value per channel (`LawConfig.channels`); may be NaN, ±inf or absurd under attack.
    y: Py<PyArray1<f64>>,
    /// Per channel: a new sample arrived this step.
    fresh: Py<PyArray1<bool>>,
    /// The world-frame acceleration [m/s²] the drive realised over the period now ending
    /// (a differential drive), or None when u was realised as asked (the linear plant).
    applied: Option<Py<PyArray1<f64>>>,
}

/// The channel names of a control setup.
pub fn channel_names(world: &World, setup: &ControlSetup) -> Vec<String> {
    let sensors = &world.file.sensors;
    setup
        .sensor_of_channel
        .iter()
        .zip(&setup.conversion)
        .map(|(&s, c)| {
            let name = &sensors[s].name;
            match c {
                Conversion::Direct => name.clone(),
                Conversion::SpeedX => format!("{name}→vx"),
                Conversion::SpeedY => format!("{name}→vy"),
            }
        })
        .collect()
}

/// A Python law factory and its name.
#[derive(Clone)]
pub struct Factory {
    pub name: String,
    obj: Arc<Py<PyAny>>,
}

impl Factory {
    /// `obj` as a law factory: callable, named by its `name` attribute or `__name__`, and not
    /// named like a built-in controller.
    pub fn new(obj: &Bound<'_, PyAny>) -> PyResult<Self> {
        if !obj.is_callable() {
            return Err(pyo3::exceptions::PyTypeError::new_err(format!(
                "a controller is a built-in name ({}) or a callable that builds a law from a \
                 LawConfig, not {}",
                ftcbf_lab::trials::CONTROLLERS.join(", "),
                obj.repr()?
            )));
        }
        let name: String = match obj.getattr("name").ok().and_then(|n| n.extract().ok()) {
            Some(n) => n,
            None => obj.getattr("__name__")?.extract()?,
        };
        if name.parse::<ftcbf_sim::world::ControllerKindSpec>().is_ok() || name.is_empty() {
            return Err(pyo3::exceptions::PyValueError::new_err(format!(
                "a Python law needs a name of its own (its `name` attribute or `__name__`), \
                 not `{name}`"
            )));
        }
        Ok(Self {
            name,
            obj: Arc::new(obj.clone().unbind()),
        })
    }

    /// Builds the law for a run of `world` with `seed`; its errors land in `error`.
    pub fn build(
        &self,
        world: &World,
        setup: &ControlSetup,
        seed: u64,
        error: &LawError,
    ) -> Result<Box<dyn ControlLaw>, String> {
        let cfg = &setup.config;
        Python::attach(|py| -> PyResult<PyLaw> {
            let config = LawConfig {
                channels: channel_names(world, setup),
                c: c_matrix(py, cfg)?,
                goal: PyArray1::from_slice(py, cfg.goal.as_slice()).unbind(),
                goal_radius: cfg.goal_radius,
                input_limit: cfg
                    .input_limit
                    .map(|l| PyArray1::from_slice(py, l.as_slice()).unbind()),
                dt: world.control_dt(),
                fault_patterns: cfg.fault_patterns.clone(),
                barriers: setup.barrier_names.clone(),
                seed,
            };
            let law = self.obj.bind(py).call1((config,))?;
            if !law.hasattr("step")? {
                return Err(pyo3::exceptions::PyTypeError::new_err(format!(
                    "the law built by `{}` has no step(readings) method",
                    self.name
                )));
            }
            Ok(PyLaw {
                obj: law.unbind(),
                name: self.name.clone(),
                error: error.clone(),
            })
        })
        .map(|l| Box::new(l) as Box<dyn ControlLaw>)
        .map_err(|e| {
            let text = e.to_string();
            error.set(e);
            text
        })
    }
}

fn c_matrix(py: Python<'_>, cfg: &ControllerConfig) -> PyResult<Py<PyArray2<f64>>> {
    let rows = cfg.model.c.len();
    let flat: Vec<f64> = cfg.model.c.iter().flat_map(|r| r.iter().copied()).collect();
    Ok(PyArray1::from_vec(py, flat).reshape([rows, 4])?.unbind())
}

/// The first exception a Python law raised in a run (shared by the law and the loop driving it).
#[derive(Clone, Default)]
pub struct LawError(Arc<Mutex<Option<PyErr>>>);

impl LawError {
    fn set(&self, e: PyErr) {
        if let Ok(mut slot) = self.0.lock() {
            slot.get_or_insert(e);
        }
    }

    /// Whether the law has failed.
    pub fn failed(&self) -> bool {
        self.0.lock().map(|s| s.is_some()).unwrap_or(true)
    }

    /// The failure as a `ControlLawError` (cause: the law's exception) with `context`.
    pub fn take(&self, context: &str) -> Option<PyErr> {
        let cause = self.0.lock().ok()?.take()?;
        Python::attach(|py| {
            let e = ControlLawError::new_err(format!("{context}: {}", cause.value(py)));
            e.set_cause(py, Some(cause));
            Some(e)
        })
    }
}

/// A law object living in Python. After it raised, it is not called again: it returns zero and
/// the loop driving it stops at the end of the step and reports the exception.
struct PyLaw {
    obj: Py<PyAny>,
    name: String,
    error: LawError,
}

impl PyLaw {
    fn call(&self, py: Python<'_>, r: &RustReadings<'_>) -> PyResult<Input> {
        let readings = Readings {
            t: r.t,
            dt: r.dt,
            y: PyArray1::from_slice(py, r.y).unbind(),
            fresh: PyArray1::from_slice(py, r.fresh).unbind(),
            applied: r
                .applied
                .map(|a| PyArray1::from_slice(py, a.as_slice()).unbind()),
        };
        let out = self.obj.bind(py).call_method1("step", (readings,))?;
        let u: Vec<f64> = out.extract().map_err(|_| {
            pyo3::exceptions::PyTypeError::new_err(format!(
                "{}.step returned {}, not two numbers (a_x, a_y)",
                self.name,
                out.repr().map_or_else(|_| "?".into(), |r| r.to_string())
            ))
        })?;
        match u.as_slice() {
            [ax, ay] => Ok(Input::new(*ax, *ay)),
            _ => Err(pyo3::exceptions::PyValueError::new_err(format!(
                "{}.step returned {} numbers, not two (a_x, a_y)",
                self.name,
                u.len()
            ))),
        }
    }
}

impl ControlLaw for PyLaw {
    fn name(&self) -> &str {
        &self.name
    }

    fn step(&mut self, r: &RustReadings<'_>) -> Decision<'_> {
        let zero = Decision {
            u: Input::zeros(),
            record: None,
        };
        if self.error.failed() {
            return zero;
        }
        match Python::attach(|py| self.call(py, r)) {
            Ok(u) => Decision { u, record: None },
            Err(e) => {
                self.error.set(e);
                zero
            }
        }
    }
}
