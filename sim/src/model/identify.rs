//! The filters' process noise q identified from the robot's own drive (issue #35).
//!
//! The filters model the robot as the double integrator (6.2) driven by the acceleration the
//! drive realised ([`ftcbf_controller::drive::realized_acceleration`]) plus white acceleration
//! noise of intensity q per axis. What the drive does not realise (the wheel motors' lag, slip,
//! the chassis' own dynamics) is that noise; Theorem 1's γ holds only if q covers it.
//!
//! The identification runs the world's robot (its URDF, physics step, drive settings and control
//! rate) alone on an empty floor for [`IDENT_SECONDS`], under a seeded excitation: accelerations
//! drawn uniformly in the world's input box (±[`DEFAULT_EXCITATION`] m/s² per axis without
//! one), each held for 0.2–1 s: the inputs of the safety-filter form, which change smoothly.
//! The paper form's QP switches its input at every step (bang-bang); with holds of one step the
//! same robot reads q ≈ 2.4e-2 and its honest filters still leave γ (paper_turtlebot, 13 of 20
//! attack-free runs), so `ftcbf check` reports the paper form on a rapier robot as outside the
//! drive model instead. At every control step it records the velocity change the filters'
//! prediction misses, w_k = Δv_true − a_realised·Δt (world frame). For white noise of intensity
//! q per axis, a sum of L consecutive w has E‖Σw‖² = 2·q·L·Δt; the mismatch is not white (motor
//! lag makes it correlated over a few steps), so q is the largest of those ratios over windows
//! of L = 1, 2, 5, 10, 25 and 50 control steps: the white noise that covers the mismatch at
//! every time scale up to one second.

use std::collections::HashMap;
use std::sync::{Mutex, OnceLock};

use ftcbf_controller::drive::{realized_acceleration, BodyCommand};
use ftcbf_controller::Input;
use rand::Rng;

use crate::physics::Pose2;
use crate::sensors::stream_rng;
use crate::world::World;

use crate::plant::{drive_config, physics_config, Plant};

/// Length of the identification run \[s\].
pub const IDENT_SECONDS: f64 = 30.0;
/// Excitation amplitude per axis without an input box [m/s²].
pub const DEFAULT_EXCITATION: f64 = 1.0;
/// Window lengths [control steps] over which the mismatch's intensity is measured.
pub const WINDOWS: [usize; 6] = [1, 2, 5, 10, 25, 50];

/// What the identification measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriveIdentification {
    /// The identified intensity q [(m/s²)²·s]: white acceleration noise per axis.
    pub q: f64,
    /// The window \[s\] at which the mismatch was largest (q was read there).
    pub window: f64,
    /// RMS of the per-step velocity mismatch ‖w_k‖ [m/s].
    pub rms_step_mismatch: f64,
    /// Excitation amplitude per axis [m/s²].
    pub excitation: f64,
    /// Length of the run \[s\].
    pub seconds: f64,
}

fn cache() -> &'static Mutex<HashMap<String, DriveIdentification>> {
    static CACHE: OnceLock<Mutex<HashMap<String, DriveIdentification>>> = OnceLock::new();
    CACHE.get_or_init(|| Mutex::new(HashMap::new()))
}

/// q of `world`'s robot and drive, identified once per process for each robot, physics, drive
/// and rate (a batch of trials computes it once), and kept on disk between processes (see
/// [`disk`]). Deterministic: its excitation has its own fixed seed, independent of the run's,
/// and a disk entry holds the numbers bit for bit, so a cached q is the q a fresh
/// identification gives.
pub fn identify(world: &World) -> Result<DriveIdentification, String> {
    let key = cache_key(world)?;
    if let Some(hit) = cache().lock().ok().and_then(|c| c.get(&key).copied()) {
        return Ok(hit);
    }
    let dir = disk::dir();
    let found = match dir.as_deref().and_then(|d| disk::load(d, &key)) {
        Some(hit) => hit,
        None => {
            let found = run(world)?;
            if let Some(d) = dir.as_deref() {
                disk::store(d, &key, &found);
            }
            found
        }
    };
    if let Ok(mut c) = cache().lock() {
        c.insert(key, found);
    }
    Ok(found)
}

