//! Materials per element set, internal forces from stresses, and the Newton–Raphson solvers of
//! nonlinear models: static load stepping with cut-back, Bossak–Newmark with Newton
//! iterations on the new acceleration (time-step cut-back), and the explicit scheme's forces.
//! When every material is linear elastic none of this runs (the cached-factor path stays).

use super::{check_finite, Model};
use crate::assembly::{self, Factor, LuFactor, MAX_ELEMENT_MATRIX};
use crate::config::{Analysis, FemConfig, MaterialSpec, SectionElements, TangentUpdate};
use crate::element::{ElementKind, Lame};
use crate::material::hyperelastic::{MooneyRivlin, NeoHooke, Ogden};
use crate::material::mohr_coulomb::MohrCoulomb;
use crate::material::{Material, Model as Law};
use crate::mesh::Mesh;
use crate::nonlinear::{self, ElementFailure, Scratch};
use crate::FemError;
use numeric::dot;
use rayon::prelude::*;

/// The materials of a scene (named ones in name order, then `[fem.material]`) and each
/// element's material index.
pub(super) fn assign_materials(
    cfg: &FemConfig,
    mesh: &Mesh,
) -> Result<(Vec<Material>, Vec<u32>), FemError> {
    let mut materials = Vec::new();
    let mut index = std::collections::BTreeMap::new();
    for (name, spec) in &cfg.materials {
        index.insert(name.clone(), materials.len() as u32);
        materials.push(Material {
            name: format!("fem.materials.{name}"),
            model: law(spec),
            density: spec.density(),
        });
    }
    let default = cfg.material.as_ref().map(|m| {
        materials.push(Material {
            name: "fem.material".into(),
            model: Law::Linear(Lame::from_young_poisson(m.youngs_modulus, m.poisson_ratio)),
            density: m.density,
        });
        materials.len() as u32 - 1
    });
    const NONE: u32 = u32::MAX;
    let ne = mesh.num_elements();
    let mut of = vec![NONE; ne];
    let mut by: Vec<usize> = vec![usize::MAX; ne];
    for (i, sec) in cfg.sections.iter().enumerate() {
        let what = format!("fem.sections[{i}].elements");
        let elements: Vec<u32> = match &sec.elements {
            SectionElements::Set(name) if name == "all" => (0..ne as u32).collect(),
            SectionElements::Set(name) => match mesh.elem_set(name) {
                Some(set) => set.clone(),
                None => {
                    let known: Vec<&str> = mesh.elem_sets.keys().map(String::as_str).collect();
                    return Err(FemError::Selection(format!(
                        "{what}: no element set \"{name}\" in {} (sets: {}; or \"all\", or a \
                         box / plane selector)",
                        mesh.source,
                        if known.is_empty() {
                            "none".to_string()
                        } else {
                            known.join(", ")
                        }
                    )));
                }
            },
            SectionElements::Select(sel) => super::gauge_elements(mesh, Some(sel), &what)?,
        };
        let m = index[&sec.material];
        for e in elements {
            let e = e as usize;
            if by[e] != usize::MAX && by[e] != i {
                return Err(FemError::Selection(format!(
                    "element {} of {} is in fem.sections[{}] and fem.sections[{i}]: give each \
                     element one material",
                    mesh.elem_ids[e], mesh.source, by[e]
                )));
            }
            by[e] = i;
            of[e] = m;
        }
    }
    let missing = of.iter().filter(|&&m| m == NONE).count();
    if missing > 0 {
        match default {
            Some(d) => of.iter_mut().filter(|m| **m == NONE).for_each(|m| *m = d),
            None => {
                let first = of.iter().position(|&m| m == NONE).expect("counted");
                return Err(FemError::Selection(format!(
                    "{missing} elements of {} have no material (first: element {}); add a \
                     [[fem.sections]] entry for them or a default [fem.material]",
                    mesh.source, mesh.elem_ids[first]
                )));
            }
        }
    }
    Ok((materials, of))
}

