//! Arlequin volume coupling of the particles with a finite element continuum (Wellmann ch. 6).
//!
//! In the overlap Ω^C, a set of FE elements the FE side declares with nodal weights w_I, both
//! models exist and share the virtual work: the particles' equations are weighted by
//! w(x) = Σ N_I(x) w_I (6.27) — each contact force at its contact point (6.29), the mass and
//! inertia at the centre (6.10)–(6.11) — the FE integrals by 1 − w. The two displacement
//! fields are tied by an L² penalty on the coarse part of the particle displacements: their
//! projection onto the FE ansatz of the coupling nodes, lumped (6.22) or consistent (6.20),
//!
//!   u^DE = Π u_d,  C = (ε/2) ∫_{Ω^C} ‖u^DE − u^FE‖² dv                          (6.23)
//!   f_I^C = ε Σ_J V_IJ (u_J^DE − u_J^FE) on the FE nodes,  V_IJ = ∫ N_I N_J dv    (6.25)
//!   f_α^C = −Σ_I Π_Iα f_I^C on the particles (at the centre, no torque)           (6.26)
//!
//! All of it is built once in the reference configuration (§6.3: small relative displacements
//! of particles and continuum); [`VolumeCoupling::drift`] measures how far a particle has left
//! the element it was located in, so that a run can refuse to go on when the assumption breaks.
//!
//! Departure from the thesis: the lumped projection reproduces constant fields exactly but an
//! affine field only up to the particle distribution's asymmetry about each node (exactly at
//! none in general, to O(spacing / element) inside a homogeneous fill, worst at the overlap's
//! boundary nodes where N_I's support is cut); the consistent one reproduces affine fields
//! exactly (both measured in the tests below).

use crate::hertz_mindlin::V3;
use faer::linalg::solvers::Solve;
use faer::sparse::linalg::solvers::Llt;
use faer::sparse::{SparseColMat, Triplet};
use faer::Side;
use numeric::iso::{self, IsoShape};
use serde::{Deserialize, Serialize};

/// How the particle displacements are projected onto the coupling nodes (W §6.2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Projection {
    /// (6.21)–(6.22): row-sum lumped A, local (each node from the particles of its elements).
    #[default]
    Lumped,
    /// (6.20): Π = A⁻¹ N V with A = N V Nᵀ (a sparse Cholesky factor, solved each step).
    Consistent,
}

/// The overlap Ω^C as the FE side declares it: elements of one interpolation, their nodes in
/// the reference configuration and the nodal weights w_I (1 on the DE side, 0 on the FE side).
#[derive(Debug, Clone, PartialEq)]
pub struct OverlapMesh {
    pub shape: IsoShape,
    /// The FE side's ids of the nodes (for messages and errors).
    pub node_ids: Vec<u64>,
    pub nodes: Vec<V3>,
    /// `shape.num_nodes()` local node indices per element.
    pub elements: Vec<u32>,
    pub weights: Vec<f64>,
}

/// A particle offered to the coupling: its id, centre and volume.
#[derive(Debug, Clone, Copy)]
pub struct Candidate {
    pub id: u32,
    pub centre: V3,
    pub volume: f64,
}

#[derive(Debug, thiserror::Error)]
pub enum VolumeError {
    #[error("overlap mesh: {0}")]
    Mesh(String),
    #[error("overlap node {node}: {message}")]
    Node { node: u64, message: String },
    #[error("particle {particle}: {message}")]
    Particle { particle: u32, message: String },
}

/// The coupling operators of one overlap, built in the reference configuration.
#[derive(Debug)]
pub struct VolumeCoupling {
    mesh: OverlapMesh,
    nn: usize,
    projection: Projection,
    penalty: f64,
    /// Coupled particles (centre in an overlap element), in the order of the candidates.
    ids: Vec<u32>,
    element: Vec<u32>,
    /// N_I(c_α), `nn` per particle.
    values: Vec<f64>,
    weight: Vec<f64>,
    weight_gradient: Vec<V3>,
    volume: Vec<f64>,
    reference: Vec<V3>,
    /// A*_II = Σ_α N_Iα V_α (6.21).
    lumped: Vec<f64>,
    /// V_IJ (6.25), rows in CSR.
    v_start: Vec<u32>,
    v_col: Vec<u32>,
    v_val: Vec<f64>,
    /// The factor of A = N V Nᵀ for the consistent projection.
    llt: Option<Llt<u32, f64>>,
}

/// A uniform grid of the elements' bounding boxes, for locating points.
struct ElementGrid {
    lo: V3,
    cell: f64,
    dims: [usize; 3],
    start: Vec<u32>,
    items: Vec<u32>,
}

impl ElementGrid {
    fn new(mesh: &OverlapMesh, nn: usize) -> ElementGrid {
        let ne = mesh.elements.len() / nn;
        let boxes: Vec<(V3, V3)> = (0..ne)
            .map(|e| {
                let mut lo = V3::repeat(f64::INFINITY);
                let mut hi = V3::repeat(f64::NEG_INFINITY);
                for &a in &mesh.elements[e * nn..(e + 1) * nn] {
                    lo = lo.inf(&mesh.nodes[a as usize]);
                    hi = hi.sup(&mesh.nodes[a as usize]);
                }
                (lo, hi)
            })
            .collect();
        let mut lo = V3::repeat(f64::INFINITY);
        let mut hi = V3::repeat(f64::NEG_INFINITY);
        let mut cell = 0.0f64;
        for (a, b) in &boxes {
            lo = lo.inf(a);
            hi = hi.sup(b);
            cell = cell.max((b - a).max());
        }
        // cells no smaller than the largest element, and no more than ~8 per element
        let span = hi - lo;
        let per_element = (span.x.max(cell) * span.y.max(cell) * span.z.max(cell)
            / (8.0 * boxes.len() as f64))
            .cbrt();
        let cell = cell.max(per_element).max(f64::MIN_POSITIVE);
        let dims = [0, 1, 2].map(|k| ((hi[k] - lo[k]) / cell).floor() as usize + 1);
        let index = |c: [usize; 3]| (c[2] * dims[1] + c[1]) * dims[0] + c[0];
        let cell_of =
            |x: f64, k: usize| (((x - lo[k]) / cell).floor().max(0.0) as usize).min(dims[k] - 1);
        let mut lists = vec![Vec::new(); dims[0] * dims[1] * dims[2]];
        for (e, (a, b)) in boxes.iter().enumerate() {
            let (c0, c1) = (
                [0, 1, 2].map(|k| cell_of(a[k], k)),
                [0, 1, 2].map(|k| cell_of(b[k], k)),
            );
            for z in c0[2]..=c1[2] {
                for y in c0[1]..=c1[1] {
                    for x in c0[0]..=c1[0] {
                        lists[index([x, y, z])].push(e as u32);
                    }
                }
            }
        }
        let mut start = vec![0u32];
        let mut items = Vec::new();
        for l in lists {
            items.extend(l);
            start.push(items.len() as u32);
        }
        ElementGrid {
            lo,
            cell,
            dims,
            start,
            items,
        }
    }

