//! The walk along the planned path: at each sample the rows at rest of every kept unit
//! (under each attack scenario), the best input along the path, where the rows stall, whether a
//! gap is passable, and whether the goal can be held.

use super::*;

impl Model<'_> {
    /// The best acceleration along `t` the rows allow at rest at `p` or beside it: the robot
    /// does not hold the path exactly (the rows themselves push it sideways), so every point
    /// across the path within [`LATERAL_REACH`] that it can slide to without touching an
    /// obstacle (h ≥ 0 all the way, true position) is tried, nearest first. `Ok` with the first
    /// acceleration ≥ [`MIN_PROGRESS`] and where; `Err` with what blocks the path point itself.
    pub(super) fn progress_near(
        &self,
        p: [f64; 2],
        t: [f64; 2],
        o: &[[f64; 2]],
        time: f64,
        (kappa, limit): (f64, Option<Input>),
        rows: &mut Vec<(HalfSpace, usize, f64)>,
    ) -> Result<(f64, [f64; 2]), Blocked> {
        let nrm = [-t[1], t[0]];
        let steps = (LATERAL_REACH / LATERAL_STEP).round() as i32;
        let mut first: Option<Blocked> = None;
        let mut open = [true, true];
        for k in 0..=steps {
            for (side, sign) in [(0usize, 1.0), (1usize, -1.0)] {
                if k == 0 && side == 1 {
                    continue;
                }
                if !open[side] {
                    continue;
                }
                let d = sign * f64::from(k) * LATERAL_STEP;
                let q = [p[0] + d * nrm[0], p[1] + d * nrm[1]];
                if k > 0 && !self.clear(q) {
                    open[side] = false;
                    continue;
                }
                self.rows(q, o, time, kappa, rows);
                match best_along(rows, limit, t) {
                    Some(a) if a >= MIN_PROGRESS => return Ok((a, q)),
                    Some(a) => {
                        first.get_or_insert(Blocked::NoProgress(a));
                    }
                    None => {
                        first.get_or_insert(Blocked::Infeasible);
                    }
                }
            }
        }
        Err(first.unwrap_or(Blocked::Infeasible))
    }

    /// The true position `q` (at rest) is inside every safe set and clear of every obstacle.
    pub(super) fn clear(&self, q: [f64; 2]) -> bool {
        let x = State::new(q[0], q[1], 0.0, 0.0);
        self.setup
            .config
            .barriers
            .iter()
            .filter(|b| b.mover().is_none())
            .all(|b| b.eval(&x).value >= 0.0)
    }
}