fn law(spec: &MaterialSpec) -> Law {
    match *spec {
        MaterialSpec::LinearElastic {
            youngs_modulus,
            poisson_ratio,
            ..
        } => Law::Linear(Lame::from_young_poisson(youngs_modulus, poisson_ratio)),
        MaterialSpec::NeoHooke {
            youngs_modulus,
            poisson_ratio,
            ..
        } => Law::NeoHooke(NeoHooke::from_young_poisson(youngs_modulus, poisson_ratio)),
        MaterialSpec::MooneyRivlin {
            youngs_modulus,
            poisson_ratio,
            second_invariant_share,
            ..
        } => Law::MooneyRivlin(MooneyRivlin::from_young_poisson_ratio(
            youngs_modulus,
            poisson_ratio,
            second_invariant_share,
        )),
        MaterialSpec::Ogden {
            ref terms,
            poisson_ratio,
            ..
        } => {
            let pairs: Vec<(f64, f64)> = terms.iter().map(|t| (t[0], t[1])).collect();
            let g: f64 = 0.5 * pairs.iter().map(|(m, a)| m * a).sum::<f64>();
            let bulk = 2.0 * g * (1.0 + poisson_ratio) / (3.0 * (1.0 - 2.0 * poisson_ratio));
            Law::Ogden(Ogden::new(bulk, &pairs).expect("validated: 1 to 3 terms, α ≠ 0"))
        }
        MaterialSpec::MohrCoulomb {
            youngs_modulus,
            poisson_ratio,
            friction_angle,
            dilation_angle,
            cohesion,
            ..
        } => Law::MohrCoulomb(MohrCoulomb::new(
            youngs_modulus,
            poisson_ratio,
            friction_angle.to_radians(),
            dilation_angle.to_radians(),
            cohesion,
        )),
    }
}

/// Element formulations the stress-based path supports: hex8i's condensed incompatible modes
/// exist only for the linear path (not in a model solved by Newton iterations, whatever the
/// element's own material), and hex8b's B̄ is small strain only.
pub(super) fn check_element_kinds(
    mesh: &Mesh,
    materials: &[Material],
    of: &[u32],
) -> Result<(), FemError> {
    for e in 0..mesh.num_elements() {
        let m = &materials[of[e] as usize];
        let kind = mesh.kinds[e];
        let bad = match kind {
            ElementKind::Hex8i => true,
            ElementKind::Hex8b => m.model.finite_strain(),
            _ => false,
        };
        if bad {
            let why = if kind == ElementKind::Hex8i {
                "hex8i (incompatible modes) works only when every material is linear elastic \
                 (the model is solved by Newton iterations here)"
            } else {
                "hex8b (mean-dilatation B̄) is small strain only"
            };
            return Err(FemError::Mesh {
                file: mesh.source.clone(),
                line: mesh.elem_lines[e],
                message: format!(
                    "element {}: {why}, and its material {} is {}; use hex8, hex20 or tet10 \
                     for it",
                    mesh.elem_ids[e],
                    m.name,
                    m.model.kind_name()
                ),
            });
        }
    }
    Ok(())
}

/// The initial point states (all zero: no plastic strain), `stride` per element.
pub(super) fn initial_points(
    mesh: &Mesh,
    materials: &[Material],
    of: &[u32],
    stride: usize,
) -> Vec<f64> {
    let _ = (materials, of);
    vec![0.0; stride * mesh.num_elements()]
}

/// Internal forces (full dofs), the tangent on the pattern, and the stored energy.
pub(super) struct Internal {
    pub f: Vec<f64>,
    pub k: Option<Vec<f64>>,
    pub energy: f64,
}

/// An element that could not be evaluated, with its index.
#[derive(Clone, Copy, Debug)]
pub(super) struct Failed {
    element: usize,
    failure: ElementFailure,
}

/// A factorised iteration matrix.
enum TangentFactor {
    Cholesky(Factor),
    Lu(Box<LuFactor>),
}

impl TangentFactor {
    fn solve_in_place(&self, b: &mut [f64]) {
        match self {
            TangentFactor::Cholesky(f) => f.solve_in_place(b),
            TangentFactor::Lu(f) => f.solve_in_place(b),
        }
    }
}

