//! Isoparametric solid elements for isotropic linear elasticity (Ullrich ch. 2.2).
//!
//! Stiffness is the Galerkin bilinear form a(N_A e_i, N_B e_j) of (2.56) with the isotropic
//! tensor (2.35)-(2.37); mass is (N_A e_i, ρ N_B e_j) of (2.78). Node orderings follow Abaqus
//! (C3D4, C3D10, C3D8, C3D20), which coincide with VTK's for these types.

use nalgebra::{Matrix3, SMatrix, Vector3};
use numeric::iso::{
    gauss_1d, hex_rule, shape, tet_collapsed_rule, tet_rule_1, tet_rule_4, IsoShape as ShapeKind,
    HEX_NODES, TET_NODES,
};
use serde::{Deserialize, Serialize};
use std::sync::LazyLock;

/// Element formulations supported by the engine.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, PartialOrd, Ord)]
#[serde(rename_all = "lowercase")]
pub enum ElementKind {
    /// 4-node linear tetrahedron (C3D4), one-point rule.
    Tet4,
    /// 10-node quadratic tetrahedron (C3D10), 4-point rule.
    Tet10,
    /// 8-node trilinear hexahedron (C3D8), full 2×2×2 rule.
    Hex8,
    /// 8-node hexahedron with Wilson–Taylor incompatible modes (C3D8I / QM6): no shear locking
    /// in bending, passes the patch test on distorted meshes.
    Hex8i,
    /// 8-node hexahedron with the mean-dilatation B̄ (Hughes 1980): full 2×2×2 rule for the
    /// deviatoric part, the element-mean volumetric strain for the volumetric part; removes
    /// volumetric locking (ν → ½), keeps hex8's shear locking in bending.
    Hex8b,
    /// 20-node serendipity hexahedron (C3D20), 3×3×3 rule.
    Hex20,
}

impl ElementKind {
    pub fn num_nodes(self) -> usize {
        match self {
            ElementKind::Tet4 => 4,
            ElementKind::Tet10 => 10,
            ElementKind::Hex8 | ElementKind::Hex8i | ElementKind::Hex8b => 8,
            ElementKind::Hex20 => 20,
        }
    }
    pub fn name(self) -> &'static str {
        match self {
            ElementKind::Tet4 => "tet4",
            ElementKind::Tet10 => "tet10",
            ElementKind::Hex8 => "hex8",
            ElementKind::Hex8i => "hex8i",
            ElementKind::Hex8b => "hex8b",
            ElementKind::Hex20 => "hex20",
        }
    }
    /// VTK cell type (node orderings of Abaqus and VTK agree for these cells).
    pub fn vtk_type(self) -> u8 {
        match self {
            ElementKind::Tet4 => 10,
            ElementKind::Tet10 => 24,
            ElementKind::Hex8 | ElementKind::Hex8i | ElementKind::Hex8b => 12,
            ElementKind::Hex20 => 25,
        }
    }
    /// Number of corner (vertex) nodes; the corners come first in the connectivity.
    pub fn num_corners(self) -> usize {
        match self {
            ElementKind::Tet4 | ElementKind::Tet10 => 4,
            _ => 8,
        }
    }
    fn shape_kind(self) -> ShapeKind {
        match self {
            ElementKind::Tet4 => ShapeKind::Tet4,
            ElementKind::Tet10 => ShapeKind::Tet10,
            ElementKind::Hex8 | ElementKind::Hex8i | ElementKind::Hex8b => ShapeKind::Hex8,
            ElementKind::Hex20 => ShapeKind::Hex20,
        }
    }
    /// Faces with outward orientation (right-hand rule on the corner order), as local node
    /// indices: corners first, then mid-side nodes between consecutive corners.
    pub fn faces(self) -> &'static [&'static [usize]] {
        match self {
            ElementKind::Tet4 => &TET4_FACES,
            ElementKind::Tet10 => &TET10_FACES,
            ElementKind::Hex8 | ElementKind::Hex8i | ElementKind::Hex8b => &HEX8_FACES,
            ElementKind::Hex20 => &HEX20_FACES,
        }
    }
    /// Reference coordinates of the element's nodes.
    pub fn reference_nodes(self) -> &'static [[f64; 3]] {
        match self.shape_kind() {
            ShapeKind::Tet4 => &TET_NODES[..4],
            ShapeKind::Tet10 => &TET_NODES,
            ShapeKind::Hex8 => &HEX_NODES[..8],
            ShapeKind::Hex20 => &HEX_NODES,
        }
    }
}

static TET4_FACES: [&[usize]; 4] = [&[0, 2, 1], &[0, 1, 3], &[1, 2, 3], &[0, 3, 2]];
// tet10 edges: 4:(0,1) 5:(1,2) 6:(2,0) 7:(0,3) 8:(1,3) 9:(2,3)
static TET10_FACES: [&[usize]; 4] = [
    &[0, 2, 1, 6, 5, 4],
    &[0, 1, 3, 4, 8, 7],
    &[1, 2, 3, 5, 9, 8],
    &[0, 3, 2, 7, 9, 6],
];
static HEX8_FACES: [&[usize]; 6] = [
    &[0, 3, 2, 1],
    &[4, 5, 6, 7],
    &[0, 1, 5, 4],
    &[1, 2, 6, 5],
    &[2, 3, 7, 6],
    &[3, 0, 4, 7],
];
// hex20 edges: 8:(0,1) 9:(1,2) 10:(2,3) 11:(3,0) 12:(4,5) 13:(5,6) 14:(6,7) 15:(7,4)
// 16:(0,4) 17:(1,5) 18:(2,6) 19:(3,7)
static HEX20_FACES: [&[usize]; 6] = [
    &[0, 3, 2, 1, 11, 10, 9, 8],
    &[4, 5, 6, 7, 12, 13, 14, 15],
    &[0, 1, 5, 4, 8, 17, 12, 16],
    &[1, 2, 6, 5, 9, 18, 13, 17],
    &[2, 3, 7, 6, 10, 19, 14, 18],
    &[3, 0, 4, 7, 11, 16, 15, 19],
];