impl Model<'_> {
    /// Whether the robot at rest at path point `p` (direction `t`) can go on at `time`, for
    /// every offset scenario of the case: `Ok` with the least progress, where, the largest
    /// spoofed offset, and — when the rows of every unit admit no input but Step 3 drops the
    /// spoofed units (their innovations give them away, [`RANKING_SHIFT`]) and the rest leave
    /// progress — the point as a joint-infeasible one; `Err` with the first blocking scenario.
    #[allow(clippy::type_complexity)]
    pub(super) fn passable(
        &self,
        p: [f64; 2],
        t: [f64; 2],
        time: f64,
        attack: bool,
        (kappa, limit): (f64, Option<Input>),
        rows: &mut Vec<(HalfSpace, usize, f64)>,
    ) -> Result<(f64, [f64; 2], f64, Option<Stall>), Stall> {
        let mut worst: Option<(f64, [f64; 2])> = None;
        let mut big_r: f64 = 0.0;
        let mut step3 = None;
        for o in self.scenarios_at(time, attack) {
            let big = o
                .iter()
                .copied()
                .max_by(|a, b| a[0].hypot(a[1]).total_cmp(&b[0].hypot(b[1])))
                .unwrap_or([0.0, 0.0]);
            big_r = big_r.max(big[0].hypot(big[1]));
            let stall = |blocked: Blocked, rows: &mut Vec<(HalfSpace, usize, f64)>| {
                self.rows(p, &o, time, kappa, rows);
                Stall {
                    at: p,
                    along: 0.0,
                    blocked,
                    binding: binding(self, rows),
                    offset: big,
                }
            };
            let got = match self.progress_near(p, t, &o, time, (kappa, limit), rows) {
                Ok(x) => x,
                Err(Blocked::Infeasible)
                    if attack
                        && self.setup.config.kind == ControllerKind::FtCbfClf
                        && (0..self.spoofed.len())
                            .all(|k| self.ranking_shift(k, time) >= RANKING_SHIFT) =>
                {
                    // Step 3 drops units by residue, and the attack gives the spoofed ones away.
                    let joint = stall(Blocked::Infeasible, rows);
                    let honest = self.without_spoofed(&o);
                    match self.progress_near(p, t, &honest, time, (kappa, limit), rows) {
                        Ok(x) => {
                            step3.get_or_insert(joint);
                            x
                        }
                        Err(_) => return Err(joint),
                    }
                }
                Err(blocked) => return Err(stall(blocked, rows)),
            };
            if worst.is_none_or(|w| got.0 < w.0) {
                worst = Some(got);
            }
        }
        let (a, q) = worst.unwrap_or((f64::INFINITY, p));
        Ok((a, q, big_r, step3))
    }

    /// `o` with every spoofed unit dropped (an infinite offset: `rows` skips the unit, as Step
    /// 2 skips an isolated one).
    pub(super) fn without_spoofed(&self, o: &[[f64; 2]]) -> Offsets {
        let mut v = o.to_vec();
        for &(ui, _) in &self.spoofed {
            v[ui] = [f64::INFINITY, f64::INFINITY];
        }
        v
    }

    /// When the robot is assumed to reach `along` metres of the path \[s\].
    pub(super) fn time_at(&self, along: f64) -> f64 {
        START_DELAY + along / self.speed.max(1e-3)
    }

    /// The spoofed estimates' offset at time `t` \[m\] (see [`AttackReach::exact`]).
    pub(super) fn reach_at(&self, t: f64) -> f64 {
        let r = declared_reach(self.world, t, self.speed, self.max_coord);
        if r.exact {
            return r.reach;
        }
        r.reach.min(self.theta_max(t) * (1.0 - 1e-9))
    }

    /// The largest θ_ia(t) over the spoofed units.
    pub(super) fn theta_max(&self, t: f64) -> f64 {
        self.spoofed
            .iter()
            .map(|&(i, a)| theta_at(self.setup, self.patterns, i, a, t))
            .fold(0.0, f64::max)
    }

    /// Length of the path \[m\].
    pub(super) fn length(&self) -> f64 {
        self.path
            .windows(2)
            .map(|w| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]))
            .sum()
    }
}

/// The largest `dir·u` over `{u : rows, |u_k| ≤ L_k}` (None: empty), by vertex enumeration.
pub(super) fn best_along(
    rows: &[(HalfSpace, usize, f64)],
    limit: Option<Input>,
    dir: [f64; 2],
) -> Option<f64> {
    let l = limit.map_or([NO_LIMIT_BOX, NO_LIMIT_BOX], |l| [l[0], l[1]]);
    let mut lines: Vec<([f64; 2], f64)> = Vec::with_capacity(rows.len() + 4);
    for (h, _, _) in rows {
        let n = h.normal.norm();
        if !(n.is_finite() && h.offset.is_finite()) {
            return None;
        }
        if n < 1e-12 {
            if h.offset < 0.0 {
                return None;
            }
            continue;
        }
        lines.push(([h.normal[0] / n, h.normal[1] / n], h.offset / n));
    }
    lines.push(([1.0, 0.0], l[0]));
    lines.push(([-1.0, 0.0], l[0]));
    lines.push(([0.0, 1.0], l[1]));
    lines.push(([0.0, -1.0], l[1]));
    let scale = lines.iter().map(|(_, b)| b.abs()).fold(1.0, f64::max);
    let tol = 1e-9 * scale;
    let mut best: Option<f64> = None;
    for i in 0..lines.len() {
        for j in (i + 1)..lines.len() {
            let (a1, b1) = lines[i];
            let (a2, b2) = lines[j];
            let det = a1[0] * a2[1] - a1[1] * a2[0];
            if det.abs() < 1e-12 {
                continue;
            }
            let u = [
                (b1 * a2[1] - b2 * a1[1]) / det,
                (a1[0] * b2 - a2[0] * b1) / det,
            ];
            if lines
                .iter()
                .all(|(a, b)| a[0] * u[0] + a[1] * u[1] - b <= tol)
            {
                let v = dir[0] * u[0] + dir[1] * u[1];
                best = Some(best.map_or(v, |b: f64| b.max(v)));
            }
        }
    }
    best
}

