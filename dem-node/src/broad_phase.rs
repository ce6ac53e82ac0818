//! Broad phase: cell grid + Verlet skin (Wellmann ch. 3.4.1, REFERENCE B4).
//!
//! Each build sorts the particles along a Morton (Z-order) curve of their grid cells, so that
//! particles close in space are close in memory at every scale (the neighbours of a particle
//! are mostly in cache from 1e3 to 1e6 particles, and a force block of [`BLOCK`] consecutive
//! particles is a compact piece of space, see `resolve_forces`). It then lists every particle
//! pair (i < j) closer than r_i + r_j + d_V (eq. 3.47) and every particle–wall candidate closer
//! than r + d_V (eq. 4.9). The lists stay valid until a particle or mesh node has moved d_V/2
//! (eq. 4.10). Lists are in a stable order (sorted by index) and the build is deterministic,
//! so results do not depend on the thread count.
//!
//! Storage (data-oriented, Wellmann ch. 3.4.3): the pair list is a CSR of partner indices with
//! one tangential history ξ per pair (24 bytes; zero when not touching); wall candidates are a
//! CSR per particle with one history per (wall, patch) group. Nothing per step is allocated.

use crate::config::CentreBox;
use crate::hertz_mindlin::V3;
use crate::narrow::superquadric::Linearised;
use crate::particles::{Orientation, Particles, SPHERE};
use crate::triangle_contact::distance_squared;
use crate::walls::{Mesh, Plane};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Particles per force block. Blocks are the parallel work units of the force stage; their
/// size is fixed (not derived from the thread count), so the summation order of every force,
/// and hence every bit of the result, is the same for any number of threads.
pub const BLOCK: usize = 1024;

/// A particle–wall candidate: a plane (`wall` < number of planes; `patch` = `triangle` = 0) or
/// a triangle of mesh `wall − number of planes` in contact patch `patch`.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq, PartialOrd, Ord)]
pub struct WallCandidate {
    pub wall: u32,
    pub patch: u32,
    pub triangle: u32,
}

/// State of the contact of a particle with one (wall, patch) group, stored at the group's
/// first candidate (unused at the others).
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
pub struct WallContact {
    /// Tangential spring displacement ξ (zero when not in contact).
    pub shear: V3,
    /// Overlap δ ≥ 0 of the last force evaluation, negative when not in contact.
    pub overlap: f64,
}

impl WallContact {
    pub const NONE: WallContact = WallContact {
        shear: V3::new(0.0, 0.0, 0.0),
        overlap: -1.0,
    };

    pub fn touching(&self) -> bool {
        self.overlap >= 0.0
    }
}

/// State of a contact of a non-spherical body (a shaped pair or a shaped body with a wall),
/// carried across list builds: the warm start of the narrow phase (temporal coherence,
/// Wellmann 3.60–3.61), the tangential force history (3.25) and the per-contact record
/// (point and force) that the gather, sensors and outputs read.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq)]
pub struct ShapedContact {
    /// Last contact normal, from the first body towards the second (or the wall); zero
    /// before the first evaluation.
    pub normal: V3,
    /// Tangential force on the first body (zero when not touching).
    pub tangential: V3,
    /// Overlap δ of the last evaluation, negative when not touching.
    pub overlap: f64,
    /// Contact point and total contact force on the first body (zero when not touching).
    pub point: V3,
    pub force: V3,
    /// γ of the elliptic Hertz law (W 3.19) used in the last evaluation (0 when not touching).
    pub stiffness: f64,
    /// A separated pair's proof of separation, kept for the next steps (*not in thesis*):
    /// H = h1(c) + h2(−c), the support functions of the two bodies in the directions of the
    /// separating `normal` c at the last evaluation (the gap is then c·(x2 − x1) − H), and the
    /// two orientations then. NaN when there is none (touching, new, or no plane found).
    #[serde(default = "nan")]
    pub support: f64,
    #[serde(default)]
    pub frames: [Orientation; 2],
    /// A polyhedral pair's last GJK simplex as vertex indices (first body, second body) × 3,
    /// `u16::MAX` where unused: the next step's GJK starts from it (temporal coherence).
    #[serde(default = "no_simplex")]
    pub simplex: [u16; 6],
    /// A touching superquadric pair's surfaces linearised about their last exact evaluation
    /// (`Linearised::NONE` otherwise): the next step's search evaluates them while the
    /// normal stays within their reach.
    #[serde(default = "no_linearisation")]
    pub linear: Linearised,
}

fn no_linearisation() -> Linearised {
    Linearised::NONE
}

fn nan() -> f64 {
    f64::NAN
}

fn no_simplex() -> [u16; 6] {
    [u16::MAX; 6]
}

impl ShapedContact {
    pub const NONE: ShapedContact = ShapedContact {
        normal: V3::new(0.0, 0.0, 0.0),
        tangential: V3::new(0.0, 0.0, 0.0),
        overlap: -1.0,
        point: V3::new(0.0, 0.0, 0.0),
        force: V3::new(0.0, 0.0, 0.0),
        stiffness: 0.0,
        support: f64::NAN,
        frames: [Orientation::new_unchecked(nalgebra::Quaternion::new(1.0, 0.0, 0.0, 0.0)); 2],
        simplex: [u16::MAX; 6],
        linear: Linearised::NONE,
    };

    pub fn touching(&self) -> bool {
        self.overlap >= 0.0
    }

    /// The same contact seen from the other body (first and second swapped).
    pub fn swapped(&self) -> ShapedContact {
        ShapedContact {
            normal: -self.normal,
            tangential: -self.tangential,
            overlap: self.overlap,
            point: self.point,
            force: -self.force,
            stiffness: self.stiffness,
            support: self.support,
            frames: [self.frames[1], self.frames[0]],
            simplex: {
                let s = self.simplex;
                [s[1], s[0], s[3], s[2], s[5], s[4]]
            },
            linear: self.linear.swapped(),
        }
    }
}

