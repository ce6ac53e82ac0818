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
        // Every value of every message is checked, so the common case (all finite) must run at
        // memory speed (an element-wise `find` ran at ~1 value per cycle: 90 µs of a 10k-node
        // round trip): blocks are tested without an early exit, in vectors, and only a block
        // that fails is searched element by element.
        const BLOCK: usize = 512;
        let bad = self.0.chunks(BLOCK).position(any_non_finite)?;
        let start = bad * BLOCK;
        self.0[start..]
            .iter()
            .enumerate()
            .find(|(_, v)| !v.is_finite())
            .map(|(i, v)| (start + i, *v))
    }
}

/// Whether `c` holds a NaN or an infinity (see [`F64Array::first_non_finite`]), with the
/// widest vectors the CPU has: the portable loop is built for SSE2, two doubles at a time.
fn any_non_finite(c: &[f64]) -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2 (checked just above)
            return unsafe { any_non_finite_avx2(c) };
        }
    }
    any_non_finite_portable(c)
}

/// # Safety
/// The CPU must have AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn any_non_finite_avx2(c: &[f64]) -> bool {
    any_non_finite_portable(c)
}

/// OR-ing [`non_finite_mark`]s is a loop of 64-bit and/add/or without an early exit; eight
/// accumulators let the compiler use whole vectors and keep several loads in flight.
#[inline(always)]
fn any_non_finite_portable(c: &[f64]) -> bool {
    let mark = |v: &f64| non_finite_mark(v.to_bits());
    let mut acc = [0u64; 8];
    let mut chunks = c.chunks_exact(8);
    for ch in &mut chunks {
        for (a, v) in acc.iter_mut().zip(ch) {
            *a |= mark(v);
        }
    }
    let tail = chunks.remainder().iter().fold(0, |a, v| a | mark(v));
    (acc.iter().fold(tail, |a, b| a | b) >> 63) != 0
}

/// Copies little-endian doubles from `src` to `dst` (same length) and tells whether they are
/// all finite: one pass instead of a copy and a check (the hot path of interface data on
/// both sides of the wire). A tail of fewer than 8 bytes is copied and not judged.
pub(crate) fn copy_finite(dst: &mut [u8], src: &[u8]) -> bool {
    assert_eq!(dst.len(), src.len(), "copy_finite: lengths differ");
    // SAFETY: dst is valid for src.len() bytes of writes
    unsafe { copy_finite_raw(dst.as_mut_ptr(), src) }
}

/// [`copy_finite`] into uninitialised memory.
///
/// # Safety
/// `dst` must be valid for `src.len()` bytes of writes and not overlap `src`.
pub(crate) unsafe fn copy_finite_raw(dst: *mut u8, src: &[u8]) -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2 (checked just above); the caller's contract
            return unsafe { copy_finite_avx2(dst, src) };
        }
    }
    // SAFETY: the caller's contract
    unsafe { copy_finite_portable(dst, src) }
}

/// # Safety
/// The CPU must have AVX2; `dst` as for [`copy_finite_raw`].
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn copy_finite_avx2(dst: *mut u8, src: &[u8]) -> bool {
    // SAFETY: the caller's contract
    unsafe { copy_finite_portable(dst, src) }
}

#[inline(always)]
unsafe fn copy_finite_portable(dst: *mut u8, src: &[u8]) -> bool {
    let word = |k: usize| u64::from_le_bytes(src[8 * k..8 * k + 8].try_into().expect("8 bytes"));
    // SAFETY (both writes): k < src.len() / 8, so 8k + 8 <= src.len() bytes, within dst
    let put = |k: usize, x: u64| unsafe { dst.add(8 * k).cast::<u64>().write_unaligned(x) };
    let words = src.len() / 8;
    let mut acc = [0u64; 8];
    let blocks = words / 8;
    for b in 0..blocks {
        for (j, a) in acc.iter_mut().enumerate() {
            let x = word(8 * b + j);
            *a |= non_finite_mark(x);
            put(8 * b + j, x.to_le());
        }
    }
    let mut tail = 0;
    for k in 8 * blocks..words {
        let x = word(k);
        tail |= non_finite_mark(x);
        put(k, x.to_le());
    }
    for (k, &byte) in src.iter().enumerate().skip(8 * words) {
        // SAFETY: k < src.len()
        unsafe { dst.add(k).write(byte) };
    }
    (acc.iter().fold(tail, |a, b| a | b) >> 63) == 0
}

