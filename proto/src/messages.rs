//! Every message on the wire (PROTOCOL.md, "Messages").
//!
//! Messages are MessagePack maps with named fields. Each carries `version` and `run_id`.
//! Large numeric arrays are [`F64Array`]s: flat, node-major `x y z` sequences stored as one
//! MessagePack `bin` of little-endian IEEE-754 doubles (8 bytes per value).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::{ProtoError, PROTOCOL_VERSION};

/// A flat array of `f64` carried as a MessagePack `bin` of little-endian doubles.
/// Decoding also accepts a MessagePack array of floats, which is easier to write by hand.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct F64Array(pub Vec<f64>);

impl F64Array {
    pub fn len(&self) -> usize {
        self.0.len()
    }
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
    pub fn as_slice(&self) -> &[f64] {
        &self.0
    }
    /// Index and value of the first NaN or infinity, if any.
    pub fn first_non_finite(&self) -> Option<(usize, f64)> {
        self.0
            .iter()
            .enumerate()
            .find(|(_, v)| !v.is_finite())
            .map(|(i, v)| (i, *v))
    }
}

impl From<Vec<f64>> for F64Array {
    fn from(v: Vec<f64>) -> Self {
        F64Array(v)
    }
}

impl Serialize for F64Array {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        // on little-endian machines the doubles' memory is already the wire format: one copy
        if cfg!(target_endian = "little") {
            return s.serialize_bytes(bytemuck::cast_slice::<f64, u8>(&self.0));
        }
        let mut bytes = Vec::with_capacity(self.0.len() * 8);
        for v in &self.0 {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        s.serialize_bytes(&bytes)
    }
}

impl<'de> Deserialize<'de> for F64Array {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> serde::de::Visitor<'de> for V {
            type Value = F64Array;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str(
                    "a bin of little-endian f64 (length a multiple of 8) or an array of floats",
                )
            }
            fn visit_bytes<E: serde::de::Error>(self, b: &[u8]) -> Result<F64Array, E> {
                if b.len() % 8 != 0 {
                    return Err(E::custom(format!(
                        "f64 bin of {} bytes is not a multiple of 8",
                        b.len()
                    )));
                }
                if cfg!(target_endian = "little") {
                    // one copy into aligned doubles (the bin itself need not be aligned)
                    let mut v = vec![0.0f64; b.len() / 8];
                    bytemuck::cast_slice_mut::<f64, u8>(&mut v).copy_from_slice(b);
                    return Ok(F64Array(v));
                }
                Ok(F64Array(
                    b.chunks_exact(8)
                        .map(|c| f64::from_le_bytes(c.try_into().expect("chunk of 8")))
                        .collect(),
                ))
            }
            fn visit_byte_buf<E: serde::de::Error>(self, b: Vec<u8>) -> Result<F64Array, E> {
                self.visit_bytes(&b)
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(
                self,
                mut seq: A,
            ) -> Result<F64Array, A::Error> {
                let mut v = Vec::with_capacity(seq.size_hint().unwrap_or(0).min(1 << 20));
                while let Some(x) = seq.next_element::<f64>()? {
                    v.push(x);
                }
                Ok(F64Array(v))
            }
        }
        d.deserialize_any(V)
    }
}

/// What a node is in the coupling.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Role {
    Dem,
    Fem,
}

impl std::fmt::Display for Role {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Role::Dem => "dem",
            Role::Fem => "fem",
        })
    }
}

/// How the DEM side moves the coupled mesh during a window (Ullrich ch. 3.3, τ from the window
/// start): `quadratic` x = P + Vτ + ½Aτ² (just-in-time), `linear` x = P + Vτ (predictive,
/// V the predictive velocity (3.4)), `fixed` x = P.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MotionRule {
    Quadratic,
    Linear,
    Fixed,
}

/// First message of a node, on its status key, once it listens for commands.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Hello {
    pub software: String,
    pub role: Role,
    /// Optional features: `snapshot`, `force_averaging`, `static`, `dynamic`, ...
    pub capabilities: Vec<String>,
    pub pid: u32,
}

/// Set-up of a node: the scene it is part of.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Init {
    /// Path of the scene file as the coordinator knows it (names it in errors, resolves
    /// relative file paths when the file system is shared).
    pub scene_path: String,
    /// The whole scene file (TOML). A node reads its own table (`[dem]` or `[fem]`).
    pub scene_toml: String,
    /// Folder where the node writes its outputs.
    pub out_dir: String,
    /// Interfaces of the coupling (empty for a single-solver run).
    pub interfaces: Vec<String>,
    /// Validate and report limits, then wait for `stop`: no stepping (`cosim check`).
    pub check_only: bool,
    /// Write per-window interface traces (CSV) for verification: the DEM its per-substep
    /// force totals and its mesh at window ends, the FEM the force totals it received and
    /// its interface positions at window ends.
    pub trace: bool,
}

