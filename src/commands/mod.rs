//! One module per command: its clap arguments and what it does. A command imports the leaves
//! (`exit`, `parsers`, `bars`) and the libraries, never another command or the top-level
//! parser, so the arrows point one way: `main` → `args` → `commands` → leaves.

pub mod batch;
pub mod check;
pub mod falsify;
pub mod gen;
pub mod regress;
pub mod report;
pub mod run;
