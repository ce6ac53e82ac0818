//! Resource checks made before anything is allocated: the memory a scene's counts need
//! against the machine's memory, the thread count against the cores, and readable figures
//! for the messages ("needs ≈ 1.2 TB", "9.9e-5 s").
//!
//! A count from a scene multiplies into allocations (a lattice `count = [1e4, 1e4, 1e4]` is
//! 1e12 particles); without these checks such a scene reaches the allocator and the node
//! aborts with a backtrace instead of naming the field.

/// Heap bytes one particle costs the engine, an order-of-magnitude estimate (not a bound):
/// the structure-of-arrays state is 170 B (`Particles::bytes_per_particle`: id, x, v, ω, F, T,
/// r, m, I, material), the neighbour lists of a dense bed add ~230 B (6–7 partners of
/// 4 B + a 24 B tangential history, the wall candidates, the position at the last build, the
/// cross-block buffers) — docs/performance.md measures 262–395 B per particle from resting
/// lattices to a settled bed — and generation and the Morton sort briefly hold one more copy
/// of some arrays. 500 B rounds that up.
pub const BYTES_PER_PARTICLE: u64 = 500;

/// Largest `threads`, whatever the machine: beyond this a pool is a mistake, not a setting.
pub const MAX_THREADS: usize = 1024;

// The machine's memory and the readable figures are proto's: one source file compiled into
// each crate that needs it, because the engine libraries build without proto
// (`--no-default-features`, as the benches build them).
#[path = "../../proto/src/resources.rs"]
mod shared;
pub use shared::*;

/// The largest sane `threads`: 4 × the cores this process may use, at most [`MAX_THREADS`].
pub fn max_threads() -> usize {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    cores.saturating_mul(4).min(MAX_THREADS)
}