/// Modified Newton keeps its factor while each iteration cuts the residual at least by this.
pub const MODIFIED_NEWTON_CONTRACTION: f64 = 0.25;

/// Why a Newton solve failed (reported after the cut-backs run out).
#[derive(Clone, Debug)]
struct NoConvergence {
    iteration: u32,
    residual: f64,
    reason: String,
}

impl Model {
    fn describe(&self, f: Failed) -> String {
        format!(
            "element {} ({}:{}): {}",
            self.mesh.elem_ids[f.element],
            self.mesh.source,
            self.mesh.elem_lines[f.element],
            f.failure
        )
    }

    /// Internal forces f_int(u) = Σ_e ∫ Bᵀσ (and with `tangent` the consistent tangent on the
    /// pattern) at the full displacement vector `u`, from the committed point states; trial
    /// states go to `states` (`state_stride` per element). Elements in parallel batches, sums
    /// in element order: the same bits for any thread count.
    pub(super) fn internal(
        &self,
        u: &[f64],
        tangent: bool,
        states: &mut [f64],
    ) -> Result<Internal, Failed> {
        let ne = self.mesh.num_elements();
        const BATCH: usize = 1024;
        let kstride = if tangent { MAX_ELEMENT_MATRIX } else { 0 };
        // element matrix, then 60 forces, then the energy
        let stride = kstride + 61;
        let ss = self.state_stride;
        let mut dummy = Vec::new();
        let states: &mut [f64] = if ss == 0 {
            dummy.resize(ne, 0.0);
            &mut dummy
        } else {
            states
        };
        let ssc = ss.max(1);
        let mut buf = vec![0.0; BATCH.min(ne.max(1)) * stride];
        let mut f = vec![0.0; self.num_dofs()];
        let mut kv = tangent.then(|| vec![0.0; self.pattern.nnz()]);
        let parts = assembly::scatter_parts(&self.pattern);
        let mut energy = 0.0;
        let mut start = 0;
        while start < ne {
            let end = (start + BATCH).min(ne);
            buf[..(end - start) * stride]
                .par_chunks_mut(stride)
                .zip(states[start * ssc..end * ssc].par_chunks_mut(ssc))
                .enumerate()
                .try_for_each_init(
                    || {
                        (
                            Vec::new(),
                            Vec::new(),
                            Scratch::default(),
                            Vec::new(),
                            Vec::new(),
                        )
                    },
                    |(x, ue, scratch, h, sc), (i, (out, st_new))| {
                        let e = start + i;
                        self.mesh.element_coords(e, x);
                        scratch.set_scale(self.mesh.element_scale(e, sc));
                        let kind = self.mesh.kinds[e];
                        let nodes = self.mesh.element_nodes(e);
                        ue.clear();
                        ue.extend(nodes.iter().map(|&n| {
                            let d = 3 * n as usize;
                            [u[d], u[d + 1], u[d + 2]]
                        }));
                        let model = &self.materials[self.elem_mat[e] as usize].model;
                        let sl = nonlinear::num_points(kind) * model.state_len();
                        let st_n = if ss == 0 {
                            &[][..]
                        } else {
                            &self.st.points[e * ss..e * ss + sl]
                        };
                        let nd = 3 * nodes.len();
                        let (kpart, rest) = out.split_at_mut(kstride);
                        let energy = nonlinear::element_response(
                            kind,
                            x,
                            ue,
                            model,
                            st_n,
                            &mut st_new[..sl],
                            &mut rest[..nd],
                            tangent.then_some(kpart),
                            scratch,
                            h,
                        )
                        .map_err(|failure| Failed {
                            element: e,
                            failure,
                        })?;
                        rest[60] = energy;
                        Ok(())
                    },
                )?;
            for e in start..end {
                let out = &buf[(e - start) * stride + kstride..];
                for (a, &n) in self.mesh.element_nodes(e).iter().enumerate() {
                    for c in 0..3 {
                        f[3 * n as usize + c] += out[3 * a + c];
                    }
                }
                energy += out[60];
            }
            if let Some(kv) = kv.as_mut() {
                let batch: Vec<u32> = (start as u32..end as u32).collect();
                assembly::scatter_batch(
                    &self.mesh,
                    &self.dofs,
                    &self.pattern,
                    &parts,
                    &batch,
                    &buf,
                    stride,
                    kv,
                );
            }
            start = end;
        }
        if let Some(pm) = &self.penalty_matrix {
            // the implicit penalty of a volume overlap: ε V u in the forces (over all dofs,
            // the supported ones and their prescribed values too), ε V in the tangent
            self.add_penalty_forces(u, &mut f);
            if let Some(kv) = kv.as_mut() {
                for (a, b) in kv.iter_mut().zip(pm) {
                    *a += b;
                }
            }
        }
        Ok(Internal { f, k: kv, energy })
    }

