//! The context `ftcbf check` prints before its hypotheses: the plant, the filters, the
//! parameters in force and how they were obtained, unused sensors, what the environment loaded,
//! the map around the start, the active-barrier rule.

use super::*;

/// The barriers by the shape of their boundary in the plane: flat (half-planes, half-space
/// obstacles), flat-sided (cuboids, convex hulls, meshes: the footprint rounds their corners)
/// and curved (ellipses, balls, cylinders, capsules, cones).
pub(super) fn barrier_boundaries(world: &World) -> (usize, usize, usize) {
    use crate::obstacles::ShapeSpec;
    let (mut flat, mut cornered, mut curved) = (0, 0, 0);
    for s in &world.file.safe_sets {
        match s {
            SafeSetSpec::HalfPlane { .. } => flat += 1,
            _ => curved += 1,
        }
    }
    for ob in &world.obstacles {
        match ob.spec.shape {
            ShapeSpec::HalfSpace { .. } => flat += 1,
            ShapeSpec::Cuboid { .. } | ShapeSpec::ConvexHull { .. } | ShapeSpec::TriMesh { .. } => {
                cornered += 1
            }
            // one barrier per piece of its outline
            ShapeSpec::OccupancyMap { .. } => cornered += ob.barrier_count(),
            ShapeSpec::Ball { .. }
            | ShapeSpec::Cylinder { .. }
            | ShapeSpec::Capsule { .. }
            | ShapeSpec::Cone { .. } => curved += 1,
        }
    }
    (flat, cornered, curved)
}

/// For an occupancy map: the blocked cells nearest the start and the goal centre.
pub(super) fn map_surroundings(world: &World, start: [f64; 2], context: &mut Vec<String>) {
    for ob in &world.obstacles {
        let Some(field) = ob.map_field() else {
            continue;
        };
        for (what, p) in [("start", start), ("goal", world.file.goal.center)] {
            if let Some(n) = field.nearest_blocked(p) {
                context.push(format!(
                    "{}: the blocked cell nearest the {what} ({:.3}, {:.3}) is column {}, row {} from the bottom, centred at ({:.3}, {:.3}), {:.3} m away (signed distance of the field there {:.3} m)",
                    ob.name,
                    p[0],
                    p[1],
                    n.cell.0,
                    n.cell.1,
                    n.centre[0],
                    n.centre[1],
                    n.distance,
                    field.signed_distance(p).0
                ));
            }
        }
    }
}

/// The description lines: plant, control, channels and patterns, filters, parameters.
pub(super) fn context(cx: Ctx<'_>) -> Vec<String> {
    let Ctx {
        world,
        setup,
        names,
    } = cx;
    let f = &world.file;
    let mut context = Vec::new();
    if let Some(d) = &f.description {
        context.push(d.clone());
    }
    context_plant(world, &mut context);
    for note in world.obstacles.iter().filter_map(|o| o.note.as_ref()) {
        context.push(format!("warning: {note}"));
    }
    let x0 = setup.config.x0;
    map_surroundings(world, [x0[0], x0[1]], &mut context);
    context.push(format!(
        "control: {} at {} Hz ({} plant steps per control step), duration {} s, seed {}",
        f.control.controller.name(),
        f.control.rate_hz,
        world.ticks_per_control,
        f.duration,
        f.seed
    ));
    context.push(format!("channels: {}", names.sensors.join(", ")));
    for (pi, idx) in world.patterns.iter().enumerate() {
        let ch: Vec<&str> = idx.iter().map(|&i| names.sensors[i]).collect();
        context.push(format!(
            "fault pattern {} = {{{}}}",
            names.patterns[pi],
            ch.join(", ")
        ));
    }
    context.push(context_filters(world).unwrap_or_else(|e| format!("filters: {e}")));
    context_parameters(world, setup, &mut context);
    lint_unused_sensors(world, setup, &mut context);
    context
}

/// Lint (issue #36): a sensor whose readings reach neither a filter (directly, or through the
/// odometry derived from it or turned with it) nor the drive's heading is only recorded; say so,
/// with the key that would route it.
pub(super) fn lint_unused_sensors(world: &World, setup: &ControlSetup, context: &mut Vec<String>) {
    let f = &world.file;
    let heading = heading_sensor(world);
    let gyro = heading_fusion(world).map(|(g, _)| g);
    for (si, s) in f.sensors.iter().enumerate() {
        let to_filter = sensor_dependents(world, si)
            .iter()
            .any(|&d| setup.channel_of_sensor.get(d).is_some_and(Option::is_some));
        let to_drive = Some(si) == heading || Some(si) == gyro;
        if to_filter || to_drive {
            continue;
        }
        let hint = match s.measures {
            crate::sensors::Quantity::Speed if heading.is_none() => {
                "a body-frame speed needs a heading sensor to become world-frame velocity: add a `measures = \"heading\"` sensor"
            }
            crate::sensors::Quantity::Speed => {
                "set `world_velocity = true` (or leave it out: the default with a heading)"
            }
            crate::sensors::Quantity::YawRate => {
                "name it as the heading's gyro (`gyro = …` on the heading sensor) to fuse it"
            }
            crate::sensors::Quantity::WheelLeft | crate::sensors::Quantity::WheelRight => {
                "derive odometry from it (`from_wheels` on a `speed` sensor)"
            }
            _ => "it is recorded only",
        };
        context.push(format!(
            "warning: sensor `{}` ({}) reaches neither a filter nor the drive: {hint}",
            s.name,
            s.measures.as_str()
        ));
    }
}

