//! Hypotheses 5–11: what the barrier rows rest on — condition 1 for every safe set and
//! obstacle, the input box's authority at rest, the attacks inside one pattern, holding the
//! goal, the start and goal, the joint rows of case (i), departures from the model.

use super::*;

/// Hypothesis 10, case (i) of Theorem 3's proof with several rows: when the kept estimates agree within θ,
/// some input must meet the rows of **every** active barrier of **every** kept unit at once,
/// inside the input box. (4.4) per barrier (item 5) and one row at rest (item 6) do not give
/// that. The liveness prediction builds exactly those rows at rest along the planned path (every
/// unit, every barrier with ĥ < δ, the box; under the declared attack with the spoofed estimates
/// where Step 2 keeps them) and decides them in 2-D: a point where no input meets them all is a
/// state the robot is planned to reach where the proof's case (i) fails, so the hypothesis
/// fails. Where they are met at rest, the same rows at speed (the drift term ∂H/∂p·v), off the
/// path and with the other units' ĥ up to ‖∂H‖θ lower are not decided: assumed.
pub(super) fn check_joint_rows(cx: Ctx<'_>, liveness: &LivenessReport, found: &mut Findings) {
    let Ctx { world, .. } = cx;
    if liveness.skipped.is_some() || liveness.cases.is_empty() {
        return;
    }
    let barriers = world.file.safe_sets.len() + world.obstacles.len();
    let name = "case (i): the rows of every kept unit and every active barrier met by one input in the box".to_string();
    let stalled = liveness
        .cases
        .iter()
        .find_map(|c| c.joint_infeasible.as_ref().map(|st| (c, st)));
    match stalled {
        Some((c, st)) => found.record(
            name,
            Status::Fails,
            format!(
                "{}, at rest along the planned path, at ({:.2}, {:.2}), {:.2} m along it{}, no input in the box meets the rows of every unit Step 2 keeps (rows of {}): Step 1 is infeasible there and Step 3 may drop an honest filter, which the proof's case (i) excludes",
                c.name,
                st.at[0],
                st.at[1],
                st.along,
                if st.offset == [0.0, 0.0] {
                    String::new()
                } else {
                    format!(
                        ", spoofed estimates off by ({:.2}, {:.2}) m",
                        st.offset[0], st.offset[1]
                    )
                },
                if st.binding.is_empty() {
                    "no barrier".to_string()
                } else {
                    st.binding.join(", ")
                }
            ),
        ),
        None => {
            found.hypotheses.push(Hypothesis {
                name,
                status: Status::Assumed,
                detail: format!(
                    "decided at rest along the planned path ({:.2} m, {} points; {}): an input meets all rows of the {barriers} barrier(s) there; at speed, off the path and with the other kept units' ĥ up to ‖∂H‖θ lower it is assumed",
                    liveness.path_length,
                    liveness.samples,
                    liveness
                        .cases
                        .iter()
                        .map(|c| c.name.as_str())
                        .collect::<Vec<_>>()
                        .join(" and ")
                ),
            });
            if barriers > 1 {
                found.assumptions.push(
                    "case (i) jointly over the barriers at speed and off the planned path (decided at rest along it)".to_string(),
                );
            }
        }
    }
}

/// Hypothesis 12, moving obstacles (issue #51): see [`crate::analysis::moving_check`]. Assumed
/// findings are also assumptions of the verdict.
pub(super) fn check_movers(cx: Ctx<'_>, found: &mut Findings) {
    let Ctx { world, setup, .. } = cx;
    let tracked = crate::analysis::tracked_check::findings(world, setup);
    for f in crate::analysis::moving_check::findings(world, setup)
        .into_iter()
        .chain(tracked)
    {
        let status = match f.holds {
            Some(true) => Status::Holds,
            Some(false) => Status::Fails,
            None => {
                found.assumptions.push(f.detail.clone());
                Status::Assumed
            }
        };
        found.record(f.name, status, f.detail);
    }
}

