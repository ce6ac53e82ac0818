//! The deformable-particle mode of Madan's DDEM (2.41)–(2.54) and its two limits: the
//! convergence of the force–strain iteration, ρ(B) < 1 (3.13)–(3.14), and the critical time
//! step of the explicit scheme (2.14)–(2.16), which the DDEM does not change (§3.5.3, §3.6.3).
//!
//! Conventions (one place, SEED-SPEC §5.11): normal forces are magnitudes, compression
//! positive; stresses are tension positive; the strain vector is ε̃ = [ε_xx, ε_yy, 2ε_xy]
//! (2.47) and the stress vector σ̃ = [σ_xx, σ_yy, σ_xy].

use super::config::Plane;

/// The compliance D̃_p of (2.48) (plane strain) or (2.49) (plane stress): ε̃ = D̃ σ̃.
pub fn compliance(e: f64, nu: f64, plane: Plane) -> [[f64; 3]; 3] {
    match plane {
        Plane::Strain => {
            let c = (1.0 + nu) / e;
            [
                [c * (1.0 - nu), -c * nu, 0.0],
                [-c * nu, c * (1.0 - nu), 0.0],
                [0.0, 0.0, 2.0 * c],
            ]
        }
        Plane::Stress => [
            [1.0 / e, -nu / e, 0.0],
            [-nu / e, 1.0 / e, 0.0],
            [0.0, 0.0, 2.0 * (1.0 + nu) / e],
        ],
    }
}

pub fn mul3(d: &[[f64; 3]; 3], s: [f64; 3]) -> [f64; 3] {
    [
        d[0][0] * s[0] + d[0][1] * s[1] + d[0][2] * s[2],
        d[1][0] * s[0] + d[1][1] * s[1] + d[1][2] * s[2],
        d[2][0] * s[0] + d[2][1] * s[1] + d[2][2] * s[2],
    ]
}

/// a = R [n_x², n_y², n_x n_y]: the normal displacement of a contact point at R n of a
/// particle with strain ε̃ is nᵀ ε (R n) = a · ε̃ (2.50)–(2.53); the symmetric part of
/// s ⊗ (−f n) for a compressive force f there is −f a (2.44).
pub fn normal_arm(r: f64, n: [f64; 2]) -> [f64; 3] {
    [r * n[0] * n[0], r * n[1] * n[1], r * n[0] * n[1]]
}

/// One end of a contact for the iteration matrix: the contact's index, the particle, its arm
/// [`normal_arm`].
#[derive(Debug, Clone, Copy)]
pub struct End {
    pub contact: usize,
    pub particle: usize,
    pub arm: [f64; 3],
}

/// The spectral radius of Madan's iteration matrix B (3.8) for the contacts `ends` (each
/// contact has two ends; a contact of a disc with its own periodic image has both on one
/// particle), particle volumes `volume` and one normal stiffness `kn`.
///
/// With compressive normal forces f, σ̃_p = −(1/V_p) Σ_{d∋p} f_d a_d^p and
/// h_c = h + Σ_{p∈c} a_c^p · D̃ σ̃_p, so f = k_n h_c gives B = −k_n Aᵀ W A with
/// W = diag(D̃ / V_p): symmetric, its spectral radius the largest eigenvalue of k_n Aᵀ W A,
/// found by Lanczos. Tangential forces do not depend on the strains (Madan §2.2) and do not
/// enter B; nor do external forces (they are part of A X in (3.8)).
pub fn spectral_radius(
    n_contacts: usize,
    ends: &[End],
    volume: &[f64],
    d: &[[f64; 3]; 3],
    kn: f64,
) -> f64 {
    if n_contacts == 0 {
        return 0.0;
    }
    let mut e = vec![[0.0f64; 3]; volume.len()];
    let apply = |x: &[f64], y: &mut [f64]| {
        e.iter_mut().for_each(|v| *v = [0.0; 3]);
        for end in ends {
            let f = x[end.contact];
            for (ek, ak) in e[end.particle].iter_mut().zip(end.arm) {
                *ek += ak * f;
            }
        }
        y.iter_mut().for_each(|v| *v = 0.0);
        for end in ends {
            let w = mul3(d, e[end.particle]);
            let a = end.arm;
            y[end.contact] += kn * (a[0] * w[0] + a[1] * w[1] + a[2] * w[2]) / volume[end.particle];
        }
    };
    numeric::lanczos_largest(
        n_contacts,
        apply,
        |x, y| y.copy_from_slice(x),
        false,
        500,
        1e-10,
    )
}