/// Bit 63 set iff the double with these bits is NaN or infinite: its magnitude bits are at
/// least those of infinity (0x7ff0…) iff adding 2^52 to them carries into the sign bit.
#[inline(always)]
fn non_finite_mark(bits: u64) -> u64 {
    (bits & 0x7fff_ffff_ffff_ffff).wrapping_add(1 << 52)
}

thread_local! {
    /// Set by [`crate::codec::decode_finite`] around one decode: bulk arrays must be finite.
    static FINITE_ONLY: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Runs `f` (a decode) with the rule that every [`F64Array`] it reads must be finite; an array
/// that is not fails with [`NON_FINITE`] in its message.
pub(crate) fn finite_only<R>(f: impl FnOnce() -> R) -> R {
    /// Clears the rule however `f` ends.
    struct Reset;
    impl Drop for Reset {
        fn drop(&mut self) {
            FINITE_ONLY.with(|c| c.set(false));
        }
    }
    FINITE_ONLY.with(|c| c.set(true));
    let _reset = Reset;
    f()
}

/// The array, or under [`finite_only`] the [`NON_FINITE`] error if it holds a NaN or an
/// infinity (the paths that do not check while they copy: plain float arrays, big-endian).
fn finite_if_asked<E: serde::de::Error>(a: F64Array) -> Result<F64Array, E> {
    if FINITE_ONLY.with(|c| c.get()) && a.first_non_finite().is_some() {
        return Err(E::custom(NON_FINITE));
    }
    Ok(a)
}

/// Marker of the decode error [`finite_only`] raises.
pub(crate) const NON_FINITE: &str = "<non-finite value in an f64 bin>";

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
                if cfg!(target_endian = "little") && FINITE_ONLY.with(|c| c.get()) {
                    // one pass: copy into aligned doubles and check them
                    let n = b.len() / 8;
                    let mut v: Vec<f64> = Vec::with_capacity(n);
                    // SAFETY: the capacity holds b.len() bytes and v is new (no overlap); the
                    // length is set only once all n doubles are written
                    let finite = unsafe { copy_finite_raw(v.as_mut_ptr().cast::<u8>(), b) };
                    if !finite {
                        return Err(E::custom(NON_FINITE));
                    }
                    // SAFETY: all n doubles were written just above
                    unsafe { v.set_len(n) };
                    return Ok(F64Array(v));
                }
                if cfg!(target_endian = "little") {
                    // one copy into aligned doubles (the bin itself need not be aligned), into
                    // uninitialised capacity: zero-filling first cost a second pass
                    let n = b.len() / 8;
                    let mut v: Vec<f64> = Vec::with_capacity(n);
                    // SAFETY: the capacity holds n doubles = b.len() bytes, the regions cannot
                    // overlap (v is new), and every bit pattern is a valid f64
                    unsafe {
                        std::ptr::copy_nonoverlapping(
                            b.as_ptr(),
                            v.as_mut_ptr().cast::<u8>(),
                            b.len(),
                        );
                        v.set_len(n);
                    }
                    return Ok(F64Array(v));
                }
                finite_if_asked(F64Array(
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
                finite_if_asked(F64Array(v))
            }
        }
        d.deserialize_any(V)
    }
}

/// What kind of solver a node is. Nodes are named by id (`dem`, `fem`, `sleeper_left`, ...);
/// the kind says what they can do on an interface: a `fem` node provides surface interfaces
/// (mesh, kinematics; it reads forces), a `dem` node uses them (it reads kinematics, writes
/// forces).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NodeKind {
    Dem,
    Fem,
}

impl std::fmt::Display for NodeKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            NodeKind::Dem => "dem",
            NodeKind::Fem => "fem",
        })
    }
}

/// What an interface couples: a surface (mesh triangles, nodal kinematics and forces) or, later,
/// a volume (Arlequin overlap).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum InterfaceKind {
    #[default]
    Surface,
    Volume,
}

