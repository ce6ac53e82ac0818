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

/// Named supports report their reactions, over the components each fixes: a block pressed by
/// 1 kPa on its top face and squeezed sideways by a moving face carries the top load through
/// its bottom (1 kPa × 1 m² = 1 kN up), and the two x faces react equal and opposite; the
/// columns reach fem_probes.csv.
#[test]
fn named_supports_report_their_reactions() {
    let mut m = model(
        "[fem]\nmesh = { size = [1.0, 1.0, 1.0], origin = [0.0, 0.0, 0.0], divisions = [2, 2, 2], \
         element = \"hex8\" }\nmaterial = { youngs_modulus = 1e6, poisson_ratio = 0.3, \
         density = 1000.0 }\nanalysis = \"static\"\n\
         [[fem.supports]]\non = { plane = { axis = \"z\", value = 0.0 } }\nname = \"bottom\"\n\
         [[fem.supports]]\non = { plane = { axis = \"x\", value = 0.0 } }\nfix = [\"x\"]\n\
         name = \"left\"\n\
         [[fem.supports]]\non = { plane = { axis = \"x\", value = 1.0 } }\nfix = [\"x\"]\n\
         displacement = [-1e-3, 0.0, 0.0]\nname = \"right\"\n\
         [[fem.loads]]\ntype = \"pressure\"\non = { plane = { axis = \"z\", value = 1.0 } }\n\
         value = 1e3\n",
    );
    let dir = tempfile::tempdir().unwrap();
    m.advance(1.0).unwrap();
    m.write_outputs(dir.path()).unwrap();
    let r: std::collections::BTreeMap<String, f64> = m.results().into_iter().collect();
    println!("{r:?}");
    assert!((r["reaction.bottom.z"] - 1e3).abs() < 1e-6 * 1e3);
    // the bottom holds x too (all components fixed): the sideways squeeze leaves through
    // the three supports together
    let fx = r["reaction.bottom.x"] + r["reaction.left.x"] + r["reaction.right.x"];
    assert!(fx.abs() < 1e-6 * r["reaction.right.x"].abs(), "{fx}");
    assert!(r["reaction.right.x"] < 0.0 && r["reaction.left.x"] > 0.0);
    // a support reports only what it fixes
    assert_eq!(r["reaction.left.y"], 0.0);
    assert_eq!(r["reaction.left.z"], 0.0);
    let csv = std::fs::read_to_string(dir.path().join("fem_probes.csv")).unwrap();
    assert!(
        csv.lines().next().unwrap().contains("reaction.right.x"),
        "{csv}"
    );
}

/// A box mesh with `[fem.overlap] carve = true` loses the elements in the particles' pocket:
/// the model builds and solves, and the nodes only the pocket used carry no unknowns.
#[test]
fn a_carved_box_mesh_builds_and_solves() {
    let mut m = model(
        "[fem]\nmesh = { size = [4.0, 4.0, 4.0], origin = [0.0, 0.0, 0.0], divisions = [4, 4, 4], \
         element = \"hex8\" }\nmaterial = { youngs_modulus = 1e6, poisson_ratio = 0.3, \
         density = 1000.0 }\nanalysis = \"static\"\n\
         [[fem.supports]]\non = { plane = { axis = \"z\", value = 0.0 } }\nname = \"bottom\"\n\
         [[fem.loads]]\ntype = \"force\"\non = { plane = { axis = \"z\", value = 4.0 } }\n\
         total = [0.0, 0.0, -1e3]\n\
         [fem.overlap]\nde_region = { min = [1.0, 1.0, 2.0], max = [3.0, 3.0, 10.0] }\n\
         width = 1.0\npenalty = 1e6\ncarve = true\n",
    );
    assert_eq!(m.mesh().num_elements(), 56);
    // of 125 nodes, only the pocket's (2, 2, 3) and (2, 2, 4) touch no element left
    let used = m.mesh().used_nodes().iter().filter(|&&u| u).count();
    assert_eq!(used, 123);
    m.advance(1.0).unwrap();
    let r: std::collections::BTreeMap<String, f64> = m.results().into_iter().collect();
    // the 123 used nodes less the 25 supported carry the unknowns
    assert_eq!(r["free_dofs"], 3.0 * (123.0 - 25.0));
    // the load goes down through the block and into the penalty (no particles here: ε V ties
    // the overlap to rest), so the support takes part of it
    let bottom = r["reaction.bottom.z"];
    assert!(
        bottom > 0.0 && bottom < 1e3 && r["max_displacement"].is_finite(),
        "{r:?}"
    );
}