/// The path sampled every [`SAMPLE_STEP`] m (every length / [`MAX_SAMPLES`] on a longer path):
/// (point, unit tangent, distance along), the goal itself excluded (it is judged by holding).
pub(super) fn samples(path: &[[f64; 2]]) -> Vec<([f64; 2], [f64; 2], f64)> {
    let length = |w: &[[f64; 2]]| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]);
    let total: f64 = path.windows(2).map(length).filter(|l| l.is_finite()).sum();
    let step = SAMPLE_STEP.max(total / MAX_SAMPLES as f64);
    let mut out = Vec::new();
    let mut along = 0.0;
    for w in path.windows(2) {
        let (a, b) = (w[0], w[1]);
        let len = length(w);
        if len < 1e-9 {
            continue;
        }
        let t = [(b[0] - a[0]) / len, (b[1] - a[1]) / len];
        let n = (len / step).ceil() as usize;
        for k in 0..n {
            let s = k as f64 * len / n as f64;
            out.push(([a[0] + t[0] * s, a[1] + t[1] * s], t, along + s));
        }
        along += len;
    }
    out
}

/// One case for κ and the box: without attack (`attack = false`), or under the declared attack
/// with the spoofed estimates where the attack has moved them when the robot gets there. In
/// phases: the walk along the path, the reach while at the goal, whether the goal holds over
/// the hold period, and whether a spoofed estimate misleads the tracker as it settles (the
/// last two from one evaluation of the offsets at each hold time).
pub(super) fn case(
    model: &Model,
    name: String,
    attack: bool,
    kappa: f64,
    limit: Option<Input>,
) -> LivenessCase {
    let mut rows = Vec::new();
    let walk = walk_path(model, attack, (kappa, limit), &mut rows);
    let reach = reach_at_goal(model, attack, walk.delay, walk.applied);
    // Holding: u = 0 satisfies every row at rest at some point of the goal set, at every time
    // from the robot's arrival (or from HOLD_WINDOW before the end, when it arrives earlier) to
    // the end of the run. `settled` is judged over the run's last SETTLE_WINDOW: an offset that
    // pushes the robot out of its goal earlier and then ends (an attack window that closes)
    // leaves it time to come back.
    let hold: Vec<(f64, Vec<Offsets>)> = hold_times(model, walk.delay)
        .into_iter()
        .map(|t| (t, model.scenarios_at(t, attack)))
        .collect();
    let goal_holds = goal_holds(model, &hold, kappa, &mut rows);
    let misled = if attack && model.response.is_some() {
        misled(model, &hold)
    } else {
        None
    };
    LivenessCase {
        name,
        reach,
        stall: walk.stall,
        least_progress: walk.least,
        goal_holds,
        misled,
        through_step3: walk.through_step3,
        joint_infeasible: walk.joint_infeasible,
        waited: walk.waited,
    }
}

/// What the walk along the path found.
pub(super) struct PathWalk {
    /// The largest spoofed offset within θ met on the way \[m\].
    applied: f64,
    /// The least progress the rows allowed, and where.
    least: (f64, [f64; 2]),
    /// Where the robot stopped for good, if it did.
    stall: Option<Stall>,
    /// Samples passed only through Step 3's joint problem.
    through_step3: usize,
    /// The first place the joint problem had no solution.
    joint_infeasible: Option<Stall>,
    /// Time waited for offsets to pass \[s\].
    delay: f64,
    /// The total wait and where the robot first waited.
    waited: Option<(f64, [f64; 2])>,
}

