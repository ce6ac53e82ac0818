//! Coupled (FEM interface) meshes: kinematics by motion rule, nodal force transfer, averaging.
mod common;
use common::*;
use dem::MotionRule;

const SCENE: &str = r#"
[dem]
time_step = 2e-5
gravity = [0.0, 0.0, 0.0]
interface_material = "steel"
[dem.materials.grain]
youngs_modulus = 1e7
poisson_ratio = 0.3
density = 1200.0
restitution = 0.5
friction = 0.4
[dem.materials.steel]
youngs_modulus = 2e11
poisson_ratio = 0.3
density = 7800.0
restitution = 0.5
friction = 0.3
[[dem.particles]]
kind = "list"
material = "grain"
spheres = [
  { position = [0.011, 0.013, 0.0098], radius = 0.01, velocity = [0.2, 0.1, -0.3] },
  { position = [0.047, 0.021, 0.0099], radius = 0.01, velocity = [-0.1, 0.3, -0.2] },
  { position = [0.032, 0.052, 0.0097], radius = 0.01, velocity = [0.0, -0.2, -0.4], angular_velocity = [5.0, 1.0, 0.0] },
  { position = [0.068, 0.071, 0.0099], radius = 0.01, velocity = [0.3, 0.0, -0.1] },
]
"#;

/// Plate z = 0 over [0, 0.08]² of 4×4 squares (32 triangles).
fn plate() -> (Vec<f64>, Vec<u32>) {
    let n = 4;
    let h = 0.02;
    let mut pos = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            pos.extend_from_slice(&[i as f64 * h, j as f64 * h, 0.0]);
        }
    }
    let id = |i: usize, j: usize| (j * (n + 1) + i) as u32;
    let mut tris = Vec::new();
    for j in 0..n {
        for i in 0..n {
            tris.extend_from_slice(&[
                id(i, j),
                id(i + 1, j),
                id(i + 1, j + 1),
                id(i, j),
                id(i + 1, j + 1),
                id(i, j + 1),
            ]);
        }
    }
    (pos, tris)
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Nodal forces sum to the total contact force, and their moment about any point equals the
/// moment of the contact forces applied at the contact points (Wellmann 4.3–4.4).
#[test]
fn nodal_forces_conserve_total_contact_force_and_moment() {
    let mut e = engine(SCENE);
    let (pos, tris) = plate();
    let m = e.add_coupled_mesh("plate", &pos, &tris).unwrap();
    let v = vec![0.0; pos.len()];
    e.set_mesh_kinematics(m, &pos, &v, &v, MotionRule::Linear)
        .unwrap();
    e.advance(3).unwrap();
    let nodal = e.interface_forces(m, false);
    let p = e.particles();
    assert_eq!(
        e.num_contacts(),
        0,
        "spheres must not touch each other for this check"
    );
    assert!(e.num_wall_contacts() >= 3);
    // with no gravity and no pair contacts a particle's force is its mesh contact force;
    // on the flat plate the contact point is the particle centre projected to z = 0
    for origin in [[0.0, 0.0, 0.0], [0.3, -1.7, 2.2]] {
        let (mut f_p, mut m_p, mut f_n, mut m_n) = ([0.0; 3], [0.0; 3], [0.0; 3], [0.0; 3]);
        for k in 0..p.len() {
            let f = [-p.force[k].x, -p.force[k].y, -p.force[k].z]; // on the mesh
            let c = [
                p.position[k].x - origin[0],
                p.position[k].y - origin[1],
                -origin[2],
            ];
            let mk = cross(c, f);
            for a in 0..3 {
                f_p[a] += f[a];
                m_p[a] += mk[a];
            }
        }
        for node in 0..pos.len() / 3 {
            let f = [nodal[3 * node], nodal[3 * node + 1], nodal[3 * node + 2]];
            let x = [
                pos[3 * node] - origin[0],
                pos[3 * node + 1] - origin[1],
                pos[3 * node + 2] - origin[2],
            ];
            let mk = cross(x, f);
            for a in 0..3 {
                f_n[a] += f[a];
                m_n[a] += mk[a];
            }
        }
        let norm = |v: [f64; 3]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        let df = norm([f_p[0] - f_n[0], f_p[1] - f_n[1], f_p[2] - f_n[2]]) / norm(f_p);
        let dm = norm([m_p[0] - m_n[0], m_p[1] - m_n[1], m_p[2] - m_n[2]]) / norm(m_p);
        println!("origin {origin:?}: |F| = {:e} N rel force error {df:e}, |M| = {:e} rel moment error {dm:e}", norm(f_p), norm(m_p));
        assert!(df <= 1e-12 && dm <= 1e-12);
    }
}