/// The plant line (and the robot's warnings).
pub(super) fn context_plant(world: &World, context: &mut Vec<String>) {
    let f = &world.file;
    match f.dynamics {
        Dynamics::Rapier => {
            if let Some(r) = &world.robot {
                context.push(format!(
                    "plant: {} in rapier3d, dt = {} s; wheel radius {:.4} m, separation {:.4} m, |v| ≤ {:.3} m/s, |ω| ≤ {:.3} rad/s, footprint radius {:.4} m",
                    r.name,
                    f.physics.dt,
                    r.wheels.geometry.radius,
                    r.wheels.geometry.separation,
                    r.limits.v_max,
                    r.limits.omega_max,
                    r.footprint_radius
                ));
                if let Some(x) = &r.xacro_output {
                    context.push(format!(
                        "xacro: {} expanded by xacro into {}",
                        world
                            .file
                            .robot
                            .as_ref()
                            .map_or_else(String::new, |s| s.urdf.display().to_string()),
                        x.display()
                    ));
                }
                if let crate::robot::LimitsSource::Maker(m) = r.limits_source {
                    context.push(format!(
                        "limits: the URDF's wheel joints carry none; {} as published for {} ({})",
                        format_args!("|v| ≤ {} m/s, |ω| ≤ {} rad/s", m.v_max, m.omega_max),
                        m.robot_name,
                        m.source
                    ));
                }
                for w in &r.warnings {
                    context.push(format!("warning: {w}"));
                }
            }
        }
        Dynamics::Linear => context.push(format!(
            "plant: linearised model (6.2), Euler–Maruyama dt = {} s",
            f.linear.as_ref().map_or(0.0, |l| l.dt)
        )),
    }
}

/// The filters' process noise (and where it came from) and initial covariance.
pub(super) fn context_filters(world: &World) -> Result<String, RunError> {
    let f = &world.file;
    let p0 = initial_covariance(world);
    let (q, source) = process_noise(world)?;
    let from = match source {
        NoiseSource::WorldFile => "set by `[control] process_noise` in the world file".to_string(),
        NoiseSource::LinearPlant => "the linear plant's own noise, `[linear] process_noise`".to_string(),
        NoiseSource::Identified(id) => format!(
            "identified from the robot's drive: {:.0} s alone under accelerations up to ±{} m/s² per axis, the velocity change the filters' prediction misses (RMS {:.2e} m/s per step) read as white acceleration noise at its worst window, {:.2} s",
            id.seconds, id.excitation, id.rms_step_mismatch, id.window
        ),
    };
    Ok(format!(
        "filters: process noise q = {:.3e} ({from}; {}: Q = {}), P0 = diag({:e}, {:e}, {:e}, {:e}) from initial_std = [{}, {}]",
        q,
        process_model(world).as_str(),
        match process_model(world) {
            crate::world::ProcessModel::Acceleration => "diag(0, 0, q, q)",
            crate::world::ProcessModel::Isotropic => "q·I₄",
        },
        p0[(0, 0)],
        p0[(1, 1)],
        p0[(2, 2)],
        p0[(3, 3)],
        f.control.initial_std[0],
        f.control.initial_std[1]
    ))
}

/// How the parameters were obtained, the ones in force, and h̄_γ per barrier.
pub(super) fn context_parameters(world: &World, setup: &ControlSetup, context: &mut Vec<String>) {
    let f = &world.file;
    let p = &setup.params;
    match &p.derivation {
        Some(c) => {
            context.push(format!(
                "parameters computed for ε = {} (\"auto\", bounds = \"{}\"):",
                p.epsilon,
                f.control.bounds.as_str()
            ));
            for line in c.report(&setup.config.ft).lines() {
                context.push(format!("  {line}"));
            }
        }
        None => context.push("parameters given in the world file".to_string()),
    }
    context.push(format!(
        "in force: γ_i = [{}], γ_baseline = {:.6}, θ_ij = [{}], δ = {}{}",
        fmt_list(&setup.config.ft.gamma),
        setup.config.ft.gamma_baseline,
        fmt_list(&setup.config.ft.theta),
        if p.delta == f64::INFINITY {
            "none (the barrier rows are imposed at every step)".to_string()
        } else {
            p.delta.to_string()
        },
        if p.delta_auto {
            " (auto: half the largest δ Prop. 1 allows for the arena)"
        } else {
            ""
        }
    ));
    context.push(format!("CBF gain: {}", setup.gain));
    let rows = world.patterns.len().max(1) * setup.config.barriers.len();
    if rows > ftcbf_controller::qp::COMPACT_CBF_ROWS {
        context.push(match setup.config.input_limit {
            Some(_) => format!(
                "active rows: up to {rows} barrier rows (filters × barriers), more than the {} a QP holds all of: a step's QP leaves out each row whose half-space holds the whole input box (|Λ₁|L₁ + |Λ₂|L₂ ≤ −ω̄, i.e. κĥ exceeds what the box can reach plus the row's drift, robustness and Itô terms: a far obstacle's ĥ is far above the band where its row could bind). Every admissible input satisfies such a row, so the feasible set, the QP's solution and Steps 1–3 (which still test every row) are unchanged: the guarantee is the same",
                ftcbf_controller::qp::COMPACT_CBF_ROWS
            ),
            None => format!(
                "active rows: up to {rows} barrier rows and no input box: no row can be shown not to bind, every row enters every QP"
            ),
        });
    }
    let v_max = crate::world::structure::obstacle_barrier_config(world).v_max;
    if let Some(line) = active_barriers_line(setup, &setup.config.ft.gamma, v_max) {
        context.push(line);
    }
    for b in &setup.config.barriers {
        let hb: Vec<f64> = setup.config.ft.gamma.iter().map(|g| b.h_bar(*g)).collect();
        context.push(format!(
            "h̄_γ({}) per fault-pattern filter = [{}], baseline = {:.6}",
            b.name(),
            fmt_list(&hb),
            b.h_bar(setup.config.ft.gamma_baseline)
        ));
    }
}