/// Hypothesis 11, departures from the thesis's setting that `check` cannot decide and the verdict rests on
/// (see the book's "What `check` proves"): Step 3's rule of keeping a unit the box cannot
/// satisfy is exact for one half-plane only, and the rows are imposed at the control rate, not
/// continuously.
pub(super) fn check_departures(cx: Ctx<'_>, found: &mut Findings) {
    let Ctx { world, .. } = cx;
    let (flat, cornered, curved) = barrier_boundaries(world);
    let barriers = world.file.safe_sets.len() + world.obstacles.len();
    if barriers > 1 || flat < barriers {
        found.assumptions.push(format!(
            "Step 3's saturation rule (keep a unit whose rows the box cannot meet) does not pull the fallback against an honest row ({barriers} barrier(s): {flat} flat, {cornered} flat-sided with corners rounded by the footprint, {curved} curved): outside the theorem",
        ));
    }
}

/// 5. Condition 1 of Theorem 3 for every safe set (decided) and obstacle (assumed).
pub(super) fn check_condition1(cx: Ctx<'_>, found: &mut Findings) {
    let Ctx { world, setup, .. } = cx;
    let theta_bar = setup.config.ft.theta.iter().copied().fold(0.0, f64::max);
    for s in &world.file.safe_sets {
        match s {
            SafeSetSpec::HalfPlane { name, a, .. } => {
                check_half_plane(setup, name, a, found);
            }
            SafeSetSpec::EllipseInside {
                name,
                center,
                semi_axes,
                angle,
                ..
            }
            | SafeSetSpec::EllipseOutside {
                name,
                center,
                semi_axes,
                angle,
                ..
            } => {
                let ellipse = Ellipse {
                    name,
                    center,
                    semi_axes: *semi_axes,
                    angle: *angle,
                    inside: matches!(s, SafeSetSpec::EllipseInside { .. }),
                };
                let prop1 = ellipse_prop1(world, setup, s);
                check_ellipse(setup, &ellipse, prop1, found);
            }
        }
    }
    for ob in &world.obstacles {
        let detail = match ob.map_field() {
            Some(_) => format!(
                "one lifted barrier per piece of the map's outline ({} pieces: convex polygons round blobs, segments along walls): the distance to a convex piece, ∂H/∂v = k∇d with ‖∇d‖ = 1, so Λ ≠ 0 for each filter; estimates within θ̄ = {theta_bar:.4} m of each other are assumed to see each piece on the same side",
                ob.outlines().len()
            ),
            None => format!(
                "lifted signed distance: ∂H/∂v = k∇d with ‖∇d‖ = 1, so Λ ≠ 0 for each filter; estimates within θ̄ = {theta_bar:.4} m of each other are assumed to see the obstacle on the same side"
            ),
        };
        found.hypotheses.push(Hypothesis {
            name: format!(
                "condition 1 (4.4) for obstacle {} ({})",
                ob.name,
                ob.spec.shape.kind()
            ),
            status: Status::Assumed,
            detail,
        });
    }
    if !world.obstacles.is_empty() {
        found.assumptions.push(format!(
            "condition 1 across filters near obstacles (estimates within θ̄ = {theta_bar:.4} m agree on a direction)"
        ));
    }
}

/// Condition 1 for a half-plane: Lemma 1.
pub(super) fn check_half_plane(
    setup: &ControlSetup,
    name: &str,
    a: &[f64; 4],
    found: &mut Findings,
) {
    let model = &setup.config.model;
    let v = check_lemma1(&State::new(a[0], a[1], a[2], a[3]), &model.f, &model.g);
    if !v.holds {
        found.reasons.push(format!(
            "{name}: aᵀG = 0, (4.4) cannot hold (relative degree {:?}; add a velocity term to a)",
            v.relative_degree
        ));
    }
    found.hypotheses.push(Hypothesis {
        name: format!("condition 1 (4.4) for {name} (half-plane)"),
        status: if v.holds {
            Status::Holds
        } else {
            Status::Fails
        },
        detail: v.to_string(),
    });
}

