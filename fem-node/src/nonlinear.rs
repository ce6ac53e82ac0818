//! Element internal forces and consistent tangents from stresses, for any [`Model`]:
//! small strain f_a = ∫ B_aᵀ σ dV, K_ab = ∫ B_aᵀ D B_b dV (B̄ for hex8b: the volumetric rows
//! use the element-mean gradients), and total Lagrangian finite strain
//! f_a = ∫ B_L,aᵀ S dV₀, K_ab = ∫ B_L,aᵀ ℂ B_L,b dV₀ + ∫ (∇N_a · S ∇N_b) I dV₀
//! (material + geometric stiffness; Wellmann §2.1.4, Wriggers 2008 ch. 4). One routine serves
//! the Newton solvers (with tangent) and the explicit scheme (forces only).

use crate::element::{self, BadJacobian, ElementKind};
use crate::material::{Model, PointFailure};

/// Reusable buffers of one worker (no allocation per element).
#[derive(Default)]
pub struct Scratch {
    g: Vec<[f64; 3]>,
    w: Vec<f64>,
    /// The element's nodal Arlequin factors 1 − w (empty outside an overlap): the caller sets
    /// them with [`Scratch::set_scale`] before each element.
    scale: Vec<f64>,
    gbar: Vec<[f64; 3]>,
    b: Vec<[[f64; 3]; 6]>,
    db: Vec<[[f64; 3]; 6]>,
}

impl Scratch {
    /// The nodal Arlequin factors of the next element (`None`: unweighted).
    pub fn set_scale(&mut self, scale: Option<&[f64]>) {
        self.scale.clear();
        if let Some(s) = scale {
            self.scale.extend_from_slice(s);
        }
    }
}

/// Why an element could not be evaluated.
#[derive(Clone, Copy, Debug)]
pub enum ElementFailure {
    /// The reference geometry is bad (checked when the mesh is read; kept for completeness).
    Jacobian(BadJacobian),
    /// An integration point of the deformed element failed.
    Point { point: usize, failure: PointFailure },
}

impl std::fmt::Display for ElementFailure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ElementFailure::Jacobian(b) => write!(f, "det J = {:.3e}", b.det_j),
            ElementFailure::Point { point, failure } => {
                write!(f, "integration point {}: {failure}", point + 1)
            }
        }
    }
}

/// Number of integration points of an element kind (the stiffness rule).
pub fn num_points(kind: ElementKind) -> usize {
    element::stiffness_rule(kind).weights.len()
}

/// Displacement gradients at the integration points into `h` (B̄-corrected for small-strain
/// hex8b), with the gradients and weights left in `s`.
fn point_gradients(
    kind: ElementKind,
    x: &[[f64; 3]],
    u: &[[f64; 3]],
    finite: bool,
    s: &mut Scratch,
    h: &mut Vec<[[f64; 3]; 3]>,
) -> Result<bool, ElementFailure> {
    let nn = kind.num_nodes();
    let tab = element::stiffness_rule(kind);
    element::gradients(tab, x, &mut s.g, &mut s.w).map_err(ElementFailure::Jacobian)?;
    if !s.scale.is_empty() {
        element::scale_weights(tab, Some(&s.scale), &mut s.w);
    }
    let bbar = kind == ElementKind::Hex8b && !finite;
    let mut mean_tr = 0.0;
    if bbar {
        let vol: f64 = s.w.iter().sum();
        s.gbar.clear();
        s.gbar.resize(nn, [0.0; 3]);
        for (wq, gq) in s.w.iter().zip(s.g.chunks_exact(nn)) {
            for (gb, ga) in s.gbar.iter_mut().zip(gq) {
                for k in 0..3 {
                    gb[k] += wq * ga[k] / vol;
                }
            }
        }
        mean_tr = (0..nn)
            .map(|a| (0..3).map(|i| s.gbar[a][i] * u[a][i]).sum::<f64>())
            .sum();
    }
    h.clear();
    for q in 0..s.w.len() {
        let g = &s.g[q * nn..(q + 1) * nn];
        let mut hq = [[0.0; 3]; 3];
        for a in 0..nn {
            for i in 0..3 {
                for j in 0..3 {
                    hq[i][j] += u[a][i] * g[a][j];
                }
            }
        }
        if bbar {
            let shift = (mean_tr - (hq[0][0] + hq[1][1] + hq[2][2])) / 3.0;
            for (i, row) in hq.iter_mut().enumerate() {
                row[i] += shift;
            }
        }
        h.push(hq);
    }
    Ok(bbar)
}

