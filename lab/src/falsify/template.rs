//! The world file as a template: the same file with its `[[attacks]]` replaced, for every
//! evaluation (so an evaluation is exactly the run `ftcbf run` makes of the written file) and for
//! the worst attack's world file.

use std::path::{Component, Path, PathBuf};

use anyhow::{anyhow, Context};
use ftcbf_sim::attacks::AttackSpec;
use ftcbf_sim::runner::CompiledWorld;
use ftcbf_sim::world::World;
use toml_edit::{ArrayOfTables, DocumentMut, Item, Table};

/// A loaded world and its text.
pub struct WorldTemplate {
    /// Where the world file is (relative paths in it are resolved against its directory).
    pub path: PathBuf,
    /// The file as written (comments and order kept).
    doc: DocumentMut,
    /// The world as loaded, with its own attacks.
    pub world: World,
    /// The same world compiled once: every candidate attack shares its controller setup.
    compiled: CompiledWorld,
}

/// What the written replay world says about itself.
pub struct ReplayInfo<'a> {
    /// The world's new `name`.
    pub name: &'a str,
    /// The world's new `description`.
    pub description: &'a str,
    /// The seed of the worst run.
    pub seed: u64,
    /// The controller of the worst run (`ft-cbf-clf`, `baseline`, `nominal`).
    pub controller: &'a str,
    /// Comment lines put at the top of the file (without `#`).
    pub header: &'a [String],
}