    /// Elements whose box may contain `x` (none if `x` lies outside the grid).
    fn candidates(&self, x: V3) -> &[u32] {
        let mut c = [0usize; 3];
        for k in 0..3 {
            let f = ((x[k] - self.lo[k]) / self.cell).floor();
            // a point beyond the last cell (by round-off) is looked up there, like the boxes
            if !(f >= 0.0 && f <= self.dims[k] as f64) {
                return &[];
            }
            c[k] = (f as usize).min(self.dims[k] - 1);
        }
        let i = (c[2] * self.dims[1] + c[1]) * self.dims[0] + c[0];
        &self.items[self.start[i] as usize..self.start[i + 1] as usize]
    }
}

/// Tolerance in ξ for a point on an element's face.
const ON_FACE: f64 = 1e-9;

impl OverlapMesh {
    fn element_nodes(&self, e: usize, nn: usize) -> Vec<[f64; 3]> {
        self.elements[e * nn..(e + 1) * nn]
            .iter()
            .map(|&a| {
                let x = self.nodes[a as usize];
                [x.x, x.y, x.z]
            })
            .collect()
    }

    fn validate(&self) -> Result<usize, VolumeError> {
        let nn = self.shape.num_nodes();
        let n = self.nodes.len();
        if self.node_ids.len() != n || self.weights.len() != n {
            return Err(VolumeError::Mesh(format!(
                "{n} nodes but {} ids and {} weights",
                self.node_ids.len(),
                self.weights.len()
            )));
        }
        if self.elements.is_empty() || self.elements.len() % nn != 0 {
            return Err(VolumeError::Mesh(format!(
                "{} element node indices is not a positive multiple of {nn} ({:?})",
                self.elements.len(),
                self.shape
            )));
        }
        for (i, &a) in self.elements.iter().enumerate() {
            if a as usize >= n {
                return Err(VolumeError::Mesh(format!(
                    "element {} refers to node index {a} of {n}",
                    i / nn
                )));
            }
        }
        for (k, (x, &w)) in self.nodes.iter().zip(&self.weights).enumerate() {
            if !x.iter().all(|c| c.is_finite()) {
                return Err(VolumeError::Node {
                    node: self.node_ids[k],
                    message: format!("non-finite position {x:?}"),
                });
            }
            if !(0.0..=1.0).contains(&w) {
                return Err(VolumeError::Node {
                    node: self.node_ids[k],
                    message: format!("weight {w} is not in [0, 1]"),
                });
            }
        }
        Ok(nn)
    }
}

/// The Gauss rule for V_IJ = ∫ N_I N_J dv: the FE side's consistent-mass rule (PROTOCOL.md),
/// so that both sides hold the same V on any element, affine or not.
fn product_rule(shape: IsoShape) -> Vec<([f64; 3], f64)> {
    match shape {
        IsoShape::Tet4 => iso::tet_rule_4(),
        IsoShape::Tet10 => iso::tet_collapsed_rule(4),
        IsoShape::Hex8 => iso::hex_rule(3),
        IsoShape::Hex20 => iso::hex_rule(4),
    }
}

impl VolumeCoupling {
    /// Locates the candidates in the overlap's elements (bounding box, then the Newton solve
    /// (6.28); a centre on a shared face goes to the lower element index) and builds the
    /// coupling terms of §6.3: weights, N_Iα, the projection and V_IJ. Every node of the
    /// overlap needs a particle centre in one of its elements (the overlap must be filled
    /// with particles, §6.3); the error names the first node without one.
    pub fn new(
        mesh: OverlapMesh,
        candidates: &[Candidate],
        projection: Projection,
        penalty: f64,
    ) -> Result<VolumeCoupling, VolumeError> {
        let nn = mesh.validate()?;
        if !(penalty.is_finite() && penalty > 0.0) {
            return Err(VolumeError::Mesh(format!(
                "penalty {penalty} is not a positive number"
            )));
        }
        let ne = mesh.elements.len() / nn;
        let grid = ElementGrid::new(&mesh, nn);
        let element_nodes: Vec<Vec<[f64; 3]>> =
            (0..ne).map(|e| mesh.element_nodes(e, nn)).collect();
        let mut c = VolumeCoupling {
            nn,
            projection,
            penalty,
            ids: Vec::new(),
            element: Vec::new(),
            values: Vec::new(),
            weight: Vec::new(),
            weight_gradient: Vec::new(),
            volume: Vec::new(),
            reference: Vec::new(),
            lumped: vec![0.0; mesh.nodes.len()],
            v_start: Vec::new(),
            v_col: Vec::new(),
            v_val: Vec::new(),
            llt: None,
            mesh,
        };
        let mut n = vec![0.0; nn];
        let mut dn = vec![[0.0; 3]; nn];
        for cand in candidates {
            if !(cand.volume > 0.0 && cand.volume.is_finite()) {
                return Err(VolumeError::Particle {
                    particle: cand.id,
                    message: format!("volume {} is not positive", cand.volume),
                });
            }
            let p = [cand.centre.x, cand.centre.y, cand.centre.z];
            let found = grid.candidates(cand.centre).iter().copied().find_map(|e| {
                iso::locate(c.mesh.shape, &element_nodes[e as usize], p, ON_FACE)
                    .filter(|l| l.inside)
                    .map(|l| (e, l.xi))
            });
            let Some((e, xi)) = found else { continue };
            iso::shape(c.mesh.shape, xi, &mut n, &mut dn);
            let conn = &c.mesh.elements[e as usize * nn..(e as usize + 1) * nn];
            let x = &element_nodes[e as usize];
            let jac =
                nalgebra::Matrix3::from_fn(|i, k| (0..nn).map(|a| x[a][i] * dn[a][k]).sum::<f64>());
            let jinv_t = jac
                .try_inverse()
                .ok_or_else(|| VolumeError::Particle {
                    particle: cand.id,
                    message: format!("singular Jacobian of overlap element {e} at its centre"),
                })?
                .transpose();
            let mut w = 0.0;
            let mut grad = V3::zeros();
            for a in 0..nn {
                let wi = c.mesh.weights[conn[a] as usize];
                w += n[a] * wi;
                grad += jinv_t * V3::from(dn[a]) * wi;
                c.lumped[conn[a] as usize] += n[a] * cand.volume;
            }
            c.ids.push(cand.id);
            c.element.push(e);
            c.values.extend_from_slice(&n);
            c.weight.push(w.clamp(0.0, 1.0));
            c.weight_gradient.push(grad);
            c.volume.push(cand.volume);
            c.reference.push(cand.centre);
        }
        if let Some(k) = c.lumped.iter().position(|&a| a <= 0.0) {
            return Err(VolumeError::Node {
                node: c.mesh.node_ids[k],
                message: "no particle centre lies in its overlap elements: the overlap must be \
                          filled with particles (Wellmann §6.3)"
                    .into(),
            });
        }
        c.build_v(&element_nodes)?;
        if projection == Projection::Consistent {
            c.factor_a()?;
        }
        Ok(c)
    }

