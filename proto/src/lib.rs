//! The wire contract of the DEM–FEM co-simulation.
//!
//! `proto` owns every byte on the wire: the message types ([`messages`]), how they are encoded
//! and validated ([`codec`]), the key expressions they travel on ([`keys`]) and the zenoh
//! session that carries them ([`link`], [`participant`]). No other crate builds a key expression
//! or encodes a message. The contract for implementers in other languages is `PROTOCOL.md`.

pub mod alloc;
pub mod cli;
pub mod codec;
pub mod error;
pub mod keys;
pub mod link;
pub mod messages;
pub mod motion;
pub mod node;
pub mod participant;
pub mod resources;

pub use codec::{decode, encode};
pub use error::ProtoError;
pub use keys::Keys;
pub use link::{LinkConfig, LinkMode};
pub use messages::*;
pub use participant::Participant;

/// Version of the wire protocol. Every message carries it; a peer speaking another version is
/// refused with an error naming both (PROTOCOL.md, "Versioning").
pub const PROTOCOL_VERSION: u32 = 2;

/// A `hello` capability: the node accepts `advance_window` commands that arrive while it is
/// still busy with an earlier window (or waiting for its data) and serves them in order, so
/// the coordinator may announce windows ahead (PROTOCOL.md §6, `coupling.lookahead`).
pub const CAPABILITY_QUEUED_COMMANDS: &str = "queued_commands";
