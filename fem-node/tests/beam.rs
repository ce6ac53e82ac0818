mod common;
use common::*;

#[test]
fn explore_a3() {
    for (el, h) in [
        ("hex8", 0.05),
        ("hex8i", 0.05),
        ("hex20", 0.05),
        ("tet10", 0.05),
        ("hex8", 0.025),
        ("hex8i", 0.025),
        ("hex20", 0.025),
    ] {
        let mut m = model(&a3_beam(el, h));
        let t = std::time::Instant::now();
        m.solve_static().unwrap();
        println!(
            "{el} {h}: c {:.4e} top {:.4e} bot {:.4e} ({:?}, {} dofs)",
            m.probe_displacement("midspan").unwrap()[2],
            m.probe_displacement("midspan_top").unwrap()[2],
            m.probe_displacement("midspan_bottom").unwrap()[2],
            t.elapsed(),
            m.num_dofs()
        );
    }
}