/// Advance one coupling window.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AdvanceWindow {
    /// Window index k, starting at 0, consecutive.
    pub window: u64,
    /// Simulation time at the start of the window (s).
    pub t_start: f64,
    /// Length of the window Δt^C (s).
    pub dt: f64,
    /// DEM substeps n^D in the window (Δt^C = n^D Δt^D); FEM ignores it.
    pub substeps: u32,
    /// How the DEM moves the coupled mesh during the window.
    pub motion: MotionRule,
    /// DEM: send the mean of the substep forces instead of the last (Ullrich (3.8)).
    pub force_averaging: bool,
    /// Interface data to wait for before computing (DEM: kinematics, FEM: forces), by the
    /// window index that data carries; `None`: compute with what the node has.
    pub input_window: Option<u64>,
    /// Window index of the interface data to publish at the end of the window (DEM: forces,
    /// FEM: kinematics); `None`: publish nothing.
    pub output_window: Option<u64>,
    /// FEM only: solve statically instead of a dynamic step (one-way coupling).
    pub static_solve: bool,
}

/// Commands from the coordinator, on `cosim/<run>/cmd/<node>`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum CommandBody {
    Init(Init),
    /// Publish the node's current interface output without stepping, labelled `window`
    /// (FEM: kinematics, e.g. the initial state before window 0 of just-in-time; DEM: forces,
    /// e.g. the settled forces of one-way coupling).
    Publish {
        window: u64,
        /// DEM: publish the mean of the last window's substep forces (Ullrich (3.8)).
        force_averaging: bool,
    },
    AdvanceWindow(AdvanceWindow),
    /// Write the full state to `path` (atomically), reply `snapshot_done`.
    Snapshot {
        window: u64,
        path: String,
    },
    /// Replace the state by the one at `path`, reply `restored`.
    Restore {
        window: u64,
        path: String,
    },
    /// Write final outputs, reply `stopped`, leave.
    Stop {
        reason: String,
    },
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Command {
    pub version: u32,
    pub run_id: String,
    /// Sequence number of the command, from 0, consecutive per node.
    pub seq: u64,
    pub body: CommandBody,
}

/// Error codes of `StatusBody::Error` (PROTOCOL.md, "Errors").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ErrorCode {
    /// The scene's table for this node is invalid.
    Scene,
    /// A message could not be decoded or failed validation.
    Protocol,
    /// Waited too long for interface data.
    Timeout,
    /// The physics diverged (NaN, unstable).
    Unstable,
    /// Writing or reading a file failed.
    Io,
    /// Anything else.
    Internal,
}

/// Status of a node, on `cosim/<run>/status/<node>`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum StatusBody {
    Hello(Hello),
    /// The node has read its scene table and is ready for windows. `limits` are the physics
    /// limits of its part of the scene (e.g. `time_step`, `rayleigh_time_step`,
    /// `critical_time_step`, `particles`, `dofs`), in SI units.
    Ready {
        limits: BTreeMap<String, f64>,
        warnings: Vec<String>,
    },
    /// The window is done. `compute_s` is the wall time spent computing (not waiting).
    WindowDone {
        window: u64,
        t_end: f64,
        compute_s: f64,
        wait_s: f64,
        monitor: BTreeMap<String, f64>,
    },
    SnapshotDone {
        window: u64,
        path: String,
    },
    Restored {
        window: u64,
    },
    Stopped {
        results: BTreeMap<String, f64>,
        compute_s: f64,
        wait_s: f64,
    },
    Error {
        code: ErrorCode,
        message: String,
        window: Option<u64>,
    },
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Status {
    pub version: u32,
    pub run_id: String,
    pub node: String,
    pub body: StatusBody,
}

/// Interface mesh, FEM → DEM at start-up (reply of the `…/iface/<name>/mesh` queryable).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InterfaceMesh {
    pub version: u32,
    pub run_id: String,
    pub interface: String,
    /// Ids of the interface nodes in the FEM mesh (informative).
    pub node_ids: Vec<u64>,
    /// Reference positions, node-major xyz (3 × nodes values).
    pub positions: F64Array,
    /// Triangles as node indices into this message's node list (3 × triangles values).
    pub triangles: Vec<u32>,
}

/// Interface kinematics for window k, FEM → DEM: positions P, velocities V, accelerations A
/// of the interface nodes at time `time` (node-major xyz).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InterfaceKinematics {
    pub version: u32,
    pub run_id: String,
    pub interface: String,
    pub window: u64,
    pub time: f64,
    pub positions: F64Array,
    pub velocities: F64Array,
    pub accelerations: F64Array,
}