/// An elliptic safe set as written.
pub(super) struct Ellipse<'a> {
    name: &'a str,
    center: &'a [f64; 2],
    semi_axes: [f64; 2],
    angle: f64,
    /// The safe set is the inside (else the outside).
    inside: bool,
}

/// Condition 1 for a lifted ellipse: Prop. 1 in position space on the barrier that runs
/// ([`ellipse_prop1`], i.e. [`crate::safe_sets::LiftedEllipse::prop1`]: rank G = 2 < n = 4, so
/// the paper's Prop. 1 applies to the position part only, where the lift makes Λ = k∇h(p); for
/// an arena it needs a finite δ, which `auto` chooses when none is given); Thm. 5 at the start
/// for an inside ellipse (reported).
pub(super) fn check_ellipse(
    setup: &ControlSetup,
    e: &Ellipse,
    prop1: Option<crate::safe_sets::LiftedProp1>,
    found: &mut Findings,
) {
    let model = &setup.config.model;
    let name = e.name;
    let phi = ellipse_phi_state(e.semi_axes, e.angle);
    let delta = setup.params.delta;
    let (holds, detail) = match &prop1 {
        // δ enters an arena's test only (a keep-out ellipse's holds for any δ)
        Some(v) if v.inside && setup.params.delta_auto => (
            v.holds,
            format!("{v}; δ = {delta:.4} (auto: half of Prop. 1's largest)"),
        ),
        Some(v) if v.inside => (v.holds, format!("{v}; δ = {delta}")),
        Some(v) => (v.holds, v.to_string()),
        None => (false, "not a lifted ellipse".to_string()),
    };
    if !holds {
        let why = match &prop1 {
            Some(v) if v.inside && v.z_min_sq <= 0.0 => format!(
                "with δ = {delta} an estimate whose row is active may sit where Λ = k∇h ≈ 0 (the centre); Prop. 1 needs δ + h̄ + 2k√λ̄·v_max < 1 (leave `delta` out for `auto`, or lower the lift or v_max)"
            ),
            Some(v) => format!(
                "θ̄ = {:.4} m exceeds Prop. 1's bound {:.4} m: two estimates within θ̄ may need opposite inputs",
                v.theta_bar, v.bound
            ),
            None => "Prop. 1 could not be evaluated".to_string(),
        };
        found.reasons.push(format!("{name}: {why}"));
    }
    found.hypotheses.push(Hypothesis {
        name: format!("condition 1 (4.4) for {name} (lifted ellipse, Prop. 1 in position space)"),
        status: if holds { Status::Holds } else { Status::Fails },
        detail,
    });
    if e.inside {
        let centre = State::new(e.center[0], e.center[1], 0.0, 0.0);
        let start = setup.config.x0;
        let w = Input::new(centre[0] - start[0], centre[1] - start[1]);
        let t5 = check_theorem5(&phi, &centre, &model.g, &w, &[start]);
        found.hypotheses.push(Hypothesis {
            name: format!("Thm. 5 for {name} at the start"),
            status: Status::Info,
            detail: t5.to_string(),
        });
    }
}

/// 7. The declared attacks stay inside one fault pattern.
pub(super) fn check_attacks(cx: Ctx<'_>, found: &mut Findings) {
    let Ctx { world, names, .. } = cx;
    match crate::world::structure::attacked_pattern(world).map_err(|e| e.to_string()) {
        Ok(Some(pi)) => found.hypotheses.push(Hypothesis {
            name: "attacks inside one fault pattern".into(),
            status: Status::Holds,
            detail: format!("every attacked channel is in {}", names.patterns[pi]),
        }),
        Ok(None) => found.hypotheses.push(Hypothesis {
            name: "attacks inside one fault pattern".into(),
            status: Status::Holds,
            detail: "no attack declared".to_string(),
        }),
        Err(e) => {
            found.reasons.push(e.clone());
            found.hypotheses.push(Hypothesis {
                name: "attacks inside one fault pattern".into(),
                status: Status::Fails,
                detail: e,
            });
        }
    }
}

