//! `ftcbf.Simulation`: one closed-loop run of a world, stepped from Python (`step()`), or run to
//! its end in Rust with the GIL released (`run()`), optionally recorded to a rerun `.rrd` file.

use std::path::PathBuf;
use std::sync::{Arc, Mutex, MutexGuard};

use ftcbf_sim::observe::{Frame as SimFrame, Observer};
use ftcbf_sim::record::{Recorder, RecordingName};
use ftcbf_sim::runner::{RunOptions, Simulation as Loop, Source};
use ftcbf_sim::world::World as SimWorld;
use numpy::{PyArray1, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::errors::{run_error, Error};
use crate::law::{Factory, LawError};
use crate::world::{pydict, World};

self_cell::self_cell!(
    /// A world and the run that borrows it.
    struct Run {
        owner: Arc<SimWorld>,
        #[not_covariant]
        dependent: Loop,
    }
);

/// How a run's control law is chosen from Python: a built-in name or a law factory.
pub enum Choice {
    Builtin(ftcbf_sim::world::ControllerKindSpec),
    Python(Factory),
}

impl Choice {
    /// `None` (the world's controller), a built-in name, or a callable law factory.
    pub fn from_py(controller: Option<&Bound<'_, PyAny>>) -> PyResult<Option<Self>> {
        let Some(c) = controller.filter(|c| !c.is_none()) else {
            return Ok(None);
        };
        if let Ok(name) = c.extract::<String>() {
            return name
                .parse::<ftcbf_sim::world::ControllerKindSpec>()
                .map(|k| Some(Choice::Builtin(k)))
                .map_err(|e| pyo3::exceptions::PyValueError::new_err(e.to_string()));
        }
        Factory::new(c).map(|f| Some(Choice::Python(f)))
    }
}

/// Starts a run of `world` with `seed` (None: the world's) and the law `choice` (None: the
/// world's controller). A Python law reports its exceptions into `error`.
pub fn start<'w>(
    source: impl Into<Source<'w>>,
    seed: Option<u64>,
    duration: Option<f64>,
    choice: Option<&Choice>,
    error: &LawError,
) -> Result<Loop<'w>, ftcbf_sim::runner::RunError> {
    let source = source.into();
    let world = source.world();
    let mut opts = RunOptions {
        seed,
        controller: None,
        duration,
    };
    match choice {
        None => Loop::new(source, &opts),
        Some(Choice::Builtin(k)) => {
            opts.controller = Some(*k);
            Loop::new(source, &opts)
        }
        Some(Choice::Python(f)) => {
            let setup = source.setup(world.file.control.controller)?;
            let seed = seed.unwrap_or(world.file.seed);
            Loop::with_law(source, &opts, |_| f.build(world, &setup, seed, error))
        }
    }
}

/// What `Simulation` keeps behind its lock.
struct State {
    run: Run,
    error: LawError,
    recorder: Option<(Recorder, PathBuf)>,
}

impl State {
    /// The law's exception (as `ControlLawError`), if it raised.
    fn law_failure(&self, name: &str) -> Option<PyErr> {
        self.error.take(&format!("control law `{name}` raised"))
    }

    /// Flushes and closes the recording, if one is open.
    fn finish_recording(&mut self) -> PyResult<()> {
        match self.recorder.take() {
            Some((rec, _)) => rec
                .finish()
                .map_err(|e| Error::new_err(format!("recording: {e}"))),
            None => Ok(()),
        }
    }
}

/// One closed-loop run of a world (sensors → attacks → control law → drive → plant), stepped
/// by `step()` or run to the end by `run()`. The same world, seed and law give the same frames
/// and summary, bit for bit, as `ftcbf run`.
#[pyclass(module = "ftcbf")]
pub struct Simulation {
    state: Mutex<State>,
    controller: String,
    seed: u64,
    sensors: Vec<String>,
    filters: Vec<String>,
    barriers: Vec<String>,
    attacks: Vec<String>,
}

impl Simulation {
    fn lock(&self) -> PyResult<MutexGuard<'_, State>> {
        self.state.try_lock().map_err(|_| {
            Error::new_err("this Simulation is in use (run() in another thread, or it panicked)")
        })
    }
}

#[pymethods]
impl Simulation {
    /// A run of `world`. `seed`: the world's when None. `controller`: the world's when None,
    /// `"ft-cbf-clf"`, `"baseline"`, `"nominal"`, or a law factory: a callable (a class)
    /// taking a `LawConfig` and returning an object with `step(readings) -> (a_x, a_y)`.
    /// `duration` [s]: the world's when None.
    #[new]
    #[pyo3(signature = (world, seed = None, controller = None, duration = None))]
    fn new(
        world: &World,
        seed: Option<u64>,
        controller: Option<&Bound<'_, PyAny>>,
        duration: Option<f64>,
    ) -> PyResult<Self> {
        let choice = Choice::from_py(controller)?;
        let error = LawError::default();
        let run = Run::try_new(world.inner.clone(), |w| {
            start(&**w, seed, duration, choice.as_ref(), &error)
        });
        let run = match run {
            Ok(run) => run,
            Err(e) => {
                let name = match &choice {
                    Some(Choice::Python(f)) => f.name.clone(),
                    _ => String::new(),
                };
                return Err(error
                    .take(&format!("building the control law `{name}`"))
                    .unwrap_or_else(|| run_error(e)));
            }
        };
        let (scene, controller, seed) = run.with_dependent(|_, sim| {
            let s = sim.summary();
            (sim.scene(), s.controller, s.seed)
        });
        Ok(Self {
            state: Mutex::new(State {
                run,
                error,
                recorder: None,
            }),
            controller,
            seed,
            sensors: scene.channels,
            filters: scene.filters,
            barriers: scene.barriers,
            attacks: scene.attacks,
        })
    }

