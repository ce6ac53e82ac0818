//! The coordinator: scene files, the coupling schedules as pure state machines, the launcher
//! and the run loop over zenoh, the stability monitor. The `cosim` binary is its CLI.
//!
//! The coordinator never links an engine: physics limits come from the nodes' `ready`
//! messages, so an external node takes part in checks like a built-in one.

pub mod checkpoint;
pub mod fit;
pub mod interrupt;
pub mod launch;
pub mod limits;
pub mod outdir;
pub mod plot;
pub mod programme;
pub mod run;
pub mod scene;
pub mod schedule;
pub mod stability;
pub mod study;
pub mod units;