    /// V_IJ = ∫_{Ω^C} N_I N_J dv by Gauss quadrature, element by element.
    fn build_v(&mut self, element_nodes: &[Vec<[f64; 3]>]) -> Result<(), VolumeError> {
        let nn = self.nn;
        let rule = product_rule(self.mesh.shape);
        let mut n = vec![0.0; nn];
        let mut dn = vec![[0.0; 3]; nn];
        let mut entries: Vec<(u32, u32, f64)> = Vec::new();
        for (e, x) in element_nodes.iter().enumerate() {
            let conn = &self.mesh.elements[e * nn..(e + 1) * nn];
            for (xi, wq) in &rule {
                iso::shape(self.mesh.shape, *xi, &mut n, &mut dn);
                let jac = nalgebra::Matrix3::from_fn(|i, k| {
                    (0..nn).map(|a| x[a][i] * dn[a][k]).sum::<f64>()
                });
                let det = jac.determinant();
                if det.is_nan() || det <= 0.0 {
                    return Err(VolumeError::Mesh(format!(
                        "element {e} has a non-positive Jacobian determinant {det:e} (inverted \
                         or degenerate)"
                    )));
                }
                for a in 0..nn {
                    for b in 0..nn {
                        entries.push((conn[a], conn[b], n[a] * n[b] * det * wq));
                    }
                }
            }
        }
        entries.sort_by_key(|&(i, j, _)| (i, j));
        let nodes = self.mesh.nodes.len();
        self.v_start = vec![0];
        let mut row = 0u32;
        for (i, j, v) in entries {
            while row < i {
                self.v_start.push(self.v_col.len() as u32);
                row += 1;
            }
            if self.v_col.len() > *self.v_start.last().unwrap() as usize
                && *self.v_col.last().unwrap() == j
            {
                *self.v_val.last_mut().unwrap() += v;
            } else {
                self.v_col.push(j);
                self.v_val.push(v);
            }
        }
        while self.v_start.len() <= nodes {
            self.v_start.push(self.v_col.len() as u32);
        }
        Ok(())
    }

    /// The sparse Cholesky factor of A = N V Nᵀ (6.19).
    fn factor_a(&mut self) -> Result<(), VolumeError> {
        let nn = self.nn;
        let mut t = Vec::with_capacity(self.ids.len() * nn * nn);
        for k in 0..self.ids.len() {
            let conn = self.connectivity(k);
            let nk = &self.values[k * nn..(k + 1) * nn];
            for a in 0..nn {
                for b in 0..nn {
                    t.push(Triplet::new(
                        conn[a],
                        conn[b],
                        nk[a] * nk[b] * self.volume[k],
                    ));
                }
            }
        }
        let n = self.mesh.nodes.len();
        let a = SparseColMat::<u32, f64>::try_new_from_triplets(n, n, &t)
            .map_err(|e| VolumeError::Mesh(format!("projection matrix A: {e:?}")))?;
        self.llt = Some(a.sp_cholesky(Side::Lower).map_err(|e| {
            VolumeError::Mesh(format!(
                "the consistent projection's A = N V Nᵀ is singular ({e:?}): too few particle \
                 centres in the overlap to determine every node; use the lumped projection or \
                 a finer fill"
            ))
        })?);
        Ok(())
    }

    fn connectivity(&self, k: usize) -> &[u32] {
        let e = self.element[k] as usize;
        &self.mesh.elements[e * self.nn..(e + 1) * self.nn]
    }

    /// Number of coupled particles.
    pub fn len(&self) -> usize {
        self.ids.len()
    }

    pub fn is_empty(&self) -> bool {
        self.ids.is_empty()
    }

    /// Ids of the coupled particles (the order of every per-particle slice).
    pub fn ids(&self) -> &[u32] {
        &self.ids
    }

    /// Number of coupling nodes (the order of every per-node slice).
    pub fn num_nodes(&self) -> usize {
        self.mesh.nodes.len()
    }

    pub fn mesh(&self) -> &OverlapMesh {
        &self.mesh
    }

    pub fn projection(&self) -> Projection {
        self.projection
    }

    pub fn penalty(&self) -> f64 {
        self.penalty
    }

    /// w(c_α) of coupled particle k (6.27).
    pub fn weight(&self, k: usize) -> f64 {
        self.weight[k]
    }

    /// ∇w at c_α (reference configuration), for the weight of a wall contact point.
    pub fn weight_gradient(&self, k: usize) -> V3 {
        self.weight_gradient[k]
    }

    /// Reference centre of coupled particle k.
    pub fn reference(&self, k: usize) -> V3 {
        self.reference[k]
    }