/// Shape values and reference derivatives tabulated at the points of a quadrature rule.
pub(crate) struct Tabulated {
    pub nn: usize,
    pub weights: Vec<f64>,
    pub points: Vec<[f64; 3]>,
    /// `n[q * nn + a]`
    pub n: Vec<f64>,
    /// `dn[q * nn + a]`
    pub dn: Vec<[f64; 3]>,
}

fn tabulate(kind: ShapeKind, nn: usize, rule: Vec<([f64; 3], f64)>) -> Tabulated {
    let mut t = Tabulated {
        nn,
        weights: Vec::new(),
        points: Vec::new(),
        n: vec![0.0; nn * rule.len()],
        dn: vec![[0.0; 3]; nn * rule.len()],
    };
    for (q, (p, w)) in rule.into_iter().enumerate() {
        shape(
            kind,
            p,
            &mut t.n[q * nn..(q + 1) * nn],
            &mut t.dn[q * nn..(q + 1) * nn],
        );
        t.weights.push(w);
        t.points.push(p);
    }
    t
}

static TET4_K: LazyLock<Tabulated> = LazyLock::new(|| tabulate(ShapeKind::Tet4, 4, tet_rule_1()));
static TET4_M: LazyLock<Tabulated> = LazyLock::new(|| tabulate(ShapeKind::Tet4, 4, tet_rule_4()));
static TET10_K: LazyLock<Tabulated> =
    LazyLock::new(|| tabulate(ShapeKind::Tet10, 10, tet_rule_4()));
static TET10_M: LazyLock<Tabulated> =
    LazyLock::new(|| tabulate(ShapeKind::Tet10, 10, tet_collapsed_rule(4)));
static HEX8_K: LazyLock<Tabulated> = LazyLock::new(|| tabulate(ShapeKind::Hex8, 8, hex_rule(2)));
static HEX8_M: LazyLock<Tabulated> = LazyLock::new(|| tabulate(ShapeKind::Hex8, 8, hex_rule(3)));
static HEX20_K: LazyLock<Tabulated> = LazyLock::new(|| tabulate(ShapeKind::Hex20, 20, hex_rule(3)));
static HEX20_M: LazyLock<Tabulated> = LazyLock::new(|| tabulate(ShapeKind::Hex20, 20, hex_rule(4)));

pub(crate) fn stiffness_rule(kind: ElementKind) -> &'static Tabulated {
    match kind {
        ElementKind::Tet4 => &TET4_K,
        ElementKind::Tet10 => &TET10_K,
        ElementKind::Hex8 | ElementKind::Hex8i | ElementKind::Hex8b => &HEX8_K,
        ElementKind::Hex20 => &HEX20_K,
    }
}

pub(crate) fn mass_rule(kind: ElementKind) -> &'static Tabulated {
    match kind {
        ElementKind::Tet4 => &TET4_M,
        ElementKind::Tet10 => &TET10_M,
        ElementKind::Hex8 | ElementKind::Hex8i | ElementKind::Hex8b => &HEX8_M,
        ElementKind::Hex20 => &HEX20_M,
    }
}

/// Why an element cannot be integrated: the Jacobian determinant at an integration point.
#[derive(Clone, Copy, Debug)]
pub struct BadJacobian {
    pub det_j: f64,
    pub inverted: bool,
}

/// Isotropic material in Lamé form (2.36).
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub struct Lame {
    pub lambda: f64,
    pub mu: f64,
}

impl Lame {
    /// Lamé constants from Young's modulus and Poisson's ratio, eq. (2.36).
    pub fn from_young_poisson(e: f64, nu: f64) -> Lame {
        Lame {
            lambda: nu * e / ((1.0 + nu) * (1.0 - 2.0 * nu)),
            mu: e / (2.0 * (1.0 + nu)),
        }
    }
}

fn jacobian(x: &[[f64; 3]], dn: &[[f64; 3]]) -> Matrix3<f64> {
    // J_ij = Σ_a x_a,i ∂N_a/∂ξ_j
    let mut j = Matrix3::zeros();
    for (xa, da) in x.iter().zip(dn) {
        for i in 0..3 {
            for k in 0..3 {
                j[(i, k)] += xa[i] * da[k];
            }
        }
    }
    j
}