/// An interface of the run as the coordinator declares it in `init`: who provides it (the node
/// that owns its mesh, publishes its kinematics and reads its forces) and who uses it (the nodes
/// that read the kinematics and publish forces).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InterfaceDecl {
    pub name: String,
    pub kind: InterfaceKind,
    pub provider: String,
    pub users: Vec<String>,
    /// Users send the mean of their forces over the window's substeps instead of the last
    /// substep's (Ullrich (3.8)).
    pub force_averaging: bool,
    /// The provider reads its forces on the interface's `forces_relaxed` key, where the
    /// coordinator publishes the estimates its acceleration computes (implicit schemes),
    /// instead of the users' `forces` (which then go to the coordinator only). Absent: false.
    #[serde(default)]
    pub relaxed_forces: bool,
    /// The users read their kinematics on the interface's `kinematics_relaxed` key, where the
    /// coordinator publishes its estimate of the provider's end state (the concurrent implicit
    /// scheme), instead of the provider's `kinematics` (which then go to the coordinator
    /// only). Absent: false.
    #[serde(default)]
    pub relaxed_kinematics: bool,
}

/// Labels interface data: the coupling window and, within it, the iteration (0 for explicit
/// schemes; implicit schemes repeat a window with iterations 1, 2, ...).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct Label {
    pub window: u64,
    pub iteration: u32,
}

impl Label {
    /// Iteration 0 of `window`.
    pub fn window(window: u64) -> Label {
        Label {
            window,
            iteration: 0,
        }
    }
}

impl std::fmt::Display for Label {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.iteration == 0 {
            write!(f, "window {}", self.window)
        } else {
            write!(f, "window {} iteration {}", self.window, self.iteration)
        }
    }
}

/// How the users of an interface move its mesh during a window (Ullrich ch. 3.3, τ from the
/// window start), from the provider's state P, V, A in the kinematics of the window
/// ([`crate::motion`]): `quadratic` x = P + Vτ + ½Aτ² (just-in-time: the state at the window
/// start), `linear` x = P₀ + (P − P₀)τ/Δt (predictive (3.4)–(3.7): from the previous end
/// position P₀ to this state, the provider's end of the window), `fixed` x = P.
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
    pub kind: NodeKind,
    /// Optional features, informative: `snapshot` (snapshot/restore), `checkpoint`
    /// (checkpoint/rollback), `static`, `dynamic`, ...
    pub capabilities: Vec<String>,
    pub pid: u32,
}

/// Set-up of a node: the scene it is part of.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Init {
    /// Path of the scene file as the coordinator knows it (names it in errors, resolves
    /// relative file paths when the file system is shared).
    pub scene_path: String,
    /// The whole scene file (TOML). A node reads its own table, `table`.
    pub scene_toml: String,
    /// The node's table in the scene (`dem`, `fem`, or the node's id for further nodes).
    pub table: String,
    /// Folder where the node writes its outputs.
    pub out_dir: String,
    /// Every interface of the run (empty for a single-solver run); a node serves those that
    /// name it as provider or user.
    pub interfaces: Vec<InterfaceDecl>,
    /// Validate and report limits, then wait for `stop`: no stepping (`cosim check`).
    pub check_only: bool,
    /// Write per-window interface traces (CSV) for verification: the DEM its per-substep
    /// force totals and its mesh at window ends, the FEM the force totals it received and
    /// its interface positions at window ends.
    pub trace: bool,
}

/// Advance one coupling window (or one iteration of it).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AdvanceWindow {
    /// Window index k, starting at 0, consecutive.
    pub window: u64,
    /// Iteration of the window (0 for explicit schemes).
    pub iteration: u32,
    /// Simulation time at the start of the window (s).
    pub t_start: f64,
    /// Length of the window Δt^C (s). A DEM node runs Δt^C / Δt^D substeps (the coordinator
    /// has checked that this is a whole number).
    pub dt: f64,
    /// How interface users move the coupled mesh during the window.
    pub motion: MotionRule,
    /// Interface data to wait for before computing (users: kinematics, providers: forces);
    /// `None`: compute with what the node has.
    pub input: Option<Label>,
    /// Label of the interface data to publish at the end of the window (users: forces,
    /// providers: kinematics); `None`: publish nothing.
    pub output: Option<Label>,
    /// Solve to equilibrium under the inputs instead of a time step (one-way coupling).
    pub static_solve: bool,
}

