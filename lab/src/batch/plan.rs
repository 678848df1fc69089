//! What a batch runs: the plan (the experiment's identity), shards, sweeps and overrides.

use std::fmt;
use std::str::FromStr;

use anyhow::anyhow;
use ftcbf_sim::world::Override;
use serde::{Deserialize, Serialize};

/// One slice of a batch: trial indices k (0-based) with `k % count == index − 1`
/// (round robin, so every shard gets early and late trials alike). Written `K/N` on the CLI.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    /// K, 1-based.
    pub index: u64,
    /// N ≥ 1.
    pub count: u64,
}

impl Shard {
    /// Does trial `k` belong to this shard?
    pub fn contains(&self, k: u64) -> bool {
        k % self.count == self.index - 1
    }

    /// The trial indices of this shard in a batch of `trials`, ascending.
    pub fn trials(&self, trials: u64) -> impl Iterator<Item = u64> {
        (self.index - 1..trials).step_by(usize::try_from(self.count).unwrap_or(usize::MAX))
    }
}

impl fmt::Display for Shard {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// A `--shard K/N` or `--sweep KEY=V,...` argument that could not be read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ArgError(pub String);

impl fmt::Display for ArgError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for ArgError {}

impl FromStr for Shard {
    type Err = ArgError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let err = |why: &str| {
            ArgError(format!(
                "invalid shard `{s}`: {why} (expected K/N with 1 ≤ K ≤ N, e.g. 2/4)"
            ))
        };
        let (k, n) = s.split_once('/').ok_or_else(|| err("no `/`"))?;
        let index: u64 = k
            .trim()
            .parse()
            .map_err(|_| err("K is not a whole number"))?;
        let count: u64 = n
            .trim()
            .parse()
            .map_err(|_| err("N is not a whole number"))?;
        if count == 0 {
            return Err(err("N must be at least 1"));
        }
        if index == 0 || index > count {
            return Err(err("K out of range"));
        }
        Ok(Shard { index, count })
    }
}

/// A parameter sweep: run the batch once per value of `key`.
#[derive(Debug, Clone, PartialEq)]
pub struct Sweep {
    /// Key path into the world file.
    pub key: String,
    /// The values, in the order given; finite and distinct.
    pub values: Vec<f64>,
}

impl FromStr for Sweep {
    type Err = ArgError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let err = |why: String| {
            ArgError(format!("invalid sweep `{s}`: {why} (expected KEY=V1,V2,..., e.g. attacks[0].value=0,0.5,1)"))
        };
        let (key, values) = s.split_once('=').ok_or_else(|| err("no `=`".into()))?;
        let key = key.trim();
        if key.is_empty() {
            return Err(err("empty key".into()));
        }
        if let Some(c) = key
            .chars()
            .find(|c| !(c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.' | '[' | ']')))
        {
            return Err(err(format!("character `{c}` is not allowed in a key path")));
        }
        let mut parsed = Vec::new();
        for (i, v) in values.split(',').enumerate() {
            let v = v.trim();
            if v.is_empty() {
                return Err(err(format!("value {} is empty", i + 1)));
            }
            let x: f64 = v
                .parse()
                .map_err(|_| err(format!("value `{v}` is not a number")))?;
            if !x.is_finite() {
                return Err(err(format!("value `{v}` is not finite")));
            }
            if parsed.contains(&x) {
                return Err(err(format!("value `{v}` is listed twice")));
            }
            parsed.push(x);
        }
        Ok(Sweep {
            key: key.to_string(),
            values: parsed,
        })
    }
}

/// What a batch runs: the experiment's identity. Two shards can be merged only when their plans
/// agree on everything but `shard` (and `world_file`, which may differ between machines).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BatchPlan {
    /// World name.
    pub world: String,
    /// World file path as given on the command line (informational).
    pub world_file: String,
    /// `fnv1a64:<hex>` of the world file's bytes: "same world" for merging.
    pub world_digest: String,
    /// Overrides applied to the world (the sweep point), empty without a sweep.
    pub overrides: Vec<Override>,
    /// Total number of trials N of the whole batch (all shards).
    pub trials: u64,
    /// Base seed S; trial k uses [`super::trial_seed`]`(S, k)`.
    pub base_seed: u64,
    /// Controllers, run side by side on the same seeds. Distinct, non-empty.
    pub controllers: Vec<String>,
    /// The slice this run covers; `None` = all trials.
    pub shard: Option<Shard>,
    /// ε of the world's claim Pr(safe) ≥ 1 − ε, if any.
    pub epsilon: Option<f64>,
    /// Confidence level of the intervals ([`crate::batch::CONFIDENCE`]).
    pub confidence: f64,
    /// `ftcbf check`'s verdict line on Theorem 3 for the world (absent in older files).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub theorem3: Option<String>,
    /// `ftcbf check`'s liveness verdict for the world (absent in older files).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub liveness: Option<String>,
}