/// Walks the path's samples at the planned times: each must be passable; under attack a
/// blocked robot waits where it is (in steps of `WAIT_STEP`) while a time-varying offset may
/// still let it on, and stalls when none does.
pub(super) fn walk_path(
    model: &Model,
    attack: bool,
    (kappa, limit): (f64, Option<Input>),
    rows: &mut Vec<(HalfSpace, usize, f64)>,
) -> PathWalk {
    let mut w = PathWalk {
        applied: 0.0,
        least: (f64::INFINITY, model.path[0]),
        stall: None,
        through_step3: 0,
        joint_infeasible: None,
        delay: 0.0,
        waited: None,
    };
    let last_wait = model.world.file.duration - HOLD_WINDOW;
    'path: for (p, t, along) in samples(&model.path) {
        let planned = model.time_at(along) + w.delay;
        let mut time = planned;
        loop {
            match model.passable(p, t, time, attack, (kappa, limit), rows) {
                Ok((a, q, r, step3)) => {
                    if r <= model.theta_max(time) {
                        w.applied = w.applied.max(r);
                    }
                    if a < w.least.0 {
                        w.least = (a, q);
                    }
                    if let Some(mut st) = step3 {
                        st.along = along;
                        w.through_step3 += 1;
                        w.joint_infeasible.get_or_insert(st);
                    }
                    break;
                }
                Err(mut st) => {
                    st.along = along;
                    if st.blocked == Blocked::Infeasible && w.joint_infeasible.is_none() {
                        w.joint_infeasible = Some(st.clone());
                    }
                    // A time-varying offset (an attack window that closes, a sinusoid) may
                    // let the robot on later: it waits where it is.
                    if attack && time + WAIT_STEP <= last_wait {
                        time += WAIT_STEP;
                        continue;
                    }
                    let mut st = st;
                    if time > planned {
                        // Blocked until the end: report it where and as it first was.
                        if let Err(first) =
                            model.passable(p, t, planned, attack, (kappa, limit), rows)
                        {
                            st = Stall { along, ..first };
                        }
                    }
                    w.stall = Some(st);
                    break 'path;
                }
            }
        }
        if time > planned {
            w.delay += time - planned;
            w.waited = Some((w.delay, w.waited.map_or(p, |x| x.1)));
        }
    }
    w
}

/// The case's reach: `applied` on the way, raised by the spoofed estimates' offsets within θ
/// while the robot is at its goal (from its arrival, `delay` late, to the end of the run).
pub(super) fn reach_at_goal(model: &Model, attack: bool, delay: f64, mut applied: f64) -> f64 {
    let duration = model.world.file.duration;
    let at_goal = (model.time_at(model.length()) + delay).min(duration);
    let mut t = at_goal;
    while t <= duration {
        for o in model.scenarios_at(t, attack) {
            for &(ui, _) in &model.spoofed {
                let r = o[ui][0].hypot(o[ui][1]);
                if r <= model.theta_max(t) {
                    applied = applied.max(r);
                }
            }
        }
        t += HOLD_STEP;
    }
    applied
}

/// The hold period's times, `HOLD_STEP` apart: from the robot's arrival (`delay` late), or
/// from `HOLD_WINDOW` before the end when it arrives earlier, to the end of the run.
pub(super) fn hold_times(model: &Model, delay: f64) -> Vec<f64> {
    let duration = model.world.file.duration;
    let arrive = (model.time_at(model.length()) + delay)
        .max(duration - HOLD_WINDOW)
        .min(duration);
    let n_hold = ((duration - arrive) / HOLD_STEP).ceil().max(0.0) as u32;
    (0..=n_hold)
        .map(|k| (arrive + f64::from(k) * HOLD_STEP).min(duration))
        .collect()
}