/// Commands from the coordinator, on `cosim/<run>/cmd/<node>`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum CommandBody {
    Init(Init),
    /// Publish the node's current interface output without stepping, labelled `label`
    /// (providers: their state, e.g. the initial state before window 0 of just-in-time; users:
    /// their forces of the last window, averaged when the interface says so).
    Publish {
        label: Label,
    },
    AdvanceWindow(AdvanceWindow),
    /// Keep the current state in memory as the start of window `window` (implicit schemes
    /// repeat a window from here). No reply.
    Checkpoint {
        window: u64,
    },
    /// Put the state of the last `checkpoint` back (it must be of window `window`). No reply.
    Rollback {
        window: u64,
    },
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
    /// The window is done. `compute_s` is the wall time spent computing (not waiting);
    /// `after_output_s` the part of it after the node's last interface data message of the
    /// window (outputs, monitor values: its partner does not wait for them, so they are off
    /// the window's critical path); 0 when it sent none, or from a node that does not say.
    WindowDone {
        window: u64,
        t_end: f64,
        compute_s: f64,
        wait_s: f64,
        monitor: BTreeMap<String, f64>,
        #[serde(default)]
        after_output_s: f64,
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
    /// Triangles as node indices into this message's node list (3 × triangles values);
    /// empty for a volume interface.
    pub triangles: Vec<u32>,
    /// A volume (Arlequin) interface: the overlap's elements and nodal weights. Absent for a
    /// surface.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub volume: Option<VolumeElements>,
}

/// The overlap of a volume interface: elements of one isoparametric interpolation over the
/// message's nodes and the particles' weight w_I at each node (Wellmann (6.27)).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VolumeElements {
    /// `tet4`, `tet10`, `hex8` or `hex20` (Abaqus/VTK node order).
    pub shape: String,
    /// The shape's node count of node indices per element.
    pub elements: Vec<u32>,
    /// One weight in [0, 1] per node: 1 on the particle side, 0 on the FE side.
    pub weights: F64Array,
    /// The penalty ε of (6.23) [N/m⁴]: the users apply −Πᵀ ε V (u^DE − u^FE) to their
    /// particles (6.26), the provider adds ε V to its operator and reads ε V u^DE as its forces.
    pub penalty: f64,
}

impl VolumeElements {
    /// Nodes per element of `shape`, `None` for an unknown shape.
    pub fn nodes_per_element(shape: &str) -> Option<usize> {
        Some(match shape {
            "tet4" => 4,
            "tet10" => 10,
            "hex8" => 8,
            "hex20" => 20,
            _ => return None,
        })
    }
}

/// Interface kinematics, provider → users: the provider's positions P, velocities V and
/// accelerations A of the interface nodes at time `time` (node-major xyz), labelled with the
/// window (and iteration) whose users read them. How a user moves its mesh from them is the
/// window's [`MotionRule`] ([`crate::motion`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InterfaceKinematics {
    pub version: u32,
    pub run_id: String,
    pub interface: String,
    pub window: u64,
    pub iteration: u32,
    pub time: f64,
    pub positions: F64Array,
    pub velocities: F64Array,
    pub accelerations: F64Array,
}