    /// Advances one control step and returns its `Frame`; None once the run is over (a
    /// recording is then closed). Raises `ControlLawError` when a Python law raised.
    fn step(&self, py: Python<'_>) -> PyResult<Option<Frame>> {
        let mut guard = self.lock()?;
        let st = &mut *guard;
        let recorder = &mut st.recorder;
        let frame = st
            .run
            .with_dependent_mut(|_, sim| -> PyResult<Option<Frame>> {
                let Some(f) = sim.step() else {
                    return Ok(None);
                };
                if let Some((rec, _)) = recorder.as_mut() {
                    rec.frame(&f);
                }
                Frame::from_sim(py, &f).map(Some)
            })?;
        if let Some(e) = st.law_failure(&self.controller) {
            return Err(e);
        }
        if frame.is_none() {
            st.finish_recording()?;
        }
        Ok(frame)
    }

    /// Runs to the end (in Rust, with the GIL released) and returns `summary()`.
    fn run<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let mut guard = self.lock()?;
        let st = &mut *guard;
        let (run, recorder, error) = (&mut st.run, &mut st.recorder, &st.error);
        py.detach(|| {
            run.with_dependent_mut(|_, sim| {
                while let Some(f) = sim.step() {
                    if let Some((rec, _)) = recorder.as_mut() {
                        rec.frame(&f);
                    }
                    if error.failed() {
                        break;
                    }
                }
            })
        });
        if let Some(e) = st.law_failure(&self.controller) {
            return Err(e);
        }
        st.finish_recording()?;
        summary_of(py, st)
    }

    /// What the run measured so far (the whole run once it is over): a dict with the fields
    /// and numbers of `ftcbf run --json`.
    fn summary<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let guard = self.lock()?;
        summary_of(py, &guard)
    }

    /// Records the run to `path` (a rerun `.rrd` file, as `ftcbf run --out` writes it): call
    /// before the first step; the file is complete when the run is over (the last `step()`
    /// or `run()`).
    fn record(&self, path: PathBuf) -> PyResult<()> {
        let mut guard = self.lock()?;
        let st = &mut *guard;
        let (k, _) = st.run.with_dependent(|_, sim| sim.progress());
        if k > 0 || st.recorder.is_some() {
            return Err(Error::new_err(
                "record() must be called once, before the first step",
            ));
        }
        let name = RecordingName {
            world: st.run.borrow_owner().name.clone(),
            controller: self.controller.clone(),
            seed: self.seed,
        };
        let mut rec = Recorder::create(&path, &name)
            .map_err(|e| Error::new_err(format!("recording: {e}")))?;
        st.run.with_dependent_mut(|_, sim| {
            sim.set_link_poses(true);
            rec.scene(&sim.scene());
        });
        st.recorder = Some((rec, path));
        Ok(())
    }

    /// The control law's name (`ft-cbf-clf`, …, or a Python law's).
    #[getter]
    fn controller(&self) -> &str {
        &self.controller
    }

    /// The run's seed.
    #[getter]
    fn seed(&self) -> u64 {
        self.seed
    }

    /// Control steps taken so far, and in the whole run.
    #[getter]
    fn progress(&self) -> PyResult<(u64, u64)> {
        Ok(self.lock()?.run.with_dependent(|_, sim| sim.progress()))
    }

    /// Sensor names, in the order of `Frame.received` and the other per-sensor arrays.
    #[getter]
    fn sensors(&self) -> Vec<String> {
        self.sensors.clone()
    }

    /// Estimator names, in the order of the rows of `Frame.estimates` and `Frame.h`.
    #[getter]
    fn filters(&self) -> Vec<String> {
        self.filters.clone()
    }

    /// Barrier names, in the order of the columns of `Frame.h` and of `Frame.h_true`.
    #[getter]
    fn barriers(&self) -> Vec<String> {
        self.barriers.clone()
    }

    /// Attack labels, in the order of `Frame.attacks_active`.
    #[getter]
    fn attacks(&self) -> Vec<String> {
        self.attacks.clone()
    }

    fn __repr__(&self) -> String {
        format!(
            "Simulation(controller={:?}, seed={})",
            self.controller, self.seed
        )
    }
}

