//! Nonlinear solids: the stress-based path and Newton iterations reproduce the linear solver
//! for a linear material; homogeneous hyperelastic states against closed forms; quadratic
//! Newton convergence; a 90° rigid rotation without stress; the Mohr–Coulomb drained triaxial
//! test with Wellmann's fitted parameters (SEED-SPEC §3.6, V8); snapshots with plastic state;
//! scene errors naming their field.
#![allow(clippy::needless_range_loop)]

mod common;
use common::*;

// ---------------------------------------------------------------------------------------------
// The linear material through the new path
// ---------------------------------------------------------------------------------------------

fn with_newton(scene: &str) -> String {
    format!("{scene}\n[fem.newton]\nalways = true\nforce_tolerance = 1e-12\n")
}

fn max_rel_diff(a: &[f64], b: &[f64]) -> f64 {
    let scale = a.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    a.iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs() / scale))
}

/// The A3 beam (hex8, hex8b, tet10, hex20) solved by Newton iterations on f_int = ∫Bᵀσ equals
/// the direct solve of K u = F to round-off.
#[test]
fn linear_material_through_newton_equals_the_direct_solve() {
    for (element, h) in [
        ("hex8", 0.05),
        ("hex8b", 0.05),
        ("tet10", 0.1),
        ("hex20", 0.1),
    ] {
        let scene = a3_beam(element, h);
        let mut direct = model(&scene);
        direct.solve_static().unwrap();
        let mut newton = model(&with_newton(&scene));
        assert!(newton.is_nonlinear() && !direct.is_nonlinear());
        newton.solve_static().unwrap();
        let d = max_rel_diff(direct.displacements(), newton.displacements());
        let its = newton.last_newton_residuals()[0].len() - 1;
        println!("{element}: Newton {its} iterations, max relative difference {d:.2e}");
        assert!(d < 1e-10, "{element}: {d:e}");
        assert!(
            its <= 2,
            "{element}: a linear problem takes one Newton step, took {its}"
        );
        let s = max_rel_diff(
            &direct.element_stresses().concat(),
            &newton.element_stresses().concat(),
        );
        assert!(s < 1e-9, "{element}: stresses differ by {s:e}");
    }
}

/// Bossak (consistent mass, Rayleigh damping) and explicit steps of a linear cantilever: the
/// Newton path gives the linear path's state to round-off.
#[test]
fn linear_material_dynamics_through_the_newton_path_match() {
    for analysis in [
        "[fem.analysis]\ntype = \"dynamic\"\nalpha_b = -0.1\nrayleigh_a = 2.0\nrayleigh_b = 1e-5",
        "[fem.analysis]\ntype = \"explicit\"\nrayleigh_a = 2.0",
    ] {
        let scene = format!(
            "[fem]\nmesh = {{ size = [0.8, 0.1, 0.1], element_size = 0.1, element = \"hex8\" }}\n\
             {STEEL}{analysis}\n[[fem.supports]]\non = {{ set = \"xmin\" }}\n\
             [[fem.loads]]\ntype = \"pressure\"\non = {{ set = \"zmax\" }}\nvalue = 1e5\n"
        );
        let mut a = model(&scene);
        let mut b = model(&with_newton(&scene));
        for _ in 0..20 {
            a.advance(2e-5).unwrap();
            b.advance(2e-5).unwrap();
        }
        let du = max_rel_diff(a.displacements(), b.displacements());
        let dv = max_rel_diff(a.velocities(), b.velocities());
        println!("{}: u {du:.2e}, v {dv:.2e}", &analysis[24..32]);
        assert!(du < 1e-9 && dv < 1e-8, "{analysis}: u {du:e}, v {dv:e}");
    }
}

// ---------------------------------------------------------------------------------------------
// Hyperelastic homogeneous states
// ---------------------------------------------------------------------------------------------

const NEO_HOOKE: &str =
    "model = \"neo_hooke\"\nyoungs_modulus = 94e6\npoisson_ratio = 0.3\ndensity = 3000.0";
const MOONEY_RIVLIN: &str = "model = \"mooney_rivlin\"\nyoungs_modulus = 9.4e6\npoisson_ratio = 0.41\nsecond_invariant_share = 0.05\ndensity = 800.0";
/// Wellmann Table 4.3 (μ = 0.5 MPa) with ν = 0.45 for the bulk modulus.
const OGDEN: &str = "model = \"ogden\"\nterms = [[745.5e3, 1.3], [1.5e3, 5.0], [-11.85e3, -2.0]]\npoisson_ratio = 0.45\ndensity = 5000.0";

/// A unit cube of 2×2×2 hex8 (one interior node) of `material`, with extra scene text.
fn cube(material: &str, extra: &str) -> String {
    format!(
        "[fem]\nmesh = {{ size = [1.0, 1.0, 1.0], divisions = [2, 2, 2], element = \"hex8\" }}\n\
         [fem.materials.m]\n{material}\n[[fem.sections]]\nelements = \"all\"\nmaterial = \"m\"\n\
         {extra}"
    )
}

