//! Strain gauges: maximum principal and von Mises equivalent strain over (part of) the mesh,
//! checked on states whose strain is known exactly.
#![allow(
    clippy::neg_cmp_op_on_partial_ord,
    clippy::needless_range_loop,
    clippy::nonminimal_bool
)]

mod common;
use common::*;

const E: f64 = 210e9;
const NU: f64 = 0.3;
const KINDS: [&str; 5] = ["tet4", "tet10", "hex8", "hex8i", "hex20"];

fn gauge<'a>(g: &'a [(String, [f64; 3])], name: &str) -> &'a [f64; 3] {
    &g.iter().find(|(n, _)| n == name).expect("gauge").1
}

fn result(m: &fem::Model, key: &str) -> f64 {
    m.results()
        .into_iter()
        .find(|(k, _)| k == key)
        .unwrap_or_else(|| panic!("{key} missing"))
        .1
}

/// A bar on rollers (x, y, z symmetry faces) pulled by σ on its end: uniaxial stress, so
/// ε_xx = σ/E, ε_yy = ε_zz = −ν σ/E in every element, and the von Mises strain is
/// (2/3)(1 + ν) σ/E. Every element type reproduces it to round-off.
fn tension_bar(element: &str) -> String {
    format!(
        r#"
[fem]
mesh = {{ size = [1.0, 0.1, 0.1], element_size = 0.05, element = "{element}" }}
[fem.material]
E = {E}
nu = {NU}
rho = 7800.0
[[fem.supports]]
on = {{ set = "xmin" }}
fix = ["x"]
[[fem.supports]]
on = {{ set = "ymin" }}
fix = ["y"]
[[fem.supports]]
on = {{ set = "zmin" }}
fix = ["z"]
[fem.histories.up_down]
type = "table"
points = [[0.0, 0.0], [1.0, 1.0], [2.0, 0.5]]
[[fem.loads]]
type = "pressure"
on = {{ set = "xmax" }}
value = -1e8
history = "up_down"
[[fem.probes]]
name = "end"
point = [1.0, 0.0, 0.0]
[[fem.strain_gauges]]
name = "bar"
[[fem.strain_gauges]]
name = "end_part"
on = {{ box = {{ min = [0.8, 0.0, 0.0], max = [1.0, 0.1, 0.1] }} }}
[fem.output]
vtu_every = 0
"#
    )
}

#[test]
fn uniform_tension_strain_is_sigma_over_e_for_every_element() {
    let sigma = 1e8;
    let eps = sigma / E;
    for el in KINDS {
        let mut m = model(&tension_bar(el));
        let dir = tempfile::tempdir().unwrap();
        m.advance(1.0).unwrap();
        m.write_outputs(dir.path()).unwrap();
        let g = m.strain_gauges();
        for name in ["bar", "end_part"] {
            let [max_p, min_p, vm] = *gauge(&g, name);
            assert!(
                (max_p / eps - 1.0).abs() < 1e-9,
                "{el} {name}: {max_p:e} vs {eps:e}"
            );
            assert!(
                (min_p / (-NU * eps) - 1.0).abs() < 1e-9,
                "{el} {name}: {min_p:e}"
            );
            let vm_exact = 2.0 / 3.0 * (1.0 + NU) * eps;
            assert!(
                (vm / vm_exact - 1.0).abs() < 1e-9,
                "{el} {name}: {vm:e} vs {vm_exact:e}"
            );
        }
        // unloading to half: the last value halves, the peak keeps the maximum
        m.advance(1.0).unwrap();
        m.write_outputs(dir.path()).unwrap();
        let last = result(&m, "strain.bar.max_principal");
        let peak = result(&m, "strain.bar.max_principal.peak");
        assert!(
            (last / (0.5 * eps) - 1.0).abs() < 1e-9,
            "{el}: last {last:e}"
        );
        assert!((peak / eps - 1.0).abs() < 1e-9, "{el}: peak {peak:e}");
        let min_peak = result(&m, "strain.bar.min_principal.peak");
        assert!(
            (min_peak / (-NU * eps) - 1.0).abs() < 1e-9,
            "{el}: {min_peak:e}"
        );
        // the time series: one row per output with probe and strain columns
        let csv = std::fs::read_to_string(dir.path().join("fem_probes.csv")).unwrap();
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(lines.len(), 3, "{csv}");
        let header: Vec<&str> = lines[0].split(',').collect();
        assert_eq!(
            header,
            [
                "time",
                "probe.end.ux",
                "probe.end.uy",
                "probe.end.uz",
                "strain.bar.max_principal",
                "strain.bar.min_principal",
                "strain.bar.von_mises",
                "strain.end_part.max_principal",
                "strain.end_part.min_principal",
                "strain.end_part.von_mises",
            ]
        );
        let row: Vec<f64> = lines[1].split(',').map(|v| v.parse().unwrap()).collect();
        assert!((row[1] / eps - 1.0).abs() < 1e-6, "{el}: end ux {}", row[1]);
        assert!((row[4] / eps - 1.0).abs() < 1e-6 && (row[7] / eps - 1.0).abs() < 1e-6);
        let row: Vec<f64> = lines[2].split(',').map(|v| v.parse().unwrap()).collect();
        assert!(
            (row[4] / (0.5 * eps) - 1.0).abs() < 1e-6,
            "{el}: {}",
            lines[2]
        );
    }
}