/// Per body, the shaped contacts it takes part in (CSR, ascending): pair k as first body is
/// entry 2k, as second 2k + 1; wall contacts are theirs alone (`wall_start`).
#[derive(Debug, Clone, Default)]
pub struct ShapedIncidence {
    pub pair_start: Vec<u32>,
    pub pair_entries: Vec<u32>,
    pub wall_start: Vec<u32>,
    /// First candidate of every (body, wall, patch) group of `shaped_mesh`, then its length;
    /// the groups of body k are `mesh_group_start[k]..mesh_group_start[k+1]`.
    pub mesh_groups: Vec<u32>,
    pub mesh_group_start: Vec<u32>,
}

#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct NeighbourLists {
    pub skin: f64,
    /// Pairs with first index i are `first_pair[i]..first_pair[i+1]`, second index
    /// `partner[k]` > i, ascending.
    pub first_pair: Vec<u32>,
    pub partner: Vec<u32>,
    /// Tangential spring displacement ξ of each pair (zero when not touching).
    pub shear: Vec<V3>,
    /// Wall candidates of particle k are `walls[wall_start[k]..wall_start[k+1]]`, sorted by
    /// (wall, patch, triangle); planes come first.
    pub wall_start: Vec<u32>,
    pub walls: Vec<WallCandidate>,
    pub wall_contacts: Vec<WallContact>,
    pub position_at_build: Vec<V3>,
    /// Displacement of each prescribed-motion wall at the last build (rebuild when one moved
    /// d_V/2 since, eq. 4.10 for a rigid translation).
    pub wall_shift_at_build: Vec<V3>,
    pub builds: u64,
    pub valid: bool,
    /// Pairs whose partner lies in a later block ("cross pairs"), derived from the pair list
    /// by [`NeighbourLists::index_blocks`] (not part of snapshots).
    #[serde(skip)]
    pub cross: CrossPairs,
    /// The pair bucket of the non-spherical bodies (Wellmann's narrow phase and elliptic
    /// law; a sphere–superquadric pair is here too): pairs (i < j) with their contacts.
    #[serde(default)]
    pub shaped_pairs: Vec<[u32; 2]>,
    #[serde(default)]
    pub shaped_pair_contacts: Vec<ShapedContact>,
    /// Plane candidates of non-spherical bodies: (body, plane), sorted, with contacts.
    #[serde(default)]
    pub shaped_walls: Vec<[u32; 2]>,
    #[serde(default)]
    pub shaped_wall_contacts: Vec<ShapedContact>,
    /// Triangle candidates of non-spherical bodies: (body, candidate), sorted; a contact per
    /// (body, wall, patch) group, stored at the group's first candidate.
    #[serde(default)]
    pub shaped_mesh: Vec<(u32, WallCandidate)>,
    #[serde(default)]
    pub shaped_mesh_contacts: Vec<ShapedContact>,
    /// Where the force of a group's contact acts on a coupled mesh (at the group's first
    /// candidate; rewritten every force evaluation).
    #[serde(default)]
    pub shaped_mesh_records: Vec<crate::resolve_forces::MeshForceRecord>,
    /// Derived from the shaped lists (not part of snapshots).
    #[serde(skip)]
    pub shaped_incidence: ShapedIncidence,
    /// Scratch of the force evaluation: the rotation matrix of every body in a shaped pair
    /// this step (formed once per body, not per pair; the others are left as they were).
    #[serde(skip)]
    pub shaped_rotations: Vec<nalgebra::Matrix3<f64>>,
    /// Periodic cell (Wellmann §5.1.1): per shaped pair, the image of its second body, whose
    /// centre is at x_j + s∘L (zero for a pair inside the cell; empty without a cell).
    #[serde(default)]
    pub shaped_pair_image: Vec<[i8; 3]>,
    /// Periodic cell: the sphere pairs that touch across the cell's faces, by pair.
    #[serde(default)]
    pub periodic_pairs: Vec<PeriodicPair>,
    /// The cell's edge lengths at the last build (`None`: no periodic cell).
    #[serde(default)]
    pub cell_at_build: Option<V3>,
}

/// A sphere pair of a periodic cell across its faces: the image of `pair[1]` shifted by
/// d = s∘L (`image` s ∈ {−1, 0, 1}³, W 5.2) meets `pair[0]`; its tangential history ξ, and
/// the force on `pair[0]` of the last evaluation with its overlap (negative when apart), which
/// the cell's average stress (W 5.5) reads.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
pub struct PeriodicPair {
    pub pair: [u32; 2],
    pub image: [i8; 3],
    pub shear: V3,
    pub force: V3,
    pub overlap: f64,
    /// The torques on `pair[0]` and `pair[1]` of the last evaluation (rewritten by every
    /// evaluation, not part of snapshots).
    #[serde(skip)]
    pub torques: [V3; 2],
}

/// The 13 shifts N⁺ of Wellmann §5.1.1 (one of each pair ±n): a ghost of particle j is made
/// for these only, so each contact across the faces is found once.
pub const HALF_SHIFTS: [[i8; 3]; 13] = [
    [1, 0, 0],
    [0, 1, 0],
    [0, 0, 1],
    [1, 1, 0],
    [1, 0, 1],
    [0, 1, 1],
    [1, 1, 1],
    [1, -1, 0],
    [1, 0, -1],
    [0, 1, -1],
    [1, 1, -1],
    [1, -1, 1],
    [-1, 1, 1],
];