/// Force averaging (Ullrich eq. 3.8) is the mean of the substeps' nodal forces.
#[test]
fn averaged_interface_forces_are_the_mean_of_substep_forces() {
    let mut e = engine(SCENE);
    let (pos, tris) = plate();
    let m = e.add_coupled_mesh("plate", &pos, &tris).unwrap();
    let v = vec![0.0; pos.len()];
    e.set_mesh_kinematics(m, &pos, &v, &v, MotionRule::Linear)
        .unwrap();
    let n = 25;
    let mut sum = vec![0.0; pos.len()];
    for _ in 0..n {
        e.advance(1).unwrap();
        for (s, f) in sum.iter_mut().zip(e.interface_forces(m, false)) {
            *s += f;
        }
    }
    let avg = e.interface_forces(m, true);
    let scale = sum.iter().map(|x| x.abs()).fold(0.0, f64::max) / n as f64;
    assert!(scale > 0.0);
    let err = sum
        .iter()
        .zip(&avg)
        .map(|(s, a)| (s / n as f64 - a).abs())
        .fold(0.0, f64::max)
        / scale;
    let last = e.interface_forces(m, false);
    let differs = last
        .iter()
        .zip(&avg)
        .any(|(l, a)| (l - a).abs() > 1e-6 * scale);
    println!("averaging error {err:e}");
    assert!(err <= 1e-14);
    assert!(
        differs,
        "the forces changed over the window, so mean and last differ"
    );
    // a new window resets the accumulator
    e.set_mesh_kinematics(m, &pos, &v, &v, MotionRule::Linear)
        .unwrap();
    e.advance(1).unwrap();
    assert_eq!(e.interface_forces(m, true), e.interface_forces(m, false));
}

/// With impact refinement (every step here has contacts, so every step runs as N sub-steps)
/// the window average weights each sub-step's nodal forces by its duration, so it equals the
/// plain average at Δt/N; the last forces, the mesh's window clock and the particles agree too.
#[test]
fn impact_substeps_average_interface_forces_over_time() {
    let run = |dt: f64, substeps: usize, steps: usize| {
        let scene = SCENE.replace(
            "time_step = 2e-5",
            &format!("time_step = {dt:e}\nimpact_substeps = {substeps}"),
        );
        let mut e = engine(&scene);
        let (pos, tris) = plate();
        let m = e.add_coupled_mesh("plate", &pos, &tris).unwrap();
        let v: Vec<f64> = (0..pos.len()).map(|k| 0.01 * (k % 3) as f64).collect();
        let zero = vec![0.0; pos.len()];
        e.set_mesh_kinematics(m, &pos, &v, &zero, MotionRule::Linear)
            .unwrap();
        e.advance(steps).unwrap();
        let x: Vec<f64> = (0..4).flat_map(|id| state_of(&e, id).0).collect();
        (
            e.interface_forces(m, true),
            e.interface_forces(m, false),
            e.mesh_positions(m),
            x,
            e.refined_steps(),
        )
    };
    let (avg_r, last_r, mesh_r, x_r, refined) = run(2e-5, 4, 25);
    let (avg_p, last_p, mesh_p, x_p, _) = run(5e-6, 1, 100);
    assert_eq!(refined, 25, "every step has contacts");
    let max_abs = |a: &[f64]| a.iter().map(|x| x.abs()).fold(0.0, f64::max);
    let rel = |a: &[f64], b: &[f64]| {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max)
            / max_abs(b).max(1e-300)
    };
    let (e_avg, e_last, e_mesh, e_x) = (
        rel(&avg_r, &avg_p),
        rel(&last_r, &last_p),
        rel(&mesh_r, &mesh_p),
        rel(&x_r, &x_p),
    );
    println!("refined vs plain at dt/4: average {e_avg:e}, last {e_last:e}, mesh {e_mesh:e}, particles {e_x:e}");
    assert!(max_abs(&avg_p) > 0.0);
    assert!(rel(&avg_p, &last_p) > 1e-3, "forces vary over the window");
    assert!(e_avg <= 1e-12 && e_last <= 1e-12 && e_mesh <= 1e-15 && e_x <= 1e-14);
}

/// Mesh nodes follow x = P + Vτ + ½Aτ² (Quadratic, JIT) or x = P + Vτ (Linear, predictive).
#[test]
fn coupled_mesh_positions_follow_the_motion_rule() {
    let mut e = engine(SCENE);
    let (pos, tris) = plate();
    let m = e.add_coupled_mesh("plate", &pos, &tris).unwrap();
    let nn = pos.len();
    let p: Vec<f64> = pos
        .iter()
        .enumerate()
        .map(|(k, x)| x - 0.002 + 1e-4 * k as f64)
        .collect();
    let v: Vec<f64> = (0..nn).map(|k| 0.01 * ((k % 7) as f64 - 3.0)).collect();
    let a: Vec<f64> = (0..nn).map(|k| 2.0 * ((k % 5) as f64 - 2.0)).collect();
    let dt = e.time_step();
    for rule in [MotionRule::Quadratic, MotionRule::Linear] {
        e.set_mesh_kinematics(m, &p, &v, &a, rule).unwrap();
        assert_eq!(e.mesh_positions(m), p);
        let mut steps = 0;
        for chunk in [1usize, 4, 12] {
            e.advance(chunk).unwrap();
            steps += chunk;
            let tau = steps as f64 * dt;
            let got = e.mesh_positions(m);
            let mut worst: f64 = 0.0;
            for k in 0..nn {
                let want = match rule {
                    MotionRule::Quadratic => p[k] + v[k] * tau + 0.5 * a[k] * tau * tau,
                    MotionRule::Linear => p[k] + v[k] * tau,
                };
                worst = worst.max((got[k] - want).abs());
            }
            println!("{rule:?} tau = {tau:e}: max deviation {worst:e} m");
            // τ accumulates as a sum of Δt: allow its round-off
            assert!(worst <= 1e-15, "{rule:?}: {worst}");
        }
    }
}

