//! Broad phase: cell grid + Verlet skin (Wellmann ch. 3.4.1, REFERENCE B4).
//!
//! Each build sorts the particles by grid cell (better locality, and the band structure of the
//! pair list Wellmann exploits in ch. 3.4.3), then lists every particle pair (i < j) closer than
//! r_i + r_j + d_V (eq. 3.47) and every particle–triangle pair closer than r + d_V (eq. 4.9).
//! The lists stay valid until a particle or mesh node has moved d_V/2 (eq. 4.10). Lists are in
//! a stable order (sorted by index), so results do not depend on the thread count.

use crate::hertz_mindlin::V3;
use crate::particles::Particles;
use crate::triangle_contact::distance_squared;
use crate::walls::Mesh;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// One neighbour pair with its tangential history and the forces of the last evaluation.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct Pair {
    pub i: u32,
    pub j: u32,
    /// Tangential spring displacement ξ (zero when not in contact).
    pub shear: V3,
    /// Force on i (j receives −force), torques on i and j.
    pub force: V3,
    pub torque_i: V3,
    pub torque_j: V3,
    /// Overlap δ (≤ 0 when not touching).
    pub overlap: f64,
}

/// A particle–triangle candidate.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq, PartialOrd, Ord)]
pub struct TriangleCandidate {
    pub mesh: u32,
    pub patch: u32,
    pub triangle: u32,
}

