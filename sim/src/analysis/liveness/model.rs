//! The model the prediction reads: each kept unit's filter gains and γ, θ_ij(t), and
//! [`Model`]'s construction from a compiled world, with the declared attack's responses, the
//! detector's view of it and the spoofed estimates' offsets over time.

use super::*;
use crate::analysis::check::estimation::filter_label;
use ftcbf_controller::controller::accepts_reading;

/// The unit of a filter that keeps `mask`, with its gain terms: steady state, or the worst
/// posterior over the run from P0 when the recursion has none.
pub(super) fn unit(world: &World, setup: &ControlSetup, mask: Vec<bool>, gamma: f64) -> Unit {
    let model = &setup.config.model;
    let dt = world.control_dt();
    let ss = steady_state_riccati(model, &mask, dt);
    let steady = ss.converged && ss.posterior.iter().all(|v| v.is_finite());
    let (prior, post) = if steady {
        (ss.prior, ss.posterior)
    } else {
        let n = world.horizon_ticks();
        let post = horizon_posterior_max(model, &mask, dt, &initial_covariance(world), n);
        let d = model.discretize(dt);
        let prior = d.phi * post * d.phi.transpose() + d.qd;
        (prior, post)
    };
    let m = gain_product(model, &mask, &post, dt);
    let diff = (prior - post) / dt;
    Unit {
        gamma,
        m,
        n: (diff + diff.transpose()) * 0.5,
        prior: steady.then_some(prior),
        mask,
    }
}

/// θ between units i and j after `t` seconds: the schedule θ_ij(t) where there is one, else
/// the constant θ_ij (or one value for all).
pub(super) fn theta_at(setup: &ControlSetup, m: usize, i: usize, j: usize, t: f64) -> f64 {
    let scheduled = pair_slot(m, i, j).and_then(|slot| {
        setup
            .config
            .ft
            .theta_schedule
            .as_ref()
            .and_then(|s| s.at(slot, t))
    });
    scheduled
        .or_else(|| FtParams::per_pair(&setup.config.ft.theta, m, i, j))
        .unwrap_or(f64::INFINITY)
}

impl<'a> Model<'a> {
    pub(super) fn new(world: &'a World, setup: &'a ControlSetup) -> Option<Self> {
        let cfg = &setup.config;
        let q = cfg.model.channels();
        let m = cfg.fault_patterns.len();
        let units: Vec<Unit> = match cfg.kind {
            ControllerKind::Nominal => return None,
            ControllerKind::FtCbfClf => (0..m)
                .map(|i| {
                    let mask = channel_mask(q, &cfg.fault_patterns, &[i]);
                    unit(world, setup, mask, setup.config.ft.gamma[i])
                })
                .collect(),
            ControllerKind::Baseline => vec![unit(
                world,
                setup,
                vec![true; q],
                setup.config.ft.gamma_baseline,
            )],
        };
        let x0 = cfg.x0;
        let mut path = vec![[x0[0], x0[1]]];
        let (goal, goal_radius) = match &cfg.form {
            ProblemForm::SafetyFilter { tracker, .. } => {
                path.extend(tracker.waypoints.iter().copied());
                (tracker.goal, tracker.goal_radius)
            }
            ProblemForm::Paper => {
                path.extend(world.file.goal.waypoints.iter().copied());
                (world.file.goal.center, world.file.goal.radius)
            }
        };
        path.push(goal);
        let max_coord = path
            .iter()
            .map(|p| p[0].abs().max(p[1].abs()))
            .fold(0.0, f64::max);
        // The declared attack: which pattern, which units it moves (those that read it).
        let attacked = crate::world::structure::attacked_pattern(world).unwrap_or_else(|e| e.first);
        let axes = declared_reach(world, 0.0, 0.0, max_coord).axes;
        let speed = match &cfg.form {
            ProblemForm::SafetyFilter { tracker, .. } => tracker.cruise_speed,
            ProblemForm::Paper => crate::world::structure::speed_bound(world).unwrap_or(0.2),
        } * NOMINAL_SPEED_SHARE;
        let spoofed = match (cfg.kind, attacked) {
            (ControllerKind::FtCbfClf, Some(a)) => {
                (0..m).filter(|&i| i != a).map(|i| (i, a)).collect()
            }
            (ControllerKind::Baseline, Some(a)) => vec![(0, a)],
            _ => Vec::new(),
        };
        let attack_name = world
            .file
            .attacks
            .iter()
            .map(|a| format!("{} on {}", a.kind.name(), a.channels.join("+")))
            .collect::<Vec<_>>()
            .join(", ");
        let mut model = Self {
            setup,
            units,
            spoofed,
            path,
            goal,
            goal_radius,
            patterns: m,
            axes,
            speed,
            max_coord,
            attack_name,
            world,
            response: None,
            response_nis: None,
            drifts: Vec::new(),
        };
        model.drifts = model.drifts();
        if let Some((off, nis)) = model.responses() {
            model.response = Some(off);
            model.response_nis = Some(nis);
        }
        Some(model)
    }