    /// Internal forces at `u` from the committed states (no tangent, states untouched).
    pub(super) fn internal_forces_at(&self, u: &[f64]) -> Result<Vec<f64>, FemError> {
        let mut trial = self.st.points.clone();
        self.internal(u, false, &mut trial)
            .map(|r| r.f)
            .map_err(|f| FemError::Solver(self.describe(f)))
    }

    /// Stored energy ∫ Ψ dV₀ of the current state [J].
    pub(super) fn stored_energy(&self) -> f64 {
        let mut trial = self.st.points.clone();
        self.internal(&self.st.u, false, &mut trial)
            .map_or(f64::NAN, |r| r.energy)
    }

    /// Factorises the iteration matrix J: Cholesky when it is symmetric (falling back to LU
    /// when it is not positive definite), LU otherwise.
    fn factor_tangent(&mut self, vals: &[f64], symmetric: bool) -> Result<TangentFactor, FemError> {
        if symmetric {
            match Factor::new(&self.pattern, vals, &mut self.symbolic) {
                Ok(f) => return Ok(TangentFactor::Cholesky(f)),
                Err(e) => tracing::debug!("newton: {e}; solving with LU"),
            }
        }
        let t0 = std::time::Instant::now();
        let lu = LuFactor::new(&self.pattern, vals, &mut self.lu_symbolic)?;
        tracing::debug!(
            "newton: LU of {} equations in {:?}",
            self.pattern.n,
            t0.elapsed()
        );
        Ok(TangentFactor::Lu(Box::new(lu)))
    }

    /// Whether the next iteration needs a new tangent: always with full Newton; with
    /// modified Newton when there is none yet or the last iteration reduced the residual by
    /// less than [`MODIFIED_NEWTON_CONTRACTION`].
    fn refresh_tangent(&self, have: bool, history: &[f64]) -> bool {
        if self.newton.tangent == TangentUpdate::Full || !have {
            return true;
        }
        let n = history.len();
        n >= 2 && history[n - 1] > MODIFIED_NEWTON_CONTRACTION * history[n - 2]
    }

