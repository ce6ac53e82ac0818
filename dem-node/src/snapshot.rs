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
/// sensor state. 4: spheres without orientation. 5: loaded walls' state (first written with
/// each wall's acceleration as a fourth number, which reading skips), particles removed by
/// sinks (a version 4 snapshot reads as one without loaded walls and removals). 6: bodies
/// with orientation and shape id, shape templates, shaped contacts (an older snapshot reads
/// as one of spheres). 7: a periodic cell's state, pairs across its faces, images of shaped
/// pairs (an older snapshot reads as one without a cell). 8: volume (Arlequin) interfaces
/// (an older snapshot reads as one without).
pub const SNAPSHOT_VERSION: u32 = 8;
/// The oldest version [`decode`] reads.
pub const OLDEST_READABLE_VERSION: u32 = 4;

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
    #[serde(default, deserialize_with = "read_loaded_walls")]
    pub loaded_walls: Vec<LoadedWallState>,
    /// Particles removed by sinks so far, and their mass.
    #[serde(default)]
    pub removed_particles: u64,
    #[serde(default)]
    pub removed_mass: f64,
    /// The periodic cell (`[dem.periodic]`): edges, rates, stresses, stage.
    #[serde(default)]
    pub cell: Option<crate::periodic::CellState>,
    /// Volume (Arlequin) interfaces: overlap, coupled particles, window state.
    #[serde(default)]
    pub volumes: Vec<crate::volume_coupling::VolumeInterfaceState>,
}

/// Loaded walls' states as written (`[u, v, contact_force]`), or as the first version 5
/// snapshots wrote them, with the acceleration (derived from the force) as a fourth number.
fn read_loaded_walls<'de, D: serde::Deserializer<'de>>(
    d: D,
) -> Result<Vec<LoadedWallState>, D::Error> {
    Vec::<Vec<f64>>::deserialize(d)?
        .into_iter()
        .map(|w| match w[..] {
            [u, v, contact_force] | [u, v, contact_force, _] => Ok(LoadedWallState {
                u,
                v,
                contact_force,
            }),
            _ => Err(serde::de::Error::custom(format!(
                "a loaded wall's state has 3 numbers, got {}",
                w.len()
            ))),
        })
        .collect()
}

pub fn encode(state: &EngineState) -> Vec<u8> {
    // serialising plain data into a Vec cannot fail
    rmp_serde::to_vec(state).expect("engine state serialises")
}

pub fn decode(bytes: &[u8]) -> Result<EngineState, String> {
    let s: EngineState =
        rmp_serde::from_slice(bytes).map_err(|e| format!("cannot decode snapshot: {e}"))?;
    if !(OLDEST_READABLE_VERSION..=SNAPSHOT_VERSION).contains(&s.version) {
        return Err(format!(
            "snapshot version {} is not {OLDEST_READABLE_VERSION}–{SNAPSHOT_VERSION}",
            s.version
        ));
    }
    let mut s = s;
    s.particles.complete_shape_columns();
    let t = s.particles.templates.len();
    if let Some(k) = s
        .particles
        .shape
        .iter()
        .position(|&id| id != crate::particles::SPHERE && id as usize >= t)
    {
        return Err(format!(
            "particle {} has shape {} but the snapshot holds {t} shape templates",
            s.particles.id[k], s.particles.shape[k]
        ));
    }
    Ok(EngineState {
        version: SNAPSHOT_VERSION,
        ..s
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The fields of a version 4 snapshot, in order.
    #[derive(Serialize)]
    struct V4 {
        version: u32,
        time: f64,
        steps: u64,
        particles: Particles,
        lists: NeighbourLists,
        records: Vec<MeshForceRecord>,
        meshes: Vec<Mesh>,
        sensors: SensorState,
    }

    #[test]
    fn a_version_4_snapshot_reads_without_loaded_walls_and_removals() {
        let mut particles = Particles::default();
        particles.push(
            crate::hertz_mindlin::V3::new(1.0, 2.0, 3.0),
            crate::hertz_mindlin::V3::zeros(),
            crate::hertz_mindlin::V3::zeros(),
            0.5,
            1000.0,
            0,
        );
        let old = V4 {
            version: 4,
            time: 0.25,
            steps: 7,
            particles,
            lists: NeighbourLists::default(),
            records: Vec::new(),
            meshes: Vec::new(),
            sensors: SensorState::default(),
        };
        let bytes = rmp_serde::to_vec(&old).unwrap();
        let s = decode(&bytes).unwrap();
        assert_eq!(s.version, SNAPSHOT_VERSION);
        assert_eq!((s.time, s.steps), (0.25, 7));
        assert_eq!(s.particles.position, old.particles.position);
        assert!(s.loaded_walls.is_empty());
        assert_eq!((s.removed_particles, s.removed_mass), (0, 0.0));
        // and a current one round-trips
        assert_eq!(decode(&encode(&s)).unwrap().time, 0.25);
        let too_old = V4 { version: 3, ..old };
        let err = decode(&rmp_serde::to_vec(&too_old).unwrap()).unwrap_err();
        assert!(err.contains("version 3"), "{err}");
    }

    #[test]
    fn a_first_version_5_snapshot_reads_with_its_loaded_walls_accelerations_skipped() {
        /// The fields of a version 5 snapshot with loaded walls written as `W`: first as
        /// [u, v, contact_force, acceleration].
        #[derive(Serialize)]
        struct V5<W> {
            version: u32,
            time: f64,
            steps: u64,
            particles: Particles,
            lists: NeighbourLists,
            records: Vec<MeshForceRecord>,
            meshes: Vec<Mesh>,
            sensors: SensorState,
            loaded_walls: Vec<W>,
            removed_particles: u64,
            removed_mass: f64,
        }
        fn v5<W>(loaded_walls: Vec<W>) -> V5<W> {
            V5 {
                version: 5,
                time: 0.5,
                steps: 9,
                particles: Particles::default(),
                lists: NeighbourLists::default(),
                records: Vec::new(),
                meshes: Vec::new(),
                sensors: SensorState::default(),
                loaded_walls,
                removed_particles: 3,
                removed_mass: 0.25,
            }
        }
        let old = v5(vec![[-0.01, -0.2, 150.0, -3.0], [0.0; 4]]);
        let s = decode(&rmp_serde::to_vec(&old).unwrap()).unwrap();
        assert_eq!(
            s.loaded_walls,
            vec![
                LoadedWallState {
                    u: -0.01,
                    v: -0.2,
                    contact_force: 150.0
                },
                LoadedWallState::default()
            ]
        );
        assert_eq!((s.removed_particles, s.removed_mass), (3, 0.25));
        // and as written now, three numbers each
        assert_eq!(decode(&encode(&s)).unwrap().loaded_walls, s.loaded_walls);
        // anything else is named
        let two = v5(vec![[1.0, 2.0]]);
        let err = decode(&rmp_serde::to_vec(&two).unwrap()).unwrap_err();
        assert!(err.contains("3 numbers, got 2"), "{err}");
    }
}