/// 8. Goal holding, per half-plane and single-drop filter.
pub(super) fn goal_holding(cx: Ctx<'_>, filters: &[FilterCheck]) -> Vec<GoalHold> {
    let Ctx { world, setup, .. } = cx;
    let f = &world.file;
    let m = setup.config.fault_patterns.len();
    let gc = State::new(f.goal.center[0], f.goal.center[1], 0.0, 0.0);
    let mut goal = Vec::new();
    for (bi, s) in f.safe_sets.iter().enumerate() {
        if let SafeSetSpec::HalfPlane { name, a, b } = s {
            let av = State::new(a[0], a[1], a[2], a[3]);
            let reach = match f.goal.metric {
                GoalMetric::State => av.norm(),
                GoalMetric::Position => (a[0] * a[0] + a[1] * a[1]).sqrt(),
            };
            let max_h = av.dot(&gc) - b + f.goal.radius * reach;
            for (i, fc) in filters.iter().enumerate().take(m) {
                let r = rest_hold(
                    world,
                    &setup.config.model,
                    &setup.config.fault_patterns,
                    setup.config.ft.gamma[i],
                    i,
                    &*setup.config.barriers[bi],
                    &av,
                    setup.config.cbf_gain,
                );
                goal.push(GoalHold {
                    barrier: name.clone(),
                    filter: fc.label.clone(),
                    needed_h: r.needed_h,
                    max_h_in_goal: max_h,
                });
            }
        }
    }
    goal
}

/// Item 9: Theorem 3 starts from x(0) ∈ C: the start state must lie in every safe set and clear of
/// every obstacle (h ≥ 0 for every barrier that runs, at the start estimate, which is the true
/// start at rest). A goal with no point clear of an obstacle (h(goal centre) + radius < 0) can
/// never be entered: the world contradicts itself, and the report says so.
pub(super) fn check_start_and_goal(cx: Ctx<'_>, found: &mut Findings) {
    let Ctx { world, setup, .. } = cx;
    let x0 = setup.config.x0;
    let mut outside = Vec::new();
    for b in &setup.config.barriers {
        let h = b.eval(&x0).value;
        if !(h.is_finite() && h >= 0.0) {
            outside.push(format!("h({}) = {h:.6}", b.name()));
        }
    }
    let (status, detail) = if outside.is_empty() {
        (
            Status::Holds,
            format!(
                "x(0) = ({:.4}, {:.4}, {:.4}, {:.4}) has h ≥ 0 for all {} barrier(s)",
                x0[0],
                x0[1],
                x0[2],
                x0[3],
                setup.config.barriers.len()
            ),
        )
    } else {
        (
            Status::Fails,
            format!(
                "the start x(0) = ({:.4}, {:.4}) is outside the safe set: {} (Theorem 3 assumes x(0) ∈ C; the run is unsafe from its first step)",
                x0[0],
                x0[1],
                outside.join(", ")
            ),
        )
    };
    found.record(
        "start inside every safe set (x(0) ∈ C)".into(),
        status,
        detail,
    );

    let f = &world.file;
    let gc = State::new(f.goal.center[0], f.goal.center[1], 0.0, 0.0);
    let n_safe = setup.safe_sets;
    let mut blocked = Vec::new();
    for b in setup.config.barriers.iter().skip(n_safe) {
        let h = b.eval(&gc).value;
        if !(h.is_finite() && h + f.goal.radius >= 0.0) {
            blocked.push(format!("{} (h at the goal's centre = {h:.6})", b.name()));
        }
    }
    if n_safe < setup.config.barriers.len() {
        let (status, detail) = if blocked.is_empty() {
            (
                Status::Holds,
                "some point of the goal set is clear of every obstacle (h + radius ≥ 0 at its centre)"
                    .to_string(),
            )
        } else {
            (
                Status::Fails,
                format!(
                    "the goal set (centre ({}, {}), radius {} m) lies inside {}: no safe run can enter it",
                    f.goal.center[0],
                    f.goal.center[1],
                    f.goal.radius,
                    blocked.join(", ")
                ),
            )
        };
        found.record("goal clear of the obstacles".into(), status, detail);
    }
}

