//! What can be said of a compiled world without running it, and of a run against what its world
//! file expects: `ftcbf check`'s verdicts ([`check`]: Theorem 3's hypotheses, the safe-stop
//! verdict of [`safe_stop`]), the liveness prediction ([`liveness`]) and the regression
//! expectations ([`expectations`]). The analyses read the world and its model
//! ([`crate::model`]); they never import the runner, and the runner never imports them.

pub mod check;
pub mod expectations;
pub mod liveness;
pub mod moving_check;
pub mod safe_stop;
pub mod tracked_check;