#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct NeighbourLists {
    pub skin: f64,
    /// Pairs sorted by (i, j), i < j.
    pub pairs: Vec<Pair>,
    /// Pairs with first index i are `pairs[first_pair[i]..first_pair[i+1]]`.
    pub first_pair: Vec<u32>,
    /// CSR of the pairs in which a particle is the second index.
    pub as_j_start: Vec<u32>,
    pub as_j: Vec<u32>,
    /// CSR of triangle candidates per particle, sorted by (mesh, patch, triangle).
    pub tri_start: Vec<u32>,
    pub tri: Vec<TriangleCandidate>,
    pub position_at_build: Vec<V3>,
    pub builds: u64,
    pub valid: bool,
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
        [0, 1, 2].map(|a| {
            let c = ((x[a] - self.origin[a]) / self.h).floor();
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
}

/// True when some particle moved more than d_V/2 since the last build (Wellmann, B4).
pub fn needs_rebuild(lists: &NeighbourLists, particles: &Particles, meshes: &[Mesh]) -> bool {
    if !lists.valid || lists.position_at_build.len() != particles.len() {
        return true;
    }
    let half2 = (0.5 * lists.skin).powi(2);
    let moved = particles
        .position
        .par_iter()
        .with_min_len(4096)
        .zip(lists.position_at_build.par_iter())
        .any(|(x, x0)| (x - x0).norm_squared() > half2);
    // (4.10): the triangles' motion is bounded by their nodes' motion
    moved
        || meshes
            .iter()
            .any(|m| m.coupled && m.max_displacement_since_build() > 0.5 * lists.skin)
}

/// Rebuilds the lists. Sorts the particles by cell first and returns the permutation applied
/// (new index k holds old particle perm[k]) so the caller can move per-particle state along;
/// pair histories are carried over here.
pub fn rebuild(
    lists: &mut NeighbourLists,
    particles: &mut Particles,
    meshes: &mut [Mesh],
) -> Vec<u32> {
    let n = particles.len();
    let r_max = particles.radius.iter().cloned().fold(0.0, f64::max);
    let cutoff = 2.0 * r_max + lists.skin;
    let grid = Grid::new(&particles.position, cutoff);

    // counting sort by cell (stable: ties keep their current order)
    let cell_of: Vec<u32> = particles
        .position
        .iter()
        .map(|x| grid.index(grid.coord(x)) as u32)
        .collect();
    let nc = grid.num_cells();
    let mut cell_start = vec![0u32; nc + 1];
    for &c in &cell_of {
        cell_start[c as usize + 1] += 1;
    }
    for c in 0..nc {
        cell_start[c + 1] += cell_start[c];
    }
    let mut fill = cell_start.clone();
    let mut perm = vec![0u32; n];
    for (k, &c) in cell_of.iter().enumerate() {
        perm[fill[c as usize] as usize] = k as u32;
        fill[c as usize] += 1;
    }
    let mut inverse = vec![0u32; n];
    for (new, &old) in perm.iter().enumerate() {
        inverse[old as usize] = new as u32;
    }
    particles.permute(&perm);

    // old histories in new numbering, sorted for the merge below
    let mut old: Vec<(u32, u32, V3)> = lists
        .pairs
        .iter()
        .filter(|p| p.shear != V3::zeros() && (p.i as usize) < n && (p.j as usize) < n)
        .map(|p| {
            let (a, b) = (inverse[p.i as usize], inverse[p.j as usize]);
            // ξ is the displacement of the first particle relative to the second: it changes
            // sign when the reordering swaps the pair
            if a < b {
                (a, b, p.shear)
            } else {
                (b, a, -p.shear)
            }
        })
        .collect();
    old.sort_unstable_by_key(|&(a, b, _)| (a, b));

    let pos = &particles.position;
    let rad = &particles.radius;
    let skin = lists.skin;
    let neighbours: Vec<Vec<u32>> = (0..n)
        .into_par_iter()
        .with_min_len(256)
        .map(|i| {
            let xi = pos[i];
            let c = grid.coord(&xi);
            let mut out = Vec::new();
            for dz in -1i64..=1 {
                for dy in -1i64..=1 {
                    for dx in -1i64..=1 {
                        let cc = [c[0] as i64 + dx, c[1] as i64 + dy, c[2] as i64 + dz];
                        if (0..3).any(|a| cc[a] < 0 || cc[a] >= grid.dims[a] as i64) {
                            continue;
                        }
                        let ci = grid.index([cc[0] as usize, cc[1] as usize, cc[2] as usize]);
                        for j in cell_start[ci]..cell_start[ci + 1] {
                            let j = j as usize;
                            if j <= i {
                                continue;
                            }
                            let reach = rad[i] + rad[j] + skin;
                            if (pos[j] - xi).norm_squared() < reach * reach {
                                out.push(j as u32);
                            }
                        }
                    }
                }
            }
            out.sort_unstable();
            out
        })
        .collect();

    let mut pairs = Vec::with_capacity(neighbours.iter().map(|v| v.len()).sum());
    let mut first_pair = Vec::with_capacity(n + 1);
    let mut oi = 0usize;
    for (i, list) in neighbours.iter().enumerate() {
        first_pair.push(pairs.len() as u32);
        for &j in list {
            let key = (i as u32, j);
            while oi < old.len() && (old[oi].0, old[oi].1) < key {
                oi += 1;
            }
            let shear = if oi < old.len() && (old[oi].0, old[oi].1) == key {
                old[oi].2
            } else {
                V3::zeros()
            };
            pairs.push(Pair {
                i: i as u32,
                j,
                shear,
                force: V3::zeros(),
                torque_i: V3::zeros(),
                torque_j: V3::zeros(),
                overlap: 0.0,
            });
        }
    }
    first_pair.push(pairs.len() as u32);

    let mut as_j_start = vec![0u32; n + 1];
    for p in &pairs {
        as_j_start[p.j as usize + 1] += 1;
    }
    for k in 0..n {
        as_j_start[k + 1] += as_j_start[k];
    }
    let mut as_j = vec![0u32; pairs.len()];
    let mut fillj = as_j_start.clone();
    for (k, p) in pairs.iter().enumerate() {
        as_j[fillj[p.j as usize] as usize] = k as u32;
        fillj[p.j as usize] += 1;
    }

    // particle–triangle candidates (4.9)
    let mut cands: Vec<(u32, TriangleCandidate)> = Vec::new();
    for (m, mesh) in meshes.iter_mut().enumerate() {
        let found: Vec<Vec<(u32, TriangleCandidate)>> = (0..mesh.triangles.len())
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
                let (clo, chi) = (grid.coord(&lo), grid.coord(&hi));
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
                for z in clo[2]..=chi[2] {
                    for y in clo[1]..=chi[1] {
                        for x in clo[0]..=chi[0] {
                            let ci = grid.index([x, y, z]);
                            for k in cell_start[ci]..cell_start[ci + 1] {
                                let k = k as usize;
                                let rr = rad[k] + skin;
                                if distance_squared(&pos[k], &a, &b, &c) <= rr * rr {
                                    out.push((
                                        k as u32,
                                        TriangleCandidate {
                                            mesh: m as u32,
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
    cands.sort_unstable();
    let mut tri_start = vec![0u32; n + 1];
    for (k, _) in &cands {
        tri_start[*k as usize + 1] += 1;
    }
    for k in 0..n {
        tri_start[k + 1] += tri_start[k];
    }
    lists.tri = cands.into_iter().map(|(_, c)| c).collect();
    lists.tri_start = tri_start;
    lists.pairs = pairs;
    lists.first_pair = first_pair;
    lists.as_j_start = as_j_start;
    lists.as_j = as_j;
    lists.position_at_build.clone_from(&particles.position);
    lists.builds += 1;
    lists.valid = true;
    perm
}
