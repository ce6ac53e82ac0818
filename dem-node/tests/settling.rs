//! A column of 10,000 randomly inserted spheres settles in a box and comes to rest.
mod common;
use common::*;

#[test]
fn settling_column_of_10k_spheres_comes_to_rest() {
    // 10,000 spheres r = 4–5 mm inserted at random (solid fraction ~0.32) and dropped into a
    // box; soft material. Δt = 0.15 Δt_R: in this soft bed the overlaps reach 7 % of the
    // radius and the counter-rotation mode of neighbours (ω² ≈ 5 Z k_t/m) is unstable at
    // 0.29 Δt_R although the Rayleigh criterion is met.
    let scene = r#"
[dem]
time_step = 4.5e-5
gravity = [0.0, 0.0, -9.81]
[dem.materials.soft]
youngs_modulus = 5e6
poisson_ratio = 0.3
density = 1000.0
restitution = 0.2
friction = 0.5
rolling_friction = 0.1
[[dem.walls]]
kind = "box"
material = "soft"
min = [0.0, 0.0, 0.0]
max = [0.2, 0.2, 0.4]
open = ["+z"]
[[dem.particles]]
kind = "fill"
material = "soft"
min = [0.0, 0.0, 0.0]
max = [0.2, 0.2, 0.3]
count = 10000
seed = 3
distribution = { kind = "uniform", min = 0.004, max = 0.005 }
"#;
    let t0 = std::time::Instant::now();
    let mut e = engine(scene);
    assert_eq!(e.num_particles(), 10_000);
    let ke_fall = {
        e.advance(1000).unwrap();
        e.kinetic_energy()
    };
    let mut ke = ke_fall;
    while e.time() < 0.6 {
        e.advance(500).unwrap();
        ke = e.kinetic_energy();
        println!(
            "  t = {:.3} s: KE = {ke:.3e} J, list builds {}",
            e.time(),
            e.neighbour_list_builds()
        );
        if ke < 2e-5 {
            break;
        }
    }
    let r: std::collections::HashMap<String, f64> = e.results().into_iter().collect();
    println!(
        "t = {:.2} s, KE = {ke:e} J (at 0.05 s: {ke_fall:e} J), contacts {}, wall contacts {}, max overlap {:e} m, \
         packing fraction {:.3}, list builds {}, wall time {:.1} s",
        e.time(),
        r["contacts"],
        r["wall_contacts"],
        r["max_overlap"],
        r["packing_fraction"],
        r["neighbour_list_builds"],
        t0.elapsed().as_secs_f64()
    );
    // 2e-5 J over 10,000 spheres of ~0.4 g: r.m.s. speed below 3 mm/s, 6e-5 of the peak
    assert!(ke < 2e-5, "kinetic energy {ke} J: not at rest");
    // poured random packing of frictional spheres (bulk value incl. the loose top layer)
    let phi = r["packing_fraction"];
    assert!(phi > 0.5 && phi < 0.64, "packing fraction {phi}");
    assert!(r["max_overlap"] < 0.05 * 0.004);
}