/// Closed-form principal Cauchy stresses of a homogeneous stretch diag(l) (SEED-SPEC §2;
/// decoupled models: σ_i = (w_i − mean w)/J + U'(J), w_i = λ̄_i ∂Ψ̄/∂λ̄_i).
fn principal_cauchy(material: &str, l: [f64; 3]) -> [f64; 3] {
    let j = l[0] * l[1] * l[2];
    let par = |key: &str| -> f64 {
        material
            .lines()
            .find_map(|s| s.strip_prefix(&format!("{key} = ")))
            .unwrap()
            .parse()
            .unwrap()
    };
    if material.contains("neo_hooke") {
        let (e, nu) = (par("youngs_modulus"), par("poisson_ratio"));
        let lam = e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu));
        let mu = e / (2.0 * (1.0 + nu));
        return l.map(|li| (lam / 2.0 * (j * j - 1.0) + mu * (li * li - 1.0)) / j);
    }
    let lb = l.map(|li| li * j.powf(-1.0 / 3.0));
    let (w, bulk): ([f64; 3], f64) = if material.contains("mooney") {
        let (e, nu, c) = (
            par("youngs_modulus"),
            par("poisson_ratio"),
            par("second_invariant_share"),
        );
        let g = e / (2.0 * (1.0 + nu));
        let (c1, c2) = ((1.0 - c) * g / 2.0, c * g / 2.0);
        let i1: f64 = lb.iter().map(|x| x * x).sum();
        (
            lb.map(|x| 2.0 * c1 * x * x + 2.0 * c2 * x * x * (i1 - x * x)),
            e / (3.0 * (1.0 - 2.0 * nu)),
        )
    } else {
        let terms = [(745.5e3, 1.3), (1.5e3, 5.0), (-11.85e3, -2.0)];
        let g: f64 = 0.5 * terms.iter().map(|(m, a)| m * a).sum::<f64>();
        let nu = par("poisson_ratio");
        (
            lb.map(|x| terms.iter().map(|(m, a)| m * x.powf(*a)).sum()),
            2.0 * g * (1.0 + nu) / (3.0 * (1.0 - 2.0 * nu)),
        )
    };
    let mean = (w[0] + w[1] + w[2]) / 3.0;
    let p = bulk / 2.0 * (j - 1.0 / j);
    [0, 1, 2].map(|i| (w[i] - mean) / j + p)
}

/// Uniaxial stress by stretch λ in x (lateral faces free) and equibiaxial stretch in x and y:
/// the lateral stretch and the axial Cauchy stresses of the FE solution (symmetry supports,
/// prescribed faces) against the closed forms, 1e-10 relative.
#[test]
fn hyperelastic_uniaxial_and_biaxial_match_closed_forms() {
    let supports = "[[fem.supports]]\non = { set = \"xmin\" }\nfix = [\"x\"]\n\
                    [[fem.supports]]\non = { set = \"ymin\" }\nfix = [\"y\"]\n\
                    [[fem.supports]]\non = { set = \"zmin\" }\nfix = [\"z\"]\n\
                    [[fem.supports]]\non = { set = \"xmax\" }\nfix = [\"x\"]\n";
    for material in [NEO_HOOKE, MOONEY_RIVLIN, OGDEN] {
        for (biaxial, stretch) in [(false, 1.3), (false, 0.8), (true, 1.2)] {
            let mut extra = supports.to_string();
            if biaxial {
                extra.push_str("[[fem.supports]]\non = { set = \"ymax\" }\nfix = [\"y\"]\n");
            }
            extra.push_str("[fem.newton]\nincrements = 3\nforce_tolerance = 1e-12\n");
            let mut m = model(&cube(material, &extra));
            for n in 0..m.mesh().num_nodes() {
                let x = m.mesh().nodes[n];
                if x[0] == 1.0 {
                    m.set_prescribed_displacement(3 * n, stretch - 1.0).unwrap();
                }
                if biaxial && x[1] == 1.0 {
                    m.set_prescribed_displacement(3 * n + 1, stretch - 1.0)
                        .unwrap();
                }
            }
            m.solve_static().unwrap();
            // lateral stretch from the FE solution; the closed form's lateral stress is 0
            let corner = (0..m.mesh().num_nodes())
                .find(|&n| m.mesh().nodes[n] == [1.0, 1.0, 1.0])
                .unwrap();
            let u = m.displacements();
            let lz = 1.0 + u[3 * corner + 2];
            let l = if biaxial {
                [stretch, stretch, lz]
            } else {
                [stretch, 1.0 + u[3 * corner + 1], lz]
            };
            let exact = principal_cauchy(material, l);
            let scale = exact.iter().fold(0.0f64, |a, b| a.max(b.abs()));
            let free_stress = exact[2].abs() / scale;
            for s in m.element_stresses() {
                let ex = (s[0] - exact[0]).abs() / scale;
                let ey = (s[1] - exact[1]).abs() / scale;
                let es = s[2].abs().max(s[3].abs()).max(s[4].abs()).max(s[5].abs()) / scale;
                assert!(
                    ex < 1e-10 && ey < 1e-10 && es < 1e-10 && free_stress < 1e-10,
                    "{material}\nbiaxial {biaxial} λ = {stretch}: σ = {s:?}, closed form {exact:?}"
                );
            }
            println!(
                "{} {} λ = {stretch}: lateral stretch {lz:.9}, σ_xx = {:.6e} Pa, closed-form \
                 lateral stress / σ_xx = {free_stress:.1e}",
                &material[7..18],
                if biaxial { "biaxial" } else { "uniaxial" },
                exact[0]
            );
        }
    }
}

