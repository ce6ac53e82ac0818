//! Snapshot/restore of the full mutable engine state (MessagePack via rmp-serde). Restoring
//! a snapshot continues bitwise identically: the neighbour lists, contact histories, last
//! forces, particle order and mesh window state are all part of it.

use crate::broad_phase::NeighbourLists;
use crate::particles::Particles;
use crate::resolve_forces::MeshForceRecord;
use crate::sensors::SensorState;
use crate::walls::{LoadedWallState, Mesh};
use serde::{Deserialize, Serialize};

/// 2: pair lists as partner CSR with histories, wall histories per candidate group.
/// 3: moving/removable static walls (mesh `active`, wall displacements at the list build),
/// sensor state. 4: spheres without orientation. 5: loaded walls' state.
pub const SNAPSHOT_VERSION: u32 = 5;

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct EngineState {
    pub version: u32,
    pub time: f64,
    pub steps: u64,
    pub particles: Particles,
    pub lists: NeighbourLists,
    /// Forces on coupled meshes per wall candidate (empty without coupled meshes).
    pub records: Vec<MeshForceRecord>,
    pub meshes: Vec<Mesh>,
    /// Flow sensors' particle sides and cumulative masses, sensor statistics.
    pub sensors: SensorState,
    /// Displacement, velocity and forces of the loaded walls (`load`), in scene order.
    pub loaded_walls: Vec<LoadedWallState>,
}

pub fn encode(state: &EngineState) -> Vec<u8> {
    // serialising plain data into a Vec cannot fail
    rmp_serde::to_vec(state).expect("engine state serialises")
}

pub fn decode(bytes: &[u8]) -> Result<EngineState, String> {
    let s: EngineState =
        rmp_serde::from_slice(bytes).map_err(|e| format!("cannot decode snapshot: {e}"))?;
    if s.version != SNAPSHOT_VERSION {
        return Err(format!(
            "snapshot version {} is not {}",
            s.version, SNAPSHOT_VERSION
        ));
    }
    Ok(s)
}