/// The identification cache on disk: one small text file per key, named by a hash of the key
/// and holding the whole key, so an entry is used only for exactly the key it was made for (a
/// hash collision or an entry from another version is a miss). A missing, unreadable, corrupt
/// or stale entry is ignored (with a warning on stderr when it exists but cannot be used) and
/// rewritten; a cache that cannot be written is skipped silently: q is then identified again
/// by the next process, never wrong.
pub mod disk {
    use std::hash::{Hash, Hasher};
    use std::path::{Path, PathBuf};

    use super::DriveIdentification;

    /// First line of an entry: the format, and what the identification's code depends on
    /// (its length, windows, excitation and the crate version: a new version identifies again).
    pub fn header() -> String {
        format!(
            "ftcbf drive identification v1 · ftcbf-sim {} · {} s · windows {:?} · excitation {}",
            env!("CARGO_PKG_VERSION"),
            super::IDENT_SECONDS,
            super::WINDOWS,
            super::DEFAULT_EXCITATION,
        )
    }

    /// The cache folder: `FTCBF_CACHE_DIR` (empty: no disk cache), else
    /// `$XDG_CACHE_HOME/ftcbf`, else `$HOME/.cache/ftcbf`; `None` when none is set.
    pub fn dir() -> Option<PathBuf> {
        let var = |k: &str| std::env::var_os(k).filter(|v| !v.is_empty());
        if let Some(v) = std::env::var_os("FTCBF_CACHE_DIR") {
            return (!v.is_empty()).then(|| PathBuf::from(v));
        }
        if let Some(x) = var("XDG_CACHE_HOME") {
            return Some(PathBuf::from(x).join("ftcbf"));
        }
        var("HOME").map(|h| PathBuf::from(h).join(".cache").join("ftcbf"))
    }

    /// The file of `key` in `dir`.
    pub fn path(dir: &Path, key: &str) -> PathBuf {
        let mut h = std::collections::hash_map::DefaultHasher::new();
        header().hash(&mut h);
        key.hash(&mut h);
        dir.join(format!("identify-{:016x}.txt", h.finish()))
    }

    /// The entry of `key`, if `dir` holds a valid one.
    pub fn load(dir: &Path, key: &str) -> Option<DriveIdentification> {
        let file = path(dir, key);
        let text = std::fs::read_to_string(&file).ok()?;
        match parse(&text, key) {
            Ok(found) => Some(found),
            Err(why) => {
                eprintln!(
                    "warning: ignoring the cached drive identification {} ({why}); identifying again",
                    file.display()
                );
                None
            }
        }
    }

    /// An entry's numbers, checked against `key`.
    fn parse(text: &str, key: &str) -> Result<DriveIdentification, String> {
        let mut lines = text.lines();
        if lines.next() != Some(header().as_str()) {
            return Err("written by another version".into());
        }
        if lines.next() != Some(key) {
            return Err("made for another robot, drive or physics".into());
        }
        let nums: Vec<f64> = lines
            .next()
            .ok_or("no numbers")?
            .split(' ')
            .map(|v| {
                v.parse::<f64>()
                    .map_err(|_| format!("`{v}` is not a number"))
            })
            .collect::<Result<_, _>>()?;
        let [q, window, rms_step_mismatch, excitation, seconds] = nums[..] else {
            return Err(format!("{} numbers where 5 were expected", nums.len()));
        };
        if !nums.iter().all(|v| v.is_finite() && *v >= 0.0) || lines.next().is_some() {
            return Err("not five finite nonnegative numbers on the third and last line".into());
        }
        Ok(DriveIdentification {
            q,
            window,
            rms_step_mismatch,
            excitation,
            seconds,
        })
    }

    /// Writes the entry of `key` (through a temporary file and a rename, so a concurrent reader
    /// sees the old entry or the new one, never half of one). Failures are ignored.
    pub fn store(dir: &Path, key: &str, id: &DriveIdentification) {
        if key.contains('\n') || std::fs::create_dir_all(dir).is_err() {
            return;
        }
        let file = path(dir, key);
        // `{:?}` of an f64 is the shortest text that parses back to the same bits.
        let text = format!(
            "{}\n{key}\n{:?} {:?} {:?} {:?} {:?}\n",
            header(),
            id.q,
            id.window,
            id.rms_step_mismatch,
            id.excitation,
            id.seconds
        );
        let tmp = file.with_extension(format!("tmp{}", std::process::id()));
        if std::fs::write(&tmp, text).is_ok() && std::fs::rename(&tmp, &file).is_err() {
            let _ = std::fs::remove_file(&tmp);
        }
    }