impl WorldTemplate {
    /// Reads and validates the world file.
    pub fn load(path: &Path) -> anyhow::Result<Self> {
        let world = World::load(path, &[])?;
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("{}: cannot read the world file", path.display()))?;
        let doc: DocumentMut = text
            .parse()
            .with_context(|| format!("{}: not a TOML document", path.display()))?;
        let compiled = CompiledWorld::new(world.with_file(world.file.clone())?)
            .with_context(|| format!("{}: the controller setup", path.display()))?;
        Ok(Self {
            path: path.to_path_buf(),
            doc,
            world,
            compiled,
        })
    }

    /// The document with `attacks` in place of the file's own `[[attacks]]`.
    pub(super) fn with_attacks(&self, attacks: &[AttackSpec]) -> anyhow::Result<DocumentMut> {
        let mut doc = self.doc.clone();
        doc.remove("attacks");
        let mut aot = ArrayOfTables::new();
        for a in attacks {
            let text = toml::to_string(a).context("writing an attack as TOML")?;
            let t: DocumentMut = text.parse().context("reading back an attack's TOML")?;
            let table: Table = t.as_table().clone();
            aot.push(table);
        }
        if !aot.is_empty() {
            doc.insert("attacks", Item::ArrayOfTables(aot));
        }
        Ok(doc)
    }

    /// The world with `attacks` in place of its own, validated exactly as `ftcbf run` validates
    /// a file with those attacks next to the original, but edited in memory (no TOML or URDF is
    /// read again; the written world's replay check confirms it is the same world).
    pub fn world_with(&self, attacks: &[AttackSpec]) -> anyhow::Result<World> {
        self.variant_with(&self.world, attacks)
    }

    /// [`WorldTemplate::world_with`], compiled: the world's controller setup (γ, θ, η,
    /// barriers, CLF, planned path) is shared, not computed again for the candidate.
    pub fn compiled_with(&self, attacks: &[AttackSpec]) -> anyhow::Result<CompiledWorld> {
        self.compiled
            .with_attacks(attacks)
            .with_context(|| format!("{}: the world with a candidate attack", self.path.display()))
    }

    /// `base` (this world or a variant of it, see [`World::with_file`]) with `attacks` in place
    /// of its own.
    pub fn variant_with(&self, base: &World, attacks: &[AttackSpec]) -> anyhow::Result<World> {
        let mut file = base.file.clone();
        file.attacks = attacks.to_vec();
        base.with_file(file)
            .with_context(|| format!("{}: the world with a candidate attack", self.path.display()))
    }

    /// The text of a world file to be written at `out`: the original with `attacks`, the given
    /// `name`, `description`, `seed` and `control.controller`, no `[expect]` (the original's
    /// expectations were about its own attacks), and relative file paths rewritten so they
    /// still point at the same files from `out`'s directory.
    pub fn replay_text(
        &self,
        attacks: &[AttackSpec],
        info: &ReplayInfo<'_>,
        out: &Path,
    ) -> anyhow::Result<String> {
        self.finish_replay(self.with_attacks(attacks)?, info, out)
    }

    /// [`WorldTemplate::replay_text`] of an already edited document `doc`.
    pub(super) fn finish_replay(
        &self,
        mut doc: DocumentMut,
        info: &ReplayInfo<'_>,
        out: &Path,
    ) -> anyhow::Result<String> {
        // The original's leading comment describes its own attack: drop it.
        if let Some((mut key, _)) = doc.as_table_mut().iter_mut().next() {
            key.leaf_decor_mut().set_prefix("");
        }
        doc.remove("expect");
        doc["name"] = toml_edit::value(info.name);
        doc["description"] = toml_edit::value(info.description);
        let seed = i64::try_from(info.seed)
            .map_err(|_| anyhow!("seed {} does not fit a TOML integer", info.seed))?;
        doc["seed"] = toml_edit::value(seed);
        if doc.get("control").is_none() {
            doc["control"] = toml_edit::table();
        }
        doc["control"]["controller"] = toml_edit::value(info.controller);
        self.rebase_paths(&mut doc, out)?;
        let mut text = String::new();
        for line in info.header {
            text.push_str("# ");
            text.push_str(line);
            text.push('\n');
        }
        text.push_str(doc.to_string().trim_start_matches('\n'));
        Ok(text)
    }

    /// Rewrites `robot.urdf`, `robot.package_paths`, `robot.packages` and `obstacles[*].shape.file` for a file
    /// written at `out` (unchanged when `out` is in the original's directory).
    fn rebase_paths(&self, doc: &mut DocumentMut, out: &Path) -> anyhow::Result<()> {
        let from = canonical_dir(&self.path)?;
        let to = canonical_dir(out)?;
        if from == to {
            return Ok(());
        }
        let fix = |s: &str| -> String {
            let p = Path::new(s);
            if p.is_absolute() {
                return s.to_string();
            }
            let target = from.join(p);
            let target = target.canonicalize().unwrap_or(target);
            relative(&target, &to).display().to_string()
        };
        if let Some(robot) = doc.get_mut("robot").and_then(Item::as_table_like_mut) {
            if let Some(u) = robot.get_mut("urdf") {
                if let Some(s) = u.as_str().map(&fix) {
                    *u = toml_edit::value(s);
                }
            }
            if let Some(arr) = robot.get_mut("package_paths").and_then(Item::as_array_mut) {
                for v in arr.iter_mut() {
                    if let Some(s) = v.as_str().map(&fix) {
                        *v = s.into();
                    }
                }
            }
            if let Some(map) = robot.get_mut("packages").and_then(Item::as_table_like_mut) {
                for (_, v) in map.iter_mut() {
                    if let Some(s) = v.as_str().map(&fix) {
                        *v = toml_edit::value(s);
                    }
                }
            }
        }
        if let Some(obs) = doc
            .get_mut("obstacles")
            .and_then(Item::as_array_of_tables_mut)
        {
            for t in obs.iter_mut() {
                let Some(shape) = t.get_mut("shape").and_then(Item::as_table_like_mut) else {
                    continue;
                };
                if let Some(f) = shape.get_mut("file") {
                    if let Some(s) = f.as_str().map(&fix) {
                        *f = toml_edit::value(s);
                    }
                }
            }
        }
        Ok(())
    }
}

/// The absolute directory a file is (or will be) in.
fn canonical_dir(file: &Path) -> anyhow::Result<PathBuf> {
    let dir = match file.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    dir.canonicalize()
        .with_context(|| format!("directory {} does not exist", dir.display()))
}

/// `target` relative to the directory `base` (both absolute).
fn relative(target: &Path, base: &Path) -> PathBuf {
    let t: Vec<Component<'_>> = target.components().collect();
    let b: Vec<Component<'_>> = base.components().collect();
    let common = t.iter().zip(&b).take_while(|(x, y)| x == y).count();
    let mut out = PathBuf::new();
    for _ in common..b.len() {
        out.push("..");
    }
    for c in &t[common..] {
        out.push(c.as_os_str());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relative_paths() {
        assert_eq!(
            relative(Path::new("/a/b/robots/x.urdf"), Path::new("/a/b/worlds")),
            PathBuf::from("../robots/x.urdf")
        );
        assert_eq!(
            relative(Path::new("/a/b/x.urdf"), Path::new("/a/b")),
            PathBuf::from("x.urdf")
        );
        assert_eq!(
            relative(Path::new("/r/x.urdf"), Path::new("/tmp/q")),
            PathBuf::from("../../r/x.urdf")
        );
    }
}