#[test]
fn coupled_mesh_input_errors_name_the_mesh() {
    let mut e = engine(SCENE);
    let err = e
        .add_coupled_mesh("sheet", &[0.0, 0.0, 0.0, 1.0, 0.0, 0.0], &[0, 1, 2])
        .unwrap_err();
    assert!(
        err.to_string().contains("sheet") && err.to_string().contains("triangles[2]"),
        "{err}"
    );
    let (pos, tris) = plate();
    let m = e.add_coupled_mesh("plate", &pos, &tris).unwrap();
    let err = e
        .set_mesh_kinematics(m, &pos[..6], &pos, &pos, MotionRule::Linear)
        .unwrap_err();
    assert!(
        err.to_string().contains("plate") && err.to_string().contains("positions"),
        "{err}"
    );
    assert!(e
        .set_mesh_kinematics(m + 5, &pos, &pos, &pos, MotionRule::Linear)
        .is_err());
}

/// The Verlet lists survive coupling windows: setting the kinematics of a mesh that barely
/// moves does not rebuild them (Wellmann eq. 4.10: only a particle or node displacement of
/// d_V/2 does), while a mesh that moves more than d_V/2 within a window still triggers a build
/// and its contact is found.
#[test]
fn coupling_windows_rebuild_lists_only_when_the_mesh_moves_half_the_skin() {
    // the four spheres of SCENE at rest, 0.5 mm above the plate
    let spheres = SCENE.find("spheres = [").expect("SCENE lists spheres");
    let at_rest = format!(
        "{}spheres = [\n{}]\n",
        &SCENE[..spheres],
        [
            [0.011, 0.013],
            [0.047, 0.021],
            [0.032, 0.052],
            [0.068, 0.071]
        ]
        .map(|[x, y]| format!("  {{ position = [{x}, {y}, 0.0105], radius = 0.01 }},\n"))
        .concat()
    );
    let mut e = engine(&at_rest);
    let (pos, tris) = plate();
    let m = e.add_coupled_mesh("plate", &pos, &tris).unwrap();
    let zeros = vec![0.0; pos.len()];
    e.set_mesh_kinematics(m, &pos, &zeros, &zeros, MotionRule::Linear)
        .unwrap();
    e.advance(1).unwrap();
    let builds0 = e.neighbour_list_builds();
    // 20 windows; the plate vibrates by 1 µm (the skin is 2.5 mm)
    for w in 0..20 {
        let p: Vec<f64> = pos
            .iter()
            .enumerate()
            .map(|(k, x)| {
                if k % 3 == 2 {
                    x + 1e-6 * (w % 2) as f64
                } else {
                    *x
                }
            })
            .collect();
        e.set_mesh_kinematics(m, &p, &zeros, &zeros, MotionRule::Linear)
            .unwrap();
        e.advance(10).unwrap();
    }
    let builds = e.neighbour_list_builds() - builds0;
    println!("20 windows of a plate vibrating by 1 µm: {builds} list builds");
    assert_eq!(builds, 0, "lists rebuilt although nothing moved d_V/2");
    assert_eq!(
        e.num_wall_contacts(),
        0,
        "the spheres hover 0.5 mm above the plate"
    );

    // now the plate rises 1.5 mm (more than d_V/2 = 1.25 mm) within a window of 10 steps
    let v: Vec<f64> = (0..pos.len())
        .map(|k| {
            if k % 3 == 2 {
                1.5e-3 / (10.0 * e.time_step())
            } else {
                0.0
            }
        })
        .collect();
    e.set_mesh_kinematics(m, &pos, &v, &zeros, MotionRule::Linear)
        .unwrap();
    e.advance(10).unwrap();
    assert!(
        e.neighbour_list_builds() > builds0,
        "a 1.5 mm motion rebuilds the lists"
    );
    assert_eq!(
        e.num_wall_contacts(),
        4,
        "all four spheres touch the risen plate"
    );
    let f = e.interface_forces(m, false);
    let fz: f64 = f.iter().skip(2).step_by(3).sum();
    assert!(fz < 0.0, "the spheres push the plate down: {fz}");
}