    /// u^DE = Π u_d: the coarse part of the particle displacements `u` (one per coupled
    /// particle) at the coupling nodes, into `out` (one per node). (6.22) or (6.20).
    pub fn project(&self, u: &[V3], out: &mut [V3]) {
        assert_eq!(u.len(), self.ids.len());
        assert_eq!(out.len(), self.mesh.nodes.len());
        out.fill(V3::zeros());
        for (k, uk) in u.iter().enumerate() {
            let nk = &self.values[k * self.nn..(k + 1) * self.nn];
            for (a, &i) in self.connectivity(k).iter().enumerate() {
                out[i as usize] += uk * (nk[a] * self.volume[k]);
            }
        }
        match &self.llt {
            None => {
                for (o, a) in out.iter_mut().zip(&self.lumped) {
                    *o /= *a;
                }
            }
            Some(llt) => solve3(llt, out),
        }
    }

    /// The penalty forces (6.25)–(6.26) for the projected particle displacements `u_de` and
    /// the FE displacements `u_fe` at the coupling nodes: on the FE nodes into `on_nodes`, on
    /// the coupled particles into `on_particles` (`scratch`: a buffer kept by the caller, so
    /// that a step allocates nothing). Returns the penalty energy C (6.23).
    pub fn penalty_forces(
        &self,
        u_de: &[V3],
        u_fe: &[V3],
        on_nodes: &mut [V3],
        on_particles: &mut [V3],
        scratch: &mut Vec<V3>,
    ) -> f64 {
        let nodes = self.mesh.nodes.len();
        assert!(u_de.len() == nodes && u_fe.len() == nodes && on_nodes.len() == nodes);
        assert_eq!(on_particles.len(), self.ids.len());
        let mut energy = 0.0;
        for i in 0..nodes {
            let mut f = V3::zeros();
            for p in self.v_start[i] as usize..self.v_start[i + 1] as usize {
                let j = self.v_col[p] as usize;
                f += (u_de[j] - u_fe[j]) * self.v_val[p];
            }
            energy += 0.5 * self.penalty * (u_de[i] - u_fe[i]).dot(&f);
            on_nodes[i] = f * self.penalty;
        }
        // Πᵀ f: lumped Π_Iα = N_Iα V_α / A*_II; consistent Πᵀ = V Nᵀ A⁻¹ (A symmetric)
        let y = scratch;
        y.clear();
        match &self.llt {
            None => y.extend(on_nodes.iter().zip(&self.lumped).map(|(f, a)| f / *a)),
            Some(llt) => {
                y.extend_from_slice(on_nodes);
                solve3(llt, y);
            }
        }
        for (k, out) in on_particles.iter_mut().enumerate() {
            let nk = &self.values[k * self.nn..(k + 1) * self.nn];
            let mut g = V3::zeros();
            for (a, &i) in self.connectivity(k).iter().enumerate() {
                g += y[i as usize] * nk[a];
            }
            *out = -g * self.volume[k];
        }
        energy
    }

    /// The penalty pull ε Σ_J V_IJ u_J^DE on the FE nodes (the force (6.25) at u^FE = 0), which
    /// a provider with the implicit penalty ε V in its operator reads as its forces.
    pub fn pull(&self, u_de: &[V3], out: &mut [V3]) {
        for (i, o) in out.iter_mut().enumerate() {
            let mut f = V3::zeros();
            for p in self.v_start[i] as usize..self.v_start[i + 1] as usize {
                f += u_de[self.v_col[p] as usize] * self.v_val[p];
            }
            *o = f * self.penalty;
        }
    }

    /// A bound of the penalty stiffness each coupled particle feels, the Gershgorin row sum
    /// k̂_α = ε Σ_I |Π_Iα| Σ_J |V_IJ| Σ_β |Π_Jβ| of K = ε Πᵀ V Π with the lumped Π (for
    /// linear elements Σ_β Π_Jβ = 1 and k̂_α = ε Σ_I Π_Iα ∫N_I dv ≈ ε V_α / Φ). With the
    /// weighted masses, Δt < 2 min_α √(w_α m_α / k̂_α) keeps the explicit integration of the
    /// penalty stable; for a fill of solid fraction Φ and density ρ that is
    /// Δt < 2 √(Φ w ρ / ε), independent of the particle size.
    pub fn particle_stiffness(&self) -> Vec<f64> {
        let nn = self.nn;
        let mut pi_sum = vec![0.0; self.mesh.nodes.len()];
        for k in 0..self.ids.len() {
            let nk = &self.values[k * nn..(k + 1) * nn];
            for (a, &i) in self.connectivity(k).iter().enumerate() {
                pi_sum[i as usize] += (nk[a] * self.volume[k] / self.lumped[i as usize]).abs();
            }
        }
        let row: Vec<f64> = (0..self.mesh.nodes.len())
            .map(|i| {
                (self.v_start[i] as usize..self.v_start[i + 1] as usize)
                    .map(|p| self.v_val[p].abs() * pi_sum[self.v_col[p] as usize])
                    .sum()
            })
            .collect();
        (0..self.ids.len())
            .map(|k| {
                let nk = &self.values[k * nn..(k + 1) * nn];
                let s: f64 = self
                    .connectivity(k)
                    .iter()
                    .enumerate()
                    .map(|(a, &i)| {
                        (nk[a] * self.volume[k] / self.lumped[i as usize]).abs() * row[i as usize]
                    })
                    .sum();
                self.penalty * s
            })
            .collect()
    }

    /// How far coupled particle k, now at `x`, lies outside the element it was located in,
    /// that element with its nodes at `nodes` (the coupling nodes' current positions in the
    /// order of the overlap's nodes; `mesh().nodes` for the reference configuration), in ξ
    /// units: 0 inside, 0.5 half an element out; infinite when the point cannot be located at
    /// all. Against the deformed element, since §6.3 assumes small displacements of the
    /// particles *relative to the continuum*: grains heaving with the continuum beside a pile
    /// stay in their element.
    pub fn drift(&self, k: usize, x: V3, nodes: &[V3]) -> f64 {
        let e = self.element[k] as usize;
        let nodes: Vec<[f64; 3]> = self.mesh.elements[e * self.nn..(e + 1) * self.nn]
            .iter()
            .map(|&a| {
                let p = nodes[a as usize];
                [p.x, p.y, p.z]
            })
            .collect();
        match iso::locate(self.mesh.shape, &nodes, [x.x, x.y, x.z], 0.0) {
            None => f64::INFINITY,
            Some(l) => match self.mesh.shape {
                IsoShape::Hex8 | IsoShape::Hex20 => {
                    l.xi.iter()
                        .map(|c| (c.abs() - 1.0).max(0.0))
                        .fold(0.0, f64::max)
                        * 0.5
                }
                IsoShape::Tet4 | IsoShape::Tet10 => {
                    let s = l.xi[0] + l.xi[1] + l.xi[2];
                    l.xi.iter()
                        .map(|c| (-c).max(0.0))
                        .fold((s - 1.0).max(0.0), f64::max)
                }
            },
        }
    }
}