/// Pure bending by a prescribed end rotation u_x = −κ L z (Saint-Venant's solution is exact
/// for any ν): ε_xx = −κ z, ε_yy = ε_zz = ν κ z. The largest strains sit at the integration
/// points nearest the fibres: max principal κ|z_q| at the bottom, min principal −κ z_q at the
/// top, von Mises (2/3)(1 + ν) κ |z_q|. Exact for the elements that represent the quadratic
/// bending field (hex8i, hex20, tet10 — see the locking table in FEM.md).
#[test]
fn pure_bending_strain_peaks_at_outer_integration_points() {
    let kappa = 1e-3;
    let h = 0.025;
    for (el, z_q) in [
        // hex 2×2×2 / 3×3×3 Gauss points: centre of the outer element ∓ (h/2)/√3, (h/2)√0.6
        ("hex8i", 0.05 - h / 2.0 + h / 2.0 / 3f64.sqrt()),
        ("hex20", 0.05 - h / 2.0 + h / 2.0 * 0.6f64.sqrt()),
    ] {
        let text = format!(
            r#"
[fem]
mesh = {{ size = [1.0, 0.1, 0.1], origin = [0.0, -0.05, -0.05], element_size = {h}, element = "{el}" }}
[fem.material]
E = {E}
nu = {NU}
rho = 7800.0
[[fem.supports]]
on = {{ set = "xmin" }}
fix = ["x"]
[[fem.supports]]
on = {{ set = "xmax" }}
fix = ["x"]
[[fem.supports]]
on = {{ box = {{ min = [-1e-9, -1e-9, -1.0], max = [1e-9, 1e-9, 1.0] }} }}
fix = ["y"]
[[fem.supports]]
on = {{ box = {{ min = [-1e-9, -1e-9, -1e-9], max = [1e-9, 1e-9, 1e-9] }} }}
fix = ["z"]
[[fem.strain_gauges]]
name = "beam"
[[fem.strain_gauges]]
name = "top_half"
on = {{ box = {{ min = [0.0, -0.05, 0.0], max = [1.0, 0.05, 0.05] }} }}
"#
        );
        let mut m = model(&text);
        let end = m.mesh().node_set("xmax").unwrap().clone();
        for &n in &end {
            let z = m.mesh().nodes[n as usize][2];
            m.set_prescribed_displacement(3 * n as usize, -kappa * z)
                .unwrap();
        }
        m.solve_static().unwrap();
        let g = m.strain_gauges();
        let [max_p, min_p, vm] = *gauge(&g, "beam");
        println!("{el}: max principal {max_p:.6e}, exact {:.6e}", kappa * z_q);
        assert!(
            (max_p / (kappa * z_q) - 1.0).abs() < 1e-6,
            "{el}: {max_p:e}"
        );
        assert!(
            (min_p / (-kappa * z_q) - 1.0).abs() < 1e-6,
            "{el}: {min_p:e}"
        );
        let vm_exact = 2.0 / 3.0 * (1.0 + NU) * kappa * z_q;
        assert!((vm / vm_exact - 1.0).abs() < 1e-6, "{el}: {vm:e}");
        // the top half is compressed along the axis: its largest principal strain is the
        // transverse ν κ z_q, its smallest −κ z_q
        let [max_top, min_top, _] = *gauge(&g, "top_half");
        assert!(
            (max_top / (NU * kappa * z_q) - 1.0).abs() < 1e-6,
            "{el}: {max_top:e}"
        );
        assert!(
            (min_top / (-kappa * z_q) - 1.0).abs() < 1e-6,
            "{el}: {min_top:e}"
        );
    }
}

#[test]
fn strain_gauge_that_selects_no_whole_element_names_its_field() {
    let text = tension_bar("hex8").replace(
        "on = { box = { min = [0.8, 0.0, 0.0], max = [1.0, 0.1, 0.1] } }",
        "on = { plane = { axis = \"x\", value = 1.0 } }",
    );
    let cfg = config(&text);
    let e = match fem::Model::from_config(&cfg, std::path::Path::new(".")) {
        Err(e) => e.to_string(),
        Ok(_) => panic!("a face selects no whole element"),
    };
    assert!(e.contains("fem.strain_gauges[1].on"), "{e}");
}

#[test]
fn repeated_strain_gauge_name_is_refused_with_its_line() {
    let text = tension_bar("hex8").replace("name = \"end_part\"", "name = \"bar\"");
    let e = fem::parse_scene_section(&text).unwrap_err();
    assert!(e.message.contains("fem.strain_gauges[1].name"), "{e}");
    // the second gauge's `name` line
    let line = text
        .lines()
        .collect::<Vec<_>>()
        .iter()
        .rposition(|l| *l == "name = \"bar\"")
        .unwrap()
        + 1;
    assert_eq!(e.line, line, "{e}");
}
