//! `ftcbf check --suggest`: the smallest change of `[control]` that makes Theorem 3 apply and
//! the path live.

use super::*;

/// The smallest change of the world's `[control]` keys that makes Theorem 3 apply and the path
/// live (`ftcbf check --suggest`, issue #36).
#[derive(Debug, Clone, PartialEq)]
pub struct Suggestion {
    /// `(key, value)` to set; empty when nothing needs to change or nothing was found.
    pub changes: Vec<(String, f64)>,
    /// Whether the world as written already has both.
    pub already: bool,
    /// The verdict and liveness lines with the changes (or of the world as written when none
    /// was found).
    pub verdict: String,
    /// The liveness line.
    pub liveness: String,
    /// How many candidate worlds were checked.
    pub tried: usize,
}

impl fmt::Display for Suggestion {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.already {
            return write!(
                f,
                "suggest: nothing to change: Theorem 3 applies and the path is live"
            );
        }
        if self.changes.is_empty() && self.tried == 0 {
            return write!(
                f,
                "suggest: nothing to try: control.cbf_gain is already at its ceiling (1/(2·dt)) and control.input_limit at or above {} m/s², and no other [control] key is searched, so what fails below needs a change to the world itself (its sensors, fault patterns, obstacles or path); as written:\n  {}\n  liveness: {}",
                liveness::LIMIT_CANDIDATES[liveness::LIMIT_CANDIDATES.len() - 1],
                self.verdict,
                self.liveness
            );
        }
        if self.changes.is_empty() {
            return write!(
                f,
                "suggest: no change of control.cbf_gain (≤ 1/(2·dt)) and control.input_limit (≤ {} m/s²), alone or together, makes Theorem 3 apply and the path live ({} worlds checked); as written:\n  {}\n  liveness: {}",
                liveness::LIMIT_CANDIDATES[liveness::LIMIT_CANDIDATES.len() - 1],
                self.tried,
                self.verdict,
                self.liveness
            );
        }
        writeln!(
            f,
            "suggest: the smallest change found ({} worlds checked) — in the world file:",
            self.tried
        )?;
        writeln!(f, "[control]")?;
        for (k, v) in &self.changes {
            writeln!(f, "{} = {v}", k.trim_start_matches("control."))?;
        }
        write!(
            f,
            "  with it: {}\n  liveness: {}",
            self.verdict, self.liveness
        )
    }
}

/// Search the changes of `control.cbf_gain` and `control.input_limit` (one key, then both) for
/// the first that makes Theorem 3 apply (when it does not) and the path live, re-checking the
/// world from its file with the change applied as `--set` would.
pub fn suggest(world: &World) -> Result<Suggestion, RunError> {
    let base = check_world(world)?;
    let ok = |r: &CheckReport| r.verdict.applies && r.liveness.live();
    if ok(&base) {
        return Ok(Suggestion {
            changes: Vec::new(),
            already: true,
            verdict: base.verdict.line(),
            liveness: base.liveness.line(),
            tried: 0,
        });
    }
    let c = &world.file.control;
    let kmax = world.kappa_max();
    let kappas: Vec<f64> = liveness::KAPPA_CANDIDATES
        .iter()
        .copied()
        .filter(|&k| k > base.liveness.kappa && k <= kmax)
        .collect();
    let current = c.input_limit.unwrap_or(f64::INFINITY);
    let limits: Vec<f64> = liveness::LIMIT_CANDIDATES
        .iter()
        .copied()
        .filter(|&l| l > current)
        .collect();
    let mut candidates: Vec<Vec<(String, f64)>> = Vec::new();
    candidates.extend(
        kappas
            .iter()
            .map(|&k| vec![("control.cbf_gain".to_string(), k)]),
    );
    candidates.extend(
        limits
            .iter()
            .map(|&l| vec![("control.input_limit".to_string(), l)]),
    );
    for &l in &limits {
        for &k in &kappas {
            candidates.push(vec![
                ("control.input_limit".to_string(), l),
                ("control.cbf_gain".to_string(), k),
            ]);
        }
    }
    let mut tried = 0;
    for changes in candidates {
        let overrides: Vec<crate::world::Override> = changes
            .iter()
            .map(|(k, v)| crate::world::Override {
                key: k.clone(),
                value: *v,
            })
            .collect();
        let Ok(w) = World::load(&world.path, &overrides) else {
            continue;
        };
        tried += 1;
        let Ok(r) = check_world(&w) else {
            continue;
        };
        if ok(&r) {
            return Ok(Suggestion {
                changes,
                already: false,
                verdict: r.verdict.line(),
                liveness: r.liveness.line(),
                tried,
            });
        }
    }
    Ok(Suggestion {
        changes: Vec::new(),
        already: false,
        verdict: base.verdict.line(),
        liveness: base.liveness.line(),
        tried,
    })
}