    /// The spoofed units the declared attack leaves without any fix of an axis ([`Drift`]):
    /// its dropouts, non-finite values and absurd ones beyond the controller's
    /// `max_abs_reading` take the attacked channels' readings away (the controller rejects
    /// them), and a unit with no other channel on the axis (position or
    /// velocity) dead-reckons it. Its estimate then runs off at the velocity error it had when
    /// the readings went: in a generated room (gen51_035 of `scripts/movers_sweep.sh 51`, NaN
    /// on gnss2_y) the unit that reads gnss2 ran 0.75 m off in 42 s, at a steady 0.018 m/s,
    /// and its rows against a wall pushed the robot out of its goal. A unit without a steady
    /// state is left out (its velocity error is not bounded by one).
    fn drifts(&self) -> Vec<Drift> {
        let f = &self.world.file;
        let cfg = &self.setup.config;
        // An absurd value the controller does not reject is a fix far off, which Step 2 isolates.
        let removes = |a: &AttackSpec| match a.kind {
            AttackKind::Dropout {} | AttackKind::NonFinite { .. } => true,
            // The controller's own test: a reading is used when finite and within the limit.
            AttackKind::Absurd { value } => !accepts_reading(value, cfg.max_abs_reading),
            _ => false,
        };
        let taking: Vec<&AttackSpec> = f.attacks.iter().filter(|a| removes(a)).collect();
        let Some(start) = taking.iter().map(|a| a.start).reduce(f64::min) else {
            return Vec::new();
        };
        let end = taking
            .iter()
            .map(|a| a.end)
            .try_fold(f64::NEG_INFINITY, |e, x| x.map(|x| e.max(x)));
        let lost = |ch: usize| {
            let name = &f.sensors[self.setup.sensor_of_channel[ch]].name;
            taking.iter().any(|a| a.channels.contains(name))
        };
        let fixes = |ch: usize, axis: usize| {
            let c = &cfg.model.c[ch];
            c[axis] != 0.0 || c[axis + 2] != 0.0
        };
        self.spoofed
            .iter()
            .filter_map(|&(ui, _)| {
                let u = &self.units[ui];
                let prior = u.prior?;
                let used = |ch: &usize| u.mask.get(*ch) == Some(&true);
                let axes = [0, 1].map(|axis| {
                    let before = (0..u.mask.len()).filter(used).any(|ch| fixes(ch, axis));
                    let after = (0..u.mask.len())
                        .filter(used)
                        .any(|ch| !lost(ch) && fixes(ch, axis));
                    before && !after
                });
                (axes[0] || axes[1]).then(|| Drift {
                    unit: ui,
                    start,
                    end,
                    axes,
                    sigma_v: [prior[(2, 2)].max(0.0).sqrt(), prior[(3, 3)].max(0.0).sqrt()],
                })
            })
            .collect()
    }