/// The extra reach of a pair across the faces of a periodic cell, as a fraction of the skin:
/// the lists stay valid until the cell's edges changed by this much since the build (its
/// images moved), besides every particle's d_V/2.
pub const CELL_MARGIN: f64 = 0.5;

/// The shift d = s∘L of image `s` in a cell of edges `size`.
#[inline]
pub fn image_shift(size: &V3, s: [i8; 3]) -> V3 {
    V3::new(
        s[0] as f64 * size.x,
        s[1] as f64 * size.y,
        s[2] as f64 * size.z,
    )
}

/// Cross-block pairs: the force block of i writes the reaction on j into `force` (numbered by
/// cross pairs in pair order), and the block of j gathers it afterwards in a fixed order.
#[derive(Debug, Clone, Default)]
pub struct CrossPairs {
    /// First cross-pair number of each block (len blocks + 1).
    pub block_start: Vec<u32>,
    /// Particles receiving cross-pair reactions, ascending; those of block b are
    /// `receivers[block_receivers[b]..block_receivers[b+1]]`.
    pub receivers: Vec<u32>,
    pub block_receivers: Vec<u32>,
    /// Receiver r gathers the cross pairs `incoming[receiver_start[r]..receiver_start[r+1]]`
    /// (ascending, i.e. by first particle).
    pub receiver_start: Vec<u32>,
    pub incoming: Vec<u32>,
    /// Reaction force and torque on the second particle of each cross pair (scratch, rewritten
    /// every force evaluation).
    pub force: Vec<[V3; 2]>,
}

impl NeighbourLists {
    /// Derives the cross-block pair index from the pair list (after a build or a restore).
    pub fn index_blocks(&mut self) {
        let n = self.first_pair.len().saturating_sub(1);
        let blocks = n.div_ceil(BLOCK);
        let c = &mut self.cross;
        c.block_start.clear();
        c.block_start.reserve(blocks + 1);
        let mut count = vec![0u32; n + 1];
        let mut total = 0u32;
        for b in 0..blocks {
            c.block_start.push(total);
            let end = ((b + 1) * BLOCK).min(n) as u32;
            let pairs = self.first_pair[b * BLOCK] as usize..self.first_pair[end as usize] as usize;
            for &j in &self.partner[pairs] {
                if j >= end {
                    count[j as usize] += 1;
                    total += 1;
                }
            }
        }
        c.block_start.push(total);
        c.receivers.clear();
        c.receiver_start.clear();
        c.block_receivers.clear();
        c.receiver_start.push(0);
        let mut fill = Vec::new();
        for (j, &m) in count.iter().enumerate().take(n) {
            if j % BLOCK == 0 {
                c.block_receivers.push(c.receivers.len() as u32);
            }
            if m > 0 {
                c.receivers.push(j as u32);
                fill.push(*c.receiver_start.last().unwrap_or(&0));
                c.receiver_start
                    .push(c.receiver_start.last().unwrap_or(&0) + m);
            }
        }
        c.block_receivers.push(c.receivers.len() as u32);
        // receiver number of each particle (only read for receivers)
        let mut slot_of = count;
        for (r, &j) in c.receivers.iter().enumerate() {
            slot_of[j as usize] = r as u32;
        }
        c.incoming.clear();
        c.incoming.resize(total as usize, 0);
        let mut ordinal = 0u32;
        for b in 0..blocks {
            let (lo, end) = (b * BLOCK, ((b + 1) * BLOCK).min(n));
            for i in lo..end {
                for &j in
                    &self.partner[self.first_pair[i] as usize..self.first_pair[i + 1] as usize]
                {
                    if j as usize >= end {
                        let r = slot_of[j as usize] as usize;
                        c.incoming[fill[r] as usize] = ordinal;
                        fill[r] += 1;
                        ordinal += 1;
                    }
                }
            }
        }
        c.force.clear();
        c.force.resize(total as usize, [V3::zeros(); 2]);
        self.index_shaped(n);
    }

    /// Derives the per-body incidence of the shaped pairs and walls.
    fn index_shaped(&mut self, n: usize) {
        let inc = &mut self.shaped_incidence;
        inc.pair_start.clear();
        inc.pair_entries.clear();
        inc.wall_start.clear();
        inc.mesh_groups.clear();
        inc.mesh_group_start.clear();
        if self.shaped_pairs.is_empty()
            && self.shaped_walls.is_empty()
            && self.shaped_mesh.is_empty()
        {
            return;
        }
        let mut count = vec![0u32; n + 1];
        for &[i, j] in &self.shaped_pairs {
            count[i as usize + 1] += 1;
            count[j as usize + 1] += 1;
        }
        for k in 0..n {
            count[k + 1] += count[k];
        }
        inc.pair_start.clone_from(&count);
        inc.pair_entries.resize(count[n] as usize, 0);
        // pairs in list order: each body's entries come out ascending
        for (k, &[i, j]) in self.shaped_pairs.iter().enumerate() {
            for (body, side) in [(i, 0), (j, 1)] {
                let at = &mut count[body as usize];
                inc.pair_entries[*at as usize] = 2 * k as u32 + side;
                *at += 1;
            }
        }
        inc.wall_start.resize(n + 1, 0);
        for &[b, _] in &self.shaped_walls {
            inc.wall_start[b as usize + 1] += 1;
        }
        for k in 0..n {
            inc.wall_start[k + 1] += inc.wall_start[k];
        }
        inc.mesh_group_start.resize(n + 1, 0);
        for g in 0..self.shaped_mesh.len() {
            let (b, c) = self.shaped_mesh[g];
            let first = g == 0 || {
                let (pb, pc) = self.shaped_mesh[g - 1];
                (pb, pc.wall, pc.patch) != (b, c.wall, c.patch)
            };
            if first {
                inc.mesh_groups.push(g as u32);
                inc.mesh_group_start[b as usize + 1] += 1;
            }
        }
        inc.mesh_groups.push(self.shaped_mesh.len() as u32);
        for k in 0..n {
            inc.mesh_group_start[k + 1] += inc.mesh_group_start[k];
        }
    }

