//! Xacro sources expanded by the real `xacro` (the PyPI package `xacro`, or ROS's).
//!
//! A URDF file with xacro markup outside XML comments (`<xacro:arg>`, `${…}`, `$(arg …)`) is
//! what ROS launch files pass through `xacro` before anything reads it. The loader does the
//! same: it runs `xacro FILE NAME:=VALUE… -o OUT`, with the file's own `$(arg)` defaults for
//! every argument not given. The expansion is cached:
//!
//! - on disk, in `<temp dir>/ftcbf-xacro/<file stem>-<16 hex digits>.urdf`, the digits an FNV-1a
//!   hash of the source's absolute path, its text, the arguments and the command, so the
//!   expanded file can be read (errors in it name its lines) and concurrent runs never share a
//!   half-written file (each writes a private temporary file and renames it);
//! - in the process: each (file, arguments) pair is expanded once per process (a batch of 200
//!   trials or a falsification run loads the world many times), and again in the next process,
//!   so an edited `<xacro:include>`d file is seen on the next run.
//!
//! `xacro` is looked up as the `xacro` program on `PATH`, then as the Python module
//! (`python3 -c "import xacro; xacro.main()"`; `python3 -m xacro` does not work, the package has
//! no `__main__`). Without it, the error says how to install it.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::{Mutex, OnceLock};

use super::RobotError;

/// How xacro sources are handled ([`super::LoadOptions::xacro`]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct XacroOptions {
    /// `$(arg NAME)` values, passed as `NAME:=VALUE`; the file's defaults apply to the others.
    pub args: BTreeMap<String, String>,
    /// Which xacro to run.
    pub command: XacroCommand,
}

/// Which xacro to run.
#[derive(Debug, Clone, Default, PartialEq)]
pub enum XacroCommand {
    /// `xacro` on `PATH`, else `python3 -c "import xacro; xacro.main()"`.
    #[default]
    Auto,
    /// This program and its leading arguments (the file and the `NAME:=VALUE` arguments follow).
    Program(Vec<String>),
    /// Never run xacro: a xacro source is refused with its line, as a plain-URDF reader does.
    Disabled,
}

/// What [`expand`] produced.
pub(crate) struct Expanded {
    /// The expanded URDF text.
    pub text: String,
    /// Where it was written.
    pub path: PathBuf,
}

/// The install hint of every "xacro is missing" message.
pub const INSTALL_HINT: &str =
    "install it with `pip install xacro` (the PyPI package runs without \
     ROS for files that need no `$(find …)`; with ROS: `sudo apt install ros-$ROS_DISTRO-xacro`)";

fn fnv1a(parts: &[&[u8]]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for p in parts {
        for &b in *p {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0000_0100_0000_01b3);
        }
        // Separator, so that ("ab", "c") and ("a", "bc") differ.
        h ^= 0xff;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// The candidate commands, in the order tried.
fn candidates(cmd: &XacroCommand) -> Vec<Vec<String>> {
    match cmd {
        XacroCommand::Auto => vec![
            vec!["xacro".to_string()],
            vec![
                "python3".to_string(),
                "-c".to_string(),
                "import sys, xacro; sys.argv[0] = 'xacro'; xacro.main()".to_string(),
            ],
        ],
        XacroCommand::Program(p) => vec![p.clone()],
        XacroCommand::Disabled => Vec::new(),
    }
}

fn memo() -> &'static Mutex<HashMap<u64, PathBuf>> {
    static MEMO: OnceLock<Mutex<HashMap<u64, PathBuf>>> = OnceLock::new();
    MEMO.get_or_init(|| Mutex::new(HashMap::new()))
}

/// Expands the xacro source `path` (whose text is `text`; `marker` is the first markup found,
/// for the "not installed" message) with `opts`.
pub(crate) fn expand(
    path: &Path,
    text: &str,
    opts: &XacroOptions,
    marker: (usize, &str),
) -> Result<Expanded, RobotError> {
    let origin = path.display().to_string();
    let abs = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    let arg_list: Vec<String> = opts.args.iter().map(|(k, v)| format!("{k}:={v}")).collect();
    let cmd_key = format!("{:?}", opts.command);
    let mut parts: Vec<&[u8]> = vec![
        abs.as_os_str().as_encoded_bytes(),
        text.as_bytes(),
        cmd_key.as_bytes(),
    ];
    parts.extend(arg_list.iter().map(|a| a.as_bytes()));
    let key = fnv1a(&parts);
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "robot".into());
    let dir = std::env::temp_dir().join("ftcbf-xacro");
    let out = dir.join(format!("{stem}-{key:016x}.urdf"));

    let cached = memo().lock().ok().and_then(|m| m.get(&key).cloned());
    if let Some(p) = cached {
        if let Ok(text) = std::fs::read_to_string(&p) {
            return Ok(Expanded { text, path: p });
        }
    }
    std::fs::create_dir_all(&dir).map_err(|e| RobotError::XacroFailed {
        origin: origin.clone(),
        command: "xacro".into(),
        message: format!("cannot create the cache directory {}: {e}", dir.display()),
    })?;
    static SERIAL: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let tmp = dir.join(format!(
        "{stem}-{key:016x}.{}-{}.tmp",
        std::process::id(),
        SERIAL.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
    ));
    let mut tried = Vec::new();
    for argv in candidates(&opts.command) {
        let shown = argv.join(" ");
        let Some((prog, lead)) = argv.split_first() else {
            continue;
        };
        let result = Command::new(prog)
            .args(lead)
            .arg(&abs)
            .args(&arg_list)
            .arg("-o")
            .arg(&tmp)
            .output();
        let output = match result {
            Ok(o) => o,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                tried.push(format!("`{prog}` not found"));
                continue;
            }
            Err(e) => {
                tried.push(format!("`{shown}`: {e}"));
                continue;
            }
        };
        let stderr = String::from_utf8_lossy(&output.stderr).trim().to_string();
        if !output.status.success() {
            let _ = std::fs::remove_file(&tmp);
            if stderr.contains("No module named") && stderr.contains("xacro") {
                tried.push(format!("`{shown}`: no Python module `xacro`"));
                continue;
            }
            return Err(RobotError::XacroFailed {
                origin,
                command: format!("{shown} {} {}", abs.display(), arg_list.join(" ")),
                message: if stderr.is_empty() {
                    format!("exit status {}", output.status)
                } else {
                    stderr
                },
            });
        }
        let text = std::fs::read_to_string(&tmp).map_err(|e| RobotError::XacroFailed {
            origin: origin.clone(),
            command: shown.clone(),
            message: format!("cannot read its output {}: {e}", tmp.display()),
        })?;
        std::fs::rename(&tmp, &out).map_err(|e| RobotError::XacroFailed {
            origin: origin.clone(),
            command: shown.clone(),
            message: format!("cannot write {}: {e}", out.display()),
        })?;
        if let Ok(mut m) = memo().lock() {
            m.insert(key, out.clone());
        }
        return Ok(Expanded { text, path: out });
    }
    Err(RobotError::XacroUnavailable {
        origin,
        line: marker.0,
        snippet: marker.1.to_string(),
        tried: if tried.is_empty() {
            "xacro expansion is disabled".to_string()
        } else {
            tried.join("; ")
        },
    })
}