    /// Each spoofed unit's estimate offset at every control step, exact by linearity: a
    /// steady-state Kalman filter's estimate moves by its own response to the offsets the attack
    /// adds to its readings (`update_gains`), whatever the state and the input, so the offset
    /// is that response to [`open_loop_offset`] along the planned timeline ([`Model::truth_at`]).
    /// A position fix attacked in a filter that also reads velocity is pulled back by it, a
    /// velocity offset in one that reads positions stays bounded, a scale follows the true
    /// coordinate where the robot is. `None` (the bound of [`declared_reach`] is used instead)
    /// when an attacked sensor is not a position or velocity fix or a speed the filters read as
    /// world velocity, or when a spoofed filter has no steady state.
    ///
    /// Sensors slower than the control rate (the periods of the setup's
    /// [`crate::world::structure::sensor_timing`], without dropouts) make the gains vary with the channels that are fresh at each
    /// tick: the filters then run their Riccati recursion on that schedule from their periodic
    /// steady state ([`ScheduledFilters`]). With steady-state gains of every channel at every
    /// tick, an honest receiver at 5 Hz pulled a stealthy attacker's bias back ten times as often
    /// as it does, and the prediction said 0.078 m where a run's spoofed estimate was 0.27 m off
    /// (gen55_027 of `scripts/movers_sweep.sh 55`).
    ///
    /// With each offset, what the attack adds to the unit's normalised innovations squared
    /// (the innovation a channel sees is the reading's offset minus the estimate's, c·x, before
    /// that channel's sequential update; S is its steady-state innovation variance): how far
    /// Step 3's χ² ranking can tell the spoofed unit from the honest one.
    #[allow(clippy::type_complexity)]
    pub(super) fn responses(&self) -> Option<(Vec<Vec<[f64; 2]>>, Vec<(Vec<f64>, usize)>)> {
        let f = &self.world.file;
        if f.attacks.is_empty() || self.spoofed.is_empty() || !self.attacks_read_as_fixes() {
            return None;
        }
        let cfg = &self.setup.config;
        let mut gains = self
            .spoofed
            .iter()
            .map(|&(ui, _)| {
                let u = &self.units[ui];
                Some(update_gains(&cfg.model, &u.mask, u.prior.as_ref()?))
            })
            .collect::<Option<Vec<_>>>()?;
        let dt = self.world.control_dt();
        let n = self.world.horizon_ticks() + 1;
        let phi = cfg.model.discretize(dt).phi;
        let q = cfg.model.channels();
        let mut e = vec![State::zeros(); gains.len()];
        let mut out = vec![Vec::with_capacity(n); gains.len()];
        let mut d = vec![0.0; q];
        let mut variances = self.innovation_variances(&gains);
        let mut nis: Vec<(Vec<f64>, usize)> = gains
            .iter()
            .map(|g| (Vec::with_capacity(n), g.len()))
            .collect();
        let mut offsets = OffsetSource {
            detector: self.stealth_detector(),
            players: f
                .attacks
                .iter()
                .map(|a| vec![StealthyPlay::default(); a.channels.len()])
                .collect(),
            rng: ChaCha20Rng::seed_from_u64(f.seed ^ 0x5354_4541_4c54_4859),
        };
        let mut e_all = State::zeros();
        let on_channel = self.attacks_by_channel();
        // Sensors slower than the control rate: the filters' gains vary with which channels are
        // fresh at each tick (a Riccati recursion on the sensors' own schedule from each
        // filter's periodic steady state), for the detector and for each spoofed unit.
        let mut sched = self.scheduled_filters(&offsets, dt);
        for k in 0..n {
            let t = k as f64 * dt;
            if let Some(sf) = sched.as_mut() {
                let (det, units) = sf.step(&cfg.model, k);
                if let Some((g, sd)) = offsets.detector.as_mut() {
                    *g = det.0;
                    *sd = det.1;
                }
                (gains, variances) = units;
            }
            let all_prior = phi * e_all;
            self.channel_offsets(t, all_prior, &on_channel, &mut offsets, &mut d);
            if let Some((g, _)) = &offsets.detector {
                let mut x = all_prior;
                for (ch, kg, ikc) in g {
                    x = ikc * x + kg * d[*ch];
                }
                e_all = x;
            }
            for (((ek, g), o), (ni, sv)) in e
                .iter_mut()
                .zip(&gains)
                .zip(out.iter_mut())
                .zip(nis.iter_mut().zip(&variances))
            {
                let mut x = phi * *ek;
                let mut a2 = 0.0;
                for ((ch, kg, ikc), s) in g.iter().zip(sv) {
                    let a = d[*ch] - (cfg.model.c[*ch] * x)[0];
                    a2 += a * a / s;
                    x = ikc * x + kg * d[*ch];
                }
                *ek = x;
                o.push([x[0], x[1]]);
                ni.0.push(a2);
            }
        }
        Some((out, nis))
    }

