//! Stage "detect particle–particle and particle–object contacts" (Ullrich Algorithm 1,
//! line 3): keeps the Verlet neighbour lists valid, rebuilding them when a particle or mesh
//! node moved half the skin (Wellmann B4, eq. 4.10). The exact overlap test runs inside the
//! force stage on these lists.

use crate::broad_phase::{needs_rebuild, rebuild, NeighbourLists, Removed};
use crate::config::CentreBox;
use crate::particles::Particles;
use crate::resolve_forces::MeshForceRecord;
use crate::walls::{Mesh, Plane};

/// `particles_moved`: some particle moved more than half the skin since the last build (the
/// drift checks this). `keep_records`: the force records are sized for the new lists (a
/// coupled mesh or loaded wall needs them), else emptied. A build removes the particles in a
/// sink. `cell`: the edges of a periodic cell (see [`rebuild`]). Returns what was removed if the lists were rebuilt (particles may have been
/// reordered), `None` if they stayed.
#[allow(clippy::too_many_arguments)]
pub fn detect(
    lists: &mut NeighbourLists,
    particles: &mut Particles,
    particles_moved: bool,
    planes: &[Plane],
    meshes: &mut [Mesh],
    records: &mut Vec<MeshForceRecord>,
    keep_records: bool,
    sinks: &[CentreBox],
    cell: Option<crate::hertz_mindlin::V3>,
) -> Option<Removed> {
    if !particles_moved && !needs_rebuild(lists, particles, meshes, cell) {
        return None;
    }
    let removed = rebuild(lists, particles, planes, meshes, sinks, cell);
    records.clear();
    if keep_records {
        records.resize(lists.walls.len(), MeshForceRecord::default());
    }
    Some(removed)
}
