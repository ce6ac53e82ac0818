//! Outputs after each window: probe CSV rows and VTU files with displacement and von Mises.
#![allow(
    clippy::neg_cmp_op_on_partial_ord,
    clippy::needless_range_loop,
    clippy::nonminimal_bool
)]

mod common;
use common::*;

#[test]
fn outputs_write_probe_csv_and_vtu_with_stress() {
    let mut m = model(&format!(
        "{}\n[fem.output]\nvtu_every = 2\n",
        a3_beam("hex8", 0.05)
    ));
    let dir = tempfile::tempdir().unwrap();
    for _ in 0..4 {
        m.advance(0.5).unwrap();
        m.write_outputs(dir.path()).unwrap();
    }
    let csv = std::fs::read_to_string(dir.path().join("fem_probes.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines.len(), 5, "{csv}");
    assert!(lines[0].starts_with("time,probe.midspan.ux,probe.midspan.uy,probe.midspan.uz"));
    let uz: f64 = lines[4].split(',').nth(3).unwrap().parse().unwrap();
    assert!((uz / -7.05e-7 - 1.0).abs() < 0.005, "{uz}");
    let t: f64 = lines[4].split(',').next().unwrap().parse().unwrap();
    assert!((t - 2.0).abs() < 1e-12);
    // VTU every 2 windows
    assert!(
        dir.path().join("fem_000002.vtu").exists() && dir.path().join("fem_000004.vtu").exists()
    );
    assert!(!dir.path().join("fem_000001.vtu").exists());
    let vtu = std::fs::read_to_string(dir.path().join("fem_000004.vtu")).unwrap();
    assert!(vtu.contains("Name=\"displacement\"") && vtu.contains("Name=\"von_mises\""));
    assert!(vtu.contains(&format!("NumberOfCells=\"{}\"", m.mesh().num_elements())));
    let pvd = std::fs::read_to_string(dir.path().join("fem.pvd")).unwrap();
    assert_eq!(pvd.matches("<DataSet").count(), 2);
    // bending stress at the clamped ends: σ_xx ≈ M/W with M = ωL²/12 (fixed-fixed beam), top fibre
    let w_mod = 0.1 * 0.1f64.powi(2) / 6.0;
    let m_end = 500.0 / 12.0;
    let vm_max = m
        .element_stresses()
        .iter()
        .map(fem::element::von_mises)
        .fold(0.0, f64::max);
    println!(
        "max element von Mises {vm_max:.4e} Pa, beam theory end stress {:.4e} Pa",
        m_end / w_mod
    );
    assert!(vm_max > 0.3 * m_end / w_mod && vm_max < 1.5 * m_end / w_mod);
    let res = m.results();
    assert!(res.iter().any(|(k, v)| k == "probe.midspan.uz" && *v == uz
        || k == "probe.midspan.uz" && (*v - uz).abs() < 1e-15));
    assert!(res
        .iter()
        .any(|(k, v)| k == "dofs" && *v == m.num_dofs() as f64));
}
