//! Stage "detect particle–particle and particle–object contacts" (Ullrich Algorithm 1,
//! line 3): keeps the Verlet neighbour lists valid (rebuilding them when a particle or mesh
//! node moved half the skin). The exact overlap test runs inside the force stage on these lists.

use crate::broad_phase::{needs_rebuild, rebuild, NeighbourLists};
use crate::particles::Particles;
use crate::resolve_forces::{MeshRecords, WallState};
use crate::walls::Mesh;

/// Returns true if the lists were rebuilt (particles may have been reordered).
pub fn detect(
    lists: &mut NeighbourLists,
    particles: &mut Particles,
    meshes: &mut [Mesh],
    wall_state: &mut Vec<WallState>,
    records: &mut Vec<MeshRecords>,
) -> bool {
    if !needs_rebuild(lists, particles, meshes) {
        return false;
    }
    let perm = rebuild(lists, particles, meshes);
    // per-particle wall histories move with their particles
    let moved: Vec<WallState> = perm.iter().map(|&k| wall_state[k as usize]).collect();
    *wall_state = moved;
    let need_records = meshes.iter().any(|m| m.coupled);
    records.clear();
    if need_records {
        records.resize(particles.len(), MeshRecords::default());
    }
    true
}