/// Internal forces `f` (3n, dof 3a+i) and, with `k`, the tangent (row-major 3n×3n) of one
/// element at nodal displacements `u`, from the committed point states `state_n`
/// (`num_points × state_len` values); the trial states go to `state_new`. Returns the stored
/// energy ∫ Ψ dV₀ [J].
#[allow(clippy::too_many_arguments)]
pub fn element_response(
    kind: ElementKind,
    x: &[[f64; 3]],
    u: &[[f64; 3]],
    model: &Model,
    state_n: &[f64],
    state_new: &mut [f64],
    f: &mut [f64],
    mut k: Option<&mut [f64]>,
    s: &mut Scratch,
    h: &mut Vec<[[f64; 3]; 3]>,
) -> Result<f64, ElementFailure> {
    let nn = kind.num_nodes();
    let nd = 3 * nn;
    let finite = model.finite_strain();
    let bbar = point_gradients(kind, x, u, finite, s, h)?;
    f[..nd].fill(0.0);
    if let Some(k) = k.as_deref_mut() {
        k[..nd * nd].fill(0.0);
    }
    let sl = model.state_len();
    s.b.resize(nn, [[0.0; 3]; 6]);
    s.db.resize(nn, [[0.0; 3]; 6]);
    let mut energy = 0.0;
    for q in 0..s.w.len() {
        let g = &s.g[q * nn..(q + 1) * nn];
        let wq = s.w[q];
        let hq = &h[q];
        let r = model
            .evaluate(
                hq,
                &state_n[q * sl..(q + 1) * sl],
                &mut state_new[q * sl..(q + 1) * sl],
            )
            .map_err(|failure| ElementFailure::Point { point: q, failure })?;
        energy += wq * r.energy;
        // B_a: 6 rows (Voigt, engineering shear) × 3 columns (u_a components)
        for a in 0..nn {
            let ga = g[a];
            let b = &mut s.b[a];
            if finite {
                // δÊ = B_L δu with δE = sym(Fᵀ δH): rows F_i1 g1, F_i2 g2, F_i3 g3,
                // F_i1 g2 + F_i2 g1, F_i2 g3 + F_i3 g2, F_i3 g1 + F_i1 g3 (F = I + H)
                for i in 0..3 {
                    let fi = |j: usize| hq[i][j] + if i == j { 1.0 } else { 0.0 };
                    b[0][i] = fi(0) * ga[0];
                    b[1][i] = fi(1) * ga[1];
                    b[2][i] = fi(2) * ga[2];
                    b[3][i] = fi(0) * ga[1] + fi(1) * ga[0];
                    b[4][i] = fi(1) * ga[2] + fi(2) * ga[1];
                    b[5][i] = fi(2) * ga[0] + fi(0) * ga[2];
                }
            } else {
                *b = [
                    [ga[0], 0.0, 0.0],
                    [0.0, ga[1], 0.0],
                    [0.0, 0.0, ga[2]],
                    [ga[1], ga[0], 0.0],
                    [0.0, ga[2], ga[1]],
                    [ga[2], 0.0, ga[0]],
                ];
                if bbar {
                    // volumetric part from the element mean: + ⅓(ḡ_a − g_a)_j in rows 0..3
                    let gb = s.gbar[a];
                    for row in b.iter_mut().take(3) {
                        for j in 0..3 {
                            row[j] += (gb[j] - ga[j]) / 3.0;
                        }
                    }
                }
            }
        }
        let sig = r.stress;
        for a in 0..nn {
            let b = &s.b[a];
            for i in 0..3 {
                let mut v = 0.0;
                for rr in 0..6 {
                    v += b[rr][i] * sig[rr];
                }
                f[3 * a + i] += wq * v;
            }
        }
        let Some(k) = k.as_deref_mut() else {
            continue;
        };
        let d = r.tangent;
        for bn in 0..nn {
            let b = &s.b[bn];
            let db = &mut s.db[bn];
            for rr in 0..6 {
                for j in 0..3 {
                    let mut v = 0.0;
                    for c in 0..6 {
                        v += d[(rr, c)] * b[c][j];
                    }
                    db[rr][j] = wq * v;
                }
            }
        }
        for a in 0..nn {
            let ba = &s.b[a];
            for bn in 0..nn {
                let db = &s.db[bn];
                let geo = if finite {
                    // ∇N_a · S ∇N_b
                    let (ga, gb) = (g[a], g[bn]);
                    let sg = [
                        sig[0] * gb[0] + sig[3] * gb[1] + sig[5] * gb[2],
                        sig[3] * gb[0] + sig[1] * gb[1] + sig[4] * gb[2],
                        sig[5] * gb[0] + sig[4] * gb[1] + sig[2] * gb[2],
                    ];
                    wq * (ga[0] * sg[0] + ga[1] * sg[1] + ga[2] * sg[2])
                } else {
                    0.0
                };
                for i in 0..3 {
                    let row = (3 * a + i) * nd + 3 * bn;
                    for j in 0..3 {
                        let mut v = 0.0;
                        for rr in 0..6 {
                            v += ba[rr][i] * db[rr][j];
                        }
                        if i == j {
                            v += geo;
                        }
                        k[row + j] += v;
                    }
                }
            }
        }
    }
    Ok(energy)
}

