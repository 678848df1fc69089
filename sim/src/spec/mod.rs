//! The world file as written: the serde schema of every table and key ([`schema`]), the
//! `kind`-tagged tables that name the key inside them in an error (`spec::tagged`), and the
//! `[expect]` table ([`expect`]). Nothing here reads a file or checks one value against
//! another: [`crate::world`] loads and validates a file into a [`World`](crate::world::World).

pub mod expect;
pub mod schema;
pub(crate) mod tagged;