    /// True if the stored lists index `n` particles consistently (checked on restore).
    pub fn consistent(&self, n: usize) -> bool {
        if !self.valid {
            return true;
        }
        let csr = |start: &[u32], len: usize| {
            start.len() == n + 1
                && start[0] == 0
                && start.windows(2).all(|w| w[0] <= w[1])
                && start[n] as usize == len
        };
        csr(&self.first_pair, self.partner.len())
            && self.shear.len() == self.partner.len()
            && (0..n).all(|i| {
                self.partner[self.first_pair[i] as usize..self.first_pair[i + 1] as usize]
                    .iter()
                    .all(|&j| j as usize > i && (j as usize) < n)
            })
            && csr(&self.wall_start, self.walls.len())
            && self.wall_contacts.len() == self.walls.len()
            && self.position_at_build.len() == n
            && self.shaped_pair_contacts.len() == self.shaped_pairs.len()
            && self.shaped_wall_contacts.len() == self.shaped_walls.len()
            && self
                .shaped_pairs
                .iter()
                .all(|&[i, j]| i < j && (j as usize) < n)
            && self.shaped_walls.windows(2).all(|w| w[0] < w[1])
            && self.shaped_walls.iter().all(|&[b, _]| (b as usize) < n)
            && self.shaped_mesh_contacts.len() == self.shaped_mesh.len()
            && self.shaped_mesh.windows(2).all(|w| w[0] <= w[1])
            && self.shaped_mesh.iter().all(|&(b, _)| (b as usize) < n)
            && (self.shaped_pair_image.is_empty()
                || self.shaped_pair_image.len() == self.shaped_pairs.len())
            && self
                .periodic_pairs
                .iter()
                .all(|p| p.pair[0] < p.pair[1] && (p.pair[1] as usize) < n)
    }
}

struct Grid {
    origin: V3,
    h: f64,
    dims: [usize; 3],
}

impl Grid {
    fn new(positions: &[V3], cutoff: f64) -> Grid {
        let mut lo = V3::repeat(f64::INFINITY);
        let mut hi = V3::repeat(f64::NEG_INFINITY);
        for x in positions {
            lo = lo.inf(x);
            hi = hi.sup(x);
        }
        if positions.is_empty() {
            lo = V3::zeros();
            hi = V3::zeros();
        }
        let ext = hi - lo;
        let mut h = cutoff.max(1e-12);
        // keep the number of cells bounded (sparse clouds, escaped particles)
        let max_cells = (8 * positions.len()).max(64) as f64;
        loop {
            let cells: f64 = (0..3).map(|a| (ext[a] / h).floor() + 1.0).product();
            if cells <= max_cells {
                break;
            }
            h *= 1.5;
        }
        let dims = [0, 1, 2].map(|a| ((ext[a] / h).floor() as usize) + 1);
        Grid {
            origin: lo,
            h,
            dims,
        }
    }

    #[inline]
    fn coord(&self, x: &V3) -> [usize; 3] {
        // `as usize` truncates, which is the floor for the non-negative values it sees
        [0, 1, 2].map(|a| {
            let c = (x[a] - self.origin[a]) / self.h;
            (c.max(0.0) as usize).min(self.dims[a] - 1)
        })
    }

    #[inline]
    fn index(&self, c: [usize; 3]) -> usize {
        (c[2] * self.dims[1] + c[1]) * self.dims[0] + c[0]
    }

    fn num_cells(&self) -> usize {
        self.dims[0] * self.dims[1] * self.dims[2]
    }

    /// Sort key of a cell: its Morton code, or the row-major index for grids too long for
    /// 21 bits per axis.
    #[inline]
    fn order_key(&self, c: [usize; 3]) -> u64 {
        if self.dims.iter().all(|&d| d <= 1 << 21) {
            spread_bits(c[0] as u64) | spread_bits(c[1] as u64) << 1 | spread_bits(c[2] as u64) << 2
        } else {
            self.index(c) as u64
        }
    }
}

/// Spreads the low 21 bits of x to every third bit (Morton encoding).
#[inline]
fn spread_bits(x: u64) -> u64 {
    let mut x = x & 0x1f_ffff;
    x = (x | x << 32) & 0x001f_0000_0000_ffff;
    x = (x | x << 16) & 0x001f_0000_ff00_00ff;
    x = (x | x << 8) & 0x100f_00f0_0f00_f00f;
    x = (x | x << 4) & 0x10c3_0c30_c30c_30c3;
    x = (x | x << 2) & 0x1249_2492_4924_9249;
    x
}

/// True when the lists must be rebuilt: invalid, another particle count, or a coupled-mesh
/// node moved more than d_V/2 since the last build (4.10). Particle displacements are checked
/// by the drift (`integrate::kick_drift`), see [`particles_moved`] otherwise.
/// With a periodic cell of edges `cell`, also when they changed by [`CELL_MARGIN`] d_V since.
pub fn needs_rebuild(
    lists: &NeighbourLists,
    particles: &Particles,
    meshes: &[Mesh],
    cell: Option<V3>,
) -> bool {
    !lists.valid
        || lists.position_at_build.len() != particles.len()
        || meshes
            .iter()
            .any(|m| m.coupled && m.max_displacement_since_build() > 0.5 * lists.skin)
        || match (cell, lists.cell_at_build) {
            (None, None) => false,
            (Some(l), Some(l0)) => (l - l0).norm() > CELL_MARGIN * lists.skin,
            _ => true,
        }
}