    /// The filters of [`Self::responses`] on the sensors' own schedule (None when every channel
    /// reads every tick: the steady-state gains are then exact).
    fn scheduled_filters(&self, src: &OffsetSource, dt: f64) -> Option<ScheduledFilters> {
        let cfg = &self.setup.config;
        let q = cfg.model.channels();
        let timing = &self.setup.params.timing;
        let every: Vec<usize> = timing.channels.iter().map(|c| c.period.max(1)).collect();
        if every.iter().all(|&e| e == 1) {
            return None;
        }
        let schedule = ftcbf_controller::params::UpdateSchedule { every };
        let start = |mask: &[bool]| -> Option<(Vec<Vec<bool>>, StateMatrix)> {
            let phases = schedule.phases(mask);
            let ss = ftcbf_controller::params::periodic_riccati(&cfg.model, &phases, dt);
            ss.converged.then_some((phases, ss.prior))
        };
        let detector = match &src.detector {
            Some(_) => Some(start(&vec![true; q])?),
            None => None,
        };
        let units = self
            .spoofed
            .iter()
            .map(|&(ui, _)| start(&self.units[ui].mask))
            .collect::<Option<Vec<_>>>()?;
        Some(ScheduledFilters {
            d: cfg.model.discretize(dt),
            detector,
            units,
        })
    }

    /// Whether every attacked channel is a position or velocity fix, or a speed the filters
    /// read as world velocity (the only readings [`Self::responses`] can follow).
    pub(super) fn attacks_read_as_fixes(&self) -> bool {
        let f = &self.world.file;
        f.attacks.iter().flat_map(|a| &a.channels).all(|c| {
            f.sensors.iter().find(|s| &s.name == c).is_some_and(|s| {
                direct_fix(s.measures) || (s.measures == Quantity::Speed && s.world_velocity)
            })
        })
    }

    /// Per spoofed unit, each sequential update's innovation variance S = c P cᵀ + r.
    pub(super) fn innovation_variances(&self, gains: &[UpdateGains]) -> Vec<Vec<f64>> {
        let model = &self.setup.config.model;
        self.spoofed
            .iter()
            .zip(gains)
            .map(|(&(ui, _), g)| {
                sequential_updates(model, g, &self.units[ui].prior.unwrap_or_default()).0
            })
            .collect()
    }

    /// A stealthy attacker hides under the all-channel filter's detector (as in a run): that
    /// filter's response to the attack, and its innovation std per channel, decide how far the
    /// bias can grow. `None` without a stealthy attack or when that filter has no prior.
    pub(super) fn stealth_detector(&self) -> Option<(UpdateGains, Vec<f64>)> {
        let f = &self.world.file;
        let cfg = &self.setup.config;
        let q = cfg.model.channels();
        let stealthy = f
            .attacks
            .iter()
            .any(|a| matches!(a.kind, AttackKind::Stealthy { .. }));
        stealthy
            .then(|| {
                let all = unit(self.world, self.setup, vec![true; q], 0.0);
                let prior = all.prior?;
                let s = innovation_stds(&cfg.model, &prior);
                Some((update_gains(&cfg.model, &all.mask, &prior), s))
            })
            .flatten()
    }