/// The weights of the bodies by slot, read by the force kernels: w(c) and ∇w (1 and 0 for a
/// body outside every overlap).
#[derive(Debug, Default, Clone)]
pub struct SlotWeights {
    pub weight: Vec<f64>,
    pub gradient: Vec<V3>,
}

impl SlotWeights {
    /// The weight of a wall contact of body `i` (centre `x`) at `point`: w linearised about
    /// the centre (6.9), clamped to [0, 1].
    #[inline(always)]
    pub fn at(&self, i: usize, x: V3, point: V3) -> f64 {
        let w = self.weight[i];
        let g = self.gradient[i];
        if g == V3::zeros() {
            return w;
        }
        (w + g.dot(&(point - x))).clamp(0.0, 1.0)
    }

    /// Whether body `i` lies outside every overlap (w = 1, ∇w = 0): its contacts with another
    /// such body weigh 1, and a kernel may skip the contact point.
    #[inline(always)]
    pub fn outside(&self, i: usize) -> bool {
        self.weight[i] == 1.0 && self.gradient[i] == V3::zeros()
    }

    /// The weight of a contact between bodies `i` and `j` (centres `xi`, `xj`) at `point`,
    /// the same for both bodies so that the weighted pair forces balance (no spurious (6.15)
    /// force): the weight field at the contact point, w linearised about each coupled body's
    /// centre (6.9) — the mean of the two where both are coupled, the coupled one's alone
    /// where the other lies outside every overlap (w = 1, ∇w = 0) — clamped to [0, 1].
    ///
    /// Departure from the thesis: (6.29) interpolates the two centres' weights along the line
    /// of centres. Where w is linear between them the two agree; across the overlap's
    /// grain-side boundary, where w stops rising at 1, (6.29) gives a contact on that boundary
    /// the weight ½(w_α + 1) < 1, and the grain beyond it, weighted 1 on its other side, a
    /// spurious net force: under a homogeneous strain the contacts there carry 1/w times the
    /// stress of the rest (+14 % in the patch test of docs/two-scale.md, 0 with this rule).
    #[inline(always)]
    pub fn pair(&self, i: usize, j: usize, xi: V3, xj: V3, point: V3) -> f64 {
        let (wi, wj) = (self.weight[i], self.weight[j]);
        let (gi, gj) = (self.gradient[i], self.gradient[j]);
        let w = match (self.outside(i), self.outside(j)) {
            (true, true) => return 1.0,
            (false, true) => wi + gi.dot(&(point - xi)),
            (true, false) => wj + gj.dot(&(point - xj)),
            (false, false) => 0.5 * (wi + gi.dot(&(point - xi)) + wj + gj.dot(&(point - xj))),
        };
        w.clamp(0.0, 1.0)
    }
}

/// The settings of a volume coupling.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VolumeSettings {
    /// The projection of the particle displacements (6.20)/(6.22).
    #[serde(default)]
    pub projection: Projection,
    /// ε of (6.23) in Pa/m² (N/m⁴); Wellmann's converged value is 1e8 Pa/mm² = 1e14. Not a
    /// scene key: a coupled run takes the provider's (`[fem.overlap] penalty`).
    #[serde(skip, default = "default_penalty")]
    pub penalty: f64,
    /// Floor of the weight of a particle's mass and inertia (w_c m → 0 at the FE side makes
    /// the unweighted penalty force's explicit step vanish, §4.3's caution); contact forces
    /// keep their unfloored weights.
    #[serde(default = "default_min_weight")]
    pub min_weight: f64,
    /// How far (in element sizes, ξ/2) a coupled particle may leave the element it was
    /// located in (with the element's nodes where the continuum has them now) before the
    /// reference-configuration terms are no longer trusted and the run stops naming it.
    #[serde(default = "default_max_drift")]
    pub max_drift: f64,
}

fn default_penalty() -> f64 {
    1e14
}

fn default_min_weight() -> f64 {
    0.05
}

fn default_max_drift() -> f64 {
    0.25
}

impl Default for VolumeSettings {
    fn default() -> Self {
        VolumeSettings {
            projection: Projection::default(),
            penalty: default_penalty(),
            min_weight: default_min_weight(),
            max_drift: default_max_drift(),
        }
    }
}

/// Everything of a volume interface that a snapshot keeps: the overlap and its coupled
/// particles as located at set-up (the coupling operators are rebuilt from them, bitwise the
/// same), the window's FE kinematics and the force accumulator.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct VolumeInterfaceState {
    pub name: String,
    /// "tet4", "tet10", "hex8" or "hex20".
    pub shape: String,
    pub node_ids: Vec<u64>,
    pub nodes: Vec<V3>,
    pub elements: Vec<u32>,
    pub weights: Vec<f64>,
    pub settings: VolumeSettings,
    /// ε of (6.23) [N/m⁴] (the provider's; `settings.penalty` is not stored).
    #[serde(default = "default_penalty")]
    pub penalty: f64,
    /// Coupled particles: id, reference centre, volume.
    pub particles: Vec<(u32, V3, f64)>,
    pub window_p: Vec<V3>,
    pub window_v: Vec<V3>,
    pub window_a: Vec<V3>,
    pub rule: crate::walls::MotionRule,
    pub window_steps: u64,
    /// Σ weight × ε V u^DE over the window's steps (the provider's forces), and their count.
    pub force_sum: Vec<V3>,
    pub window_substeps: u64,
    /// The penalty energy C (6.23) of the last evaluation.
    pub energy: f64,
    /// Work of the penalty forces on the FE nodes as they moved in the DEM this window,
    /// Σ_steps Δt Σ_I f_I·v_I [J] (the interface energy audit).
    #[serde(default)]
    pub window_work: f64,
    /// The net load the window's prediction of the FE nodes missed, |Σ_I ε Σ_J V_IJ δ_J| with δ
    /// the nodes' new positions less where the window's rule had carried them [N]: a
    /// staggered coupling's error, which the stiff penalty turns into a spurious load on
    /// both sides (0 before the second window).
    #[serde(default)]
    pub prediction_defect: f64,
}