/// Per integration point: Cauchy stress (Voigt) and weight det J · w, from the committed
/// state (the stress the converged state carries).
pub fn point_stresses(
    kind: ElementKind,
    x: &[[f64; 3]],
    u: &[[f64; 3]],
    model: &Model,
    state_n: &[f64],
    s: &mut Scratch,
    out: &mut Vec<([f64; 6], f64)>,
) -> Result<(), ElementFailure> {
    let mut h = Vec::new();
    point_gradients(kind, x, u, model.finite_strain(), s, &mut h)?;
    let sl = model.state_len();
    let mut scratch_state = [0.0; crate::material::MOHR_COULOMB_STATE];
    out.clear();
    for (q, hq) in h.iter().enumerate() {
        let r = model
            .evaluate(hq, &state_n[q * sl..(q + 1) * sl], &mut scratch_state[..sl])
            .map_err(|failure| ElementFailure::Point { point: q, failure })?;
        out.push((crate::material::cauchy(model, hq, &r.stress), s.w[q]));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::element::Lame;
    use crate::material::hyperelastic::{MooneyRivlin, NeoHooke, Ogden};
    use crate::material::mohr_coulomb::MohrCoulomb;

    fn rng(seed: &mut u64) -> f64 {
        *seed ^= *seed << 13;
        *seed ^= *seed >> 7;
        *seed ^= *seed << 17;
        (*seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    }

    /// The element tangent equals central differences of the element forces, for every
    /// model and element kind (hex8b only small strain), at random displacements.
    #[test]
    fn element_tangent_matches_finite_differences_of_the_forces() {
        let models = [
            Model::Linear(Lame::from_young_poisson(1e7, 0.3)),
            Model::NeoHooke(NeoHooke::from_young_poisson(1e7, 0.3)),
            Model::MooneyRivlin(MooneyRivlin::from_young_poisson_ratio(1e7, 0.41, 0.2)),
            Model::Ogden(
                Ogden::new(2e6, &[(745.5e3, 1.3), (1.5e3, 5.0), (-11.85e3, -2.0)]).unwrap(),
            ),
            Model::MohrCoulomb(MohrCoulomb::new(
                1e7,
                0.3,
                30f64.to_radians(),
                10f64.to_radians(),
                1e3,
            )),
        ];
        let mut seed = 0x2545_F491_4F6C_DD1Du64;
        for kind in [
            ElementKind::Tet4,
            ElementKind::Tet10,
            ElementKind::Hex8,
            ElementKind::Hex8b,
            ElementKind::Hex20,
        ] {
            for model in &models {
                if kind == ElementKind::Hex8b && model.finite_strain() {
                    continue;
                }
                let nn = kind.num_nodes();
                let nd = 3 * nn;
                let x: Vec<[f64; 3]> = kind
                    .reference_nodes()
                    .iter()
                    .map(|p| [0.1 * p[0] + 0.01 * rng(&mut seed), 0.1 * p[1], 0.1 * p[2]])
                    .collect();
                // MC: a compressive triaxial strain that yields, plus a random part
                let plastic = matches!(model, Model::MohrCoulomb(_));
                let amp = if plastic { 1e-5 } else { 0.02 };
                let base = if plastic {
                    [-1e-2, 1e-3, 1e-3]
                } else {
                    [0.0; 3]
                };
                let u: Vec<[f64; 3]> = x
                    .iter()
                    .map(|p| [0, 1, 2].map(|c| base[c] * p[c] + amp * rng(&mut seed)))
                    .collect();
                let np = num_points(kind);
                let sl = model.state_len();
                let st_n = vec![0.0; np * sl];
                let mut st = vec![0.0; np * sl];
                let mut s = Scratch::default();
                let mut h = Vec::new();
                let mut f = vec![0.0; nd];
                let mut k = vec![0.0; nd * nd];
                element_response(
                    kind,
                    &x,
                    &u,
                    model,
                    &st_n,
                    &mut st,
                    &mut f,
                    Some(&mut k),
                    &mut s,
                    &mut h,
                )
                .unwrap();
                if plastic {
                    assert!(
                        (0..np).all(|q| st[q * sl + 7] == 1.0),
                        "{kind:?}: every point yields"
                    );
                }
                let kmax = k.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                let eps = 1e-7 * amp.max(1e-3);
                let mut worst: f64 = 0.0;
                for j in 0..nd {
                    let mut up = u.clone();
                    let mut um = u.clone();
                    up[j / 3][j % 3] += eps;
                    um[j / 3][j % 3] -= eps;
                    let mut fp = vec![0.0; nd];
                    let mut fm = vec![0.0; nd];
                    element_response(
                        kind, &x, &up, model, &st_n, &mut st, &mut fp, None, &mut s, &mut h,
                    )
                    .unwrap();
                    element_response(
                        kind, &x, &um, model, &st_n, &mut st, &mut fm, None, &mut s, &mut h,
                    )
                    .unwrap();
                    for i in 0..nd {
                        let fd = (fp[i] - fm[i]) / (2.0 * eps);
                        worst = worst.max((fd - k[i * nd + j]).abs() / kmax);
                    }
                }
                println!("{kind:?} {}: tangent error {worst:.2e}", model.kind_name());
                // (Mohr–Coulomb edge returns carry a trace of the elastic stiffness; the exact
                // consistent tangent is checked in material::mohr_coulomb to 1e-8)
                let tol = if plastic {
                    1e-6 + 2.0 * crate::material::EDGE_REGULARISATION
                } else {
                    1e-6
                };
                assert!(
                    worst < tol,
                    "{kind:?} {}: tangent error {worst:e}",
                    model.kind_name()
                );
            }
        }
    }
}