/// Characteristic length³ used to decide "degenerate" (|det J| ≪ h³).
fn size_cubed(x: &[[f64; 3]]) -> f64 {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in x {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let h = (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f64::max);
    h * h * h
}

/// Physical gradients dN/dx at every point of `tab`, with det J · w.
/// Fails on an inverted (det J ≤ 0) or degenerate (det J < 1e-10 h³) element.
pub(crate) fn gradients(
    tab: &Tabulated,
    x: &[[f64; 3]],
    grads: &mut Vec<[f64; 3]>,
    wdet: &mut Vec<f64>,
) -> Result<(), BadJacobian> {
    let nn = tab.nn;
    grads.clear();
    wdet.clear();
    let tiny = 1e-10 * size_cubed(x);
    for q in 0..tab.weights.len() {
        let dn = &tab.dn[q * nn..(q + 1) * nn];
        let (j, det) = checked_jacobian(x, dn, tiny)?;
        let jinv = j.try_inverse().ok_or(BadJacobian {
            det_j: det,
            inverted: false,
        })?;
        for d in dn {
            // ∂N/∂x_k = Σ_j ∂N/∂ξ_j (J⁻¹)_jk
            let mut g = [0.0; 3];
            for k in 0..3 {
                g[k] = d[0] * jinv[(0, k)] + d[1] * jinv[(1, k)] + d[2] * jinv[(2, k)];
            }
            grads.push(g);
        }
        wdet.push(det * tab.weights[q]);
    }
    Ok(())
}

/// The Jacobian at a point with shape derivatives `dn` and its determinant, refused when it
/// is not above `tiny` (inverted or degenerate).
fn checked_jacobian(
    x: &[[f64; 3]],
    dn: &[[f64; 3]],
    tiny: f64,
) -> Result<(Matrix3<f64>, f64), BadJacobian> {
    let j = jacobian(x, dn);
    let det = j.determinant();
    if !(det > tiny) {
        return Err(BadJacobian {
            det_j: det,
            inverted: det < 0.0,
        });
    }
    Ok((j, det))
}

/// det J · w at every point of `tab` (what [`gradients`] gives besides the gradients, checked
/// the same way), times the Arlequin factor with `scale`, for integrals without derivatives
/// (masses, volume); computed point by point, nothing allocated.
fn point_weights<'a>(
    tab: &'a Tabulated,
    x: &'a [[f64; 3]],
    scale: Option<&'a [f64]>,
) -> impl Iterator<Item = Result<f64, BadJacobian>> + 'a {
    let nn = tab.nn;
    let tiny = 1e-10 * size_cubed(x);
    (0..tab.weights.len()).map(move |q| {
        let (_, det) = checked_jacobian(x, &tab.dn[q * nn..(q + 1) * nn], tiny)?;
        Ok(det * tab.weights[q] * scale.map_or(1.0, |s| arlequin_factor(tab, s, q)))
    })
}

/// The Arlequin factor 1 − w at point `q` of `tab`, interpolated from its nodal values `s`
/// (Wellmann (6.3), (6.27)).
fn arlequin_factor(tab: &Tabulated, s: &[f64], q: usize) -> f64 {
    let nn = tab.nn;
    tab.n[q * nn..(q + 1) * nn]
        .iter()
        .zip(s)
        .map(|(n, s)| n * s)
        .sum()
}

/// Multiplies the integration weights `wdet` of the points of `tab` by the Arlequin factor
/// (see [`arlequin_factor`]); no-op for `None`.
pub(crate) fn scale_weights(tab: &Tabulated, scale: Option<&[f64]>, wdet: &mut [f64]) {
    let Some(s) = scale else { return };
    for (q, w) in wdet.iter_mut().enumerate() {
        *w *= arlequin_factor(tab, s, q);
    }
}

/// Checks the Jacobian at the stiffness integration points (used by the mesh readers).
pub fn check_jacobian(kind: ElementKind, x: &[[f64; 3]]) -> Result<(), BadJacobian> {
    let mut g = Vec::new();
    let mut w = Vec::new();
    gradients(stiffness_rule(kind), x, &mut g, &mut w)
}

/// Adds w · a(N_a e_i, N_b e_j) (2.56)/(2.47) for isotropic C (2.35) into the node blocks
/// a ≤ b of `k` (row-major, dof 3a+i); [`mirror_upper`] completes the symmetric matrix
/// once all points are added (half the work of the whole matrix at every point).
#[inline]
fn add_isotropic_block(k: &mut [f64], ndof: usize, ga: &[[f64; 3]], w: f64, mat: Lame) {
    let n = ga.len();
    let (lam, mu) = (mat.lambda * w, mat.mu * w);
    for a in 0..n {
        let pa = ga[a];
        // λ ∂_i N_a and μ ∂_j N_a, the products' first factors (the same roundings as
        // λ ∂_i N_a ∂_j N_b evaluated left to right)
        let la = [lam * pa[0], lam * pa[1], lam * pa[2]];
        let ma = [mu * pa[0], mu * pa[1], mu * pa[2]];
        for b in a..n {
            let pb = ga[b];
            let dot = mu * (pa[0] * pb[0] + pa[1] * pb[1] + pa[2] * pb[2]);
            for i in 0..3 {
                let row = (3 * a + i) * ndof + 3 * b;
                let r = &mut k[row..row + 3];
                for j in 0..3 {
                    // C_ikjl ∂_k N_a ∂_l N_b = λ ∂_i N_a ∂_j N_b + μ ∂_j N_a ∂_i N_b + μ δ_ij ∇N_a·∇N_b
                    let mut v = la[i] * pb[j] + ma[j] * pb[i];
                    if i == j {
                        v += dot;
                    }
                    r[j] += v;
                }
            }
        }
    }
}

/// Copies the upper triangle of `k` (ndof × ndof) into the lower: completes the node blocks
/// b < a that [`add_isotropic_block`] leaves out, and makes the matrix exactly symmetric
/// (the two triangles of a diagonal block are rounded differently).
fn mirror_upper(k: &mut [f64], ndof: usize) {
    for r in 0..ndof {
        for c in r + 1..ndof {
            k[c * ndof + r] = k[r * ndof + c];
        }
    }
}

