//! Snapshot / restore: continuation after restore is bitwise identical.
#![allow(
    clippy::neg_cmp_op_on_partial_ord,
    clippy::needless_range_loop,
    clippy::nonminimal_bool
)]

mod common;
use common::*;

const SCENE: &str = r#"
[fem]
mesh = { size = [0.6, 0.1, 0.1], element_size = 0.05, element = "hex8i" }
[fem.material]
youngs_modulus = 210e9
poisson_ratio = 0.3
density = 7800.0
[fem.analysis]
type = "dynamic"
alpha_b = -0.1
rayleigh_a = 2.0
rayleigh_b = 1e-6
[[fem.supports]]
on = { set = "xmin" }
[fem.histories.shake]
type = "sine"
amplitude = 500.0
frequency = 50.0
[[fem.loads]]
type = "force"
on = { set = "xmax" }
total = [0.0, 1.0, -1.0]
history = "shake"
"#;

fn run(m: &mut fem::Model, steps: usize) {
    let n = m.interface_mesh().node_ids.len();
    for k in 0..steps {
        let f: Vec<f64> = (0..3 * n).map(|i| ((i + k) % 7) as f64 - 3.0).collect();
        m.set_interface_forces(&f).unwrap();
        m.advance(2e-4).unwrap();
    }
}

#[test]
fn snapshot_restore_continues_bitwise() {
    let mut a = model(SCENE);
    run(&mut a, 7);
    let snap = a.snapshot();
    run(&mut a, 9);
    let ref_u = a.displacements().to_vec();
    let ref_kin = a.interface_kinematics();

    // same model instance
    a.restore(&snap).unwrap();
    run(&mut a, 9);
    assert!(a
        .displacements()
        .iter()
        .zip(&ref_u)
        .all(|(x, y)| x.to_bits() == y.to_bits()));

    // a fresh model built from the same scene
    let mut b = model(SCENE);
    b.restore(&snap).unwrap();
    run(&mut b, 9);
    let kin = b.interface_kinematics();
    assert!(b
        .displacements()
        .iter()
        .zip(&ref_u)
        .all(|(x, y)| x.to_bits() == y.to_bits()));
    for (p, q) in [
        (&kin.0, &ref_kin.0),
        (&kin.1, &ref_kin.1),
        (&kin.2, &ref_kin.2),
    ] {
        assert!(p
            .iter()
            .zip(q.iter())
            .all(|(x, y)| x.to_bits() == y.to_bits()));
    }
    assert_eq!(b.time().to_bits(), a.time().to_bits());
    assert!(ref_u.iter().any(|x| *x != 0.0));
}

#[test]
fn restore_rejects_foreign_snapshot() {
    let mut a = model(SCENE);
    let other = model(&SCENE.replace("element_size = 0.05", "element_size = 0.1"));
    let err = a.restore(&other.snapshot()).unwrap_err().to_string();
    assert!(err.contains("dofs"), "{err}");
    assert!(a.restore(b"not a snapshot").is_err());
}