    /// Per channel: its sensor, and the attacks on it with the attack's index and the
    /// channel's place in it.
    pub(super) fn attacks_by_channel(&self) -> Vec<ChannelHits<'_>> {
        let f = &self.world.file;
        (0..self.setup.config.model.channels())
            .map(|ch| {
                let s = &f.sensors[self.setup.sensor_of_channel[ch]];
                let hits: Vec<_> = f
                    .attacks
                    .iter()
                    .enumerate()
                    .filter_map(|(ai, a)| {
                        Some((ai, a, a.channels.iter().position(|c| c == &s.name)?))
                    })
                    .collect();
                (s, hits)
            })
            .collect()
    }

    /// Each channel's reading offset at `t` into `d`: the sum of the attacks on it, a stealthy
    /// one played against the detector's prior `all_prior` with a drawn honest innovation, and
    /// a `speed` reading turned into world velocity along the path's heading.
    pub(super) fn channel_offsets(
        &self,
        t: f64,
        all_prior: State,
        on_channel: &[ChannelHits],
        src: &mut OffsetSource,
        d: &mut [f64],
    ) {
        let cfg = &self.setup.config;
        // The heading a `speed` channel is read along: the path's direction now.
        let heading = self.truth_at(t).1;
        for ((ch, dk), (s, hits)) in d.iter_mut().enumerate().zip(on_channel) {
            let truth = |tt: f64| {
                let (p, tan, v) = self.truth_at(tt);
                match s.measures {
                    Quantity::X => p[0],
                    Quantity::Y => p[1],
                    Quantity::Vx => v * tan[0],
                    Quantity::Vy => v * tan[1],
                    _ => v,
                }
            };
            let mut off = 0.0;
            for &(ai, a, j) in hits {
                off += match (&a.kind, &src.detector) {
                    (AttackKind::Stealthy { .. }, Some((_, sd))) if direct_fix(s.measures) => {
                        let nu =
                            sd[ch] * Distribution::<f64>::sample(&StandardNormal, &mut src.rng);
                        let moved = (cfg.model.c[ch] * all_prior)[0];
                        src.players[ai][j].offset(a, j, t, nu, moved, sd[ch])
                    }
                    _ => open_loop_offset(a, j, t, &truth),
                };
            }
            *dk = if s.measures == Quantity::Speed {
                // Read as world velocity along the heading.
                off * if cfg.model.c[ch][2] != 0.0 {
                    heading[0]
                } else {
                    heading[1]
                }
            } else {
                off
            };
        }
    }

    /// How far the attack moves the spoofed unit `k` (index into `spoofed`)'s windowed χ²
    /// score over the [`RESIDUE_WINDOW`] ending at `t`, in the score's own units (an honest
    /// filter's score is ≈ N(0, 1)): the attack's a²/S added to the window's expected sum.
    pub(super) fn ranking_shift(&self, k: usize, t: f64) -> f64 {
        let Some((nis, channels)) = self.response_nis.as_ref().and_then(|v| v.get(k)) else {
            return 0.0;
        };
        let dt = self.world.control_dt();
        let end = ((t / dt).round().max(0.0) as usize).min(nis.len().saturating_sub(1));
        let len = ((RESIDUE_WINDOW / dt).round() as usize).max(1);
        let start = (end + 1).saturating_sub(len);
        let added: f64 = nis[start..=end].iter().sum();
        let dof = (len * channels) as u32;
        chi_square_z(f64::from(dof) + added, dof) - chi_square_z(f64::from(dof), dof)
    }

    /// Where the robot is assumed at time `t` on the planned timeline (still for
    /// [`START_DELAY`], then along the path at `speed`, then at the goal): position, the path's
    /// direction there (the heading), and speed.
    pub(super) fn truth_at(&self, t: f64) -> ([f64; 2], [f64; 2], f64) {
        let along = ((t - START_DELAY) * self.speed).max(0.0);
        let moving = t > START_DELAY && along < self.length();
        let mut rest = along;
        let mut last = ([self.path[0][0], self.path[0][1]], [1.0, 0.0]);
        for w in self.path.windows(2) {
            let (a, b) = (w[0], w[1]);
            let len = (b[0] - a[0]).hypot(b[1] - a[1]);
            if len < 1e-9 {
                continue;
            }
            let tan = [(b[0] - a[0]) / len, (b[1] - a[1]) / len];
            if rest <= len {
                let p = [a[0] + tan[0] * rest, a[1] + tan[1] * rest];
                return (p, tan, if moving { self.speed } else { 0.0 });
            }
            rest -= len;
            last = (b, tan);
        }
        (last.0, last.1, 0.0)
    }

    /// The estimates' offsets to try at time `t`: none without attack; under it, the exact
    /// response where there is one, else every direction of the declared reach for every
    /// spoofed unit.
    pub(super) fn scenarios_at(&self, t: f64, attack: bool) -> Vec<Offsets> {
        let zero = vec![[0.0, 0.0]; self.units.len()];
        if !attack {
            return vec![zero];
        }
        let base = self.spoofing_at(t, zero);
        // A unit that dead-reckons an axis runs off along it, in either direction.
        let drifts: Vec<(usize, [f64; 2])> = self
            .drifts
            .iter()
            .filter_map(|d| Some((d.unit, d.at(t)?)))
            .collect();
        if drifts.is_empty() {
            return base;
        }
        let axes = [0, 1].map(|a| drifts.iter().any(|(_, o)| o[a] > 0.0));
        let add = |v: &mut Offsets, dir: [f64; 2]| {
            for &(ui, o) in &drifts {
                v[ui][0] += dir[0] * o[0];
                v[ui][1] += dir[1] * o[1];
            }
        };
        if let [one] = base.as_slice() {
            return offsets(axes, 1.0)
                .into_iter()
                .map(|dir| {
                    let mut v = one.clone();
                    add(&mut v, dir);
                    v
                })
                .collect();
        }
        // The declared reach already spans the directions: each runs off along its own.
        base.into_iter()
            .map(|mut v| {
                let r = self.spoofed.first().map_or([1.0, 0.0], |&(ui, _)| v[ui]);
                let n = r[0].hypot(r[1]);
                let dir = if n > 0.0 {
                    [r[0] / n, r[1] / n]
                } else {
                    [1.0, 0.0]
                };
                add(&mut v, dir);
                v
            })
            .collect()
    }

    /// What the declared attack's lost fixes do ([`Drift`]), in one phrase (None: nothing lost).
    pub(super) fn drift_note(&self) -> Option<String> {
        let f = &self.world.file;
        let end = f.duration;
        let patterns: Vec<&str> = f.fault_patterns.iter().map(|p| p.name.as_str()).collect();
        let lines: Vec<String> = self
            .drifts
            .iter()
            .map(|d| {
                let unit = match self.setup.config.kind {
                    ControllerKind::FtCbfClf => filter_label(&[d.unit], &patterns),
                    _ => "the baseline's filter".to_string(),
                };
                let axes: Vec<&str> = [("x", d.axes[0]), ("y", d.axes[1])]
                    .iter()
                    .filter(|a| a.1)
                    .map(|a| a.0)
                    .collect();
                let sigma = (0..2)
                    .filter(|&a| d.axes[a])
                    .map(|a| d.sigma_v[a])
                    .fold(0.0, f64::max);
                let last = d.end.map_or(end, |e| e.min(end));
                let far = d.at(last - 1e-9).map_or(0.0, |o| o[0].hypot(o[1]));
                format!(
                    "{unit} has no fix of {} from t = {:.1} s: it dead-reckons at the velocity error it had then (std {sigma:.4} m/s; taken at {ONE_SIDED_95} std, one side's 95 %), up to {far:.3} m off by t = {last:.1} s, and its rows keep the robot clear of the obstacles from there",
                    axes.join(" or "),
                    d.start,
                )
            })
            .collect();
        (!lines.is_empty()).then(|| {
            format!(
                "{}. A fix of that axis the attack cannot take (wheel odometry in every filter, or a third receiver) bounds it",
                lines.join("; ")
            )
        })
    }

    /// Unit `ui`'s steady-state position-error std, its larger axis's \[m\] (0 without one).
    pub(super) fn position_std(&self, ui: usize) -> f64 {
        self.units
            .get(ui)
            .and_then(|u| u.prior)
            .map_or(0.0, |p| p[(0, 0)].max(p[(1, 1)]).max(0.0).sqrt())
    }

    /// Whether unit `ui` dead-reckons some axis at `t` ([`Drift`]).
    pub(super) fn drifting(&self, ui: usize, t: f64) -> bool {
        self.drifts
            .iter()
            .any(|d| d.unit == ui && d.at(t).is_some())
    }

    /// The spoofed estimates' offsets at `t` under the declared attack, before any drift: the
    /// exact response where there is one, else every direction of the declared reach.
    fn spoofing_at(&self, t: f64, zero: Offsets) -> Vec<Offsets> {
        if let Some(resp) = &self.response {
            let mut v = zero;
            for (&(ui, _), r) in self.spoofed.iter().zip(resp) {
                let k = ((t / self.world.control_dt()).round().max(0.0) as usize)
                    .min(r.len().saturating_sub(1));
                v[ui] = r.get(k).copied().unwrap_or([0.0, 0.0]);
            }
            return vec![v];
        }
        offsets(self.axes, self.reach_at(t))
            .into_iter()
            .map(|o| {
                let mut v = zero.clone();
                for &(ui, _) in &self.spoofed {
                    v[ui] = o;
                }
                v
            })
            .collect()
    }

    /// The rows `a·u ≤ b` (unit normals) of every unit at its estimate, with the barrier index
    /// of each, for κ and a given offset of the spoofed units.
    pub(super) fn rows(
        &self,
        p: [f64; 2],
        offsets: &[[f64; 2]],
        t: f64,
        kappa: f64,
        out: &mut Vec<(HalfSpace, usize, f64)>,
    ) {
        out.clear();
        let cfg = &self.setup.config;
        for (ui, u) in self.units.iter().enumerate() {
            let off = offsets[ui];
            // Step 2 drops an estimate farther than θ_ia(t) from the honest one (the baseline
            // has no Step 2).
            if let Some(&(i, a)) = self.spoofed.iter().find(|(i, _)| *i == ui) {
                if cfg.kind == ControllerKind::FtCbfClf
                    && off[0].hypot(off[1]) > theta_at(self.setup, self.patterns, i, a, t)
                {
                    continue;
                }
            }
            let x = State::new(p[0] + off[0], p[1] + off[1], 0.0, 0.0);
            // Rows out of reach hold for every input of the box: they change neither the best
            // acceleration nor the rows that demand a push (issue #52, crate::active). A moving
            // obstacle's rows are not a place on the path: whether the robot waits for it or is
            // blocked for good is `crate::movers::passage::liveness`'s.
            let far = crate::active::out_of_reach(cfg, &x, (&u.m, &u.n), u.gamma, kappa);
            for (bi, b) in cfg.barriers.iter().enumerate() {
                if far.get(bi) == Some(&true) || b.mover().is_some() {
                    continue;
                }
                let eval = b.eval(&x);
                let h_bar = b.h_bar(u.gamma);
                if eval.value - h_bar >= cfg.delta {
                    continue;
                }
                let row = cbf_row(&cfg.model, &eval, &x, &u.m, &u.n, u.gamma, h_bar, kappa);
                out.push((row.half_space(), bi, row.omega_bar));
            }
        }
    }
}