fn summary_of<'py>(py: Python<'py>, st: &State) -> PyResult<Bound<'py, PyAny>> {
    let s = st.run.with_dependent(|_, sim| sim.summary());
    let text = serde_json::to_string(&s).map_err(|e| Error::new_err(e.to_string()))?;
    crate::json_to_py(py, &text)
}

/// One control step as Python data (numpy arrays, floats, strings).
#[pyclass(frozen, get_all, module = "ftcbf")]
pub struct Frame {
    /// Simulation time [s].
    t: f64,
    /// Control step index.
    step: u64,
    /// Ground truth: x, y [m], theta [rad], vx, vy, v_body [m/s], omega [rad/s], wheel speeds
    /// [rad/s] and angles [rad] (NaN without wheels).
    truth: Py<PyDict>,
    /// Per sensor (`Simulation.sensors`): what the controller received after the attacks.
    received: Py<PyArray1<f64>>,
    /// Per sensor: the clean measurement (truth + noise + bias).
    clean: Py<PyArray1<f64>>,
    /// Per sensor: a new sample arrived this step.
    fresh: Py<PyArray1<bool>>,
    /// Per sensor: the controller threw the reading out.
    rejected: Py<PyArray1<bool>>,
    /// Per sensor: the all-channel filter's normalised innovation (NaN when not applicable).
    detector_z: Py<PyArray1<f64>>,
    /// Per estimator (`Simulation.filters`): x̂ = (p_x, p_y, v_x, v_y), shape (filters, 4).
    estimates: Py<PyAny>,
    /// Per estimator: the residue norm of Step 3.
    residues: Py<PyArray1<f64>>,
    /// Per estimator: V(x̂) of the CLF.
    clf: Py<PyArray1<f64>>,
    /// h(x̂) per estimator (row) and barrier (column), shape (filters, barriers).
    h: Py<PyAny>,
    /// h(x_true) per barrier (`Simulation.barriers`).
    h_true: Py<PyArray1<f64>>,
    /// The input u = (a_x, a_y) [m/s²].
    u: Py<PyArray1<f64>>,
    /// The body command (v [m/s], ω [rad/s]) sent to the drive (zero for the linear plant).
    command: Py<PyArray1<f64>>,
    /// Which stage of the policy decided (`step1`, `clf_relaxed`, `step2`, `step3`,
    /// `infeasible`), or the law's name for a law without stages.
    stage: String,
    /// Why constraints were dropped this step ("" when none were).
    note: String,
    /// Per attack (`Simulation.attacks`): active now.
    attacks_active: Py<PyArray1<bool>>,
    /// Collisions and safety violations that started this step.
    events: Vec<String>,
}

impl Frame {
    fn from_sim(py: Python<'_>, f: &SimFrame<'_>) -> PyResult<Self> {
        let arr = |v: Vec<f64>| PyArray1::from_vec(py, v).unbind();
        let flags = |v: Vec<bool>| PyArray1::from_vec(py, v).unbind();
        let ch = f.channels;
        let tr = f.truth;
        let truth = pydict!(py, {
            "x": tr.x, "y": tr.y, "theta": tr.theta, "vx": tr.vx, "vy": tr.vy,
            "v_body": tr.v_body, "omega": tr.omega,
            "wheel_left": tr.wheel_left, "wheel_right": tr.wheel_right,
            "wheel_angle_left": tr.wheel_angle_left, "wheel_angle_right": tr.wheel_angle_right,
        });
        let n_filters = f.estimates.len();
        let estimates: Vec<f64> = f.estimates.iter().flat_map(|e| e.x).collect();
        let n_barriers = f.barrier_truth.len();
        let h = PyArray1::from_slice(py, f.barrier_values);
        let h = if n_filters * n_barriers == f.barrier_values.len() {
            h.reshape([n_filters, n_barriers])?.into_any().unbind()
        } else {
            h.into_any().unbind()
        };
        Ok(Self {
            t: f.t,
            step: f.step,
            truth: truth.unbind(),
            received: arr(ch.iter().map(|c| c.received).collect()),
            clean: arr(ch.iter().map(|c| c.clean).collect()),
            fresh: flags(ch.iter().map(|c| c.fresh).collect()),
            rejected: flags(ch.iter().map(|c| c.rejected).collect()),
            detector_z: arr(ch.iter().map(|c| c.detector_z).collect()),
            estimates: PyArray1::from_vec(py, estimates)
                .reshape([n_filters, 4])?
                .into_any()
                .unbind(),
            residues: arr(f.estimates.iter().map(|e| e.residue).collect()),
            clf: arr(f.estimates.iter().map(|e| e.clf).collect()),
            h,
            h_true: arr(f.barrier_truth.to_vec()),
            u: arr(f.u.to_vec()),
            command: arr(f.body_cmd.to_vec()),
            stage: f.decided_by.to_string(),
            note: f.decision_note.to_string(),
            attacks_active: flags(f.attacks_active.to_vec()),
            events: f.events.to_vec(),
        })
    }
}

#[pymethods]
impl Frame {
    fn __repr__(&self) -> String {
        format!(
            "Frame(t={:.3}, step={}, stage={:?}, events={:?})",
            self.t, self.step, self.stage, self.events
        )
    }
}