/// True when some particle moved more than d_V/2 since the last build (Wellmann, B4).
pub fn particles_moved(lists: &NeighbourLists, particles: &Particles) -> bool {
    if lists.position_at_build.len() != particles.len() {
        return true;
    }
    let half2 = (0.5 * lists.skin).powi(2);
    particles
        .position
        .par_iter()
        .with_min_len(4096)
        .zip(lists.position_at_build.par_iter())
        .any(|(x, x0)| (x - x0).norm_squared() > half2)
}

/// Rebuilds the lists. Sorts the particles along the Morton curve of their cells first
/// (`particles` are permuted: new index k holds old particle `perm[k]`); tangential histories of
/// pairs and wall contacts are carried over.
///
/// With a periodic cell of edges `cell` (Wellmann §5.1.1), the centres that left [0, L) are
/// put back on the opposite side first, and the pairs across the faces are found from the
/// ghosts of the 13 shifts N⁺ ([`HALF_SHIFTS`]); the cell must be at least twice the reach of
/// a pair in every direction (one image per pair, checked by the engine).
pub fn rebuild(
    lists: &mut NeighbourLists,
    particles: &mut Particles,
    planes: &[Plane],
    meshes: &mut [Mesh],
    sinks: &[CentreBox],
    cell: Option<V3>,
) -> Removed {
    if let Some(l) = cell {
        for x in &mut particles.position {
            for a in 0..3 {
                if !(0.0..l[a]).contains(&x[a]) {
                    x[a] -= (x[a] / l[a]).floor() * l[a];
                    if x[a] >= l[a] {
                        x[a] = 0.0; // round-off of a centre just below 0
                    }
                }
            }
        }
    }
    let r_max = particles.radius.iter().cloned().fold(0.0, f64::max);
    // a pair across a periodic cell's faces is listed within a longer reach (the edges may
    // change by CELL_MARGIN d_V before the next build): the cells hold that reach, so that
    // the ghosts' search over the neighbouring cells misses none
    let cutoff = 2.0 * r_max
        + lists.skin
            * if cell.is_some() {
                1.0 + CELL_MARGIN
            } else {
                1.0
            };
    let grid = Grid::new(&particles.position, cutoff);

    // Morton order of the cells; ties (same cell) keep their current order
    let mut keys: Vec<(u64, u32)> = particles
        .position
        .par_iter()
        .enumerate()
        .map(|(k, x)| (grid.order_key(grid.coord(x)), k as u32))
        .collect();
    keys.par_sort_unstable();
    // particles in a sink leave here: the permutation skips them
    let mut removed = Removed::default();
    let perm: Vec<u32> = keys
        .iter()
        .map(|&(_, k)| k)
        .filter(|&k| {
            let x = &particles.position[k as usize];
            let gone = sinks.iter().any(|s| s.contains([x.x, x.y, x.z]));
            if gone {
                removed.count += 1;
                removed.mass += particles.mass[k as usize];
            }
            !gone
        })
        .collect();
    drop(keys);
    let mut inverse = vec![u32::MAX; particles.len()];
    for (new, &old) in perm.iter().enumerate() {
        inverse[old as usize] = new as u32;
    }
    particles.permute(&perm);
    let n = particles.len();

    // cell table: particles of a cell are contiguous after the sort
    let nc = grid.num_cells();
    let mut cell_start = vec![0u32; nc];
    let mut cell_end = vec![0u32; nc];
    for (k, x) in particles.position.iter().enumerate() {
        let c = grid.index(grid.coord(x));
        if cell_end[c] != k as u32 || cell_start[c] == cell_end[c] {
            cell_start[c] = k as u32;
        }
        cell_end[c] = k as u32 + 1;
    }

    // old shaped contacts in new numbering (a swapped pair is seen from the other body)
    let mut old_shaped: Vec<([u32; 2], ShapedContact)> = Vec::new();
    for (&[i, j], c) in lists.shaped_pairs.iter().zip(&lists.shaped_pair_contacts) {
        let (Some(&a), Some(&b)) = (inverse.get(i as usize), inverse.get(j as usize)) else {
            continue;
        };
        if a == u32::MAX || b == u32::MAX || c.normal == V3::zeros() {
            continue;
        }
        old_shaped.push(if a < b {
            ([a, b], *c)
        } else {
            ([b, a], c.swapped())
        });
    }
    old_shaped.sort_unstable_by_key(|e| e.0);
    let mut old_shaped_walls: Vec<([u32; 2], ShapedContact)> = Vec::new();
    for (&[b, w], c) in lists.shaped_walls.iter().zip(&lists.shaped_wall_contacts) {
        match inverse.get(b as usize) {
            Some(&nb) if nb != u32::MAX && c.normal != V3::zeros() => {
                old_shaped_walls.push(([nb, w], *c))
            }
            _ => {}
        }
    }
    old_shaped_walls.sort_unstable_by_key(|e| e.0);
    let mut old_shaped_mesh: Vec<([u32; 3], ShapedContact)> = Vec::new();
    for (&(b, w), c) in lists.shaped_mesh.iter().zip(&lists.shaped_mesh_contacts) {
        match inverse.get(b as usize) {
            Some(&nb) if nb != u32::MAX && c.normal != V3::zeros() => {
                old_shaped_mesh.push(([nb, w.wall, w.patch], *c))
            }
            _ => {}
        }
    }
    old_shaped_mesh.sort_unstable_by_key(|e| e.0);

    // old histories in new numbering, sorted for the merges below
    let mut old_pairs: Vec<(u32, u32, V3)> = Vec::new();
    if lists.first_pair.len() >= 2 {
        let n_old = lists.first_pair.len() - 1;
        for i in 0..n_old {
            for k in lists.first_pair[i] as usize..lists.first_pair[i + 1] as usize {
                let (j, s) = (lists.partner[k] as usize, lists.shear[k]);
                if s == V3::zeros() || i >= inverse.len() || j >= inverse.len() {
                    continue;
                }
                let (a, b) = (inverse[i], inverse[j]);
                if a == u32::MAX || b == u32::MAX {
                    continue; // removed by a sink
                }
                // ξ is the displacement of the first particle relative to the second: it
                // changes sign when the reordering swaps the pair
                old_pairs.push(if a < b { (a, b, s) } else { (b, a, -s) });
            }
        }
    }
    for pp in &lists.periodic_pairs {
        let (i, j) = (pp.pair[0] as usize, pp.pair[1] as usize);
        if pp.shear == V3::zeros() || i >= inverse.len() || j >= inverse.len() {
            continue;
        }
        let (a, b) = (inverse[i], inverse[j]);
        if a != u32::MAX && b != u32::MAX {
            old_pairs.push(if a < b {
                (a, b, pp.shear)
            } else {
                (b, a, -pp.shear)
            });
        }
    }
    old_pairs.sort_unstable_by_key(|&(a, b, _)| (a, b));
    let mut old_walls: Vec<(u32, u32, u32, V3)> = Vec::new();
    if lists.wall_start.len() >= 2 {
        let n_old = lists.wall_start.len() - 1;
        for (i, &new) in inverse.iter().enumerate().take(n_old) {
            if new == u32::MAX {
                continue; // removed by a sink
            }
            for k in lists.wall_start[i] as usize..lists.wall_start[i + 1] as usize {
                let c = &lists.wall_contacts[k];
                if c.touching() {
                    let w = &lists.walls[k];
                    old_walls.push((new, w.wall, w.patch, c.shear));
                }
            }
        }
    }
    old_walls.sort_unstable_by_key(|&(a, w, p, _)| (a, w, p));

    // pairs, in fixed chunks (deterministic for any thread count)
    let pos = &particles.position;
    let rad = &particles.radius;
    let skin = lists.skin;
    // row-major index offsets of the 27 cells around a cell not on the grid boundary
    let (dx, dxy) = (
        grid.dims[0] as isize,
        (grid.dims[0] * grid.dims[1]) as isize,
    );
    let mut stencil = [0isize; 27];
    for (s, o) in stencil.iter_mut().enumerate() {
        let (ox, oy, oz) = (
            (s % 3) as isize - 1,
            ((s / 3) % 3) as isize - 1,
            (s / 9) as isize - 1,
        );
        *o = oz * dxy + oy * dx + ox;
    }
    let shape = &particles.shape;
    let shaped_any = particles.has_shapes();
    #[allow(clippy::type_complexity)] // (counts, partners, shaped pairs) of one block
    let chunks: Vec<(Vec<u32>, Vec<u32>, Vec<[u32; 2]>)> = (0..n.div_ceil(BLOCK))
        .into_par_iter()
        .map(|b| {
            let range = b * BLOCK..((b + 1) * BLOCK).min(n);
            let mut counts = Vec::with_capacity(range.len());
            let mut out = Vec::with_capacity(8 * range.len());
            let mut shaped = Vec::new();
            let mut cells = [0usize; 27];
            for i in range {
                let xi = pos[i];
                let c = grid.coord(&xi);
                let interior = (0..3).all(|a| c[a] >= 1 && c[a] + 1 < grid.dims[a]);
                let nc = if interior {
                    let ci = grid.index(c) as isize;
                    for (cell, o) in cells.iter_mut().zip(&stencil) {
                        *cell = (ci + o) as usize;
                    }
                    27
                } else {
                    let mut m = 0;
                    for dz in -1i64..=1 {
                        for dy in -1i64..=1 {
                            for dx in -1i64..=1 {
                                let cc = [c[0] as i64 + dx, c[1] as i64 + dy, c[2] as i64 + dz];
                                if (0..3).any(|a| cc[a] < 0 || cc[a] >= grid.dims[a] as i64) {
                                    continue;
                                }
                                cells[m] =
                                    grid.index([cc[0] as usize, cc[1] as usize, cc[2] as usize]);
                                m += 1;
                            }
                        }
                    }
                    m
                };
                let start = out.len();
                let (ri, first) = (rad[i], i as u32 + 1);
                for &ci in &cells[..nc] {
                    // only partners j > i
                    for j in cell_start[ci].max(first)..cell_end[ci] {
                        let j = j as usize;
                        let reach = ri + rad[j] + skin;
                        if (pos[j] - xi).norm_squared() < reach * reach {
                            // (3.47) for bounding spheres; a pair with a non-spherical body
                            // goes to the shaped bucket
                            if shaped_any && (shape[i] != SPHERE || shape[j] != SPHERE) {
                                shaped.push([i as u32, j as u32]);
                            } else {
                                out.push(j as u32);
                            }
                        }
                    }
                }
                out[start..].sort_unstable();
                counts.push((out.len() - start) as u32);
            }
            (counts, out, shaped)
        })
        .collect();
    let total: usize = chunks.iter().map(|c| c.1.len()).sum();
    // pairs across the faces of a periodic cell: (a < b, image of b), spheres and shaped
    let (periodic, shaped_periodic) = match cell {
        Some(l) => ghost_pairs(&grid, &cell_start, &cell_end, particles, skin, l),
        None => (Vec::new(), Vec::new()),
    };
    let mut shaped: Vec<([u32; 2], [i8; 3])> = chunks
        .iter()
        .flat_map(|c| c.2.iter().map(|&p| (p, [0i8; 3])))
        .chain(shaped_periodic)
        .collect();
    shaped.sort_unstable();
    lists.shaped_pairs.clear();
    lists.shaped_pairs.extend(shaped.iter().map(|e| e.0));
    lists.shaped_pair_image.clear();
    if cell.is_some() {
        lists.shaped_pair_image.extend(shaped.iter().map(|e| e.1));
    }
    lists.periodic_pairs.clear();
    lists
        .periodic_pairs
        .extend(periodic.into_iter().map(|(pair, image)| {
            PeriodicPair {
                pair,
                image,
                shear: old_pairs
                    .binary_search_by_key(&(pair[0], pair[1]), |&(a, b, _)| (a, b))
                    .map_or(V3::zeros(), |k| old_pairs[k].2),
                force: V3::zeros(),
                overlap: -1.0,
                torques: [V3::zeros(); 2],
            }
        }));
    lists.cell_at_build = cell;
    lists.shaped_pair_contacts.clear();
    lists
        .shaped_pair_contacts
        .extend(lists.shaped_pairs.iter().map(|key| {
            old_shaped
                .binary_search_by_key(key, |e| e.0)
                .map_or(ShapedContact::NONE, |k| old_shaped[k].1)
        }));
    lists.first_pair.clear();
    lists.first_pair.reserve(n + 1);
    lists.partner.clear();
    lists.partner.reserve(total);
    lists.first_pair.push(0);
    for (counts, js, _) in chunks {
        let mut at = lists.partner.len() as u32;
        for c in counts {
            at += c;
            lists.first_pair.push(at);
        }
        lists.partner.extend_from_slice(&js);
    }
    lists.shear.clear();
    lists.shear.resize(total, V3::zeros());
    let mut oi = 0usize;
    for i in 0..n {
        for k in lists.first_pair[i] as usize..lists.first_pair[i + 1] as usize {
            let key = (i as u32, lists.partner[k]);
            while oi < old_pairs.len() && (old_pairs[oi].0, old_pairs[oi].1) < key {
                oi += 1;
            }
            if oi < old_pairs.len() && (old_pairs[oi].0, old_pairs[oi].1) == key {
                lists.shear[k] = old_pairs[oi].2;
            }
        }
    }

    // particle–wall candidates (4.9): planes, then mesh triangles
    let n_planes = planes.len() as u32;
    let mut cands: Vec<(u32, WallCandidate)> = if planes.is_empty() {
        Vec::new()
    } else {
        (0..n)
            .into_par_iter()
            .with_min_len(BLOCK)
            .flat_map_iter(|k| {
                planes.iter().enumerate().filter_map(move |(w, pl)| {
                    let d = (pos[k] - pl.point).dot(&pl.normal);
                    // shaped bodies' plane candidates are listed below
                    (pl.active && d < rad[k] + skin && shape[k] == SPHERE).then_some((
                        k as u32,
                        WallCandidate {
                            wall: w as u32,
                            patch: 0,
                            triangle: 0,
                        },
                    ))
                })
            })
            .collect()
    };
    lists.shaped_walls.clear();
    if shaped_any {
        for k in 0..n {
            if shape[k] == SPHERE {
                continue;
            }
            for (w, pl) in planes.iter().enumerate() {
                let d = (pos[k] - pl.point).dot(&pl.normal);
                if pl.active && d < rad[k] + skin {
                    lists.shaped_walls.push([k as u32, w as u32]);
                }
            }
        }
    }
    lists.shaped_wall_contacts.clear();
    lists
        .shaped_wall_contacts
        .extend(lists.shaped_walls.iter().map(|key| {
            old_shaped_walls
                .binary_search_by_key(key, |e| e.0)
                .map_or(ShapedContact::NONE, |k| old_shaped_walls[k].1)
        }));
    for (m, mesh) in meshes.iter_mut().enumerate() {
        if !mesh.active {
            mesh.positions_at_build.clone_from(&mesh.positions);
            continue;
        }
        let found: Vec<Vec<(u32, WallCandidate)>> = (0..mesh.triangles.len())
            .into_par_iter()
            .map(|t| {
                let [a, b, c] = mesh.corners(t);
                let reach = r_max + skin;
                let lo = a.inf(&b).inf(&c) - V3::repeat(reach);
                let hi = a.sup(&b).sup(&c) + V3::repeat(reach);
                let mut out = Vec::new();
                if n == 0 {
                    return out;
                }
                // skip triangles entirely outside the particle bounding box
                let gmax = grid.origin
                    + V3::repeat(grid.h).component_mul(&V3::new(
                        grid.dims[0] as f64,
                        grid.dims[1] as f64,
                        grid.dims[2] as f64,
                    ));
                if (0..3).any(|ax| hi[ax] < grid.origin[ax] || lo[ax] > gmax[ax]) {
                    return out;
                }
                let (clo, chi) = (grid.coord(&lo), grid.coord(&hi));
                for z in clo[2]..=chi[2] {
                    for y in clo[1]..=chi[1] {
                        for x in clo[0]..=chi[0] {
                            let ci = grid.index([x, y, z]);
                            for k in cell_start[ci]..cell_end[ci] {
                                let k = k as usize;
                                let rr = rad[k] + skin;
                                if distance_squared(&pos[k], &a, &b, &c) <= rr * rr {
                                    out.push((
                                        k as u32,
                                        WallCandidate {
                                            wall: n_planes + m as u32,
                                            patch: mesh.patch[t],
                                            triangle: t as u32,
                                        },
                                    ));
                                }
                            }
                        }
                    }
                }
                out
            })
            .collect();
        cands.extend(found.into_iter().flatten());
        mesh.positions_at_build.clone_from(&mesh.positions);
    }
    cands.par_sort_unstable();
    // triangle candidates of shaped bodies go to their own bucket, grouped by (body, wall,
    // patch) as the spheres' are; their contact state lives at a group's first candidate
    lists.shaped_mesh.clear();
    if shaped_any {
        lists
            .shaped_mesh
            .extend(cands.iter().filter(|(k, _)| shape[*k as usize] != SPHERE));
        cands.retain(|(k, _)| shape[*k as usize] == SPHERE);
    }
    lists.shaped_mesh_contacts.clear();
    lists
        .shaped_mesh_contacts
        .resize(lists.shaped_mesh.len(), ShapedContact::NONE);
    lists.shaped_mesh_records.clear();
    lists
        .shaped_mesh_records
        .resize(lists.shaped_mesh.len(), Default::default());
    for g in 0..lists.shaped_mesh.len() {
        let (b, c) = lists.shaped_mesh[g];
        if g > 0 && {
            let (pb, pc) = lists.shaped_mesh[g - 1];
            (pb, pc.wall, pc.patch) == (b, c.wall, c.patch)
        } {
            continue;
        }
        let key = [b, c.wall, c.patch];
        if let Ok(k) = old_shaped_mesh.binary_search_by_key(&key, |e| e.0) {
            lists.shaped_mesh_contacts[g] = old_shaped_mesh[k].1;
        }
    }
    lists.wall_start.clear();
    lists.wall_start.resize(n + 1, 0);
    for (k, _) in &cands {
        lists.wall_start[*k as usize + 1] += 1;
    }
    for k in 0..n {
        lists.wall_start[k + 1] += lists.wall_start[k];
    }
    lists.walls.clear();
    lists.walls.extend(cands.iter().map(|&(_, c)| c));
    lists.wall_contacts.clear();
    lists
        .wall_contacts
        .resize(lists.walls.len(), WallContact::NONE);
    // a history lives at the first candidate of its (wall, patch) group
    let mut oi = 0usize;
    for (k, &(p, c)) in cands.iter().enumerate() {
        let first = k == 0 || cands[k - 1].0 != p || {
            let prev = cands[k - 1].1;
            (prev.wall, prev.patch) != (c.wall, c.patch)
        };
        if !first {
            continue;
        }
        let key = (p, c.wall, c.patch);
        while oi < old_walls.len() && (old_walls[oi].0, old_walls[oi].1, old_walls[oi].2) < key {
            oi += 1;
        }
        if oi < old_walls.len() && (old_walls[oi].0, old_walls[oi].1, old_walls[oi].2) == key {
            // carried history of a contact that existed in the last evaluation
            lists.wall_contacts[k] = WallContact {
                shear: old_walls[oi].3,
                overlap: 0.0,
            };
        }
    }

    lists.position_at_build.clone_from(&particles.position);
    lists.builds += 1;
    lists.valid = true;
    lists.index_blocks();
    removed
}