/// The (reported) hypothesis of one goal-holding check: information, unless its numbers are
/// not finite (then it fails: nothing was verified).
pub(super) fn goal_hypothesis(g: &GoalHold) -> Hypothesis {
    let finite = g.needed_h.is_finite() && g.max_h_in_goal.is_finite();
    Hypothesis {
        name: format!("goal can be held at rest ({}, {})", g.barrier, g.filter),
        status: if finite { Status::Info } else { Status::Fails },
        detail: format!(
            "{}: at rest the CBF row needs h ≥ h̄_γ + γ‖(Kc̄)ᵀa‖/κ = {:.6}; the goal set reaches h ≤ {:.6}{}",
            if g.holds() { "yes" } else { "NO" },
            g.needed_h,
            g.max_h_in_goal,
            if g.holds() {
                ""
            } else {
                " — the robot can pass through the goal but cannot settle in it with these margins"
            }
        ),
    }
}

/// Per fault-pattern filter x̂_i: its label, γ_i in force and steady-state gain product K c̄.
pub(super) fn single_filter_gains(
    world: &World,
    setup: &ControlSetup,
    filters: &[FilterCheck],
) -> Vec<(String, f64, StateMatrix)> {
    let model = &setup.config.model;
    let m = setup.config.fault_patterns.len();
    let dt = world.control_dt();
    filters
        .iter()
        .take(m)
        .enumerate()
        .map(|(i, fc)| {
            let mask = channel_mask(model.channels(), &setup.config.fault_patterns, &[i]);
            (
                fc.label.clone(),
                setup.config.ft.gamma[i],
                steady_state_gain_product(model, &mask, dt),
            )
        })
        .collect()
}

/// The input a CBF row with gradient `grad` needs, at rest on its own boundary ĥ = 0, relative
/// to what the box gives: `γ‖(Kc̄)ᵀ∂h‖ / Σ_k |Λ_k| l_k` with `Λ = Gᵀ∂h` (≤ 1: the row can be
/// met; +∞: the input does not act on h at rest).
pub(super) fn rest_demand(
    setup: &ControlSetup,
    grad: &State,
    gamma: f64,
    kc: &StateMatrix,
    l: &Input,
) -> f64 {
    let lambda: Input = setup.config.model.g.transpose() * grad;
    let authority = lambda[0].abs() * l[0] + lambda[1].abs() * l[1];
    let needed = gamma * (kc.transpose() * grad).norm();
    if authority > 1e-12 {
        needed / authority
    } else if needed <= 0.0 {
        0.0
    } else {
        f64::INFINITY
    }
}

/// The gradients at rest a barrier's boundary can present: one for a half-plane (or half-space
/// obstacle), else 360 sampled outward normals n with the lift's velocity part (n, k·n) for
/// obstacles and the barrier's own gradient on a ring around an ellipse's centre. The second
/// value says whether the sampling is exact (flat boundary: the curvature term ½tr(∇²h N) is
/// zero) or leaves that term out.
pub(super) fn rest_gradients(world: &World, setup: &ControlSetup, bi: usize) -> (Vec<State>, bool) {
    let barrier = &setup.config.barriers[bi];
    let n_safe = world.file.safe_sets.len();
    let ring = |cx: f64, cy: f64, r: f64| -> Vec<State> {
        (0..360)
            .map(|d| {
                let a = (d as f64).to_radians();
                barrier
                    .eval(&State::new(cx + r * a.cos(), cy + r * a.sin(), 0.0, 0.0))
                    .gradient
            })
            .collect()
    };
    if bi < n_safe {
        match &world.file.safe_sets[bi] {
            SafeSetSpec::HalfPlane { .. } => (vec![barrier.eval(&State::zeros()).gradient], true),
            SafeSetSpec::EllipseInside {
                center, semi_axes, ..
            }
            | SafeSetSpec::EllipseOutside {
                center, semi_axes, ..
            } => (
                ring(center[0], center[1], semi_axes[0].min(semi_axes[1])),
                false,
            ),
        }
    } else {
        // a map gives one barrier per outline piece: barrier index ≠ obstacle index
        let Some(ob) = crate::obstacles::obstacle_of_barrier(&world.obstacles, bi - n_safe) else {
            return (Vec::new(), false);
        };
        if ob.is_half_space() {
            (vec![barrier.eval(&State::zeros()).gradient], true)
        } else {
            let k = world.file.control.obstacle_lift;
            let grads = (0..360)
                .map(|d| {
                    let a = (d as f64).to_radians();
                    State::new(a.cos(), a.sin(), k * a.cos(), k * a.sin())
                })
                .collect();
            (grads, false)
        }
    }
}