/// `check`'s `environment:` section: what the environment file gave, and the three obstacles
/// nearest the start and the goal with the robot footprint's clearance from each (empty for a
/// world without `[environment]`).
pub(super) fn environment_lines(world: &World) -> Vec<String> {
    let Some(env) = &world.environment else {
        return Vec::new();
    };
    let mut out = env.lines();
    out.extend(crate::model::setup::route_notes(world));
    let (r, z) = world
        .robot
        .as_ref()
        .map_or((0.0, 0.0), |r| (r.footprint_radius, r.centre_height));
    let start = world.file.robot.as_ref().map_or_else(
        || {
            let x0 = world.file.linear.as_ref().map_or([0.0; 4], |l| l.x0);
            [x0[0], x0[1]]
        },
        |rb| [rb.start.x, rb.start.y],
    );
    for (what, p) in [("start", start), ("goal", world.file.goal.center)] {
        let mut near: Vec<(f64, &str)> = world
            .obstacles
            .iter()
            .map(|o| {
                let d = o.signed_distance(nalgebra::Vector3::new(p[0], p[1], z)) - r;
                (d, o.name.as_str())
            })
            .collect();
        near.sort_by(|a, b| a.0.total_cmp(&b.0));
        let list: Vec<String> = near
            .iter()
            .take(3)
            .map(|(d, n)| format!("{n} {d:.3} m"))
            .collect();
        out.push(format!(
            "nearest the {what} ({:.3}, {:.3}), footprint clearance: {}",
            p[0],
            p[1],
            list.join(", ")
        ));
    }
    out
}

/// One line on the active barriers (issue #52, [`ftcbf_controller::reach`]) when the world has
/// an index: how many barriers it covers, the rule, and the reach radius at rest and at v_max
/// before the filters' robustness and Itô terms (each step adds them to A and B).
pub(super) fn active_barriers_line(
    setup: &crate::model::setup::ControlSetup,
    gamma: &[f64],
    v_max: f64,
) -> Option<String> {
    use ftcbf_controller::reach::ReachTerms;
    let index = setup.config.barrier_index.as_ref()?;
    let limit = setup.config.input_limit?;
    let bars = &setup.config.barriers;
    let covered: Vec<usize> = (0..bars.len()).filter(|&b| index.covers(b)).collect();
    let h_bar = covered
        .iter()
        .flat_map(|&b| gamma.iter().map(move |&g| bars[b].h_bar(g)))
        .fold(0.0_f64, f64::max);
    let radius = |s: f64| {
        let a = setup.config.model.g.norm() * limit.norm() + s;
        ReachTerms {
            kappa: setup.config.cbf_gain,
            h_bar,
            a,
            b: 0.0,
            a_planar: a,
            b_planar: 0.0,
            delta: setup.config.delta,
            speed: s,
        }
        .radius(index.as_ref())
    };
    Some(format!(
        "active barriers: {} of {} barriers are indexed (a parry BVH over their boxes); a step builds a unit's row only for those within its reach radius D of the estimate, the least D with κ(h_lower(D, s) − h̄_γ) > ‖∂h‖·A + ‖∇²h‖_F·B (h_lower = D − r − margin − k·s; A = ‖G‖‖L‖ + ‖F x̂‖ + γ‖M‖, B = ½‖N‖): beyond D every input of the box satisfies the row, so leaving it out changes no feasible set and the guarantee is the same. With κ = {:.3}, h̄_γ ≤ {:.4}: D = {:.2} m at rest, {:.2} m at {:.2} m/s (before the filters' γ‖M‖ and Itô terms)",
        covered.len(),
        bars.len(),
        setup.config.cbf_gain,
        h_bar,
        radius(0.0),
        radius(v_max),
        v_max
    ))
}