    /// Static equilibrium f_int(u) = F(t) by Newton–Raphson with load stepping: from the
    /// converged state (its internal forces are the load it carries) to the loads and
    /// prescribed displacements at `t`, in `newton.increments` equal increments, each halved
    /// on failure up to `newton.max_cutbacks` times.
    pub(super) fn newton_static(&mut self, t: f64) -> Result<(), FemError> {
        let f_target = self.dofs.gather(&self.external_forces(t));
        let f_start = self
            .dofs
            .gather(&self.internal_forces_at(&self.st.u.clone())?);
        let g_start = self.st.u.clone();
        let g_target = self.st.prescribed.clone();
        let mut s = 0.0;
        let ds0 = 1.0 / self.newton.increments as f64;
        let mut ds = ds0;
        // consecutive halvings of the current increment
        let mut cutbacks = 0;
        self.last_newton.clear();
        // the force scale of the convergence test: the largest load or internal force of the
        // converged states of this solve (a stress-free end state, e.g. after a rigid
        // rotation, has none of its own), the increment's load, and the internal forces of its
        // first iterate (a prescribed displacement's)
        let mut scale = dot(&f_start, &f_start)
            .sqrt()
            .max(dot(&f_target, &f_target).sqrt());
        while s < 1.0 {
            let s1 = if s + ds > 1.0 - 1e-12 { 1.0 } else { s + ds };
            let load: Vec<f64> = f_start
                .iter()
                .zip(&f_target)
                .map(|(a, b)| a + s1 * (b - a))
                .collect();
            let mut u = self.st.u.clone();
            for (d, &e) in self.dofs.eq.iter().enumerate() {
                if e == assembly::FIXED {
                    u[d] = g_start[d] + s1 * (g_target[d] - g_start[d]);
                }
            }
            match self.newton_increment(u, &load, &mut scale) {
                Ok(history) => {
                    self.last_newton.push(history);
                    s = s1;
                    // after a cut-back, grow the increment again
                    cutbacks = 0;
                    ds = (2.0 * ds).min(ds0);
                }
                Err(fail) => {
                    cutbacks += 1;
                    if cutbacks > self.newton.max_cutbacks {
                        return Err(FemError::Solver(format!(
                            "Newton iterations did not converge at t = {t:.6e} s (solve {}): \
                             load factor {s:.6} → {s1:.6} after {} cut-backs; iteration {}: \
                             relative residual {:.3e} (tolerance {:.1e}); {}. Try more \
                             [fem.newton] increments or smaller changes of load per window \
                             (shorter windows or load histories), or check the loads and \
                             supports (a perfectly plastic body above its collapse load has no \
                             equilibrium)",
                            self.st.steps + 1,
                            cutbacks - 1,
                            fail.iteration,
                            fail.residual,
                            self.newton.force_tolerance,
                            fail.reason
                        )));
                    }
                    ds *= 0.5;
                    tracing::debug!(
                        "newton: cut back to load increment {ds:.3e} at factor {s:.6} ({})",
                        fail.reason
                    );
                }
            }
        }
        self.st.v.fill(0.0);
        self.st.a.fill(0.0);
        self.st.accel_ready = false;
        Ok(())
    }

    /// Newton iterations of one load increment from the trial displacement `u` (prescribed
    /// dofs already at their target); commits u and the point states on convergence and
    /// returns the relative residuals of the iterations.
    fn newton_increment(
        &mut self,
        mut u: Vec<f64>,
        load: &[f64],
        scale: &mut f64,
    ) -> Result<Vec<f64>, NoConvergence> {
        let tol_f = self.newton.force_tolerance;
        let tol_u = self.newton.displacement_tolerance;
        let symmetric = self.symmetric_tangent;
        let u_start = self.dofs.gather(&self.st.u);
        let mut trial = self.st.points.clone();
        let mut history = Vec::new();
        let mut last_du = f64::INFINITY;
        let mut local = scale.max(dot(load, load).sqrt());
        // the factor lives for one increment (a restored snapshot iterates the same way)
        let mut factor: Option<TangentFactor> = None;
        for it in 0..=self.newton.max_iterations {
            let refresh = self.refresh_tangent(factor.is_some(), &history);
            let r = self
                .internal(&u, refresh, &mut trial)
                .map_err(|f| NoConvergence {
                    iteration: it,
                    residual: f64::NAN,
                    reason: self.describe(f),
                })?;
            let fint = self.dofs.gather(&r.f);
            let mut res: Vec<f64> = load.iter().zip(&fint).map(|(a, b)| a - b).collect();
            let fnorm = dot(&r.f, &r.f).sqrt();
            if it == 0 {
                local = local.max(fnorm);
            }
            let rn = dot(&res, &res).sqrt();
            let rel = if local > 0.0 { rn / local } else { 0.0 };
            history.push(rel);
            if !rel.is_finite() {
                return Err(NoConvergence {
                    iteration: it,
                    residual: rel,
                    reason: "non-finite residual".into(),
                });
            }
            let u_free = self.dofs.gather(&u);
            let incr: f64 = u_free
                .iter()
                .zip(&u_start)
                .map(|(a, b)| (a - b) * (a - b))
                .sum::<f64>()
                .sqrt();
            let du_ok = it == 0 || last_du <= tol_u * incr.max(f64::MIN_POSITIVE);
            // the residual at the round-off floor of the internal forces (tiny strains of a
            // stiff finite-strain material): the displacement has converged far below its
            // tolerance and the residual is within 1000 × the force tolerance
            let floor = it > 0
                && last_du <= 1e-3 * tol_u * incr.max(f64::MIN_POSITIVE)
                && rel <= 1e3 * tol_f;
            if (rel <= tol_f && (du_ok || rel <= tol_f * 1e-3)) || floor {
                *scale = local.max(fnorm);
                let mut u = u;
                // keep the converged free dofs; prescribed dofs stay at their targets
                self.st.u.copy_from_slice(&u);
                if self.state_stride > 0 {
                    std::mem::swap(&mut self.st.points, &mut trial);
                }
                u.clear();
                return Ok(history);
            }
            if it == self.newton.max_iterations {
                return Err(NoConvergence {
                    iteration: it,
                    residual: rel,
                    reason: format!(
                        "no convergence in {} iterations",
                        self.newton.max_iterations
                    ),
                });
            }
            if refresh {
                let k = r.k.expect("tangent requested");
                factor = Some(
                    self.factor_tangent(&k, symmetric)
                        .map_err(|e| NoConvergence {
                            iteration: it,
                            residual: rel,
                            reason: e.to_string(),
                        })?,
                );
            }
            factor
                .as_ref()
                .expect("factorised")
                .solve_in_place(&mut res);
            if res.iter().any(|x| !x.is_finite()) {
                return Err(NoConvergence {
                    iteration: it,
                    residual: rel,
                    reason: "non-finite correction (singular tangent)".into(),
                });
            }
            last_du = dot(&res, &res).sqrt();
            let mut u_new = u_free;
            for (a, d) in u_new.iter_mut().zip(&res) {
                *a += d;
            }
            self.dofs.scatter_free(&u_new, &mut u);
        }
        unreachable!("the loop returns")
    }