impl BatchPlan {
    /// The claimed safety probability 1 − ε.
    pub fn claimed_safety(&self) -> Option<f64> {
        self.epsilon.map(|e| 1.0 - e)
    }

    /// Check the plan's own consistency (before running or after reading a file).
    pub fn validate(&self) -> anyhow::Result<()> {
        if self.trials == 0 {
            return Err(anyhow!("the number of trials must be at least 1"));
        }
        if self.controllers.is_empty() {
            return Err(anyhow!("at least one controller is needed"));
        }
        for (i, c) in self.controllers.iter().enumerate() {
            if self.controllers[..i].contains(c) {
                return Err(anyhow!("controller `{c}` is listed twice"));
            }
        }
        if let Some(e) = self.epsilon {
            if !(e > 0.0 && e < 1.0) {
                return Err(anyhow!("the world's epsilon must lie in (0, 1), got {e}"));
            }
        }
        if let Some(s) = self.shard {
            if s.count == 0 || s.index == 0 || s.index > s.count {
                return Err(anyhow!(
                    "shard {s} is invalid (expected K/N with 1 ≤ K ≤ N)"
                ));
            }
            if s.index > self.trials {
                return Err(anyhow!(
                    "shard {s} of {} trials holds no trial (use at most as many shards as trials)",
                    self.trials
                ));
            }
        }
        if !(self.confidence > 0.0 && self.confidence < 1.0) {
            return Err(anyhow!(
                "confidence must lie in (0, 1), got {}",
                self.confidence
            ));
        }
        Ok(())
    }

    /// Trial indices this plan runs, ascending.
    pub fn trial_indices(&self) -> Vec<u64> {
        match self.shard {
            Some(s) => s.trials(self.trials).collect(),
            None => (0..self.trials).collect(),
        }
    }
}

/// How a batch executes (does not change its results).
#[derive(Clone, Copy)]
pub struct Execution<'a> {
    /// Worker threads; `None` = all cores.
    pub jobs: Option<usize>,
    /// Told how many trials run and each one that finishes ([`crate::progress::Silent`]: nothing shown).
    pub progress: &'a dyn crate::progress::Progress,
}

impl std::fmt::Debug for Execution<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Execution")
            .field("jobs", &self.jobs)
            .finish_non_exhaustive()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shard_parsing_and_membership() {
        let s: Shard = "2/3".parse().expect("valid shard");
        assert_eq!(s, Shard { index: 2, count: 3 });
        assert_eq!(s.trials(10).collect::<Vec<_>>(), vec![1, 4, 7]);
        assert!(s.contains(4) && !s.contains(5));
        assert_eq!(Shard { index: 3, count: 3 }.trials(2).count(), 0);
        for (bad, why) in [
            ("3", "no `/`"),
            ("0/2", "K out of range"),
            ("3/2", "K out of range"),
            ("1/0", "N must be at least 1"),
            ("a/2", "K is not a whole number"),
            ("1/-2", "N is not a whole number"),
        ] {
            let e = bad.parse::<Shard>().expect_err(bad).to_string();
            assert!(e.contains(why) && e.contains(bad), "{bad}: {e}");
        }
    }

    #[test]
    fn sweep_parsing() {
        let s: Sweep = "attacks[0].value=0, 0.5,1e-1".parse().expect("valid sweep");
        assert_eq!(s.key, "attacks[0].value");
        assert_eq!(s.values, vec![0.0, 0.5, 0.1]);
        for (bad, why) in [
            ("attacks[0].value", "no `=`"),
            ("=1,2", "empty key"),
            ("a b=1", "character ` ` is not allowed"),
            ("k=1,,2", "value 2 is empty"),
            ("k=1,x", "value `x` is not a number"),
            ("k=1,inf", "value `inf` is not finite"),
            ("k=1,2,1.0", "value `1.0` is listed twice"),
            ("k=", "value 1 is empty"),
        ] {
            let e = bad.parse::<Sweep>().expect_err(bad).to_string();
            assert!(e.contains(why), "{bad}: {e}");
        }
    }
}