    #[cfg(test)]
    mod tests {
        use super::*;

        fn id() -> DriveIdentification {
            DriveIdentification {
                q: 1.0 / 3.0 * 1e-3,
                window: 0.1,
                rms_step_mismatch: 2.0_f64.sqrt() * 1e-3,
                excitation: 0.5,
                seconds: 30.0,
            }
        }

        fn scratch(name: &str) -> PathBuf {
            let d =
                std::env::temp_dir().join(format!("ftcbf-identify-{name}-{}", std::process::id()));
            let _ = std::fs::remove_dir_all(&d);
            d
        }

        #[test]
        fn an_entry_reads_back_bit_for_bit_and_only_for_its_key() {
            let d = scratch("roundtrip");
            assert_eq!(load(&d, "k1"), None);
            store(&d, "k1", &id());
            let back = load(&d, "k1").expect("stored");
            assert_eq!(back.q.to_bits(), id().q.to_bits());
            assert_eq!(
                back.rms_step_mismatch.to_bits(),
                id().rms_step_mismatch.to_bits()
            );
            assert_eq!(back, id());
            assert_eq!(load(&d, "k2"), None);
            // the file of k1 copied to k2's name (a collision): its key line does not match
            std::fs::copy(path(&d, "k1"), path(&d, "k2")).expect("copy");
            assert_eq!(load(&d, "k2"), None);
            let _ = std::fs::remove_dir_all(&d);
        }

        #[test]
        fn a_corrupt_or_stale_entry_is_ignored() {
            let d = scratch("corrupt");
            store(&d, "k", &id());
            let f = path(&d, "k");
            let good = std::fs::read_to_string(&f).expect("read");
            let bad = [
                good.replace(
                    "ftcbf drive identification v1",
                    "ftcbf drive identification v0",
                ),
                good.replacen("0.5 ", "NaN ", 1),
                good.replacen("0.5 ", "-0.5 ", 1),
                good.replacen("0.5 ", "half ", 1),
                good.replacen(" 30.0", "", 1),
                format!("{good}extra\n"),
                good.lines().take(2).collect::<Vec<_>>().join("\n"),
                String::new(),
            ];
            for text in bad {
                std::fs::write(&f, &text).expect("write");
                assert_eq!(load(&d, "k"), None, "{text:?} was trusted");
            }
            // rewritten after a miss
            store(&d, "k", &id());
            assert_eq!(load(&d, "k"), Some(id()));
            let _ = std::fs::remove_dir_all(&d);
        }
    }
}

/// What the identification depends on: the robot's dynamics (bodies' mass, inertia and
/// colliders, joints, wheels, limits; not its visual meshes, which can hold thousands of
/// vertices and would be formatted for every run of a batch), the drive as configured for the
/// world's form, every physics setting the plant runs with ([`physics_config`]: step, friction,
/// gravity, motors, solver iterations, contacts; a changed default is a changed key, so a disk
/// entry made with other physics is never used), the control rate and the excitation amplitude.
fn cache_key(world: &World) -> Result<String, String> {
    let robot = world
        .robot
        .as_ref()
        .ok_or_else(|| "rapier dynamics without a robot".to_string())?;
    let dynamics: Vec<_> = robot
        .bodies
        .iter()
        .map(|b| (b.pose_in_root, b.mass, b.com, b.inertia, &b.colliders))
        .collect();
    let f = &world.file;
    Ok(format!(
        "{dynamics:?}|{:?}|{:?}|{:?}|{:?}|{:?}|{}|{}|{:?}",
        robot.joints,
        robot.wheels,
        robot.limits,
        drive_config(world, &robot.limits),
        physics_config(world),
        world.control_dt(),
        world.ticks_per_control,
        f.control.input_limit,
    ))
}

