//! Hypotheses 1–4b and 6b: what the estimation rests on — disjoint patterns, converted
//! odometry, the heading, white noise, each filter's R̄, detectability and bound, the sensors'
//! timing, finite γ and θ, the transient from P0, the drive model.

use super::*;

/// 1b. Wheel odometry turned into world-frame velocity with the heading: its channels are made
/// from the speed channel, the wheel channels it is derived from, the heading channel and the gyro
/// fused into it, so a fault in any of their patterns corrupts them. The patterns stay disjoint in
/// effect only if all of those sensors that are in a pattern are in the same one (the others are
/// trusted: an attack on them is outside the model).
pub(super) fn check_converted_odometry(cx: Ctx<'_>, found: &mut Findings) {
    let Ctx { world, names, .. } = cx;
    let f = &world.file;
    let Some(h) = heading_sensor(world) else {
        return;
    };
    let pattern_of = |si: usize| world.patterns.iter().position(|p| p.contains(&si));
    for (si, s) in f.sensors.iter().enumerate() {
        if !s.world_velocity {
            continue;
        }
        let sources: Vec<usize> = (0..f.sensors.len())
            .filter(|&o| sensor_dependents(world, o).contains(&si))
            .collect();
        let list = |sel: &dyn Fn(usize) -> bool| -> String {
            sources
                .iter()
                .filter(|&&o| sel(o))
                .map(|&o| f.sensors[o].name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        };
        let name = format!(
            "odometry {} → world velocity with heading {}",
            s.name, f.sensors[h].name
        );
        let mut held: Vec<usize> = sources.iter().filter_map(|&o| pattern_of(o)).collect();
        held.sort_unstable();
        held.dedup();
        let trusted = list(&|o| pattern_of(o).is_none());
        let (status, detail) = match held.as_slice() {
            [] => (
                Status::Holds,
                format!(
                    "made from {}, all in no fault pattern (trusted: an attack on them is outside the model)",
                    list(&|_| true)
                ),
            ),
            [p] => (
                Status::Holds,
                format!(
                    "made from {}; {} in {}{}",
                    list(&|_| true),
                    list(&|o| pattern_of(o) == Some(*p)),
                    names.patterns[*p],
                    if trusted.is_empty() {
                        String::new()
                    } else {
                        format!(", {trusted} in none (trusted)")
                    }
                ),
            ),
            many => {
                let d = format!(
                    "{} is made from {}, which are in {} different fault patterns ({}): a fault in either corrupts {}'s channels, so the patterns are not disjoint in effect; put them in one pattern",
                    s.name,
                    list(&|o| pattern_of(o).is_some()),
                    many.len(),
                    many.iter()
                        .map(|&p| names.patterns[p].to_string())
                        .collect::<Vec<_>>()
                        .join(", "),
                    s.name
                );
                (Status::Fails, d)
            }
        };
        found.record(name, status, detail);
    }
}

/// 1c. The robot's drive turns u into wheel speeds about the heading ((6.3)–(6.4)), outside every
/// filter: the theorem's u is applied as computed only if that heading (and a gyro fused into it)
/// is in no fault pattern. A malformed heading is dead-reckoned over by the runner; a finite lie
/// misapplies u.
pub(super) fn check_drive_heading(cx: Ctx<'_>, found: &mut Findings) {
    let Ctx { world, names, .. } = cx;
    if world.robot.is_none() {
        return;
    }
    let Some(h) = heading_sensor(world) else {
        return;
    };
    let sources = std::iter::once(h).chain(heading_fusion(world).map(|(g, _)| g));
    let held: Vec<(usize, usize)> = sources
        .filter_map(|si| {
            world
                .patterns
                .iter()
                .position(|p| p.contains(&si))
                .map(|p| (si, p))
        })
        .collect();
    let name = "the drive's heading is trusted ((6.3)–(6.4))".to_string();
    let (status, detail) = if held.is_empty() {
        (
            Status::Holds,
            format!(
                "{} is in no fault pattern: the drive turns u into wheel speeds about a heading no modelled fault touches",
                names.sensors[h]
            ),
        )
    } else {
        let list = held
            .iter()
            .map(|&(si, p)| format!("{} is in {}", names.sensors[si], names.patterns[p]))
            .collect::<Vec<_>>()
            .join(", ");
        (
            Status::Fails,
            format!(
                "{list}: the drive turns u into wheel speeds about this heading, outside every filter, so a fault there misapplies u, which the theorem (u applied as computed) does not cover; malformed readings are dead-reckoned over, a finite lie is not"
            ),
        )
    };
    found.record(name, status, detail);
}

/// 1. Disjoint fault patterns (§3.1); names the last overlap found.
pub(super) fn check_disjoint_patterns(cx: Ctx<'_>, found: &mut Findings) {
    let Ctx { setup, names, .. } = cx;
    let patterns = &setup.config.fault_patterns;
    let m = patterns.len();
    let mut overlap = None;
    for i in 0..m {
        for j in (i + 1)..m {
            if let Some(c) = patterns[i].iter().find(|c| patterns[j].contains(c)) {
                overlap = Some((i, j, *c));
            }
        }
    }
    match overlap {
        None => found.hypotheses.push(Hypothesis {
            name: "disjoint fault patterns (§3.1)".into(),
            status: Status::Holds,
            detail: format!("{m} patterns, no shared channel"),
        }),
        Some((i, j, c)) => {
            let d = format!(
                "{} and {} share {}",
                names.patterns[i], names.patterns[j], names.channels[c]
            );
            found.reasons.push(format!("fault patterns overlap ({d})"));
            found.hypotheses.push(Hypothesis {
                name: "disjoint fault patterns (§3.1)".into(),
                status: Status::Fails,
                detail: d,
            });
        }
    }
}

/// The channels a filter that drops the fault patterns `drop` uses.
/// 2-4. Every filter of the bank (single drops, then pair drops): invertible R̄,
/// detectability and what bounds its covariance.
pub(super) fn check_filters(cx: Ctx<'_>, found: &mut Findings) -> Vec<FilterCheck> {
    let Ctx {
        world,
        setup,
        names,
    } = cx;
    let m = setup.config.fault_patterns.len();
    let mut drops: Vec<Vec<usize>> = (0..m).map(|i| vec![i]).collect();
    for i in 0..m {
        for j in (i + 1)..m {
            drops.push(vec![i, j]);
        }
    }
    let mut filters = Vec::new();
    for d in &drops {
        let gamma = setup.params.derivation.as_ref().map(|c| match d[..] {
            [i, j] => pair_slot(m, i, j).map_or(f64::NAN, |k| c.gamma_pair[k]),
            _ => setup.config.ft.gamma[d[0]],
        });
        filters.push(check_filter(world, setup, names, d, gamma, found));
    }
    filters
}

/// "x̂_1 (drops gnss1)", "x̂_12 (drops gnss1 ∪ gnss2)".
pub(crate) fn filter_label(d: &[usize], pattern_names: &[&str]) -> String {
    match d {
        [i] => format!("x̂_{} (drops {})", i + 1, pattern_names[*i]),
        [i, j] => format!(
            "x̂_{}{} (drops {} ∪ {})",
            i + 1,
            j + 1,
            pattern_names[*i],
            pattern_names[*j]
        ),
        _ => unreachable!("one or two patterns per filter"),
    }
}

/// The filter that drops the fault patterns `d`, with γ `gamma` in force: its R̄ and
/// detectability hypotheses.
pub(super) fn check_filter(
    world: &World,
    setup: &ControlSetup,
    names: &Names,
    d: &[usize],
    gamma: Option<f64>,
    found: &mut Findings,
) -> FilterCheck {
    let model = &setup.config.model;
    let q = model.channels();
    let uses = channel_mask(q, &setup.config.fault_patterns, d);
    let label = filter_label(d, &names.patterns);
    let channels: Vec<String> = (0..q)
        .filter(|&k| uses[k])
        .map(|k| names.channels[k].clone())
        .collect();
    let r_bar_min = (0..q)
        .filter(|&k| uses[k])
        .map(|k| model.r[k])
        .fold(f64::INFINITY, f64::min);
    let det = detectability(model, &uses);
    let velocity_lost = det
        .unobservable_basis
        .iter()
        .any(|b| b[2].abs() > 1e-9 || b[3].abs() > 1e-9);
    let horizon = world.file.duration;
    let bound = if det.detectable {
        CovarianceBound::SteadyState
    } else if velocity_lost {
        CovarianceBound::OpenLoop { seconds: horizon }
    } else {
        CovarianceBound::FiniteHorizon { seconds: horizon }
    };
    // R̄ invertible.
    let floored = (0..q).any(|k| uses[k] && model.r[k] <= MIN_VARIANCE);
    found.hypotheses.push(Hypothesis {
        name: format!("invertible R̄ for {label}"),
        status: Status::Holds,
        detail: if channels.is_empty() {
            "no channel left: open-loop estimator (§4.1), R̄ is empty".to_string()
        } else {
            format!(
                "diagonal, smallest variance {:.3e}{}",
                r_bar_min,
                if floored {
                    format!(" (a noise-free channel floored at {MIN_VARIANCE:e})")
                } else {
                    String::new()
                }
            )
        },
    });
    check_detectability(&label, &channels, &det, bound, gamma, found);
    FilterCheck {
        label,
        channels,
        r_bar_min,
        detectability: det,
        bound,
        gamma,
    }
}

/// Detectability of one filter and what bounds its covariance.
pub(super) fn check_detectability(
    label: &str,
    channels: &[String],
    det: &Detectability,
    bound: CovarianceBound,
    gamma: Option<f64>,
    found: &mut Findings,
) {
    let unobs = if det.unobservable.is_empty() {
        "none".to_string()
    } else {
        det.unobservable.join(", ")
    };
    let gtxt = gamma.map_or(String::new(), |g| format!(", γ = {g:.6}"));
    let (status, detail) = match bound {
        CovarianceBound::SteadyState => (
            Status::Holds,
            format!(
                "uses {{{}}}; PBH rank 4 at every eigenvalue of F with Re λ ≥ 0; steady-state covariance{gtxt}",
                channels.join(", ")
            ),
        ),
        CovarianceBound::FiniteHorizon { seconds } => {
            found.finite_horizon = true;
            (
                Status::Holds,
                format!(
                    "uses {{{}}}; NOT detectable (PBH fails at λ = 0; unobservable: {unobs}) — §3.1's assumption fails, but the velocity is measured, so the position error is dead-reckoned: finite-horizon bound over {seconds} s from initial_std{gtxt}",
                    channels.join(", ")
                ),
            )
        }
        CovarianceBound::OpenLoop { seconds } => {
            let why = if channels.is_empty() {
                "keeps no channel at all".to_string()
            } else {
                format!("keeps only {{{}}}", channels.join(", "))
            };
            found.reasons.push(format!(
                "{label} {why}: no position and no velocity fix (unobservable: {unobs}); its error over {seconds} s is bounded only by the assumed process noise, nothing measured bounds it, so (4.5) cannot be certified"
            ));
            (
                Status::Fails,
                format!("{why}; NOT detectable (unobservable: {unobs}); open loop{gtxt}"),
            )
        }
    };
    found.hypotheses.push(Hypothesis {
        name: format!("detectable (F, c̄) for {label}"),
        status,
        detail,
    });
}

/// 1d. White, unbiased noise on every filter channel: γ, θ and η come from Riccati recursions
/// whose readings carry zero-mean white noise, so a sensor that reaches a filter with a declared
/// `bias` or `bias_walk_std` (the channel itself, the wheel channels odometry is derived from, or
/// the heading that turns a speed into world velocity) is outside them, and the hypothesis fails
/// naming it. A constant heading bias b_θ is worst where no position fix corrects it: the world
/// velocity then errs by up to v_max·b_θ across track, which a filter without position fixes (a
/// pair filter that keeps only odometry) integrates to v_max·(b_θ + 3w_θ√T)·T over the run. A gyro
/// fused into the heading is exempt: the heading filter estimates its bias and walk (augmented
/// state (θ, b)).
pub(super) fn check_white_noise(cx: Ctx<'_>, found: &mut Findings) {
    let Ctx { world, setup, .. } = cx;
    let sensors = &world.file.sensors;
    let heading = heading_sensor(world);
    let mut feeding: Vec<usize> = Vec::new();
    for (c, &si) in setup.sensor_of_channel.iter().enumerate() {
        feeding.push(si);
        feeding.extend(
            crate::sensors::wheel_sources(sensors, si)
                .into_iter()
                .flatten(),
        );
        if setup.conversion[c] != Conversion::Direct {
            feeding.extend(heading);
        }
    }
    feeding.sort_unstable();
    feeding.dedup();
    let t = world.file.duration;
    let v_max = speed_bound(world).unwrap_or(f64::INFINITY);
    let biased: Vec<String> = feeding
        .iter()
        .filter(|&&si| sensors[si].bias != 0.0 || sensors[si].bias_walk_std != 0.0)
        .map(|&si| {
            let s = &sensors[si];
            let unit = s.measures.unit();
            let declared = format!(
                "\"{}\" declares bias {} {unit} and bias walk {} {unit}/√s",
                s.name, s.bias, s.bias_walk_std
            );
            if Some(si) == heading {
                let b = s.bias.abs() + 3.0 * s.bias_walk_std * t.sqrt();
                format!(
                    "{declared}: the world velocity made with it errs by up to v_max·b_θ = {:.4} m/s across track, not white; a filter without position fixes integrates it to {:.3} m over {t} s (v_max·(|b_θ| + 3w_θ√T)·T), which γ, θ and η do not cover",
                    v_max * b,
                    v_max * b * t
                )
            } else {
                format!(
                    "{declared}: an offset on a filter channel is not the white noise γ, θ and η are computed for (the estimates carry it, and Step 2 sees it as a fault)"
                )
            }
        })
        .collect();
    let stale = heading_hold(world)
        .filter(|h| h.age > 0.0 && feeding.contains(&h.sensor))
        .map(|h| {
            let s = &sensors[h.sensor];
            let omega_max = turn_rate_bound(world).unwrap_or(f64::INFINITY);
            let held = if h.age.is_finite() {
                format!("up to {:.3} s", h.age)
            } else {
                "for the whole run (no finite gap fits the budget)".to_string()
            };
            format!(
                "\"{}\" (no gyro fused) is held {held} between fresh samples: the world velocity made with it errs by up to v_max·ω_max·age = {:.4} m/s while the robot turns, an error that follows the turn, not white noise (its bound is in the conversion's variance); fuse a gyro (`gyro = \"…\"` on the heading channel) or read the heading every control step",
                s.name,
                v_max * omega_max * h.age
            )
        });
    let biased: Vec<String> = biased.into_iter().chain(stale).collect();
    let name = "white, unbiased noise on every filter channel (γ, θ, η model no bias)".to_string();
    if biased.is_empty() {
        found.record(
            name,
            Status::Holds,
            "no sensor that reaches a filter declares a bias or a bias walk (a gyro fused into the heading is modelled by the heading filter)".to_string(),
        );
    } else {
        found.record(name, Status::Fails, biased.join("; "));
    }
}

/// 4a. The sensors' rates and dropouts γ, θ and η are computed for ([`sensor_timing`]): reported,
/// with the longest gap chosen from ε.
///
/// [`sensor_timing`]: crate::world::structure::sensor_timing
pub(super) fn report_sensor_timing(cx: Ctx<'_>, found: &mut Findings) {
    let Ctx {
        world,
        setup,
        names,
    } = cx;
    let timing = &setup.params.timing;
    let name = "γ, θ, η for the sensors' rates and dropouts".to_string();
    if timing.every_tick() {
        found.record(
            name,
            Status::Holds,
            "every filter channel reads every control tick without dropouts (the paper's setting)"
                .to_string(),
        );
        return;
    }
    let sensors = &world.file.sensors;
    let slow: Vec<String> = timing
        .channels
        .iter()
        .filter(|c| c.every != 1)
        .map(|c| {
            let s = &sensors[c.sensor];
            let rate = s
                .rate_hz
                .map_or("every tick".to_string(), |r| format!("{r} Hz"));
            let gap = if c.every == 0 {
                "never counted on (no finite gap fits the budget)".to_string()
            } else {
                format!("modelled as every {} ticks", c.every)
            };
            let by = if setup.sensor_of_channel[c.channel] == c.sensor {
                String::new()
            } else {
                format!("timed by {}: ", s.name)
            };
            let lost = if c.dropout >= 1.0 {
                format!(
                    ", a sample every {} ticks, dropout {}: every sample is lost",
                    c.period, c.dropout
                )
            } else if c.missed == usize::MAX {
                format!(
                    ", a sample every {} ticks, dropout {}: losses in a row as long as the run \
                     are too likely to bound",
                    c.period, c.dropout
                )
            } else if c.dropout > 0.0 {
                format!(
                    ", a sample every {} ticks, dropout {}: up to {} lost in a row",
                    c.period, c.dropout, c.missed
                )
            } else {
                String::new()
            };
            format!("{} ({by}{rate}{lost}) {gap}", names.channels[c.channel])
        })
        .collect();
    let budget = if timing.eps_gaps > 0.0 {
        format!(
            "; ε/2 = {} bounds the gaps (N·p^(n+1) ≤ ε/(2·{}) per lossy sensor, N its samples in the run), the other ε/2 the errors",
            timing.eps_gaps, timing.lossy_sensors
        )
    } else {
        String::new()
    };
    found.record(
        name,
        Status::Holds,
        format!(
            "{}: each Riccati recursion is periodic, γ, θ, η take its worst phase{budget}",
            slow.join("; ")
        ),
    );
}

/// Finite γ_i and θ_ij (and whether they were derived from ε).
pub(super) fn check_finite_parameters(cx: Ctx<'_>, found: &mut Findings) {
    let Ctx { world, setup, .. } = cx;
    let p = &setup.params;
    let finite = setup
        .config
        .ft
        .gamma
        .iter()
        .chain(&setup.config.ft.theta)
        .all(|v| v.is_finite())
        && setup.config.ft.gamma_baseline.is_finite();
    found.hypotheses.push(Hypothesis {
        name: "finite γ_i and θ_ij".into(),
        status: if finite { Status::Holds } else { Status::Fails },
        detail: format!(
            "γ_i = [{}], θ_ij = [{}]{}",
            fmt_list(&setup.config.ft.gamma),
            fmt_list(&setup.config.ft.theta),
            match &p.derivation {
                Some(c) => format!(
                    ", per-sample ε' = {:.3e} (union bound over the {} samples of the run and each sample's events)",
                    c.eps_per_sample,
                    world.horizon_ticks(),
                ),
                None => " (given in the world file; not derived from ε)".to_string(),
            }
        ),
    });
    if !finite {
        found.reasons.push("γ or θ is not finite".to_string());
    }
    if p.derivation.is_none() {
        found.assumptions.push(
            "γ and θ are given in the world file: (4.5) holds only if they bound the errors"
                .to_string(),
        );
    }
}

/// 6b. The filters' model is true of the rapier robot: they predict with the acceleration the
/// drive realised and cover the rest with q, identified from inputs held 0.2–1 s (see
/// `model::identify`). The paper form's QP switches its input at every step (bang-bang), which
/// the wheel motors do not follow: measured on paper_turtlebot without its attack, the honest
/// filters left γ in 12 of 12 runs (3.1 γ) with the paper's q = 1e-3, and in 13 of 20 (1.2 γ)
/// with q identified under one-step holds (2.4e-2). (4.5) is then not what the robot does.
pub(super) fn check_drive_model(cx: Ctx<'_>, found: &mut Findings) {
    let Ctx { world, .. } = cx;
    use crate::world::FormSpec;
    if world.file.control.form == FormSpec::Paper {
        found.record(
            "the filters' model is true of the drive".into(),
            Status::Fails,
            "`form = \"paper\"` on the rapier robot: the QP's input switches at every step (bang-bang) and the wheel motors do not follow it, so the filters' errors leave γ (measured on paper_turtlebot without its attack: 12 of 12 runs, up to 3.1 γ); use `form = \"safety_filter\"`, whose inputs the identified process noise covers".into(),
        );
    } else {
        found.record(
            "the filters' model is true of the drive".into(),
            Status::Holds,
            "the filters predict with the acceleration the drive realised (after its limits and low-speed law), and the process noise covers the rest at the safety-filter form's input rates (see the `filters:` line); `ftcbf batch` measures ‖x − x̂_i‖ against γ_i per trial".into(),
        );
    }
}

/// 4b. γ_i bounds §4.3's P_t at every step, not only its limit: with the paper's bound (the
/// steady state) and a P0 above it, each filter's error in its first steps is larger than γ_i
/// allows (issue #35: 20-40 of 40 attack-free runs left γ on the paper's worlds with P0 = 1e-2·I).
pub(super) fn check_transient(cx: Ctx<'_>, found: &mut Findings) {
    let Ctx { world, setup, .. } = cx;
    use ftcbf_controller::params::{
        chi_square_quantile, horizon_posterior_max_scheduled, BoundMethod,
    };
    let Some(c) = setup.params.derivation.as_ref() else {
        return;
    };
    if c.method != BoundMethod::Paper {
        return;
    }
    let model = &setup.config.model;
    let patterns = &setup.config.fault_patterns;
    let q = model.channels();
    let dt = world.control_dt();
    let n = world.horizon_ticks();
    let chi = chi_square_quantile(4, 1.0 - c.eps_per_sample);
    let p0 = initial_covariance(world);
    let mut worst: Option<(String, f64, f64)> = None;
    // The filters Theorem 3's (4.5) is about: x̂_i, each without one fault pattern.
    let singles =
        (0..patterns.len()).map(|i| (format!("x̂_{}", i + 1), vec![i], setup.config.ft.gamma[i]));
    for (label, drop, gamma) in singles {
        let uses = channel_mask(q, patterns, &drop);
        let phases = setup.params.timing.schedule.phases(&uses);
        let reached = horizon_posterior_max_scheduled(model, &phases, dt, &p0, n)
            .symmetric_eigenvalues()
            .max();
        let covered = gamma * gamma / chi;
        let ratio = reached / covered;
        if worst.as_ref().is_none_or(|w| ratio > w.1) {
            worst = Some((label, ratio, reached));
        }
    }
    let Some((label, ratio, reached)) = worst else {
        return;
    };
    let holds = ratio <= 1.0 + 1e-9;
    let detail = if holds {
        format!(
            "from P0 = diag({:.3e}, {:.3e}, {:.3e}, {:.3e}) the filters' covariance stays within the steady state: λ̄(P_t) ≤ λ̄(P∞) at every estimate (largest λ̄(P_t)/λ̄(P∞) = {ratio:.3}, {label})",
            p0[(0, 0)], p0[(1, 1)], p0[(2, 2)], p0[(3, 3)]
        )
    } else {
        format!(
            "{label}: from P0 = diag({:.3e}, {:.3e}, {:.3e}, {:.3e}) its covariance reaches λ̄ = {reached:.3e}, {ratio:.2}× the steady state that γ bounds (`bounds = \"paper\"`): its error in the first steps is larger than γ allows; set `[control] initial_std` to the start's real uncertainty (default [0.01, 0.01]) or `bounds = \"horizon\"`",
            p0[(0, 0)], p0[(1, 1)], p0[(2, 2)], p0[(3, 3)]
        )
    };
    found.record(
        "γ covers the filters' transient from P0 (§4.3's P_t)".into(),
        if holds { Status::Holds } else { Status::Fails },
        detail,
    );
}
