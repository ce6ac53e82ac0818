//! Typed errors at the wire boundary.

use std::time::Duration;

/// Everything that can go wrong between two nodes: decoding, validation, transport, timeouts.
#[derive(Debug, thiserror::Error)]
pub enum ProtoError {
    #[error("cannot decode {what}: {reason}")]
    Decode { what: &'static str, reason: String },
    #[error("cannot encode {what}: {reason}")]
    Encode { what: &'static str, reason: String },
    #[error(
        "protocol version mismatch in {what}: the message speaks version {got}, this node speaks version {expected}"
    )]
    Version {
        what: &'static str,
        got: u32,
        expected: u32,
    },
    #[error("{what} belongs to run `{got}`, this node is in run `{expected}`")]
    WrongRun {
        what: &'static str,
        got: String,
        expected: String,
    },
    #[error("{what} is for coupling {got}, expected {expected}")]
    WrongWindow {
        what: &'static str,
        got: crate::messages::Label,
        expected: crate::messages::Label,
    },
    #[error("{what}: field `{field}` has {got} values, expected {expected} ({detail})")]
    Size {
        what: &'static str,
        field: &'static str,
        got: usize,
        expected: usize,
        detail: String,
    },
    #[error("{what}: field `{field}` value {index} is not finite ({value})")]
    NotFinite {
        what: &'static str,
        field: &'static str,
        index: usize,
        value: f64,
    },
    #[error(
        "the solver diverged: its own {what} for interface `{interface}` at window {window} are not finite (`{field}` value {index} = {value}); not published"
    )]
    Diverged {
        what: &'static str,
        interface: String,
        window: u64,
        field: &'static str,
        index: usize,
        value: f64,
    },
    #[error("{what}: {reason}")]
    Invalid { what: &'static str, reason: String },
    #[error("invalid name `{name}` for {what}: use 1-64 characters of A-Z a-z 0-9 _ -")]
    Name { what: &'static str, name: String },
    #[error("timed out after {:.1} s waiting for {what}", waited.as_secs_f64())]
    Timeout { what: String, waited: Duration },
    #[error("node `{node}` left the run (its liveliness token disappeared) {context}")]
    PeerLost { node: String, context: String },
    #[error("zenoh: {0}")]
    Zenoh(String),
    #[error("link configuration: {0}")]
    Config(String),
    #[error(
        "run `{run}` is already under way with another `{node}` node (the first command this one received is number {seq}): refusing to join"
    )]
    LateJoin { run: String, node: String, seq: u64 },
    #[error("stopped by the coordinator: {reason}")]
    Stopped { reason: String },
    #[error("the session is closed")]
    Closed,
}

impl ProtoError {
    pub(crate) fn zenoh(e: impl std::fmt::Display) -> Self {
        ProtoError::Zenoh(e.to_string())
    }
}