/// Interface forces, user → provider: forces exerted by the user (the particles) on the
/// interface nodes (N, node-major xyz), the last substep's or the mean over the window's
/// `samples` substeps.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InterfaceForces {
    pub version: u32,
    pub run_id: String,
    pub interface: String,
    pub window: u64,
    pub iteration: u32,
    pub time: f64,
    pub forces: F64Array,
    pub averaged: bool,
    /// Substeps the forces are the mean of (1 when not averaged).
    pub samples: u32,
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
        if let Some(v) = &self.volume {
            if !self.triangles.is_empty() {
                return Err(ProtoError::Invalid {
                    what: W,
                    reason: "a volume interface has elements, not triangles".into(),
                });
            }
            let nn =
                VolumeElements::nodes_per_element(&v.shape).ok_or_else(|| ProtoError::Invalid {
                    what: W,
                    reason: format!(
                        "unknown element shape `{}` (tet4, tet10, hex8, hex20)",
                        v.shape
                    ),
                })?;
            if v.elements.is_empty() || v.elements.len() % nn != 0 {
                return Err(ProtoError::Invalid {
                    what: W,
                    reason: format!(
                        "`elements` has {} indices, expected a positive multiple of {nn} ({})",
                        v.elements.len(),
                        v.shape
                    ),
                });
            }
            if let Some(k) = v.elements.iter().position(|&i| i as usize >= n) {
                return Err(ProtoError::Invalid {
                    what: W,
                    reason: format!(
                        "element {} refers to node index {}, but there are {n} nodes",
                        k / nn,
                        v.elements[k]
                    ),
                });
            }
            let mut used = vec![false; n];
            for (e, el) in v.elements.chunks_exact(nn).enumerate() {
                for (a, &i) in el.iter().enumerate() {
                    if el[..a].contains(&i) {
                        return Err(ProtoError::Invalid {
                            what: W,
                            reason: format!("element {e} repeats node index {i}: {el:?}"),
                        });
                    }
                    used[i as usize] = true;
                }
            }
            if let Some(i) = used.iter().position(|u| !u) {
                return Err(ProtoError::Invalid {
                    what: W,
                    reason: format!(
                        "node {} (index {i}) is in no element of the volume interface",
                        self.node_ids[i]
                    ),
                });
            }
            check_len(W, "weights", v.weights.len(), n, || {
                format!("1 per node, {n} nodes")
            })?;
            if !(v.penalty.is_finite() && v.penalty > 0.0) {
                return Err(ProtoError::Invalid {
                    what: W,
                    reason: format!("penalty {} is not a positive number", v.penalty),
                });
            }
            check_finite(W, "weights", &v.weights)?;
            if let Some(k) = v.weights.0.iter().position(|w| !(0.0..=1.0).contains(w)) {
                return Err(ProtoError::Invalid {
                    what: W,
                    reason: format!("weights[{k}] = {} is not in [0, 1]", v.weights.0[k]),
                });
            }
            return Ok(());
        }
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
    pub fn label(&self) -> Label {
        Label {
            window: self.window,
            iteration: self.iteration,
        }
    }

    /// Sizes agree with a mesh of `nodes` nodes, values finite, label as expected.
    pub fn validate(&self, nodes: usize, expected: Label) -> Result<(), ProtoError> {
        self.check(nodes, expected, true)
    }

    /// [`Self::validate`] without the finiteness of the arrays (known from
    /// [`crate::codec::decode_finite`]).
    pub fn validate_sizes(&self, nodes: usize, expected: Label) -> Result<(), ProtoError> {
        self.check(nodes, expected, false)
    }

    fn check(&self, nodes: usize, expected: Label, finite: bool) -> Result<(), ProtoError> {
        const W: &str = "interface kinematics";
        if self.label() != expected {
            return Err(ProtoError::WrongWindow {
                what: W,
                got: self.label(),
                expected,
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
            if finite {
                check_finite(W, field, a)?;
            }
        }
        Ok(())
    }
}

impl InterfaceForces {
    pub fn label(&self) -> Label {
        Label {
            window: self.window,
            iteration: self.iteration,
        }
    }

    /// Sizes agree with a mesh of `nodes` nodes, values finite, label as expected.
    pub fn validate(&self, nodes: usize, expected: Label) -> Result<(), ProtoError> {
        self.check(nodes, expected, true)
    }

    /// [`Self::validate`] without the finiteness of the forces (known from
    /// [`crate::codec::decode_finite`]).
    pub fn validate_sizes(&self, nodes: usize, expected: Label) -> Result<(), ProtoError> {
        self.check(nodes, expected, false)
    }

    fn check(&self, nodes: usize, expected: Label, finite: bool) -> Result<(), ProtoError> {
        const W: &str = "interface forces";
        if self.label() != expected {
            return Err(ProtoError::WrongWindow {
                what: W,
                got: self.label(),
                expected,
            });
        }
        check_time(W, self.time)?;
        check_len(W, "forces", self.forces.len(), 3 * nodes, || {
            format!(
                "3 per node, interface `{}` has {nodes} nodes",
                self.interface
            )
        })?;
        if finite {
            check_finite(W, "forces", &self.forces)?;
        }
        Ok(())
    }
}