/// All boundary nodes of the cube at u = (F − I) X, the interior node free: simple shear of
/// Neo-Hooke (σ = μ(b − I): σ_xx = μγ², σ_xy = μγ) and a 90° rigid rotation (no stress; the
/// interior node ends at R X).
#[test]
fn simple_shear_and_rigid_rotation_of_ninety_degrees() {
    let mut extra = String::new();
    for side in ["xmin", "xmax", "ymin", "ymax", "zmin", "zmax"] {
        extra.push_str(&format!("[[fem.supports]]\non = {{ set = \"{side}\" }}\n"));
    }
    extra.push_str("[fem.newton]\nincrements = 4\nforce_tolerance = 1e-12\n");
    let mu = 94e6 / 2.6;
    let gamma = 0.5;
    let shear = [[1.0, gamma, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let rot = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]];
    for (name, f) in [("simple shear", shear), ("rotation", rot)] {
        let mut m = model(&cube(NEO_HOOKE, &extra));
        let interior = (0..m.mesh().num_nodes())
            .find(|&n| m.mesh().nodes[n] == [0.5, 0.5, 0.5])
            .unwrap();
        assert!(!m.is_fixed(3 * interior), "the interior node is free");
        let target = |x: [f64; 3]| -> [f64; 3] {
            [0, 1, 2].map(|i| (0..3).map(|j| f[i][j] * x[j]).sum::<f64>() - x[i])
        };
        for n in 0..m.mesh().num_nodes() {
            if n != interior {
                let u = target(m.mesh().nodes[n]);
                for c in 0..3 {
                    m.set_prescribed_displacement(3 * n + c, u[c]).unwrap();
                }
            }
        }
        m.solve_static().unwrap();
        let exact = if name == "rotation" {
            [0.0; 6]
        } else {
            [mu * gamma * gamma, 0.0, 0.0, mu * gamma, 0.0, 0.0]
        };
        for s in m.element_stresses() {
            for c in 0..6 {
                assert!(
                    (s[c] - exact[c]).abs() <= 1e-10 * mu,
                    "{name}: σ = {s:?}, exact {exact:?}"
                );
            }
        }
        let ui = &m.displacements()[3 * interior..3 * interior + 3];
        let want = target([0.5; 3]);
        for c in 0..3 {
            assert!(
                (ui[c] - want[c]).abs() < 1e-12,
                "{name}: interior node at {ui:?}, want {want:?}"
            );
        }
        let its: Vec<usize> = m
            .last_newton_residuals()
            .iter()
            .map(|h| h.len() - 1)
            .collect();
        println!(
            "{name}: stresses within 1e-10 μ of {exact:?}; Newton iterations per increment {its:?}"
        );
    }
}

/// A hex20 cube clamped at its base, compressed and sheared at its top (pressure 0.15 G,
/// shear load 0.15 G per unit area: strains of ten percent and more), one increment: Newton
/// converges quadratically for every hyperelastic model. The relative residuals are printed;
/// some iteration with r_k < 1e-2 has r_{k+1} ≤ r_k^1.8 (quadratic: r_{k+1} ≈ C r_k²).
/// (A slender hex20 cantilever also converges, in 6–8 iterations, but its residual floor —
/// element forces far larger than their sum — hides the last quadratic step.)
#[test]
fn newton_converges_quadratically() {
    for (material, g) in [
        (NEO_HOOKE, 94e6 / 2.6),
        (MOONEY_RIVLIN, 9.4e6 / 2.82),
        (OGDEN, 0.5e6),
    ] {
        let scene = format!(
            "[fem]\nmesh = {{ size = [1.0, 1.0, 1.0], divisions = [2, 2, 2], element = \"hex20\" }}\n\
             [fem.materials.m]\n{material}\n[[fem.sections]]\nelements = \"all\"\nmaterial = \"m\"\n\
             [[fem.supports]]\non = {{ set = \"zmin\" }}\n\
             [[fem.loads]]\ntype = \"pressure\"\non = {{ set = \"zmax\" }}\nvalue = {p}\n\
             [[fem.loads]]\ntype = \"force\"\non = {{ set = \"zmax\" }}\ntotal = [{p}, 0.0, 0.0]\n\
             [fem.newton]\nforce_tolerance = 1e-13\ndisplacement_tolerance = 1e-13\n",
            p = 0.15 * g
        );
        let mut m = model(&scene);
        m.solve_static().unwrap();
        let h = &m.last_newton_residuals()[0];
        let ratios: Vec<String> = h.iter().map(|r| format!("{r:.2e}")).collect();
        println!(
            "{}: relative residuals {}",
            &material[7..20],
            ratios.join(", ")
        );
        assert_eq!(m.last_newton_residuals().len(), 1, "no cut-back needed");
        assert!(h.len() <= 11, "{} iterations", h.len() - 1);
        let quadratic = h
            .windows(2)
            .any(|p| p[0] < 1e-2 && p[1] > 2e-14 && p[1].ln() / p[0].ln() >= 1.8);
        assert!(quadratic, "no quadratic step in {ratios:?}");
    }
}

// ---------------------------------------------------------------------------------------------
// Mohr–Coulomb
// ---------------------------------------------------------------------------------------------

