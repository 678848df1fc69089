//! A world compiled once for its runs (the model/data split): everything a run derives from the
//! world alone — the channels the linear model observes, the model, the barriers, γ, θ and η
//! (Riccati), κ, the CLF and the planned path ([`ControlSetup`]) — computed by
//! [`CompiledWorld::new`] and shared, read-only, by every [`Simulation`](crate::runner::Simulation)
//! built from it, on any thread. A run ([`Simulation::new`](super::Simulation::new) with a
//! `&CompiledWorld`) then builds only its own state: sensors, attacks, the control law, the
//! plant.
//!
//! Nothing in the compiled model depends on the seed, the controller kind or the duration:
//! the controller kind is only the `kind` of the configuration handed to the law, so a run with
//! another controller than the world's borrows everything else.

use std::borrow::Cow;

use crate::attacks::AttackSpec;
use crate::world::{ControllerKindSpec, World, WorldError};

use super::setup::ControlSetup;
use super::RunError;

/// A validated [`World`] and its [`ControlSetup`], computed once. Immutable, `Send + Sync`:
/// share it between trials and threads by reference (or in an `Arc`).
pub struct CompiledWorld {
    world: World,
    setup: ControlSetup,
}

impl CompiledWorld {
    /// Compiles `world` (its own controller kind sets the stored configuration's `kind`); fails
    /// exactly where a run of it would fail to set up.
    pub fn new(world: World) -> Result<Self, RunError> {
        let setup = ControlSetup::new(&world, world.file.control.controller)?;
        Ok(Self { world, setup })
    }

    /// The world it was compiled from.
    pub fn world(&self) -> &World {
        &self.world
    }

    /// The controller setup of the world's own controller kind.
    pub fn setup(&self) -> &ControlSetup {
        &self.setup
    }

    /// The controller setup of a run with `kind`: the stored one, or — for another controller
    /// than the world's — a copy whose configuration names `kind` (nothing else depends on it).
    pub fn setup_for(&self, kind: ControllerKindSpec) -> Cow<'_, ControlSetup> {
        if kind == self.world.file.control.controller {
            Cow::Borrowed(&self.setup)
        } else {
            let mut s = self.setup.clone();
            s.config.kind = kind.into();
            Cow::Owned(s)
        }
    }

    /// This world with `attacks` in place of its own, validated as a file with them would be
    /// (the robot description is reused, no file is read), sharing this world's controller
    /// setup: nothing in the setup depends on the attacks, so nothing is computed again
    /// (`ftcbf falsify` runs its candidate attacks so).
    pub fn with_attacks(&self, attacks: &[AttackSpec]) -> Result<CompiledWorld, WorldError> {
        let mut file = self.world.file.clone();
        file.attacks = attacks.to_vec();
        Ok(Self {
            world: self.world.with_file(file)?,
            setup: self.setup.clone(),
        })
    }

    /// The world back, dropping the compiled setup.
    pub fn into_world(self) -> World {
        self.world
    }
}

impl std::fmt::Debug for CompiledWorld {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CompiledWorld")
            .field("world", &self.world.name)
            .field("path", &self.world.path)
            .field("barriers", &self.setup.barrier_names)
            .finish_non_exhaustive()
    }
}

/// What a [`Simulation`](crate::runner::Simulation) is built from: a world (compiled for that run
/// alone) or a [`CompiledWorld`] (shared).
#[derive(Clone, Copy)]
pub enum Source<'w> {
    /// A world: the run computes its controller setup itself.
    World(&'w World),
    /// A compiled world: the run borrows its controller setup.
    Compiled(&'w CompiledWorld),
}

impl<'w> Source<'w> {
    /// The world.
    pub fn world(self) -> &'w World {
        match self {
            Source::World(w) => w,
            Source::Compiled(c) => c.world(),
        }
    }

    /// The controller setup of a run with `kind` (computed now for a world, borrowed from a
    /// compiled world).
    pub fn setup(self, kind: ControllerKindSpec) -> Result<Cow<'w, ControlSetup>, RunError> {
        match self {
            Source::World(w) => ControlSetup::new(w, kind).map(Cow::Owned),
            Source::Compiled(c) => Ok(c.setup_for(kind)),
        }
    }
}

impl<'w> From<&'w World> for Source<'w> {
    fn from(w: &'w World) -> Self {
        Source::World(w)
    }
}

impl<'w> From<&'w CompiledWorld> for Source<'w> {
    fn from(c: &'w CompiledWorld) -> Self {
        Source::Compiled(c)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_compiled_world_is_shareable_between_threads() {
        fn send_sync<T: Send + Sync>() {}
        send_sync::<CompiledWorld>();
    }

    /// What `with_attacks` shares is what the world with those attacks would compute itself.
    #[test]
    fn the_setup_shared_across_attacks_is_the_one_computed_afresh() {
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../worlds/stealthy_gnss.toml");
        let world = World::load(&path, &[]).expect("world loads");
        assert!(!world.file.attacks.is_empty());
        let compiled = CompiledWorld::new(world).expect("compiles");
        let variant = compiled.with_attacks(&[]).expect("valid without attacks");
        assert!(variant.world().file.attacks.is_empty());
        let kind = variant.world().file.control.controller;
        let fresh = ControlSetup::new(variant.world(), kind).expect("sets up");
        let shared = variant.setup();
        assert_eq!(
            format!("{:?}", shared.config),
            format!("{:?}", fresh.config)
        );
        assert_eq!(
            format!("{:?}", shared.params),
            format!("{:?}", fresh.params)
        );
        assert_eq!(shared.gain, fresh.gain);
        assert_eq!(shared.barrier_names, fresh.barrier_names);
        assert_eq!(shared.sensor_of_channel, fresh.sensor_of_channel);
        assert_eq!(shared.channel_of_sensor, fresh.channel_of_sensor);
        assert_eq!(shared.conversion, fresh.conversion);
        assert_eq!(shared.safe_sets, fresh.safe_sets);
    }

    /// A run with another controller than the world's differs in the configuration's kind only.
    #[test]
    fn another_controller_changes_only_the_kind() {
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../worlds/paper_linear.toml");
        let world = World::load(&path, &[]).expect("world loads");
        let compiled = CompiledWorld::new(world).expect("compiles");
        let own = compiled.world().file.control.controller;
        let other = if own == ControllerKindSpec::Baseline {
            ControllerKindSpec::FtCbfClf
        } else {
            ControllerKindSpec::Baseline
        };
        assert!(matches!(compiled.setup_for(own), Cow::Borrowed(_)));
        let shared = compiled.setup_for(other);
        let fresh = ControlSetup::new(compiled.world(), other).expect("sets up");
        assert_eq!(shared.config.kind, other.into());
        assert_eq!(
            format!("{:?}", shared.config),
            format!("{:?}", fresh.config)
        );
    }
}