/// Element stiffness matrix, row-major (3n)×(3n), dof index 3a+i; with `scale` the nodal
/// Arlequin factors 1 − w of an overlap element ([`scale_weights`]).
pub fn stiffness(
    kind: ElementKind,
    x: &[[f64; 3]],
    mat: Lame,
    scale: Option<&[f64]>,
    k: &mut Vec<f64>,
) -> Result<(), BadJacobian> {
    let nn = kind.num_nodes();
    let ndof = 3 * nn;
    k.clear();
    k.resize(ndof * ndof, 0.0);
    let tab = stiffness_rule(kind);
    let mut g = Vec::with_capacity(nn * tab.weights.len());
    let mut w = Vec::with_capacity(tab.weights.len());
    gradients(tab, x, &mut g, &mut w)?;
    scale_weights(tab, scale, &mut w);
    if kind == ElementKind::Hex8i {
        return hex8i_stiffness(x, mat, &g, &w, k);
    }
    if kind == ElementKind::Hex8b {
        // B̄ with the mean dilatation (Hughes 1980): with κ = λ + ⅔μ the energy splits into
        // 2μ dev ε : dev ε (full rule; λ' = −⅔μ in the isotropic block) and κ V (tr ε̄)², where
        // tr ε̄ = Σ_a ḡ_a · u_a with the element-mean gradients ḡ_a = (1/V) ∫ ∇N_a dV.
        let dev = Lame {
            lambda: -2.0 / 3.0 * mat.mu,
            mu: mat.mu,
        };
        for q in 0..w.len() {
            add_isotropic_block(k, ndof, &g[q * nn..(q + 1) * nn], w[q], dev);
        }
        let (gbar, vol) = mean_gradients(&g, &w, nn);
        let kappa_v = (mat.lambda + 2.0 / 3.0 * mat.mu) * vol;
        for r in 0..ndof {
            for c in r..ndof {
                k[r * ndof + c] += kappa_v * gbar[r / 3][r % 3] * gbar[c / 3][c % 3];
            }
        }
        mirror_upper(k, ndof);
        return Ok(());
    }
    for q in 0..w.len() {
        add_isotropic_block(k, ndof, &g[q * nn..(q + 1) * nn], w[q], mat);
    }
    mirror_upper(k, ndof);
    Ok(())
}

/// Element-mean shape-function gradients ḡ_a = (1/V) Σ_q w_q ∇N_a(x_q) and the volume V.
pub(crate) fn mean_gradients(g: &[[f64; 3]], w: &[f64], nn: usize) -> (Vec<[f64; 3]>, f64) {
    let vol: f64 = w.iter().sum();
    let mut gbar = vec![[0.0; 3]; nn];
    for (wq, gq) in w.iter().zip(g.chunks_exact(nn)) {
        for (gb, ga) in gbar.iter_mut().zip(gq) {
            for k in 0..3 {
                gb[k] += wq * ga[k] / vol;
            }
        }
    }
    (gbar, vol)
}

/// Gradients of the three incompatible bubble modes 1−ξ², 1−η², 1−ζ² at each point, evaluated
/// with the centroid Jacobian J₀ and scaled by det J₀ / det J (Taylor–Beresford–Wilson), so
/// that ∫ B_inc dV = 0 and the element passes the patch test on distorted meshes.
fn hex8i_bubble_gradients(x: &[[f64; 3]], tab: &Tabulated, wdet: &[f64]) -> Vec<[f64; 3]> {
    let mut n0 = [0.0; 8];
    let mut dn0 = [[0.0; 3]; 8];
    shape(ShapeKind::Hex8, [0.0; 3], &mut n0, &mut dn0);
    let j0 = jacobian(x, &dn0);
    let det0 = j0.determinant();
    let j0inv = j0.try_inverse().unwrap_or_else(Matrix3::zeros);
    let mut out = Vec::with_capacity(3 * tab.points.len());
    for (q, p) in tab.points.iter().enumerate() {
        let det = wdet[q] / tab.weights[q];
        let scale = det0 / det;
        for m in 0..3 {
            let mut d = [0.0; 3];
            d[m] = -2.0 * p[m];
            let mut g = [0.0; 3];
            for k in 0..3 {
                g[k] = scale * (d[0] * j0inv[(0, k)] + d[1] * j0inv[(1, k)] + d[2] * j0inv[(2, k)]);
            }
            out.push(g);
        }
    }
    out
}

type Mat9 = SMatrix<f64, 9, 9>;
type Mat24x9 = SMatrix<f64, 24, 9>;

/// Extended 11-"node" (8 nodes + 3 bubbles) stiffness blocks of the incompatible hex: the
/// upper triangle of the 33×33 matrix (row-major), K_ci and the whole K_ii.
fn hex8i_blocks(x: &[[f64; 3]], mat: Lame, g: &[[f64; 3]], w: &[f64]) -> (Vec<f64>, Mat24x9, Mat9) {
    let tab = stiffness_rule(ElementKind::Hex8i);
    let bub = hex8i_bubble_gradients(x, tab, w);
    let mut ext = vec![0.0; 33 * 33];
    let mut ga = [[0.0; 3]; 11];
    for q in 0..w.len() {
        ga[..8].copy_from_slice(&g[q * 8..(q + 1) * 8]);
        ga[8..].copy_from_slice(&bub[q * 3..(q + 1) * 3]);
        add_isotropic_block(&mut ext, 33, &ga, w[q], mat);
    }
    // only the upper triangle of `ext` is added (its users read no more): K_ci lies in it,
    // K_ii is read from it symmetrically
    let kci = Mat24x9::from_fn(|r, c| ext[r * 33 + 24 + c]);
    let kii = Mat9::from_fn(|r, c| ext[(24 + r.min(c)) * 33 + 24 + r.max(c)]);
    (ext, kci, kii)
}

fn hex8i_stiffness(
    x: &[[f64; 3]],
    mat: Lame,
    g: &[[f64; 3]],
    w: &[f64],
    k: &mut [f64],
) -> Result<(), BadJacobian> {
    let (ext, kci, kii) = hex8i_blocks(x, mat, g, w);
    // Static condensation of the internal modes: K = K_cc − K_ci K_ii⁻¹ K_ic.
    let chol = kii.cholesky().ok_or(BadJacobian {
        det_j: 0.0,
        inverted: false,
    })?;
    let x_ = chol.solve(&kci.transpose());
    let corr = kci * x_;
    for r in 0..24 {
        for c in r..24 {
            k[r * 24 + c] = ext[r * 33 + c] - corr[(r, c)];
        }
    }
    mirror_upper(k, 24);
    Ok(())
}