impl VolumeInterfaceState {
    /// The FE nodes' positions and velocities at window time τ by the window's rule.
    pub fn node_motion(&self, i: usize, tau: f64) -> (V3, V3) {
        match self.rule {
            crate::walls::MotionRule::Quadratic => (
                self.window_p[i] + self.window_v[i] * tau + self.window_a[i] * (0.5 * tau * tau),
                self.window_v[i] + self.window_a[i] * tau,
            ),
            crate::walls::MotionRule::Linear => {
                (self.window_p[i] + self.window_v[i] * tau, self.window_v[i])
            }
        }
    }
}

/// The name of an isoparametric shape in scenes and messages.
pub fn shape_name(shape: IsoShape) -> &'static str {
    match shape {
        IsoShape::Tet4 => "tet4",
        IsoShape::Tet10 => "tet10",
        IsoShape::Hex8 => "hex8",
        IsoShape::Hex20 => "hex20",
    }
}

/// The shape of a name of [`shape_name`].
pub fn shape_of(name: &str) -> Option<IsoShape> {
    Some(match name {
        "tet4" => IsoShape::Tet4,
        "tet10" => IsoShape::Tet10,
        "hex8" => IsoShape::Hex8,
        "hex20" => IsoShape::Hex20,
        _ => return None,
    })
}

/// A volume interface while the engine runs: its state, its operators and scratch.
#[derive(Debug)]
pub struct VolumeInterface {
    pub coupling: VolumeCoupling,
    /// Slot of each coupled particle in the engine's particle arrays.
    pub slot: Vec<u32>,
    pub u_d: Vec<V3>,
    pub u_de: Vec<V3>,
    pub u_fe: Vec<V3>,
    pub on_nodes: Vec<V3>,
    pub on_particles: Vec<V3>,
    /// ε V u^DE of the last evaluation (what the provider reads).
    pub pull: Vec<V3>,
    /// Scratch of the penalty evaluation.
    pub scratch: Vec<V3>,
}

impl VolumeInterface {
    /// The operators of a stored interface state (its particles are exactly the coupled
    /// ones, so the location finds each again in the same element).
    pub fn from_state(st: &VolumeInterfaceState) -> Result<VolumeInterface, VolumeError> {
        let shape = shape_of(&st.shape)
            .ok_or_else(|| VolumeError::Mesh(format!("unknown element shape `{}`", st.shape)))?;
        let mesh = OverlapMesh {
            shape,
            node_ids: st.node_ids.clone(),
            nodes: st.nodes.clone(),
            elements: st.elements.clone(),
            weights: st.weights.clone(),
        };
        let cands: Vec<Candidate> = st
            .particles
            .iter()
            .map(|&(id, centre, volume)| Candidate { id, centre, volume })
            .collect();
        let coupling = VolumeCoupling::new(mesh, &cands, st.settings.projection, st.penalty)?;
        if coupling.len() != cands.len() {
            return Err(VolumeError::Mesh(format!(
                "{} of the {} stored coupled particles were located again",
                coupling.len(),
                cands.len()
            )));
        }
        Ok(VolumeInterface::new(coupling))
    }

    /// The scratch of a coupling (slots unknown until the engine maps them).
    pub fn new(coupling: VolumeCoupling) -> VolumeInterface {
        let (n, p) = (coupling.num_nodes(), coupling.len());
        VolumeInterface {
            coupling,
            slot: vec![u32::MAX; p],
            u_d: vec![V3::zeros(); p],
            u_de: vec![V3::zeros(); n],
            u_fe: vec![V3::zeros(); n],
            on_nodes: vec![V3::zeros(); n],
            on_particles: vec![V3::zeros(); p],
            pull: vec![V3::zeros(); n],
            scratch: Vec::with_capacity(n),
        }
    }
}