    /// One Bossak step of a nonlinear model: Newton on a_{n+1} of
    /// M[(1−α_B) a_{n+1} + α_B a_n] + C v_{n+1} + f_int(u_{n+1}) = F_{n+1}, with
    /// J = (1−α_B) M + γΔt C + βΔt² K_T and C = a M + b K₀ (K₀ the initial stiffness).
    /// A step that does not converge is retried as two half steps (up to
    /// `newton.max_cutbacks` levels).
    pub(super) fn bossak_nonlinear(&mut self, dt: f64) -> Result<(), FemError> {
        if !self.st.accel_ready {
            self.initial_acceleration()?;
        }
        self.last_newton.clear();
        self.bossak_nonlinear_level(dt, 0)
    }

    fn bossak_nonlinear_level(&mut self, dt: f64, level: u32) -> Result<(), FemError> {
        match self.bossak_newton(dt) {
            Ok(history) => {
                self.last_newton.push(history);
                Ok(())
            }
            Err(fail) if level < self.newton.max_cutbacks => {
                tracing::debug!(
                    "newton: Bossak step {dt:.3e} s cut in half ({})",
                    fail.reason
                );
                self.bossak_nonlinear_level(0.5 * dt, level + 1)?;
                self.bossak_nonlinear_level(0.5 * dt, level + 1)
            }
            Err(fail) => Err(FemError::Solver(format!(
                "Newton iterations of the Bossak step did not converge at t = {:.6e} s (step {}) \
                 after halving the step {level} times (to {dt:.3e} s); iteration {}: relative \
                 residual {:.3e} (tolerance {:.1e}); {}. Try a shorter coupling window or more \
                 [fem.newton] max_cutbacks, or check the loads and supports",
                self.st.time,
                self.st.steps + 1,
                fail.iteration,
                fail.residual,
                self.newton.force_tolerance,
                fail.reason
            ))),
        }
    }

