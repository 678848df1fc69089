//! Why a robot description could not be loaded: every message names the file (when there is
//! one), the element and line, and what to fix.

use super::*;

/// Errors of URDF loading. Every message names the file (when there is one) and what to fix.
#[derive(Debug, thiserror::Error)]
pub enum RobotError {
    /// The URDF file could not be read.
    #[error("cannot read URDF file {path}: {source}")]
    Io {
        /// File path.
        path: PathBuf,
        /// Underlying error.
        source: std::io::Error,
    },
    /// The XML is malformed or does not follow the URDF schema (what ROS's parser would refuse
    /// too): the message names the element and its `name`.
    #[error("{origin}: {}malformed URDF: {message}", line_prefix(*.line))]
    Parse {
        /// File path or `"<string>"`.
        origin: String,
        /// 1-based line of the offending element, when known.
        line: Option<usize>,
        /// What is wrong, naming the element.
        message: String,
    },
    /// Xacro macros or substitutions are still in the file.
    #[error(
        "{origin}: line {line}: xacro leftover `{snippet}` in {context}; \
         this is a xacro source, run `xacro file.urdf.xacro > file.urdf` first"
    )]
    Xacro {
        /// File path or `"<string>"`.
        origin: String,
        /// 1-based line number.
        line: usize,
        /// The offending text.
        snippet: String,
        /// Where it sits (link/joint name and attribute, when found).
        context: String,
    },
    /// The file is a xacro source and no xacro could be run.
    #[error(
        "{origin}: line {line}: `{snippet}` is xacro markup, so this file must be expanded by \
         xacro first, and xacro is not available ({tried}); {}",
        xacro::INSTALL_HINT
    )]
    XacroUnavailable {
        /// File path.
        origin: String,
        /// 1-based line of the first markup.
        line: usize,
        /// The markup.
        snippet: String,
        /// What was tried.
        tried: String,
    },
    /// xacro ran and failed.
    #[error("{origin}: xacro failed (`{command}`): {message}")]
    XacroFailed {
        /// File path.
        origin: String,
        /// The command line.
        command: String,
        /// xacro's message.
        message: String,
    },
    /// The URDF's structure is not a tree the loader can use.
    #[error("{origin}: {message}")]
    Structure {
        /// File path or `"<string>"`.
        origin: String,
        /// What is wrong.
        message: String,
    },
    /// A movable body has no positive mass.
    #[error(
        "{origin}: link `{link}` moves (joint `{joint}`) but its mass is {mass} kg; \
         give it an <inertial> with a positive <mass value>"
    )]
    NonPositiveMass {
        /// File path or `"<string>"`.
        origin: String,
        /// Link name.
        link: String,
        /// Joint that makes it movable ("root" for the root body).
        joint: String,
        /// The (merged) mass.
        mass: f64,
    },
    /// A number in the URDF is invalid (negative size, non-finite value, …).
    #[error("{origin}: {what}")]
    InvalidValue {
        /// File path or `"<string>"`.
        origin: String,
        /// What is wrong, naming the link/joint and attribute.
        what: String,
    },
    /// The drive wheels could not be identified.
    #[error("{origin}: cannot find the drive wheels: {message}")]
    Wheels {
        /// File path or `"<string>"`.
        origin: String,
        /// What is wrong.
        message: String,
    },
    /// A collision mesh could not be resolved or read.
    #[error("{origin}: collision mesh `{filename}` of link `{link}`: {message}")]
    CollisionMesh {
        /// File path or `"<string>"`.
        origin: String,
        /// Link name.
        link: String,
        /// The filename as written in the URDF.
        filename: String,
        /// What went wrong.
        message: String,
    },
}

fn line_prefix(line: Option<usize>) -> String {
    line.map(|l| format!("line {l}: ")).unwrap_or_default()
}