/// The pairs across the faces of a periodic cell of edges `l`: for each particle j and shift
/// n ∈ N⁺ whose ghost x_j + n∘L lies within a reach of the cell, the particles i near the
/// ghost (W 5.2). Each is returned as (a < b, image of b): (i, j, n) or (j, i, −n). Spheres
/// first, then pairs with a non-spherical body; both sorted.
#[allow(clippy::type_complexity)] // two lists of (pair, image)
fn ghost_pairs(
    grid: &Grid,
    cell_start: &[u32],
    cell_end: &[u32],
    particles: &Particles,
    skin: f64,
    l: V3,
) -> (Vec<([u32; 2], [i8; 3])>, Vec<([u32; 2], [i8; 3])>) {
    let (pos, rad, shape) = (&particles.position, &particles.radius, &particles.shape);
    let r_max = rad.iter().cloned().fold(0.0, f64::max);
    let margin = CELL_MARGIN * skin;
    let reach_max = 2.0 * r_max + skin + margin;
    let found: Vec<([u32; 2], [i8; 3])> = (0..pos.len())
        .into_par_iter()
        .with_min_len(BLOCK)
        .flat_map_iter(|j| {
            let mut out = Vec::new();
            for n in HALF_SHIFTS {
                let g = pos[j] + image_shift(&l, n);
                if (0..3).any(|a| g[a] < -reach_max || g[a] > l[a] + reach_max) {
                    continue;
                }
                // a ghost outside the grid maps to its edge cells (the clamped coordinate),
                // which still hold every particle within one cell of it
                let c = grid.coord(&g);
                let range = |a: usize| c[a].saturating_sub(1)..=(c[a] + 1).min(grid.dims[a] - 1);
                for z in range(2) {
                    for y in range(1) {
                        for x in range(0) {
                            let ci = grid.index([x, y, z]);
                            for i in cell_start[ci]..cell_end[ci] {
                                let i = i as usize;
                                if i == j {
                                    continue;
                                }
                                let reach = rad[i] + rad[j] + skin + margin;
                                if (pos[i] - g).norm_squared() < reach * reach {
                                    out.push(if i < j {
                                        ([i as u32, j as u32], n)
                                    } else {
                                        ([j as u32, i as u32], n.map(|v| -v))
                                    });
                                }
                            }
                        }
                    }
                }
            }
            out
        })
        .collect();
    let (mut spheres, mut shaped): (Vec<_>, Vec<_>) = found
        .into_iter()
        .partition(|(p, _)| shape[p[0] as usize] == SPHERE && shape[p[1] as usize] == SPHERE);
    spheres.par_sort_unstable();
    shaped.par_sort_unstable();
    (spheres, shaped)
}

/// Particles a list build removed because their centre lay in a sink.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Removed {
    pub count: u64,
    pub mass: f64,
}