/// Solves A x = b in place for the three components of `b` with the factor of A.
fn solve3(llt: &Llt<u32, f64>, b: &mut [V3]) {
    let n = b.len();
    let mut m = faer::Mat::<f64>::zeros(n, 3);
    for (i, v) in b.iter().enumerate() {
        for k in 0..3 {
            m[(i, k)] = v[k];
        }
    }
    llt.solve_in_place(m.as_mut());
    for (i, v) in b.iter_mut().enumerate() {
        *v = V3::new(m[(i, 0)], m[(i, 1)], m[(i, 2)]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A box [0, nx h] × [0, ny h] × [0, nz h] of hex8 elements with weights linear in z,
    /// 1 at the top, 0 at the bottom.
    fn block(nx: usize, ny: usize, nz: usize, h: f64) -> OverlapMesh {
        let id = |i: usize, j: usize, k: usize| (k * (ny + 1) + j) * (nx + 1) + i;
        let mut nodes = Vec::new();
        let mut weights = Vec::new();
        for k in 0..=nz {
            for j in 0..=ny {
                for i in 0..=nx {
                    nodes.push(V3::new(i as f64 * h, j as f64 * h, k as f64 * h));
                    weights.push(k as f64 / nz as f64);
                }
            }
        }
        let mut elements = Vec::new();
        for k in 0..nz {
            for j in 0..ny {
                for i in 0..nx {
                    // the corners in hex8 order: reference ±1 → lattice offsets 0/1
                    for r in &IsoShape::Hex8.reference_nodes()[..8] {
                        let [a, b, c] = r.map(|x| usize::from(x > 0.0));
                        elements.push(id(i + a, j + b, k + c) as u32);
                    }
                }
            }
        }
        OverlapMesh {
            shape: IsoShape::Hex8,
            node_ids: (1..=nodes.len() as u64).collect(),
            nodes,
            elements,
            weights,
        }
    }

    /// A regular lattice of `m` particles per element edge (centres at the cell centres of a
    /// finer grid), optionally jittered.
    fn lattice(mesh_size: [usize; 3], h: f64, m: usize, jitter: f64) -> Vec<Candidate> {
        let s = h / m as f64;
        let mut seed = 12345u64;
        let mut rnd = move || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let mut out = Vec::new();
        for k in 0..mesh_size[2] * m {
            for j in 0..mesh_size[1] * m {
                for i in 0..mesh_size[0] * m {
                    let c = V3::new(i as f64 + 0.5, j as f64 + 0.5, k as f64 + 0.5) * s
                        + V3::new(rnd(), rnd(), rnd()) * (jitter * s);
                    out.push(Candidate {
                        id: out.len() as u32,
                        centre: c,
                        volume: s * s * s * (0.5 + 0.1 * (out.len() % 7) as f64),
                    });
                }
            }
        }
        out
    }

    fn affine(x: V3) -> V3 {
        let a = nalgebra::Matrix3::new(1e-3, 2e-4, -3e-4, 5e-4, -2e-3, 1e-4, 0.0, 7e-4, 1.5e-3);
        a * x + V3::new(1e-5, -2e-5, 3e-6)
    }

    fn projected(c: &VolumeCoupling, f: impl Fn(V3) -> V3) -> Vec<V3> {
        let u: Vec<V3> = (0..c.len()).map(|k| f(c.reference(k))).collect();
        let mut out = vec![V3::zeros(); c.num_nodes()];
        c.project(&u, &mut out);
        out
    }

    #[test]
    fn consistent_projection_reproduces_affine_fields_exactly() {
        let h = 2e-3;
        let mesh = block(3, 2, 2, h);
        let cands = lattice([3, 2, 2], h, 3, 0.6);
        let c = VolumeCoupling::new(mesh.clone(), &cands, Projection::Consistent, 1e14).unwrap();
        assert_eq!(c.len(), cands.len());
        let u = projected(&c, affine);
        for (i, x) in mesh.nodes.iter().enumerate() {
            let e = (u[i] - affine(*x)).norm();
            assert!(
                e < 1e-12 * affine(*x).norm().max(1e-6),
                "node {i}: error {e:e}"
            );
        }
    }

    /// The lumped projection (6.22) reproduces translations exactly; an affine field exactly
    /// at the interior nodes of a lattice symmetric about them, not at the overlap's boundary
    /// nodes (the departure stated in the module documentation).
    #[test]
    fn lumped_projection_reproduces_translations_and_symmetric_affine_fields() {
        let h = 2e-3;
        let mesh = block(2, 2, 2, h);
        let mut cands = lattice([2, 2, 2], h, 4, 0.0);
        for c in &mut cands {
            c.volume = 1e-9;
        }
        let c = VolumeCoupling::new(mesh.clone(), &cands, Projection::Lumped, 1e14).unwrap();
        let t = V3::new(1e-5, 2e-5, -3e-5);
        for u in projected(&c, |_| t) {
            assert!((u - t).norm() < 1e-15);
        }
        let u = projected(&c, affine);
        let interior = 13; // node (1, 1, 1) of the 3 × 3 × 3 nodes
        assert_eq!(mesh.nodes[interior], V3::new(h, h, h));
        let exact = affine(mesh.nodes[interior]);
        assert!((u[interior] - exact).norm() < 1e-13 * exact.norm());
        let corner = (u[0] - affine(mesh.nodes[0])).norm();
        let scale = 1e-3 * h;
        assert!(
            corner > 0.1 * scale,
            "corner error {corner:e} unexpectedly small"
        );
        assert!(
            corner < scale,
            "corner error {corner:e} larger than a / 2 · |∇u|"
        );
    }

    /// (6.25)–(6.26) are the gradient of C (6.23): f_α = −∂C/∂u_α, f_I = −∂C/∂u_I^FE; and
    /// they conserve momentum (Σ f_α + Σ f_I = 0) for both projections.
    #[test]
    fn penalty_forces_are_the_gradient_of_the_penalty_energy() {
        let h = 2e-3;
        for proj in [Projection::Lumped, Projection::Consistent] {
            let mesh = block(2, 1, 2, h);
            let cands = lattice([2, 1, 2], h, 2, 0.5);
            let c = VolumeCoupling::new(mesh, &cands, proj, 1e14).unwrap();
            let (np, nn) = (c.len(), c.num_nodes());
            let ud: Vec<V3> = (0..np)
                .map(|k| V3::new((k as f64).sin(), (2.0 * k as f64).cos(), 0.3) * 1e-6)
                .collect();
            let ufe: Vec<V3> = (0..nn)
                .map(|i| V3::new(0.2, (i as f64).sin(), (3.0 * i as f64).cos()) * 1e-6)
                .collect();
            let energy = |ud: &[V3], ufe: &[V3]| {
                let mut ude = vec![V3::zeros(); nn];
                c.project(ud, &mut ude);
                let (mut a, mut b) = (vec![V3::zeros(); nn], vec![V3::zeros(); np]);
                c.penalty_forces(&ude, ufe, &mut a, &mut b, &mut Vec::new())
            };
            let mut ude = vec![V3::zeros(); nn];
            c.project(&ud, &mut ude);
            let (mut fi, mut fa) = (vec![V3::zeros(); nn], vec![V3::zeros(); np]);
            let e0 = c.penalty_forces(&ude, &ufe, &mut fi, &mut fa, &mut Vec::new());
            assert!(e0 > 0.0);
            let total: V3 = fi.iter().chain(&fa).sum();
            let scale: f64 = fi.iter().map(|f| f.norm()).sum();
            assert!(
                total.norm() < 1e-12 * scale,
                "{proj:?}: net force {total:?}"
            );
            let d = 1e-10;
            for k in [0, np / 3, np - 1] {
                for ax in 0..3 {
                    let (mut p, mut m) = (ud.clone(), ud.clone());
                    p[k][ax] += d;
                    m[k][ax] -= d;
                    let g = (energy(&p, &ufe) - energy(&m, &ufe)) / (2.0 * d);
                    assert!(
                        (fa[k][ax] + g).abs() < 1e-6 * fa[k].norm().max(1e-3 * scale / np as f64),
                        "{proj:?} particle {k} axis {ax}: f {} vs -dC/du {}",
                        fa[k][ax],
                        -g
                    );
                }
            }
            for i in [0, nn / 2, nn - 1] {
                for ax in 0..3 {
                    let (mut p, mut m) = (ufe.clone(), ufe.clone());
                    p[i][ax] += d;
                    m[i][ax] -= d;
                    let g = (energy(&ud, &p) - energy(&ud, &m)) / (2.0 * d);
                    assert!(
                        (fi[i][ax] + g).abs() < 1e-6 * scale,
                        "{proj:?} node {i} axis {ax}: f {} vs -dC/du {}",
                        fi[i][ax],
                        -g
                    );
                }
            }
        }
    }

    /// Particles moved with the FE field feel no penalty: the coupled fields agree.
    #[test]
    fn a_common_affine_motion_is_free_of_penalty_with_the_consistent_projection() {
        let h = 2e-3;
        let mesh = block(2, 2, 1, h);
        let cands = lattice([2, 2, 1], h, 3, 0.4);
        let c = VolumeCoupling::new(mesh.clone(), &cands, Projection::Consistent, 1e14).unwrap();
        let ude = projected(&c, affine);
        let ufe: Vec<V3> = mesh.nodes.iter().map(|x| affine(*x)).collect();
        let (mut fi, mut fa) = (vec![V3::zeros(); c.num_nodes()], vec![V3::zeros(); c.len()]);
        let e = c.penalty_forces(&ude, &ufe, &mut fi, &mut fa, &mut Vec::new());
        // against the force of a rigid offset of one element size × strain
        let unit = 1e14 * h * h * h * 1e-3 * h;
        assert!(e.abs() < 1e-20, "energy {e:e}");
        assert!(fi.iter().chain(&fa).all(|f| f.norm() < 1e-9 * unit));
    }

    /// Contact weights are the weight field at the contact point, shared by the pair: linear
    /// between two coupled centres (where (6.29) gives the same), 1 at the overlap's grain-side
    /// boundary beside a body outside it (where (6.29) would give ½(w + 1)), clamped to [0, 1].
    #[test]
    fn contact_weights_are_the_field_at_the_contact_point_and_shared_by_the_pair() {
        // w = z/2 for z in [0, 2], 1 above: bodies at z = 0.5, 1.5 (coupled) and 2.5 (outside)
        let g = V3::new(0.0, 0.0, 0.5);
        let w = SlotWeights {
            weight: vec![0.25, 0.75, 1.0],
            gradient: vec![g, g, V3::zeros()],
        };
        let c = [0.5, 1.5, 2.5].map(|z| V3::new(0.0, 0.0, z));
        let at = |z: f64| V3::new(0.1, 0.0, z);
        let close = |a: f64, b: f64| assert!((a - b).abs() < 1e-15, "{a} vs {b}");
        close(w.pair(0, 1, c[0], c[1], at(1.0)), 0.5);
        close(w.pair(1, 0, c[1], c[0], at(1.2)), 0.6);
        // the boundary contact: the field's 1, not (6.29)'s 0.875
        close(w.pair(1, 2, c[1], c[2], at(2.0)), 1.0);
        close(w.pair(2, 1, c[2], c[1], at(2.0)), 1.0);
        close(w.pair(1, 2, c[1], c[2], at(1.9)), 0.95);
        close(w.pair(2, 2, c[2], c[2], at(2.2)), 1.0);
        // clamped below 0 beyond the FE side
        close(w.pair(0, 0, c[0], c[0], at(-0.4)), 0.0);
    }

    #[test]
    fn weights_and_gradients_follow_the_nodal_weights() {
        let h = 2e-3;
        let mesh = block(1, 1, 2, h);
        let cands = lattice([1, 1, 2], h, 2, 0.3);
        let c = VolumeCoupling::new(mesh, &cands, Projection::Lumped, 1e14).unwrap();
        for k in 0..c.len() {
            let z = c.reference(k).z;
            assert!((c.weight(k) - z / (2.0 * h)).abs() < 1e-12);
            assert!((c.weight_gradient(k) - V3::new(0.0, 0.0, 0.5 / h)).norm() < 1e-9 / h);
        }
        let k = c.particle_stiffness();
        assert!(k.iter().all(|&s| s > 0.0 && s.is_finite()));
    }

    #[test]
    fn bad_overlaps_are_refused_naming_the_node() {
        let h = 2e-3;
        let mesh = block(2, 1, 1, h);
        // particles only in the first element: the nodes at x = 2h have none
        let cands: Vec<Candidate> = lattice([2, 1, 1], h, 2, 0.0)
            .into_iter()
            .filter(|c| c.centre.x < h)
            .collect();
        let e = VolumeCoupling::new(mesh.clone(), &cands, Projection::Lumped, 1e14).unwrap_err();
        assert!(e.to_string().contains("overlap node 3:"), "{e}");
        let mut bad = mesh.clone();
        bad.weights[4] = 1.5;
        let e = VolumeCoupling::new(bad, &cands, Projection::Lumped, 1e14).unwrap_err();
        assert!(e.to_string().contains("overlap node 5: weight 1.5"), "{e}");
        let mut bad = mesh.clone();
        bad.elements.pop();
        let e = VolumeCoupling::new(bad, &cands, Projection::Lumped, 1e14).unwrap_err();
        assert!(e.to_string().contains("multiple of 8"), "{e}");
        let e = VolumeCoupling::new(mesh, &cands, Projection::Lumped, -1.0).unwrap_err();
        assert!(e.to_string().contains("penalty"), "{e}");
    }

    #[test]
    fn drift_measures_how_far_a_particle_left_its_element() {
        let h = 2e-3;
        let mesh = block(1, 1, 1, h);
        let cands = lattice([1, 1, 1], h, 2, 0.0);
        let c = VolumeCoupling::new(mesh, &cands, Projection::Lumped, 1e14).unwrap();
        let x = c.reference(0);
        let reference = &c.mesh().nodes;
        assert_eq!(c.drift(0, x, reference), 0.0);
        // half an element beyond the face x = 0
        let d = c.drift(0, V3::new(-0.5 * h, x.y, x.z), reference);
        assert!((d - 0.5).abs() < 1e-12, "{d}");
        // the same point inside the element moved by −h/2 in x with its nodes
        let moved: Vec<V3> = c
            .mesh()
            .nodes
            .iter()
            .map(|p| p - V3::new(0.5 * h, 0.0, 0.0))
            .collect();
        assert_eq!(c.drift(0, V3::new(-0.5 * h, x.y, x.z), &moved), 0.0);
        // and a particle left behind by an element that moved on by h
        let on: Vec<V3> = c
            .mesh()
            .nodes
            .iter()
            .map(|p| p + V3::new(h, 0.0, 0.0))
            .collect();
        assert!(c.drift(0, x, &on) > 0.1);
    }
}