/// Wellmann's Mohr–Coulomb fit to the DEM sand (§5.4): E = 60 MPa, ν = 0.145, φ = 23.15°,
/// ψ = 5.17°, c = 15 Pa.
const SAND: &str = "model = \"mohr_coulomb\"\nyoungs_modulus = 60e6\npoisson_ratio = 0.145\n\
                    friction_angle = 23.15\ndilation_angle = 5.17\ncohesion = 15.0\ndensity = 1600.0";

/// One hex8 unit cube in a drained triaxial test: lateral pressure `p` on xmax and ymax,
/// symmetry supports, the top (zmax) displacement-controlled.
fn triaxial_cell(p: f64) -> fem::Model {
    model(&format!(
        "[fem]\nmesh = {{ size = [1.0, 1.0, 1.0], divisions = [1, 1, 1], element = \"hex8\" }}\n\
         [fem.materials.sand]\n{SAND}\n[[fem.sections]]\nelements = \"all\"\nmaterial = \"sand\"\n\
         [[fem.supports]]\non = {{ set = \"xmin\" }}\nfix = [\"x\"]\n\
         [[fem.supports]]\non = {{ set = \"ymin\" }}\nfix = [\"y\"]\n\
         [[fem.supports]]\non = {{ set = \"zmin\" }}\nfix = [\"z\"]\n\
         [[fem.supports]]\non = {{ set = \"zmax\" }}\nfix = [\"z\"]\n\
         [[fem.loads]]\ntype = \"pressure\"\non = {{ set = \"xmax\" }}\nvalue = {p}\n\
         [[fem.loads]]\ntype = \"pressure\"\non = {{ set = \"ymax\" }}\nvalue = {p}\n\
         [fem.newton]\nforce_tolerance = 1e-12\ndisplacement_tolerance = 1e-12\n\
         [[fem.strain_gauges]]\nname = \"cell\"\n"
    ))
}

/// Sets the top's axial strain (compression negative) and solves; returns the axial and a
/// lateral stress and the sum of the two lateral strains.
fn triaxial_step(m: &mut fem::Model, eps_axial: f64) -> (f64, f64, f64) {
    for n in 0..m.mesh().num_nodes() {
        if m.mesh().nodes[n][2] == 1.0 {
            m.set_prescribed_displacement(3 * n + 2, eps_axial).unwrap();
        }
    }
    m.advance(1.0).unwrap();
    let corner = (0..m.mesh().num_nodes())
        .find(|&n| m.mesh().nodes[n] == [1.0, 1.0, 1.0])
        .unwrap();
    // both lateral strains: on a Mohr–Coulomb edge only their sum is determined
    let u = m.displacements();
    let s = m.element_stresses()[0];
    (s[2], s[0], u[3 * corner] + u[3 * corner + 1])
}