/// Consistent scalar mass matrix ρ ∫ N_a N_b dV (2.78), row-major n×n (same for each direction);
/// with `scale` the Arlequin-weighted ρ ∫ (1 − w) N_a N_b dV.
pub fn mass(
    kind: ElementKind,
    x: &[[f64; 3]],
    rho: f64,
    scale: Option<&[f64]>,
    m: &mut Vec<f64>,
) -> Result<(), BadJacobian> {
    let nn = kind.num_nodes();
    m.clear();
    m.resize(nn * nn, 0.0);
    let tab = mass_rule(kind);
    for (q, wq) in point_weights(tab, x, scale).enumerate() {
        let n = &tab.n[q * nn..(q + 1) * nn];
        let f = rho * wq?;
        for a in 0..nn {
            for b in 0..nn {
                m[a * nn + b] += f * n[a] * n[b];
            }
        }
    }
    Ok(())
}

/// Lumped (HRZ diagonal-scaling) nodal masses: positive for quadratic elements too.
pub fn lumped_mass(
    kind: ElementKind,
    x: &[[f64; 3]],
    rho: f64,
    scale: Option<&[f64]>,
    out: &mut [f64],
) -> Result<(), BadJacobian> {
    // HRZ needs the consistent mass's diagonal, m_aa = Σ_q ρ w_q det J_q N_a², and its total,
    // Σ_ab m_ab = Σ_q ρ w_q det J_q (the N_a sum to 1): no full matrix, no gradients
    let nn = kind.num_nodes();
    let tab = mass_rule(kind);
    let mut total = 0.0;
    out[..nn].fill(0.0);
    for (q, wq) in point_weights(tab, x, scale).enumerate() {
        let n = &tab.n[q * nn..(q + 1) * nn];
        let f = rho * wq?;
        total += f;
        for a in 0..nn {
            out[a] += f * n[a] * n[a];
        }
    }
    let diag: f64 = out[..nn].iter().sum();
    for o in &mut out[..nn] {
        *o *= total / diag;
    }
    Ok(())
}

/// Element volume.
pub fn volume(kind: ElementKind, x: &[[f64; 3]]) -> Result<f64, BadJacobian> {
    point_weights(mass_rule(kind), x, None).sum()
}

/// Displacement gradients at the integration points and their weights w_q det J_q.
pub type PointGradients = (Vec<[[f64; 3]; 3]>, Vec<f64>);

/// Displacement gradients H_ij = ∂u_i/∂x_j at the element's stiffness integration points,
/// with their weights w_q det J_q. For the incompatible hex the condensed internal modes
/// α = −K_ii⁻¹ K_ic u are recovered and their gradients added, so that the strain is the one
/// the element's stiffness saw.
pub fn point_gradients(
    kind: ElementKind,
    x: &[[f64; 3]],
    u: &[[f64; 3]],
    mat: Lame,
) -> Result<PointGradients, BadJacobian> {
    let nn = kind.num_nodes();
    let tab = stiffness_rule(kind);
    let mut g = Vec::new();
    let mut w = Vec::new();
    gradients(tab, x, &mut g, &mut w)?;
    let mut bub_amp = [[0.0; 3]; 3];
    let mut bub = Vec::new();
    if kind == ElementKind::Hex8i {
        let (_, kci, kii) = hex8i_blocks(x, mat, &g, &w);
        let ue = SMatrix::<f64, 24, 1>::from_fn(|r, _| u[r / 3][r % 3]);
        let rhs = -(kci.transpose() * ue);
        if let Some(ch) = kii.cholesky() {
            let al = ch.solve(&rhs);
            for m in 0..3 {
                for i in 0..3 {
                    bub_amp[m][i] = al[3 * m + i];
                }
            }
        }
        bub = hex8i_bubble_gradients(x, tab, &w);
    }
    let mut out = Vec::with_capacity(w.len());
    for q in 0..w.len() {
        let mut h = [[0.0; 3]; 3];
        for a in 0..nn {
            let ga = g[q * nn + a];
            for i in 0..3 {
                for j in 0..3 {
                    h[i][j] += u[a][i] * ga[j];
                }
            }
        }
        if kind == ElementKind::Hex8i {
            for m in 0..3 {
                let ga = bub[q * 3 + m];
                for i in 0..3 {
                    for j in 0..3 {
                        h[i][j] += bub_amp[m][i] * ga[j];
                    }
                }
            }
        }
        out.push(h);
    }
    if kind == ElementKind::Hex8b {
        // B̄: the volumetric part of each point's gradient is the element mean
        let (gbar, _) = mean_gradients(&g, &w, nn);
        let mean_tr: f64 = (0..nn)
            .map(|a| (0..3).map(|i| gbar[a][i] * u[a][i]).sum::<f64>())
            .sum();
        for h in &mut out {
            let shift = (mean_tr - (h[0][0] + h[1][1] + h[2][2])) / 3.0;
            for (i, row) in h.iter_mut().enumerate() {
                row[i] += shift;
            }
        }
    }
    Ok((out, w))
}

/// Mean Cauchy stress over the element's integration points, Voigt order
/// (xx, yy, zz, xy, yz, zx), from σ = λ tr ε I + 2 μ ε (2.37).
pub fn mean_stress(
    kind: ElementKind,
    x: &[[f64; 3]],
    u: &[[f64; 3]],
    mat: Lame,
) -> Result<[f64; 6], BadJacobian> {
    let (h, w) = point_gradients(kind, x, u, mat)?;
    let vol: f64 = w.iter().sum();
    let mut acc = [0.0; 6];
    for (hq, wq) in h.iter().zip(&w) {
        let s = stress_from_gradient(hq, mat);
        for c in 0..6 {
            acc[c] += s[c] * wq / vol;
        }
    }
    Ok(acc)
}