/// The analytic spectral radius of the simple-cubic (square) packing (3.41).
pub fn square_spectral_radius(kn: f64, e: f64, nu: f64, depth: f64) -> f64 {
    4.0 * kn * (1.0 + nu) / (std::f64::consts::PI * e * depth)
}

/// The analytic spectral radius of the hexagonal close packing (3.76)–(3.78).
pub fn hexagonal_spectral_radius(kn: f64, e: f64, nu: f64, depth: f64) -> f64 {
    let c = kn * (1.0 + nu) / (std::f64::consts::PI * e * depth);
    c * f64::max(3.0, (6.0 * (1.0 - 2.0 * nu)).abs())
}

/// A spring of the stiffness operator: a contact between `i` and `j` (the same disc for a
/// periodic image) at arms s_i, s_j from the centres, normal n from i to j.
#[derive(Debug, Clone, Copy)]
pub struct Spring {
    pub i: usize,
    pub j: usize,
    pub n: [f64; 2],
    pub si: [f64; 2],
    pub sj: [f64; 2],
}

/// The critical time step 2/ν_max of the central-difference scheme (2.14)–(2.15) for the
/// linear springs `springs` (normal `kn`, tangential `kt`) on discs of mass `m` and moment of
/// inertia `j`, with `free[3p + k]` false for a fixed coordinate (x, y, θ): ν_max² is the
/// largest eigenvalue of M^{-½} K M^{-½}, by Lanczos. `None` without any free, loaded
/// coordinate.
pub fn critical_time_step(
    springs: &[Spring],
    m: &[f64],
    j: &[f64],
    free: &[bool],
    kn: f64,
    kt: f64,
) -> Option<f64> {
    let n = m.len();
    // free coordinates, numbered
    let mut index = vec![usize::MAX; 3 * n];
    let mut scale = Vec::new();
    for p in 0..n {
        for k in 0..3 {
            // a coordinate without inertia (a rotation without tangential springs) carries no
            // frequency: leave it out
            if free[3 * p + k] && !(k == 2 && kt == 0.0) {
                index[3 * p + k] = scale.len();
                scale.push(1.0 / if k == 2 { j[p] } else { m[p] }.sqrt());
            }
        }
    }
    let dofs = scale.len();
    if dofs == 0 || springs.is_empty() {
        return None;
    }
    let get = |x: &[f64], p: usize, k: usize| {
        let i = index[3 * p + k];
        if i == usize::MAX {
            0.0
        } else {
            x[i] * scale[i]
        }
    };
    let apply = |x: &[f64], y: &mut [f64]| {
        y.iter_mut().for_each(|v| *v = 0.0);
        let add = |y: &mut [f64], p: usize, k: usize, v: f64| {
            let i = index[3 * p + k];
            if i != usize::MAX {
                y[i] += v * scale[i];
            }
        };
        for s in springs {
            let t = [-s.n[1], s.n[0]];
            // displacement of each contact point: u + θ ẑ × s
            let point = |p: usize, arm: [f64; 2]| {
                let th = get(x, p, 2);
                [get(x, p, 0) - th * arm[1], get(x, p, 1) + th * arm[0]]
            };
            let ui = point(s.i, s.si);
            let uj = point(s.j, s.sj);
            let d = [uj[0] - ui[0], uj[1] - ui[1]];
            let dn = kn * (d[0] * s.n[0] + d[1] * s.n[1]);
            let dt = kt * (d[0] * t[0] + d[1] * t[1]);
            let f = [dn * s.n[0] + dt * t[0], dn * s.n[1] + dt * t[1]];
            // (K u)_j = f, (K u)_i = −f, moments s × f
            add(y, s.j, 0, f[0]);
            add(y, s.j, 1, f[1]);
            add(y, s.j, 2, s.sj[0] * f[1] - s.sj[1] * f[0]);
            add(y, s.i, 0, -f[0]);
            add(y, s.i, 1, -f[1]);
            add(y, s.i, 2, -(s.si[0] * f[1] - s.si[1] * f[0]));
        }
    };
    let lam = numeric::lanczos_largest(dofs, apply, |x, y| y.copy_from_slice(x), false, 600, 1e-10);
    (lam > 0.0).then(|| 2.0 / lam.sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A periodic cell of one disc: each contact direction is a contact of the disc with its
    /// own image, both ends on the disc, arms R n and −R n.
    fn periodic_cell(directions: &[f64], r: f64) -> Vec<End> {
        let mut ends = Vec::new();
        for (c, &a) in directions.iter().enumerate() {
            let n = [a.cos(), a.sin()];
            ends.push(End {
                contact: c,
                particle: 0,
                arm: normal_arm(r, n),
            });
            ends.push(End {
                contact: c,
                particle: 0,
                arm: normal_arm(r, [-n[0], -n[1]]),
            });
        }
        ends
    }

    #[test]
    fn the_assembled_iteration_matrices_of_periodic_lattices_match_3_41_and_3_76() {
        let r = 1e-3;
        let kn = 7e10;
        let v = [std::f64::consts::PI * r * r];
        use std::f64::consts::FRAC_PI_3;
        for nu in [0.0, 0.05, 0.2, 0.25, 0.3, 0.35, 0.45] {
            for e in [8e10, 2e11] {
                let d = compliance(e, nu, Plane::Strain);
                let sq = spectral_radius(2, &periodic_cell(&[0.0, FRAC_PI_2], r), &v, &d, kn);
                let want = square_spectral_radius(kn, e, nu, 1.0);
                assert!(
                    (sq - want).abs() < 1e-12 * want,
                    "SC ν={nu}: {sq} vs {want}"
                );
                let hex = spectral_radius(
                    3,
                    &periodic_cell(&[0.0, FRAC_PI_3, 2.0 * FRAC_PI_3], r),
                    &v,
                    &d,
                    kn,
                );
                let want = hexagonal_spectral_radius(kn, e, nu, 1.0);
                assert!(
                    (hex - want).abs() < 1e-12 * want,
                    "HCP ν={nu}: {hex} vs {want}"
                );
            }
        }
        // Table 3.2's analytic limits: ρ = 1 at k_n/E_p = π/(4(1 + ν_p))
        for (nu, ratio) in [(0.05, 0.748), (0.2, 0.654), (0.35, 0.582), (0.45, 0.542)] {
            let e = kn / ratio;
            let rho = square_spectral_radius(kn, e, nu, 1.0);
            assert!((rho - 1.0).abs() < 1e-3, "ν={nu}: ρ = {rho}");
        }
        // Table 3.3's: 0.554 at ν = 0.05, 0.838 at 0.25, 0.722 at 0.45
        for (nu, ratio) in [(0.05, 0.554), (0.25, 0.838), (0.45, 0.722)] {
            let rho = hexagonal_spectral_radius(kn, kn / ratio, nu, 1.0);
            assert!((rho - 1.0).abs() < 1e-3, "ν={nu}: ρ = {rho}");
        }
    }

    use std::f64::consts::FRAC_PI_2;

    #[test]
    fn the_critical_step_of_a_chain_is_the_chain_formula() {
        // 20 masses between two fixed ones, springs k: ν_max = 2√(k/m) sin(20π/42) (3.44)
        let n = 22;
        let (m, k) = (6.283e-3, 7e10);
        let springs: Vec<Spring> = (0..n - 1)
            .map(|i| Spring {
                i,
                j: i + 1,
                n: [1.0, 0.0],
                si: [1e-3, 0.0],
                sj: [-1e-3, 0.0],
            })
            .collect();
        let mut free = vec![false; 3 * n];
        for p in 1..n - 1 {
            free[3 * p] = true;
        }
        let dt = critical_time_step(&springs, &vec![m; n], &vec![1.0; n], &free, k, 0.0).unwrap();
        let nu_max = 2.0 * (k / m).sqrt() * (20.0 * std::f64::consts::PI / 42.0).sin();
        assert!(
            (dt - 2.0 / nu_max).abs() < 1e-9 * dt,
            "{dt} vs {}",
            2.0 / nu_max
        );
        // (3.47): √(m/k) = 2.9959e-7 s is just below
        assert!((m / k).sqrt() < dt && dt < 1.003 * (m / k).sqrt());
    }
}