/// Whether u = 0 satisfies every row at rest, at every hold time and offset of `hold`, at the
/// goal's centre or else at one of 32 points on two rings inside the goal.
pub(super) fn goal_holds(
    model: &Model,
    hold: &[(f64, Vec<Offsets>)],
    kappa: f64,
    rows: &mut Vec<(HalfSpace, usize, f64)>,
) -> bool {
    let mut holds_at = |g: [f64; 2]| {
        hold.iter().all(|(t, offs)| {
            offs.iter().all(|o| {
                model.rows(g, o, *t, kappa, rows);
                rows.iter()
                    .all(|(h, _, _)| h.offset.is_finite() && h.offset >= -1e-12)
            })
        })
    };
    if holds_at(model.goal) {
        return true;
    }
    let r = model.goal_radius * 0.8;
    for ring in [0.5, 1.0] {
        for k in 0..16 {
            let a = std::f64::consts::TAU * f64::from(k) / 16.0;
            let g = [
                model.goal[0] + ring * r * a.cos(),
                model.goal[1] + ring * r * a.sin(),
            ];
            if holds_at(g) {
                return true;
            }
        }
    }
    false
}

/// Settling: the tracker follows the kept unit Step 3 ranks first; a spoofed estimate Step 2
/// cannot isolate may rank first, and the robot then rests where that estimate is in the goal.
/// The largest such offset beyond the goal radius over the run's last `SETTLE_WINDOW` of
/// `hold`, with its θ.
pub(super) fn misled(model: &Model, hold: &[(f64, Vec<Offsets>)]) -> Option<(f64, f64)> {
    let mut misled: Option<(f64, f64)> = None;
    let end = model.world.file.duration;
    for (t, offs) in hold.iter().filter(|(t, _)| *t >= end - SETTLE_WINDOW) {
        let t = *t;
        for o in offs {
            for (k, &(ui, a)) in model.spoofed.iter().enumerate() {
                if model.ranking_shift(k, t) >= RANKING_SHIFT {
                    // Its innovations give it away: the tracker does not follow it.
                    continue;
                }
                if model.setup.config.kind == ControllerKind::FtCbfClf && model.drifting(ui, t) {
                    // It dead-reckons an axis: its spread outgrows its γ (starved), and the
                    // tracker follows a fed unit, the honest one at least.
                    continue;
                }
                let r = o[ui][0].hypot(o[ui][1]);
                let theta = match model.setup.config.kind {
                    ControllerKind::FtCbfClf => theta_at(model.setup, model.patterns, ui, a, t),
                    _ => f64::INFINITY,
                };
                // The robot rests where the estimate it follows is at the goal: that estimate's
                // own error moves it further, towards the goal's edge or away, one side.
                let noise = ONE_SIDED_95 * model.position_std(ui);
                if r <= theta && r + noise > model.goal_radius && misled.is_none_or(|m| r > m.0) {
                    misled = Some((r, theta));
                }
            }
        }
    }
    misled
}

/// The barriers whose rows demand a push (ω̄ > 0), most demanding first, each named once.
pub(super) fn binding(model: &Model, rows: &[(HalfSpace, usize, f64)]) -> Vec<String> {
    let mut v: Vec<(f64, usize)> = rows
        .iter()
        .filter(|(_, _, w)| *w > 0.0 || !w.is_finite())
        .map(|(_, b, w)| (*w, *b))
        .collect();
    v.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut names: Vec<String> = Vec::new();
    for (_, b) in v {
        let n = model.setup.config.barriers[b].name().to_string();
        if !names.contains(&n) {
            names.push(n);
        }
    }
    names
}

pub(super) fn cases(model: &Model, kappa: f64, limit: Option<Input>) -> Vec<LivenessCase> {
    let mut out = vec![case(model, "without attack".into(), false, kappa, limit)];
    if !model.spoofed.is_empty() && !model.world.file.attacks.is_empty() {
        out.push(case(
            model,
            format!("under the declared attack ({})", model.attack_name),
            true,
            kappa,
            limit,
        ));
    }
    out
}