/// Small-strain tensor ε = ½(H + Hᵀ) (2.32) at each stiffness integration point, as
/// (xx, yy, zz, xy, yz, zx) tensor components (not engineering shear).
pub fn point_strains(
    kind: ElementKind,
    x: &[[f64; 3]],
    u: &[[f64; 3]],
    mat: Lame,
) -> Result<Vec<[f64; 6]>, BadJacobian> {
    let (h, _) = point_gradients(kind, x, u, mat)?;
    Ok(h.iter().map(strain_from_gradient).collect())
}

/// ε = ½(H + Hᵀ) as (xx, yy, zz, xy, yz, zx) tensor components.
pub fn strain_from_gradient(h: &[[f64; 3]; 3]) -> [f64; 6] {
    [
        h[0][0],
        h[1][1],
        h[2][2],
        0.5 * (h[0][1] + h[1][0]),
        0.5 * (h[1][2] + h[2][1]),
        0.5 * (h[2][0] + h[0][2]),
    ]
}

/// Principal values of a symmetric tensor given as (xx, yy, zz, xy, yz, zx), ascending.
pub fn principal_values(t: &[f64; 6]) -> [f64; 3] {
    let m = Matrix3::new(t[0], t[3], t[5], t[3], t[1], t[4], t[5], t[4], t[2]);
    let e = m.symmetric_eigenvalues();
    let mut v = [e[0], e[1], e[2]];
    v.sort_by(f64::total_cmp);
    v
}

/// Von Mises equivalent strain ε_eq = √(⅔ e:e), e = ε − ⅓ tr ε I (tensor components):
/// equals the axial strain in incompressible uniaxial tension, (2/3)(1+ν) ε for a linear
/// elastic bar.
pub fn von_mises_strain(e: &[f64; 6]) -> f64 {
    let m = (e[0] + e[1] + e[2]) / 3.0;
    let (a, b, c) = (e[0] - m, e[1] - m, e[2] - m);
    let ee = a * a + b * b + c * c + 2.0 * (e[3] * e[3] + e[4] * e[4] + e[5] * e[5]);
    (2.0 / 3.0 * ee).sqrt()
}

/// σ (Voigt xx,yy,zz,xy,yz,zx) from the displacement gradient, eqs. (2.32), (2.37).
pub fn stress_from_gradient(h: &[[f64; 3]; 3], mat: Lame) -> [f64; 6] {
    let tr = h[0][0] + h[1][1] + h[2][2];
    let l = mat.lambda * tr;
    [
        l + 2.0 * mat.mu * h[0][0],
        l + 2.0 * mat.mu * h[1][1],
        l + 2.0 * mat.mu * h[2][2],
        mat.mu * (h[0][1] + h[1][0]),
        mat.mu * (h[1][2] + h[2][1]),
        mat.mu * (h[2][0] + h[0][2]),
    ]
}

/// Von Mises equivalent stress.
pub fn von_mises(s: &[f64; 6]) -> f64 {
    let (a, b, c) = (s[0] - s[1], s[1] - s[2], s[2] - s[0]);
    (0.5 * (a * a + b * b + c * c) + 3.0 * (s[3] * s[3] + s[4] * s[4] + s[5] * s[5])).sqrt()
}

/// Consistent nodal loads of a uniform pressure p on a face (positive p pushes against the
/// outward normal): f_a = −p ∫ N_a n dA, the (v, h)_Γ term of (2.46).
pub fn face_pressure_loads(face_x: &[[f64; 3]], p: f64, out: &mut [[f64; 3]]) {
    let nn = face_x.len();
    let rule: Vec<([f64; 2], f64)> = match nn {
        3 | 6 => vec![
            ([1.0 / 6.0, 1.0 / 6.0], 1.0 / 6.0),
            ([2.0 / 3.0, 1.0 / 6.0], 1.0 / 6.0),
            ([1.0 / 6.0, 2.0 / 3.0], 1.0 / 6.0),
        ],
        _ => {
            let g = gauss_1d(if nn == 4 { 2 } else { 3 });
            let mut r = Vec::new();
            for &(t, wt) in &g {
                for &(s, ws) in &g {
                    r.push(([s, t], ws * wt));
                }
            }
            r
        }
    };
    for o in out.iter_mut() {
        *o = [0.0; 3];
    }
    let mut n = [0.0; 8];
    let mut dn = [[0.0; 2]; 8];
    for (pt, w) in rule {
        face_shape(nn, pt, &mut n, &mut dn);
        let mut ts = Vector3::zeros();
        let mut tt = Vector3::zeros();
        for a in 0..nn {
            let xa = Vector3::from(face_x[a]);
            ts += xa * dn[a][0];
            tt += xa * dn[a][1];
        }
        // n dA = (∂x/∂s × ∂x/∂t) ds dt, outward for the faces' corner ordering
        let nda = ts.cross(&tt) * w;
        for a in 0..nn {
            for k in 0..3 {
                out[a][k] -= p * n[a] * nda[k];
            }
        }
    }
}