/// Filters whose gains follow the sensors' schedule ([`Model::scheduled_filters`]): each one's
/// update phases and its current prior covariance.
pub(super) struct ScheduledFilters {
    d: ftcbf_controller::model::Discretization,
    detector: Option<(Vec<Vec<bool>>, StateMatrix)>,
    units: Vec<(Vec<Vec<bool>>, StateMatrix)>,
}

impl ScheduledFilters {
    /// Tick `k`'s gains and innovation stds for the detector, and gains and innovation
    /// variances for each unit; each prior then moves to tick k + 1.
    #[allow(clippy::type_complexity)]
    pub(super) fn step(
        &mut self,
        model: &ftcbf_controller::LinearModel,
        k: usize,
    ) -> ((UpdateGains, Vec<f64>), (Vec<UpdateGains>, Vec<Vec<f64>>)) {
        let d = &self.d;
        let advance = |phases: &[Vec<bool>], p: &mut StateMatrix| -> (UpdateGains, Vec<f64>) {
            let g = update_gains(model, &phases[k % phases.len()], p);
            let (s, post) = sequential_updates(model, &g, p);
            *p = d.phi * post * d.phi.transpose() + d.qd;
            (g, s)
        };
        let det = match self.detector.as_mut() {
            Some((phases, p)) => {
                let sd = innovation_stds(model, p);
                let (g, _) = advance(phases, p);
                (g, sd)
            }
            None => (Vec::new(), Vec::new()),
        };
        let (mut gs, mut vs) = (Vec::new(), Vec::new());
        for (phases, p) in self.units.iter_mut() {
            let (g, s) = advance(phases, p);
            gs.push(g);
            vs.push(s);
        }
        (det, (gs, vs))
    }
}

/// Each sequential update's innovation variance S = c P cᵀ + r of a filter with `gains` from
/// `prior`, and its posterior (Joseph form).
fn sequential_updates(
    model: &ftcbf_controller::LinearModel,
    gains: &UpdateGains,
    prior: &StateMatrix,
) -> (Vec<f64>, StateMatrix) {
    let mut p = *prior;
    let s = gains
        .iter()
        .map(|(ch, kg, ikc)| {
            let c = model.c[*ch];
            let s = (c * p * c.transpose())[0] + model.r[*ch];
            p = ikc * p * ikc.transpose() + kg * kg.transpose() * model.r[*ch];
            s
        })
        .collect();
    (s, p)
}

/// Per channel, the innovation standard deviation √(c P cᵀ + r) of a filter with `prior`.
fn innovation_stds(model: &ftcbf_controller::LinearModel, prior: &StateMatrix) -> Vec<f64> {
    (0..model.channels())
        .map(|ch| {
            let c = model.c[ch];
            ((c * prior * c.transpose())[0] + model.r[ch]).sqrt()
        })
        .collect()
}
