//! Resource checks made before anything is allocated: the memory a mesh needs against the
//! machine's memory, and readable figures for the messages ("needs ≈ 1.2 TB", "9.9e-5 s").
//!
//! A count from a scene multiplies into allocations (a generated box with
//! `divisions = [1e5, 1e5, 1e5]` is 1e15 elements); without these checks such a scene reaches
//! the allocator and the node aborts with a backtrace instead of naming the field.

/// Heap bytes one mesh node costs a model, an order-of-magnitude estimate (not a bound): the
/// static hex8 beam of docs/performance.md peaks at 1.45 GB for 88,641 nodes (16 kB per node:
/// the stiffness matrix with ~81 entries per row and its sparse Cholesky factor, the larger
/// part) and at 190 MB for 12,221 nodes (15.5 kB). Quadratic elements couple more nodes per
/// row, dynamic analyses add the mass matrix and the effective matrix's factor, and the
/// factor's fill grows faster than the node count, so large models need more: a refusal
/// from this estimate is certain, an acceptance is no promise.
pub const BYTES_PER_NODE: u64 = 16_000;

/// Heap bytes one element costs beyond its nodes: connectivity (up to 20 indices of 8 B),
/// offsets, kind, file id and line, strain-gauge and assembly scratch; ~300 B.
pub const BYTES_PER_ELEMENT: u64 = 300;

/// Memory a model of `nodes` nodes and `elements` elements needs (see [`BYTES_PER_NODE`]).
pub fn model_bytes(nodes: u64, elements: u64) -> f64 {
    nodes as f64 * BYTES_PER_NODE as f64 + elements as f64 * BYTES_PER_ELEMENT as f64
}

// The machine's memory and the readable figures are proto's: one source file compiled into
// each crate that needs it, because the engine libraries build without proto
// (`--no-default-features`, as the benches build them).
#[path = "../../proto/src/resources.rs"]
mod shared;
pub use shared::*;