/// Item 6, condition 1 under the input limit. The proof of Theorem 3 (case i) scales a witness
/// input without bound; with a box |u_k| ≤ l_k the Ω_i row of the honest filter must be
/// satisfiable by the box itself. At rest on ĥ_i = 0 the row reads Λu ≥ γ_i‖(K_i c̄_i)ᵀ∂h‖
/// (the Itô term ½tr(∇²h N) vanishes on flat boundaries); when the box cannot give that, the
/// honest row becomes infeasible near the boundary, Step 3 must drop units by residue, and a
/// stealthy attacker (residue at its nominal level) wins that ranking about half the time.
pub(super) fn check_input_authority(cx: Ctx<'_>, filters: &[FilterCheck], found: &mut Findings) {
    let Ctx { world, setup, .. } = cx;
    let Some(limit) = setup.config.input_limit else {
        found.hypotheses.push(Hypothesis {
            name: "condition 1 under the input limit".into(),
            status: Status::Holds,
            detail: "no input limit: the proof's scaling of the witness input applies".into(),
        });
        return;
    };
    let gains = single_filter_gains(world, setup, filters);
    for bi in 0..setup.config.barriers.len() {
        let name = setup.config.barriers[bi].name().to_string();
        let (grads, exact) = rest_gradients(world, setup, bi);
        let mut worst = (0.0_f64, String::new());
        for (label, gamma, kc) in &gains {
            for g in &grads {
                let r = rest_demand(setup, g, *gamma, kc, &limit);
                if r > worst.0 || worst.1.is_empty() {
                    worst = (r, label.clone());
                }
            }
        }
        let (ratio, filter) = worst;
        let holds = ratio <= 1.0;
        let needed = format!(
            "at rest on ĥ = 0 the row of {filter} needs {:.3} × the box's authority (|u| ≤ ({}, {}) m/s²){}",
            ratio,
            limit[0],
            limit[1],
            if exact {
                ""
            } else {
                "; worst of 360 boundary normals, curvature term left out"
            }
        );
        if !holds && ratio.is_finite() {
            found.reasons.push(format!(
                "{name}: the input limit cannot meet the robust CBF row at rest on its boundary ({needed}); raise control.input_limit to ≥ ({:.3}, {:.3}) m/s², or lower γ‖Kc̄‖ (less process noise, more precise sensors)",
                limit[0] * ratio,
                limit[1] * ratio
            ));
        } else if !holds {
            // Λ = Gᵀ∂h = 0 at rest: no box can help, the barrier needs a velocity term.
            found.reasons.push(format!(
                "{name}: the input does not act on this barrier at rest (Λ = Gᵀ∂h = 0), so no input limit can meet its robust row ({needed}); give the barrier a velocity term (relative degree 2: a ≠ 0 on v_x or v_y)"
            ));
        }
        found.hypotheses.push(Hypothesis {
            name: format!("condition 1 under the input limit for {name}"),
            status: match (holds, exact) {
                (false, _) => Status::Fails,
                (true, true) => Status::Holds,
                (true, false) => Status::Assumed,
            },
            detail: needed,
        });
        if holds && !exact {
            found.assumptions.push(format!(
                "{name}: the curvature term ½tr(∇²h N) does not turn the input-limit margin ({:.3}) negative",
                1.0 - ratio
            ));
        }
    }
}