/// Face shape functions: tri3, tri6 (corners, then mids 01,12,20), quad4, quad8 (corners, then
/// mids 01,12,23,30).
pub(crate) fn face_shape(nn: usize, p: [f64; 2], n: &mut [f64], dn: &mut [[f64; 2]]) {
    let [s, t] = p;
    match nn {
        3 => {
            n[..3].copy_from_slice(&[1.0 - s - t, s, t]);
            dn[..3].copy_from_slice(&[[-1.0, -1.0], [1.0, 0.0], [0.0, 1.0]]);
        }
        6 => {
            let l = [1.0 - s - t, s, t];
            let dl = [[-1.0, -1.0], [1.0, 0.0], [0.0, 1.0]];
            for a in 0..3 {
                n[a] = l[a] * (2.0 * l[a] - 1.0);
                for k in 0..2 {
                    dn[a][k] = (4.0 * l[a] - 1.0) * dl[a][k];
                }
            }
            for (m, (i, j)) in [(0, 1), (1, 2), (2, 0)].into_iter().enumerate() {
                n[3 + m] = 4.0 * l[i] * l[j];
                for k in 0..2 {
                    dn[3 + m][k] = 4.0 * (dl[i][k] * l[j] + l[i] * dl[j][k]);
                }
            }
        }
        4 => {
            const C: [[f64; 2]; 4] = [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]];
            for a in 0..4 {
                let (fs, ft) = (1.0 + C[a][0] * s, 1.0 + C[a][1] * t);
                n[a] = 0.25 * fs * ft;
                dn[a] = [0.25 * C[a][0] * ft, 0.25 * C[a][1] * fs];
            }
        }
        8 => {
            const C: [[f64; 2]; 8] = [
                [-1.0, -1.0],
                [1.0, -1.0],
                [1.0, 1.0],
                [-1.0, 1.0],
                [0.0, -1.0],
                [1.0, 0.0],
                [0.0, 1.0],
                [-1.0, 0.0],
            ];
            for a in 0..8 {
                let [sa, ta] = C[a];
                if a < 4 {
                    let (fs, ft) = (1.0 + sa * s, 1.0 + ta * t);
                    let g = sa * s + ta * t - 1.0;
                    n[a] = 0.25 * fs * ft * g;
                    dn[a] = [0.25 * sa * ft * (g + fs), 0.25 * ta * fs * (g + ft)];
                } else if sa == 0.0 {
                    let ft = 1.0 + ta * t;
                    n[a] = 0.5 * (1.0 - s * s) * ft;
                    dn[a] = [-s * ft, 0.5 * (1.0 - s * s) * ta];
                } else {
                    let fs = 1.0 + sa * s;
                    n[a] = 0.5 * (1.0 - t * t) * fs;
                    dn[a] = [0.5 * (1.0 - t * t) * sa, -t * fs];
                }
            }
        }
        _ => unreachable!("face with {nn} nodes"),
    }
}