fn run(world: &World) -> Result<DriveIdentification, String> {
    let dt = world.control_dt();
    let mut plant = Plant::robot(
        world,
        Pose2 {
            x: 0.0,
            y: 0.0,
            theta: 0.0,
        },
        &[],
    )?;
    let l = world.file.control.input_limit.unwrap_or(DEFAULT_EXCITATION);
    let mut rng = stream_rng(0, "identify", "excitation");
    let n = (IDENT_SECONDS / dt).round() as usize;
    let mut w: Vec<[f64; 2]> = Vec::with_capacity(n);
    let mut u = Input::zeros();
    let mut hold = 0usize;
    let mut before = BodyCommand::default();
    for _ in 0..n {
        if hold == 0 {
            u = Input::new(rng.random_range(-l..=l), rng.random_range(-l..=l));
            hold = ((rng.random_range(0.2..=1.0) / dt).round() as usize).max(1);
        }
        hold -= 1;
        let t0 = plant.truth();
        let sent = plant.apply_input(&u, t0.theta, dt);
        let after = BodyCommand {
            v: sent[0],
            omega: sent[1],
        };
        let a = realized_acceleration(before, after, t0.theta, dt)
            .ok_or_else(|| "the drive's command is not finite".to_string())?;
        before = after;
        for _ in 0..world.ticks_per_control {
            plant.tick();
        }
        let t1 = plant.truth();
        let m = [t1.vx - t0.vx - a[0] * dt, t1.vy - t0.vy - a[1] * dt];
        if !(m[0].is_finite() && m[1].is_finite()) {
            return Err("the robot's velocity became non-finite".to_string());
        }
        w.push(m);
    }
    Ok(estimate(&w, dt, l))
}

/// q from the per-step mismatches `w` (see the module docs).
fn estimate(w: &[[f64; 2]], dt: f64, excitation: f64) -> DriveIdentification {
    let mut q = 0.0f64;
    let mut window = dt;
    for &len in &WINDOWS {
        let sums: Vec<f64> = w
            .chunks_exact(len)
            .map(|c| {
                let sx: f64 = c.iter().map(|m| m[0]).sum();
                let sy: f64 = c.iter().map(|m| m[1]).sum();
                sx * sx + sy * sy
            })
            .collect();
        if sums.is_empty() {
            continue;
        }
        let qi = sums.iter().sum::<f64>() / sums.len() as f64 / (2.0 * len as f64 * dt);
        if qi > q {
            q = qi;
            window = len as f64 * dt;
        }
    }
    let rms =
        (w.iter().map(|m| m[0] * m[0] + m[1] * m[1]).sum::<f64>() / w.len().max(1) as f64).sqrt();
    DriveIdentification {
        q,
        window,
        rms_step_mismatch: rms,
        excitation,
        seconds: w.len() as f64 * dt,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand_distr::StandardNormal;

    #[test]
    fn white_mismatch_gives_its_own_intensity() {
        // w ~ N(0, q·dt) per axis and step: every window reads q (within sampling error).
        let (q, dt): (f64, f64) = (2e-3, 0.02);
        let mut rng = stream_rng(7, "test", "white");
        let w: Vec<[f64; 2]> = (0..200_000)
            .map(|_| {
                let s = (q * dt).sqrt();
                [
                    s * rng.sample::<f64, _>(StandardNormal),
                    s * rng.sample::<f64, _>(StandardNormal),
                ]
            })
            .collect();
        let id = estimate(&w, dt, 1.0);
        // The largest of six estimates, each within a few % of q at these counts.
        assert!((id.q / q - 1.0).abs() < 0.08, "q = {}", id.q);
        assert!(
            (id.rms_step_mismatch - (2.0 * q * dt).sqrt()).abs() < 0.01 * (2.0 * q * dt).sqrt()
        );
    }

    #[test]
    fn correlated_mismatch_is_read_at_its_worst_window() {
        // A mismatch that repeats for 10 steps (a lag): summed over 10 steps it is 10× larger,
        // so q is read at the 10-step window, 10× the one-step intensity.
        let dt = 0.02;
        let w: Vec<[f64; 2]> = (0..10_000)
            .map(|k| {
                if (k / 10) % 2 == 0 {
                    [0.01, 0.0]
                } else {
                    [-0.01, 0.0]
                }
            })
            .collect();
        let id = estimate(&w, dt, 1.0);
        let one_step = 1e-4 / (2.0 * dt);
        assert!(
            (id.q / (10.0 * one_step) - 1.0).abs() < 1e-9,
            "q = {}",
            id.q
        );
        assert!((id.window - 10.0 * dt).abs() < 1e-12);
    }
}