    fn bossak_newton(&mut self, dt: f64) -> Result<Vec<f64>, NoConvergence> {
        let Analysis::Dynamic { alpha_b, .. } = self.analysis else {
            unreachable!("Bossak needs a dynamic analysis")
        };
        let (ra, rb) = self.rayleigh();
        let gamma = 0.5 - alpha_b;
        let beta = 0.25 * (1.0 - alpha_b).powi(2);
        let tol_f = self.newton.force_tolerance;
        let tol_u = self.newton.displacement_tolerance;
        let symmetric = self.symmetric_tangent;
        let u = self.dofs.gather(&self.st.u);
        let v = self.dofs.gather(&self.st.v);
        let a = self.dofs.gather(&self.st.a);
        let n = u.len();
        let ut: Vec<f64> = (0..n)
            .map(|i| u[i] + dt * v[i] + dt * dt * (0.5 - beta) * a[i])
            .collect();
        let vt: Vec<f64> = (0..n).map(|i| v[i] + dt * (1.0 - gamma) * a[i]).collect();
        let t1 = self.st.time + dt;
        let fext = self.free_rhs_with(t1, None);
        let fail = |it: u32, rel: f64, reason: String| NoConvergence {
            iteration: it,
            residual: rel,
            reason,
        };
        let mut a1 = a.clone();
        let mut trial = self.st.points.clone();
        let mut full = self.st.u.clone();
        for (d, &e) in self.dofs.eq.iter().enumerate() {
            if e == assembly::FIXED {
                full[d] = self.st.prescribed[d];
            }
        }
        let mut history = Vec::new();
        let (mut tmp, mut tmp2) = (vec![0.0; n], vec![0.0; n]);
        let mut last_da = f64::INFINITY;
        // the factor lives for one step (a restored snapshot iterates the same way)
        let mut factor: Option<TangentFactor> = None;
        for it in 0..=self.newton.max_iterations {
            let u1: Vec<f64> = (0..n).map(|i| ut[i] + beta * dt * dt * a1[i]).collect();
            let v1: Vec<f64> = (0..n).map(|i| vt[i] + gamma * dt * a1[i]).collect();
            self.dofs.scatter_free(&u1, &mut full);
            let refresh = self.refresh_tangent(factor.is_some(), &history);
            let r = self
                .internal(&full, refresh, &mut trial)
                .map_err(|f| fail(it, f64::NAN, self.describe(f)))?;
            let fint = self.dofs.gather(&r.f);
            // R = F − M[(1−α)a1 + α a_n + ra v1] − rb K₀ v1 − f_int
            let w: Vec<f64> = (0..n)
                .map(|i| (1.0 - alpha_b) * a1[i] + alpha_b * a[i] + ra * v1[i])
                .collect();
            self.mass_mul(&w, &mut tmp);
            if rb != 0.0 {
                self.pattern.mul(&self.k, &v1, &mut tmp2);
            } else {
                tmp2.fill(0.0);
            }
            let mut res: Vec<f64> = (0..n)
                .map(|i| fext[i] - tmp[i] - rb * tmp2[i] - fint[i])
                .collect();
            let scale = dot(&fext, &fext)
                .sqrt()
                .max(dot(&r.f, &r.f).sqrt())
                .max(dot(&tmp, &tmp).sqrt());
            let rn = dot(&res, &res).sqrt();
            let rel = if scale > 0.0 { rn / scale } else { 0.0 };
            history.push(rel);
            if !rel.is_finite() {
                return Err(fail(it, rel, "non-finite residual".into()));
            }
            let step: f64 = (0..n).map(|i| (u1[i] - u[i]).powi(2)).sum::<f64>().sqrt();
            let du = beta * dt * dt * last_da;
            let du_ok = it == 0 || du <= tol_u * step.max(f64::MIN_POSITIVE);
            let floor =
                it > 0 && du <= 1e-3 * tol_u * step.max(f64::MIN_POSITIVE) && rel <= 1e3 * tol_f;
            if (rel <= tol_f && (du_ok || rel <= tol_f * 1e-3)) || floor {
                self.set_free(0, &u1);
                self.set_free(1, &v1);
                self.set_free(2, &a1);
                if self.state_stride > 0 {
                    std::mem::swap(&mut self.st.points, &mut trial);
                }
                self.st.time = t1;
                return Ok(history);
            }
            if it == self.newton.max_iterations {
                return Err(fail(
                    it,
                    rel,
                    format!(
                        "no convergence in {} iterations",
                        self.newton.max_iterations
                    ),
                ));
            }
            if refresh {
                // J = βΔt² K_T + γΔt rb K₀ + [(1−α) + γΔt ra] M
                let mut jac = r.k.expect("tangent requested");
                let ck = beta * dt * dt;
                let cm = (1.0 - alpha_b) + gamma * dt * ra;
                for (j, k0) in jac.iter_mut().zip(&self.k) {
                    *j = ck * *j + gamma * dt * rb * k0;
                }
                self.add_mass(&mut jac, cm);
                factor = Some(
                    self.factor_tangent(&jac, symmetric)
                        .map_err(|e| fail(it, rel, e.to_string()))?,
                );
            }
            factor
                .as_ref()
                .expect("factorised")
                .solve_in_place(&mut res);
            if res.iter().any(|x| !x.is_finite()) {
                return Err(fail(
                    it,
                    rel,
                    "non-finite correction (singular tangent)".into(),
                ));
            }
            last_da = dot(&res, &res).sqrt();
            for (ai, d) in a1.iter_mut().zip(&res) {
                *ai += d;
            }
        }
        unreachable!("the loop returns")
    }