/// SEED-SPEC V8 with the fitted parameters at σ_lateral = 100 kPa: elastic slope E, elastic
/// ε_V/ε_axial = 1 − 2ν, yield at σ_axial/σ_lateral = 2.296 (cohesion included exactly),
/// axial strain at yield 0.216 %, then constant stress and −Δε_V/Δε_axial = 2 sin ψ/(1 − sin ψ)
/// = 0.198; the element reports the plastic zone and the equivalent plastic strain.
#[test]
fn mohr_coulomb_triaxial_single_element() {
    let p = 1e5;
    let (e, nu) = (60e6, 0.145);
    let (sphi, spsi) = (23.15f64.to_radians().sin(), 5.17f64.to_radians().sin());
    let cphi = 23.15f64.to_radians().cos();
    let mut m = triaxial_cell(p);
    // isotropic consolidation: the elastic strain of σ = −p I
    let eps0 = -p * (1.0 - 2.0 * nu) / e;
    let (sa, sl, _) = triaxial_step(&mut m, eps0);
    assert!(
        (sa + p).abs() < 1e-6 * p && (sl + p).abs() < 1e-6 * p,
        "isotropic: {sa}, {sl}"
    );
    let de = -1e-5;
    let mut rows = vec![(eps0, sa, 2.0 * eps0)];
    for k in 1..=400 {
        let ea = eps0 + k as f64 * de;
        let (sa, sl, lat) = triaxial_step(&mut m, ea);
        assert!(
            (sl + p).abs() < 1e-6 * p,
            "step {k}: lateral stress held: {sl}, axial {sa}, residuals {:?}",
            m.last_newton_residuals()
        );
        rows.push((ea, sa, lat));
    }
    let sigma_yield = -(p * (1.0 + sphi) + 2.0 * 15.0 * cphi) / (1.0 - sphi);
    let vol = |r: &(f64, f64, f64)| r.0 + r.2;
    // elastic part
    let slope = (rows[1].1 - rows[0].1) / (rows[1].0 - rows[0].0);
    let dv = (vol(&rows[1]) - vol(&rows[0])) / (rows[1].0 - rows[0].0);
    // plastic part: the last steps
    let n = rows.len();
    let plateau = rows[n - 1].1;
    let dil = -(vol(&rows[n - 1]) - vol(&rows[n - 2])) / (rows[n - 1].0 - rows[n - 2].0);
    let first_plastic = rows
        .iter()
        .position(|r| (r.1 - sigma_yield).abs() < 1e-9 * p)
        .unwrap();
    let yield_strain = (sigma_yield + p) / e;
    let observed = rows[first_plastic].0 - eps0;
    println!(
        "elastic slope {:.6e} Pa (E = 60 MPa), ε_V/ε_axial {dv:.6} (1 − 2ν = {:.3}); yield \
         stress ratio {:.6} (closed form {:.6}, (1+sinφ)/(1−sinφ) = {:.4}); axial strain at yield \
         {:.5} % (closed form {:.5} %), first plastic step at {:.5} %; −Δε_V/Δε_axial {dil:.6} \
         (2 sinψ/(1 − sinψ) = {:.6})",
        slope,
        1.0 - 2.0 * nu,
        plateau / -p,
        sigma_yield / -p,
        (1.0 + sphi) / (1.0 - sphi),
        -100.0 * yield_strain,
        -100.0 * (sigma_yield + p) / e,
        -100.0 * observed,
        2.0 * spsi / (1.0 - spsi)
    );
    assert!((slope - e).abs() < 1e-8 * e, "slope {slope}");
    assert!((dv - (1.0 - 2.0 * nu)).abs() < 1e-8, "{dv}");
    assert!(
        (plateau - sigma_yield).abs() < 1e-9 * p,
        "{plateau} vs {sigma_yield}"
    );
    assert!((sigma_yield / -p - 2.2961).abs() < 1e-4);
    assert!(
        (dil - 2.0 * spsi / (1.0 - spsi)).abs() < 1e-8,
        "dilatancy {dil}: {:e}",
        dil - 2.0 * spsi / (1.0 - spsi)
    );
    assert!(
        (-100.0 * yield_strain - 0.2160).abs() < 5e-4,
        "{yield_strain}"
    );
    assert!(
        (observed - yield_strain).abs() <= 1e-5 + 1e-12,
        "{observed} vs {yield_strain}"
    );
    // the VTU reports the plastic zone and ε̄ᵖ
    let dir = std::env::temp_dir().join(format!("fem-mc-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    m.write_outputs(&dir).unwrap();
    let vtu = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|x| x == "vtu"))
        .expect("a vtu file");
    let text = std::fs::read_to_string(&vtu).unwrap();
    let array = |name: &str| -> f64 {
        let at = text
            .find(&format!("Name=\"{name}\""))
            .unwrap_or_else(|| panic!("{name}"));
        let body = &text[at..];
        let start = body.find('>').unwrap() + 1;
        body[start..]
            .split_whitespace()
            .next()
            .unwrap()
            .parse()
            .unwrap()
    };
    assert_eq!(array("plastic_zone"), 1.0);
    let peeq = array("equivalent_plastic_strain");
    assert!(peeq > 1e-3 && peeq < 5e-3, "ε̄ᵖ = {peeq}");
    // and so do the gauge columns of fem_probes.csv
    let csv = std::fs::read_to_string(dir.join("fem_probes.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let row: Vec<f64> = lines
        .next()
        .unwrap()
        .split(',')
        .map(|v| v.parse().unwrap())
        .collect();
    let col = |name: &str| {
        row[header
            .iter()
            .position(|h| *h == name)
            .unwrap_or_else(|| panic!("{name} in {header:?}"))]
    };
    // (the CSV has 10 significant digits, the VTU full precision)
    assert!((col("equivalent_plastic_strain.cell") - peeq).abs() < 1e-9 * peeq);
    assert_eq!(col("plastic_zone.cell"), 1.0);
    let s = m.element_stresses()[0];
    assert!((col("stress_von_mises.cell") - (s[0] - s[2]).abs()).abs() < 1e-6 * p);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A snapshot in the plastic range restores the plastic strains: the continuation is bitwise
/// the uninterrupted one.
#[test]
fn plastic_state_survives_snapshot_and_restore() {
    let mut a = triaxial_cell(1e5);
    let e0 = -1e5 * (1.0 - 0.29) / 60e6;
    for k in 0..=300 {
        triaxial_step(&mut a, e0 - 1e-5 * k as f64);
    }
    let snap = a.snapshot();
    let mut b = triaxial_cell(1e5);
    b.restore(&snap).unwrap();
    for k in 301..=330 {
        let ra = triaxial_step(&mut a, e0 - 1e-5 * k as f64);
        let rb = triaxial_step(&mut b, e0 - 1e-5 * k as f64);
        assert_eq!(ra.0.to_bits(), rb.0.to_bits());
        assert_eq!(ra.2.to_bits(), rb.2.to_bits());
    }
    assert_eq!(a.displacements(), b.displacements());
    // the plastic strain is remembered: unloaded to the consolidation strain, the cell keeps
    // its dilation, a fresh cell does not
    let ra = triaxial_step(&mut a, e0);
    let mut c = triaxial_cell(1e5);
    let rc = triaxial_step(&mut c, e0);
    println!(
        "lateral strain sum after unloading {:.4e}, without history {:.4e}",
        ra.2, rc.2
    );
    assert!(
        (ra.2 - rc.2).abs() > 1e-4,
        "history matters: {} vs {}",
        ra.2,
        rc.2
    );
}

// ---------------------------------------------------------------------------------------------
// Scene keys
// ---------------------------------------------------------------------------------------------

const TWO_MATERIALS: &str = r#"[fem]
mesh = { size = [1.0, 0.1, 0.1], divisions = [10, 1, 1], element = "hex8" }

[fem.materials.rubber]
model = "neo_hooke"
youngs_modulus = 94e6
poisson_ratio = 0.3
density = 3000.0

[fem.materials.sand]
model = "mohr_coulomb"
youngs_modulus = 60e6
poisson_ratio = 0.145
friction_angle = 23.15
dilation_angle = 5.17
cohesion = 15.0
density = 1600.0

[[fem.sections]]
elements = { box = { min = [-1.0, -1.0, -1.0], max = [0.5, 1.0, 1.0] } }
material = "rubber"

[[fem.sections]]
elements = { box = { min = [0.5, -1.0, -1.0], max = [2.0, 1.0, 1.0] } }
material = "sand"

[[fem.supports]]
on = { set = "xmin" }
"#;

/// Inconsistent parameters are refused naming the field and its line.
#[test]
fn bad_material_parameters_name_their_field() {
    let cases = [
        (
            "dilation_angle = 5.17",
            "dilation_angle = 30.0",
            "fem.materials.sand.dilation_angle",
            "exceeds the friction angle",
        ),
        (
            "friction_angle = 23.15",
            "friction_angle = 95.0",
            "fem.materials.sand.friction_angle",
            "90°",
        ),
        (
            "cohesion = 15.0",
            "cohesion = -1.0",
            "fem.materials.sand.cohesion",
            "≥ 0 Pa",
        ),
        (
            "poisson_ratio = 0.3",
            "poisson_ratio = 0.5",
            "fem.materials.rubber.poisson_ratio",
            "0.5",
        ),
        (
            "material = \"sand\"",
            "material = \"gravel\"",
            "fem.sections[1].material",
            "no material \"gravel\"",
        ),
        (
            "model = \"neo_hooke\"",
            "model = \"neo_hook\"",
            "",
            "neo_hooke",
        ),
    ];
    for (from, to, field, words) in cases {
        let text = TWO_MATERIALS.replace(from, to);
        let e = fem::parse_scene_section(&text).unwrap_err();
        println!("{e}");
        assert!(
            e.message.contains(field) && e.message.contains(words),
            "{to}: {e}"
        );
        assert!(e.line > 0, "{to}: a line number");
    }
    let ogden = TWO_MATERIALS.replace(
        "model = \"neo_hooke\"\nyoungs_modulus = 94e6\npoisson_ratio = 0.3",
        "model = \"ogden\"\nterms = [[745.5e3, 1.3], [-1.5e3, 5.0]]\npoisson_ratio = 0.45",
    );
    let e = fem::parse_scene_section(&ogden).unwrap_err();
    println!("{e}");
    assert!(
        e.message.contains("fem.materials.rubber.terms[1]") && e.message.contains("stability"),
        "{e}"
    );
}

/// Sections assign materials by box, set or "all"; an element in two sections, an element in
/// none without a default material, an unknown set and a finite-strain material on hex8i are
/// refused naming the element or set.
#[test]
fn sections_assign_materials_and_refuse_conflicts() {
    let m = model(TWO_MATERIALS);
    assert!(m.is_nonlinear());
    let names: Vec<&str> = m.materials().iter().map(|x| x.name.as_str()).collect();
    assert_eq!(names, ["fem.materials.rubber", "fem.materials.sand"]);
    let fail = |text: &str| {
        let cfg = config(text);
        match fem::Model::from_config(&cfg, std::path::Path::new(".")) {
            Ok(_) => panic!("accepted:\n{text}"),
            Err(e) => e.to_string(),
        }
    };
    let e = fail(&TWO_MATERIALS.replace("max = [0.5, 1.0, 1.0]", "max = [0.6, 1.0, 1.0]"));
    println!("{e}");
    assert!(
        e.contains("element 6") && e.contains("fem.sections[0] and fem.sections[1]"),
        "{e}"
    );
    let e = fail(&TWO_MATERIALS.replace("max = [2.0, 1.0, 1.0]", "max = [0.8, 1.0, 1.0]"));
    println!("{e}");
    assert!(e.contains("2 elements") && e.contains("no material"), "{e}");
    let e = fail(&TWO_MATERIALS.replace(
        "elements = { box = { min = [0.5, -1.0, -1.0], max = [2.0, 1.0, 1.0] } }",
        "elements = \"body\"",
    ));
    println!("{e}");
    assert!(
        e.contains("no element set \"body\"") && e.contains("all"),
        "{e}"
    );
    let e = fail(&TWO_MATERIALS.replace("element = \"hex8\"", "element = \"hex8i\""));
    println!("{e}");
    assert!(
        e.contains("hex8i") && e.contains("fem.materials.rubber"),
        "{e}"
    );
    // a default linear material covers what the sections leave out
    let with_default = TWO_MATERIALS.replace("max = [2.0, 1.0, 1.0]", "max = [0.8, 1.0, 1.0]")
        + "[fem.material]\nyoungs_modulus = 210e9\npoisson_ratio = 0.3\ndensity = 7800.0\n";
    let m = model(&with_default);
    assert_eq!(m.materials().len(), 3);
}

// ---------------------------------------------------------------------------------------------
// A boundary-value plasticity benchmark with a closed form
// ---------------------------------------------------------------------------------------------

/// Prandtl: the limit pressure of the footing above is (2 + π) c = 51.4 kPa. The computed
/// collapse pressure levels off, overestimates on the coarse meshes (+13.2 % at h = 0.25 m,
/// the rigid footing's edge element carries load beyond x = b), and the linear extrapolation
/// 2 q(h) − q(2h) from h = 0.5 and 0.25 m lies within 5 % of Prandtl.
#[test]
fn strip_footing_bearing_capacity_matches_prandtl() {
    let c = 1e4;
    let prandtl = (2.0 + std::f64::consts::PI) * c;
    let mut limits = Vec::new();
    for h in [0.5, 0.25] {
        let (curve, iterations, wall) = common::footing::strip_footing(h, 18);
        for (s, q) in &curve {
            println!("h = {h}: settlement {:.3} m, q = {:.3} c", s, q / c);
        }
        let q_end = curve.last().unwrap().1;
        let q_prev = curve[curve.len() - 2].1;
        println!(
            "h = {h} m: limit pressure {:.3} c (Prandtl 2 + π = {:.3}): {:+.1} %; {iterations} \
             Newton iterations in {} steps, {wall:.2} s",
            q_end / c,
            prandtl / c,
            100.0 * (q_end / prandtl - 1.0),
            curve.len()
        );
        assert!(
            (q_end - q_prev).abs() < 0.01 * q_end,
            "h = {h}: the pressure levels off"
        );
        assert!(
            q_end > prandtl && q_end < 1.3 * prandtl,
            "h = {h}: {}",
            q_end / c
        );
        limits.push(q_end);
    }
    let extrapolated = 2.0 * limits[1] - limits[0];
    println!(
        "extrapolated to h → 0: {:.3} c ({:+.1} % from Prandtl)",
        extrapolated / c,
        100.0 * (extrapolated / prandtl - 1.0)
    );
    assert!(limits[1] < limits[0], "the finer mesh is closer");
    assert!(
        (extrapolated / prandtl - 1.0).abs() < 0.05,
        "{}",
        extrapolated / c
    );
}

// ---------------------------------------------------------------------------------------------
// Moving supports
// ---------------------------------------------------------------------------------------------

/// A support with `displacement` and `history` moves: its dofs follow value × h(t) in static,
/// Bossak and explicit analyses, linear and Neo-Hooke; the body follows it; a displacement of a
/// component that is not fixed is refused.
#[test]
fn moving_supports_follow_their_history() {
    let base = |material: &str, analysis: &str| {
        format!(
            "[fem]\nmesh = {{ size = [1.0, 0.1, 0.1], divisions = [10, 1, 1], element = \"hex8\" }}\n\
             {material}\n{analysis}\n\
             [fem.histories.ramp]\ntype = \"table\"\npoints = [[0.0, 0.0], [1.0, 1.0]]\n\
             [[fem.supports]]\non = {{ set = \"xmin\" }}\n\
             [[fem.supports]]\non = {{ set = \"xmax\" }}\nfix = [\"x\"]\n\
             displacement = [2e-3, 0.0, 0.0]\nhistory = \"ramp\"\n"
        )
    };
    let rubber =
        "[fem.materials.r]\nmodel = \"neo_hooke\"\nyoungs_modulus = 9.4e6\npoisson_ratio = 0.3\n\
                  density = 1000.0\n[[fem.sections]]\nelements = \"all\"\nmaterial = \"r\"";
    let linear = "[fem.material]\nyoungs_modulus = 9.4e6\npoisson_ratio = 0.3\ndensity = 1000.0";
    for (material, analysis, dt, steps) in [
        (linear, "", 0.25, 2),
        (rubber, "", 0.25, 2),
        (
            linear,
            "[fem.analysis]\ntype = \"dynamic\"\nmass = \"lumped\"",
            0.005,
            100,
        ),
        (
            rubber,
            "[fem.analysis]\ntype = \"dynamic\"\nmass = \"lumped\"",
            0.005,
            100,
        ),
        (rubber, "[fem.analysis]\ntype = \"explicit\"", 0.005, 100),
    ] {
        let mut m = model(&base(material, analysis));
        for _ in 0..steps {
            m.advance(dt).unwrap();
        }
        let t = m.time();
        let u = m.displacements();
        let (mut end, mut mid) = (f64::NAN, f64::NAN);
        for n in 0..m.mesh().num_nodes() {
            let x = m.mesh().nodes[n];
            if x[0] == 1.0 {
                end = u[3 * n];
            }
            if (x[0] - 0.5).abs() < 1e-12 {
                mid = u[3 * n];
            }
        }
        println!("{analysis:?}: t = {t}, end {end:.6e}, midspan {mid:.6e}");
        assert!(
            (end - 2e-3 * t).abs() < 1e-15,
            "end at {end}, want {}",
            2e-3 * t
        );
        assert!(
            mid > 0.2 * end && mid < 0.8 * end,
            "the bar follows: {mid} of {end}"
        );
    }
    let bad = base(linear, "").replace(
        "displacement = [2e-3, 0.0, 0.0]",
        "displacement = [2e-3, 1e-3, 0.0]",
    );
    let e = fem::parse_scene_section(&bad).unwrap_err();
    println!("{e}");
    assert!(
        e.message.contains("fem.supports[1].displacement") && e.message.contains("y is not in fix"),
        "{e}"
    );
}

/// `[fem.newton] tangent = "modified"` (one factor per increment or step, refreshed when the
/// residual falls too slowly) converges to the same state as full Newton: a sheared,
/// compressed Neo-Hooke cube (static) and 20 Bossak steps of a loaded Neo-Hooke cantilever.
#[test]
fn modified_newton_reaches_the_full_newton_state() {
    let cube = |tangent: &str| {
        format!(
            "[fem]\nmesh = {{ size = [1.0, 1.0, 1.0], divisions = [2, 2, 2], element = \"hex20\" }}\n\
             [fem.materials.m]\n{NEO_HOOKE}\n[[fem.sections]]\nelements = \"all\"\nmaterial = \"m\"\n\
             [[fem.supports]]\non = {{ set = \"zmin\" }}\n\
             [[fem.loads]]\ntype = \"pressure\"\non = {{ set = \"zmax\" }}\nvalue = 5e6\n\
             [[fem.loads]]\ntype = \"force\"\non = {{ set = \"zmax\" }}\ntotal = [5e6, 0.0, 0.0]\n\
             [fem.newton]\nforce_tolerance = 1e-11\ntangent = \"{tangent}\"\n"
        )
    };
    let beam = |tangent: &str| {
        format!(
            "[fem]\nmesh = {{ size = [0.5, 0.05, 0.05], element_size = 0.025, element = \"hex8\" }}\n\
             [fem.materials.m]\n{NEO_HOOKE}\n[[fem.sections]]\nelements = \"all\"\nmaterial = \"m\"\n\
             [fem.analysis]\ntype = \"dynamic\"\nalpha_b = -0.1\n\
             [[fem.supports]]\non = {{ set = \"xmin\" }}\n\
             [[fem.loads]]\ntype = \"force\"\non = {{ set = \"xmax\" }}\ntotal = [0.0, 0.0, -500.0]\n\
             [fem.newton]\nforce_tolerance = 1e-11\ntangent = \"{tangent}\"\n"
        )
    };
    for (name, scene, steps, dt) in [
        ("static cube", cube as fn(&str) -> String, 1, 1.0),
        ("Bossak cantilever", beam, 20, 1e-3),
    ] {
        let mut full = model(&scene("full"));
        let mut modified = model(&scene("modified"));
        let (mut its_full, mut its_mod) = (0, 0);
        for _ in 0..steps {
            full.advance(dt).unwrap();
            modified.advance(dt).unwrap();
            its_full += full
                .last_newton_residuals()
                .iter()
                .map(|h| h.len() - 1)
                .sum::<usize>();
            its_mod += modified
                .last_newton_residuals()
                .iter()
                .map(|h| h.len() - 1)
                .sum::<usize>();
        }
        let d = max_rel_diff(full.displacements(), modified.displacements());
        println!("{name}: full Newton {its_full} iterations, modified {its_mod}; states differ by {d:.2e}");
        assert!(d < 1e-8, "{name}: {d:e}");
        assert!(
            its_mod >= its_full,
            "modified Newton iterates more (it factorises less)"
        );
    }
}

/// A Mohr–Coulomb block pulled apart on every face reaches the apex σ = c cot φ everywhere
/// (a body of zero stiffness: the exact tangent vanishes there) and Newton still converges —
/// as the volumetric unloading path of Wellmann's coupled triaxial cube does to its continuum.
#[test]
fn a_block_pulled_into_the_apex_converges_at_c_cot_phi() {
    let mut m = model(
        "[fem]\nmesh = { size = [1.0, 1.0, 1.0], divisions = [2, 2, 2], element = \"hex8\" }\n\
         [fem.materials.sand]\nmodel = \"mohr_coulomb\"\nyoungs_modulus = 1e6\n\
         poisson_ratio = 0.3\nfriction_angle = 27.0\ndilation_angle = 5.0\ncohesion = 100.0\n\
         density = 1500.0\n[[fem.sections]]\nelements = \"all\"\nmaterial = \"sand\"\n\
         [fem.histories.ramp]\ntype = \"table\"\npoints = [[0.0, 0.0], [1.0, 1.0]]\n\
         [[fem.supports]]\non = { set = \"xmin\" }\nfix = [\"x\"]\n\
         [[fem.supports]]\non = { set = \"ymin\" }\nfix = [\"y\"]\n\
         [[fem.supports]]\non = { set = \"zmin\" }\nfix = [\"z\"]\n\
         [[fem.supports]]\non = { set = \"xmax\" }\nfix = [\"x\"]\n\
         displacement = [1e-3, 0.0, 0.0]\nhistory = \"ramp\"\nname = \"xmax\"\n\
         [[fem.supports]]\non = { set = \"ymax\" }\nfix = [\"y\"]\n\
         displacement = [0.0, 1.5e-3, 0.0]\nhistory = \"ramp\"\n\
         [[fem.supports]]\non = { set = \"zmax\" }\nfix = [\"z\"]\n\
         displacement = [0.0, 0.0, 0.5e-3]\nhistory = \"ramp\"\n",
    );
    for _ in 0..10 {
        m.advance(0.1).unwrap();
    }
    let apex = 100.0 / 27f64.to_radians().tan();
    for s in m.element_stresses() {
        for i in 0..3 {
            assert!((s[i] - apex).abs() < 1e-6 * apex, "{s:?} vs {apex}");
        }
    }
    let r: std::collections::BTreeMap<String, f64> = m.results().into_iter().collect();
    // the support holds the face against the tension c cot φ over its 1 m²
    assert!(
        (r["reaction.xmax.x"] - apex).abs() < 1e-6 * apex,
        "{}",
        r["reaction.xmax.x"]
    );
}