/// Interface forces for window k, DEM → FEM: forces exerted by the particles on the interface
/// nodes (N, node-major xyz), the last substep's or the mean over the window's substeps.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InterfaceForces {
    pub version: u32,
    pub run_id: String,
    pub interface: String,
    pub window: u64,
    pub time: f64,
    pub forces: F64Array,
    pub averaged: bool,
    pub substeps: u32,
}

impl Command {
    pub fn new(run_id: &str, seq: u64, body: CommandBody) -> Self {
        Command {
            version: PROTOCOL_VERSION,
            run_id: run_id.to_string(),
            seq,
            body,
        }
    }
}

impl Status {
    pub fn new(run_id: &str, node: &str, body: StatusBody) -> Self {
        Status {
            version: PROTOCOL_VERSION,
            run_id: run_id.to_string(),
            node: node.to_string(),
            body,
        }
    }
}

fn check_len(
    what: &'static str,
    field: &'static str,
    got: usize,
    expected: usize,
    detail: impl FnOnce() -> String,
) -> Result<(), ProtoError> {
    if got == expected {
        Ok(())
    } else {
        Err(ProtoError::Size {
            what,
            field,
            got,
            expected,
            detail: detail(),
        })
    }
}

fn check_finite(what: &'static str, field: &'static str, a: &F64Array) -> Result<(), ProtoError> {
    match a.first_non_finite() {
        None => Ok(()),
        Some((index, value)) => Err(ProtoError::NotFinite {
            what,
            field,
            index,
            value,
        }),
    }
}

fn check_time(what: &'static str, time: f64) -> Result<(), ProtoError> {
    if time.is_finite() {
        Ok(())
    } else {
        Err(ProtoError::Invalid {
            what,
            reason: format!("time is {time}"),
        })
    }
}

impl InterfaceMesh {
    pub fn num_nodes(&self) -> usize {
        self.node_ids.len()
    }

    /// Self-consistency: sizes agree, coordinates finite, triangles index existing nodes and
    /// are not degenerate in their indices.
    pub fn validate(&self) -> Result<(), ProtoError> {
        const W: &str = "interface mesh";
        let n = self.node_ids.len();
        if n == 0 {
            return Err(ProtoError::Invalid {
                what: W,
                reason: format!("interface `{}` has no nodes", self.interface),
            });
        }
        check_len(W, "positions", self.positions.len(), 3 * n, || {
            format!("3 per node, {n} nodes")
        })?;
        check_finite(W, "positions", &self.positions)?;
        if self.triangles.len() % 3 != 0 || self.triangles.is_empty() {
            return Err(ProtoError::Invalid {
                what: W,
                reason: format!(
                    "`triangles` has {} indices, expected a positive multiple of 3",
                    self.triangles.len()
                ),
            });
        }
        for (t, tri) in self.triangles.chunks_exact(3).enumerate() {
            if let Some(&bad) = tri.iter().find(|&&i| i as usize >= n) {
                return Err(ProtoError::Invalid {
                    what: W,
                    reason: format!(
                        "triangle {t} refers to node index {bad}, but there are {n} nodes"
                    ),
                });
            }
            if tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] {
                return Err(ProtoError::Invalid {
                    what: W,
                    reason: format!("triangle {t} repeats a node: {tri:?}"),
                });
            }
        }
        Ok(())
    }
}

impl InterfaceKinematics {
    /// Sizes agree with a mesh of `nodes` nodes, values finite, window as expected.
    pub fn validate(&self, nodes: usize, expected_window: u64) -> Result<(), ProtoError> {
        const W: &str = "interface kinematics";
        if self.window != expected_window {
            return Err(ProtoError::WrongWindow {
                what: W,
                got: self.window,
                expected: expected_window,
            });
        }
        check_time(W, self.time)?;
        for (field, a) in [
            ("positions", &self.positions),
            ("velocities", &self.velocities),
            ("accelerations", &self.accelerations),
        ] {
            check_len(W, field, a.len(), 3 * nodes, || {
                format!(
                    "3 per node, interface `{}` has {nodes} nodes",
                    self.interface
                )
            })?;
            check_finite(W, field, a)?;
        }
        Ok(())
    }
}

impl InterfaceForces {
    /// Sizes agree with a mesh of `nodes` nodes, values finite, window as expected.
    pub fn validate(&self, nodes: usize, expected_window: u64) -> Result<(), ProtoError> {
        const W: &str = "interface forces";
        if self.window != expected_window {
            return Err(ProtoError::WrongWindow {
                what: W,
                got: self.window,
                expected: expected_window,
            });
        }
        check_time(W, self.time)?;
        check_len(W, "forces", self.forces.len(), 3 * nodes, || {
            format!(
                "3 per node, interface `{}` has {nodes} nodes",
                self.interface
            )
        })?;
        check_finite(W, "forces", &self.forces)
    }
}