    /// f_int(u) on the free equations for the explicit scheme and the initial acceleration;
    /// with `commit` the trial point states become the committed ones (an explicit step).
    pub(super) fn free_internal_forces(
        &mut self,
        u_free: &[f64],
        commit: bool,
    ) -> Result<Vec<f64>, FemError> {
        let mut full = self.st.u.clone();
        self.dofs.scatter(u_free, &mut full);
        for (d, &e) in self.dofs.eq.iter().enumerate() {
            if e == assembly::FIXED {
                full[d] = self.st.prescribed[d];
            }
        }
        let mut trial = self.st.points.clone();
        let r = self
            .internal(&full, false, &mut trial)
            .map_err(|f| FemError::Solver(self.describe(f)))?;
        if commit && self.state_stride > 0 {
            self.st.points = trial;
        }
        let f = self.dofs.gather(&r.f);
        check_finite(&f, "internal forces")?;
        Ok(f)
    }

    /// Per element: mean Cauchy stress over its points, the largest equivalent plastic strain,
    /// and the share of its points that yielded in the last converged update.
    pub(super) fn element_point_summaries(&self) -> (Vec<[f64; 6]>, Vec<f64>, Vec<f64>) {
        let ss = self.state_stride;
        let rows: Vec<([f64; 6], f64, f64)> = (0..self.mesh.num_elements())
            .into_par_iter()
            .map_init(
                || (Scratch::default(), Vec::new()),
                |(scratch, pts), e| {
                    // stresses as output: the element's own, not Arlequin-weighted, means
                    let (x, u) = self.element_state(e);
                    let kind = self.mesh.kinds[e];
                    let model = &self.materials[self.elem_mat[e] as usize].model;
                    let np = nonlinear::num_points(kind);
                    let sl = model.state_len();
                    let st = if ss == 0 {
                        &[][..]
                    } else {
                        &self.st.points[e * ss..e * ss + np * sl]
                    };
                    if nonlinear::point_stresses(kind, &x, &u, model, st, scratch, pts).is_err() {
                        return ([f64::NAN; 6], f64::NAN, f64::NAN);
                    }
                    let vol: f64 = pts.iter().map(|p| p.1).sum();
                    let mut mean = [0.0; 6];
                    for (s, w) in pts.iter() {
                        for c in 0..6 {
                            mean[c] += s[c] * w / vol;
                        }
                    }
                    let (mut peeq, mut yielding) = (0.0f64, 0.0);
                    if sl == crate::material::MOHR_COULOMB_STATE {
                        for q in 0..np {
                            peeq = peeq.max(st[q * sl + 6]);
                            yielding += st[q * sl + 7] / np as f64;
                        }
                    }
                    (mean, peeq, yielding)
                },
            )
            .collect();
        let mut out = (Vec::new(), Vec::new(), Vec::new());
        for (s, p, y) in rows {
            out.0.push(s);
            out.1.push(p);
            out.2.push(y);
        }
        out
    }
}