/// Splits a face (tri3/tri6/quad4/quad8 local node list) into linear triangles with the
/// face's orientation, using the mid-side nodes of quadratic faces.
pub fn triangulate_face(face: &[u32], out: &mut Vec<[u32; 3]>) {
    match face.len() {
        3 => out.push([face[0], face[1], face[2]]),
        4 => {
            out.push([face[0], face[1], face[2]]);
            out.push([face[0], face[2], face[3]]);
        }
        6 => {
            let (c0, c1, c2, m01, m12, m20) =
                (face[0], face[1], face[2], face[3], face[4], face[5]);
            out.push([c0, m01, m20]);
            out.push([m01, c1, m12]);
            out.push([m20, m12, c2]);
            out.push([m01, m12, m20]);
        }
        8 => {
            let c = &face[..4];
            let m = &face[4..];
            // corner triangles (c_k, m_k, m_{k-1}), then the inner quad of mid-side nodes
            for k in 0..4 {
                out.push([c[k], m[k], m[(k + 3) % 4]]);
            }
            out.push([m[0], m[1], m[2]]);
            out.push([m[0], m[2], m[3]]);
        }
        _ => unreachable!(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shape_functions_partition_unity_and_interpolate_nodes() {
        for kind in [
            ElementKind::Tet4,
            ElementKind::Tet10,
            ElementKind::Hex8,
            ElementKind::Hex20,
        ] {
            let nn = kind.num_nodes();
            let refs = kind.reference_nodes();
            let mut n = vec![0.0; nn];
            let mut dn = vec![[0.0; 3]; nn];
            for (a, p) in refs.iter().enumerate() {
                shape(kind.shape_kind(), *p, &mut n, &mut dn);
                for b in 0..nn {
                    let e = if a == b { 1.0 } else { 0.0 };
                    assert!((n[b] - e).abs() < 1e-14, "{kind:?} N_{b}({a}) = {}", n[b]);
                }
            }
            // derivative consistency by finite differences at an interior point
            let p = [0.21, 0.17, 0.13];
            shape(kind.shape_kind(), p, &mut n, &mut dn);
            let s: f64 = n.iter().sum();
            assert!((s - 1.0).abs() < 1e-14);
            for k in 0..3 {
                let mut pp = p;
                pp[k] += 1e-7;
                let mut n2 = vec![0.0; nn];
                let mut dn2 = vec![[0.0; 3]; nn];
                shape(kind.shape_kind(), pp, &mut n2, &mut dn2);
                for a in 0..nn {
                    let fd = (n2[a] - n[a]) / 1e-7;
                    assert!(
                        (fd - dn[a][k]).abs() < 1e-6,
                        "{kind:?} dN{a}/dξ{k}: {fd} vs {}",
                        dn[a][k]
                    );
                }
            }
        }
    }

    /// The element stiffness (upper node blocks at each point, mirrored once) is exactly
    /// symmetric, has the six rigid modes in its kernel, and a linear field u = E x gives the
    /// energy uᵀKu = V (λ (tr E)² + 2μ E:E) of its constant strain: for every kind, on a
    /// non-affine element.
    #[test]
    fn element_stiffness_is_symmetric_with_rigid_modes_and_exact_constant_strain_energy() {
        let mat = Lame {
            lambda: 3.0,
            mu: 2.0,
        };
        let e = [[0.3, 0.1, -0.2], [0.1, -0.4, 0.05], [-0.2, 0.05, 0.7]];
        for kind in [
            ElementKind::Tet4,
            ElementKind::Tet10,
            ElementKind::Hex8,
            ElementKind::Hex8i,
            ElementKind::Hex8b,
            ElementKind::Hex20,
        ] {
            let x: Vec<[f64; 3]> = kind
                .reference_nodes()
                .iter()
                .map(|p| {
                    [
                        2.0 * p[0] + 0.3 * p[1] + 0.1 * p[0] * p[1],
                        3.0 * p[1] + 0.05 * p[1] * p[2],
                        4.0 * p[2] - 0.1 * p[2] * p[0],
                    ]
                })
                .collect();
            let mut k = Vec::new();
            stiffness(kind, &x, mat, None, &mut k).unwrap();
            let nd = 3 * kind.num_nodes();
            let kmax = k.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            for r in 0..nd {
                for c in 0..nd {
                    assert_eq!(k[r * nd + c], k[c * nd + r], "{kind:?} K[{r}][{c}]");
                }
            }
            let apply = |u: &[f64]| -> Vec<f64> {
                (0..nd)
                    .map(|r| (0..nd).map(|c| k[r * nd + c] * u[c]).sum())
                    .collect()
            };
            // three translations, three rotations
            for m in 0..6 {
                let u: Vec<f64> = x
                    .iter()
                    .flat_map(|p| {
                        let mut d = [0.0; 3];
                        if m < 3 {
                            d[m] = 1.0;
                        } else {
                            let (i, j) = ((m + 1) % 3, (m + 2) % 3);
                            d[i] = -p[j];
                            d[j] = p[i];
                        }
                        d
                    })
                    .collect();
                let f = apply(&u);
                let worst = f.iter().fold(0.0f64, |a, v| a.max(v.abs()));
                assert!(
                    worst < 1e-12 * kmax * 4.0,
                    "{kind:?} rigid mode {m}: {worst}"
                );
            }
            let u: Vec<f64> = x
                .iter()
                .flat_map(|p| [0, 1, 2].map(|i| e[i][0] * p[0] + e[i][1] * p[1] + e[i][2] * p[2]))
                .collect();
            let energy: f64 = u.iter().zip(apply(&u)).map(|(a, b)| a * b).sum();
            let (mut g, mut w) = (Vec::new(), Vec::new());
            gradients(stiffness_rule(kind), &x, &mut g, &mut w).unwrap();
            let vol: f64 = w.iter().sum();
            let tr = e[0][0] + e[1][1] + e[2][2];
            let ee: f64 = e.iter().flatten().map(|v| v * v).sum();
            let exact = vol * (mat.lambda * tr * tr + 2.0 * mat.mu * ee);
            assert!(
                (energy - exact).abs() < 1e-11 * exact,
                "{kind:?}: uᵀKu = {energy}, V(λ tr² + 2μ E:E) = {exact}"
            );
        }
    }

    #[test]
    fn element_masses_sum_to_rho_volume() {
        for kind in [
            ElementKind::Tet4,
            ElementKind::Tet10,
            ElementKind::Hex8,
            ElementKind::Hex20,
        ] {
            // reference element mapped by an affine map with det 2·3·4 = 24
            let x: Vec<[f64; 3]> = kind
                .reference_nodes()
                .iter()
                .map(|p| [2.0 * p[0] + 0.3 * p[1], 3.0 * p[1], 4.0 * p[2]])
                .collect();
            let vref = if kind.num_corners() == 4 {
                1.0 / 6.0
            } else {
                8.0
            };
            let mut m = Vec::new();
            mass(kind, &x, 7.0, None, &mut m).unwrap();
            let total: f64 = m.iter().sum();
            assert!(
                (total - 7.0 * 24.0 * vref).abs() < 1e-10 * total,
                "{kind:?}: {total}"
            );
            let mut l = vec![0.0; kind.num_nodes()];
            lumped_mass(kind, &x, 7.0, None, &mut l).unwrap();
            assert!(l.iter().all(|&v| v > 0.0));
        }
    }

    #[test]
    fn face_pressure_resultant_is_pressure_times_area() {
        // quad8 and tri6 on a flat 2×3 rectangle / right triangle in z = 1, outward normal +z
        let quad8 = [
            [0.0, 0.0, 1.0],
            [2.0, 0.0, 1.0],
            [2.0, 3.0, 1.0],
            [0.0, 3.0, 1.0],
            [1.0, 0.0, 1.0],
            [2.0, 1.5, 1.0],
            [1.0, 3.0, 1.0],
            [0.0, 1.5, 1.0],
        ];
        let mut f = [[0.0; 3]; 8];
        face_pressure_loads(&quad8, 10.0, &mut f);
        let fz: f64 = f.iter().map(|v| v[2]).sum();
        assert!((fz + 60.0).abs() < 1e-12);
        // serendipity quad8 under uniform pressure: corners −1/12, mids +1/3 of the total
        assert!((f[0][2] - 60.0 / 12.0).abs() < 1e-12 && (f[4][2] + 60.0 / 3.0).abs() < 1e-12);
        let tri6 = [
            [0.0, 0.0, 0.0],
            [2.0, 0.0, 0.0],
            [0.0, 2.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
        ];
        let mut f = [[0.0; 3]; 6];
        face_pressure_loads(&tri6, 1.0, &mut f);
        assert!(f[0][2].abs() < 1e-14 && (f[3][2] + 2.0 / 3.0).abs() < 1e-12);
    }
}
