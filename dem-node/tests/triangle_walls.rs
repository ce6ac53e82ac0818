//! Particle–triangle contact (Wellmann ch. 4, REFERENCE B3) on meshes.
mod common;
use common::*;
use dem::MotionRule;

fn material(e: f64, rest: f64, mu: f64) -> String {
    format!(
        "[dem.materials.ball]\nyoungs_modulus = {e:e}\npoisson_ratio = 0.25\ndensity = 1000.0\nrestitution = {rest}\nfriction = {mu}\n"
    )
}

fn scene(dt: f64, gravity: [f64; 3], rotation: bool, mat: &str, spheres: &str) -> String {
    format!(
        "[dem]\ntime_step = {dt:e}\ngravity = [{}, {}, {}]\nrotation = {rotation}\ninterface_material = \"ball\"\nallow_large_time_step = true\n{mat}\n\
         [[dem.particles]]\nkind = \"list\"\nmaterial = \"ball\"\nspheres = [ {spheres} ]\n",
        gravity[0], gravity[1], gravity[2]
    )
}

/// Flat grid of n×n squares of size h (2 triangles each) in the plane z = 0, centred at the
/// origin, then rotated about the y axis by `tilt` (rad).
fn grid_mesh(n: usize, h: f64, tilt: f64) -> (Vec<f64>, Vec<u32>) {
    let mut pos = Vec::new();
    let half = 0.5 * n as f64 * h;
    let (c, s) = (tilt.cos(), tilt.sin());
    for j in 0..=n {
        for i in 0..=n {
            let (x, y) = (i as f64 * h - half, j as f64 * h - half);
            pos.extend_from_slice(&[c * x, y, -s * x]);
        }
    }
    let mut tris = Vec::new();
    let id = |i: usize, j: usize| (j * (n + 1) + i) as u32;
    for j in 0..n {
        for i in 0..n {
            // alternate the diagonal so that edges meet at vertices of valence 4 and 8
            if (i + j) % 2 == 0 {
                tris.extend_from_slice(&[id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                tris.extend_from_slice(&[id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            } else {
                tris.extend_from_slice(&[id(i, j), id(i + 1, j), id(i, j + 1)]);
                tris.extend_from_slice(&[id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
    }
    (pos, tris)
}

fn add_static(e: &mut dem::Engine, name: &str, pos: &[f64], tris: &[u32]) -> usize {
    let m = e.add_coupled_mesh(name, pos, tris).unwrap();
    let zeros = vec![0.0; pos.len()];
    e.set_mesh_kinematics(m, pos, &zeros, &zeros, MotionRule::Linear)
        .unwrap();
    e.refresh_forces();
    m
}

const R: f64 = 0.01;
const G: f64 = 9.81;

fn mass() -> f64 {
    1000.0 * 4.0 / 3.0 * std::f64::consts::PI * R.powi(3)
}

fn e_star(e: f64) -> f64 {
    e / (2.0 * (1.0 - 0.25f64.powi(2)))
}

/// Sphere on an incline made of a triangle mesh, rotation disabled (a rotating sphere would
/// roll: with rotation the sticking limit is tan θ = 3.5 μ). Sticks for tan θ < μ, slides
/// with a = g(sin θ − μ cos θ) for tan θ > μ.
#[test]
fn sphere_on_inclined_mesh_sticks_below_and_slides_above_friction_angle() {
    let mu = 0.5;
    let e_mod = 1e7;
    for theta_deg in [20.0f64, 35.0] {
        let theta = theta_deg.to_radians();
        let dt = 5e-5;
        // start at the static normal overlap to avoid a bounce
        let delta =
            (mass() * G * theta.cos() / (4.0 / 3.0 * e_star(e_mod) * R.sqrt())).powf(2.0 / 3.0);
        let d = R - delta;
        let (nx, nz) = (theta.sin(), theta.cos()); // surface normal of the tilted grid
        let sph = format!(
            "{{ position = [{}, 0.0, {}], radius = {R} }}",
            d * nx,
            d * nz
        );
        let mut e = engine(&scene(
            dt,
            [0.0, 0.0, -G],
            false,
            &material(e_mod, 0.5, mu),
            &sph,
        ));
        let (pos, tris) = grid_mesh(40, 0.005, theta);
        add_static(&mut e, "incline", &pos, &tris);
        let slope_dir = [theta.cos(), 0.0, -theta.sin()];
        let along = |v: [f64; 3]| v[0] * slope_dir[0] + v[2] * slope_dir[2];
        e.advance(2000).unwrap(); // 0.1 s
        let (x1, v1) = state_of(&e, 0);
        let t1 = e.time();
        e.advance(2000).unwrap();
        let (x2, v2) = state_of(&e, 0);
        let t2 = e.time();
        if theta.tan() < mu {
            let creep = along([x2[0] - x1[0], 0.0, x2[2] - x1[2]]).abs();
            println!(
                "theta {theta_deg}: creep over 0.1 s {creep:e} m, speed {:e}",
                along(v2).abs()
            );
            assert!(creep < 1e-7, "sphere should stick, moved {creep}");
        } else {
            let a = (along(v2) - along(v1)) / (t2 - t1);
            let a_th = G * (theta.sin() - mu * theta.cos());
            println!(
                "theta {theta_deg}: a = {a} vs {a_th} (rel {:e})",
                (a - a_th).abs() / a_th
            );
            assert!((a - a_th).abs() / a_th < 0.01);
        }
    }
}

/// A sphere sliding across many coplanar triangles (through edges and vertices) feels a
/// constant normal force: no jump, no double counting at edges.
#[test]
fn sphere_crossing_coplanar_triangles_feels_constant_normal_force() {
    let e_mod = 1e7;
    let dt = 2e-5;
    let delta = (mass() * G / (4.0 / 3.0 * e_star(e_mod) * R.sqrt())).powf(2.0 / 3.0);
    let sph = format!(
        "{{ position = [-0.04, -0.0123, {}], radius = {R}, velocity = [0.8, 0.3, 0.0] }}",
        R - delta
    );
    let mut e = engine(&scene(
        dt,
        [0.0, 0.0, -G],
        true,
        &material(e_mod, 1.0, 0.0),
        &sph,
    ));
    let (pos, tris) = grid_mesh(20, 0.006, 0.0);
    add_static(&mut e, "floor", &pos, &tris);
    let (mut lo, mut hi) = (f64::MAX, f64::MIN);
    for _ in 0..5000 {
        e.advance(1).unwrap();
        let p = e.particles();
        let normal = p.force[0].z + mass() * G; // contact force = total − gravity
        lo = lo.min(normal);
        hi = hi.max(normal);
    }
    let (x, _) = state_of(&e, 0);
    let variation = (hi - lo) / (mass() * G);
    println!(
        "sphere travelled to x = {:.4}, normal force variation {variation:e}",
        x[0]
    );
    assert!(x[0] > 0.03, "the sphere crossed the mesh");
    assert!(variation <= 1e-9, "normal force variation {variation}");
}

/// Elastic frictionless sphere hitting a mesh edge or vertex: kinetic energy after the
/// impact equals the energy before (conservative contact field).
fn bounce_energy_error(pos: &[f64], tris: &[u32], start: [f64; 3], vel: [f64; 3]) -> f64 {
    let dt = 1e-5;
    let sph = format!(
        "{{ position = [{}, {}, {}], radius = {R}, velocity = [{}, {}, {}] }}",
        start[0], start[1], start[2], vel[0], vel[1], vel[2]
    );
    let mut e = engine(&scene(dt, [0.0; 3], true, &material(1e7, 1.0, 0.0), &sph));
    add_static(&mut e, "obstacle", pos, tris);
    let k0 = e.kinetic_energy();
    let mut touched = false;
    for _ in 0..20_000 {
        e.advance(10).unwrap();
        let c = e.num_wall_contacts();
        touched |= c > 0;
        if touched && c == 0 {
            break;
        }
    }
    assert!(touched, "the sphere hit the mesh");
    assert_eq!(e.num_wall_contacts(), 0, "the sphere left the mesh");
    (e.kinetic_energy() - k0).abs() / k0
}

#[test]
fn frictionless_elastic_bounce_on_edges_and_vertices_conserves_energy() {
    let s = 0.05;
    // convex ridge along y: faces sloping down ±30° from the edge x = 0, z = 0
    let t = 30f64.to_radians().tan();
    let ridge_pos = [
        -s,
        -s,
        -s * t,
        0.0,
        -s,
        0.0,
        s,
        -s,
        -s * t,
        -s,
        s,
        -s * t,
        0.0,
        s,
        0.0,
        s,
        s,
        -s * t,
    ];
    let ridge_tris = [0, 1, 4, 0, 4, 3, 1, 2, 5, 1, 5, 4];
    // concave groove: same with the faces rising
    let groove_pos: Vec<f64> = ridge_pos
        .iter()
        .enumerate()
        .map(|(k, &v)| if k % 3 == 2 { -v } else { v })
        .collect();
    // convex vertex: pyramid apex at the origin
    let pyr_pos = [
        0.0,
        0.0,
        0.0,
        -s,
        -s,
        -s * t,
        s,
        -s,
        -s * t,
        s,
        s,
        -s * t,
        -s,
        s,
        -s * t,
    ];
    let pyr_tris = [0, 1, 2, 0, 2, 3, 0, 3, 4, 0, 4, 1];
    // concave vertex: inside corner of three perpendicular squares (floor, two walls)
    let corner_pos = [
        0.0, 0.0, 0.0, s, 0.0, 0.0, s, s, 0.0, 0.0, s, 0.0, // floor z = 0
        0.0, 0.0, s, s, 0.0, s, 0.0, s, s, // tops of the walls y = 0 and x = 0
    ];
    let corner_tris = [
        0, 1, 2, 0, 2, 3, /* y=0 wall */ 0, 5, 1, 0, 4, 5, /* x=0 wall */ 0, 3, 6, 0, 6,
        4,
    ];
    type Case = (&'static str, Vec<f64>, Vec<u32>, [f64; 3], [f64; 3]);
    let cases: Vec<Case> = vec![
        (
            "convex edge",
            ridge_pos.to_vec(),
            ridge_tris.to_vec(),
            [-0.004, 0.0, 0.03],
            [0.1, 0.05, -1.0],
        ),
        (
            "concave edge",
            groove_pos.clone(),
            ridge_tris.to_vec(),
            [-0.004, 0.0, 0.03],
            [0.3, 0.05, -1.0],
        ),
        (
            "convex vertex",
            pyr_pos.to_vec(),
            pyr_tris.to_vec(),
            [-0.003, 0.002, 0.03],
            [0.05, 0.02, -1.0],
        ),
        (
            "concave vertex",
            corner_pos.to_vec(),
            corner_tris.to_vec(),
            [0.03, 0.03, 0.03],
            [-0.7, -0.6, -0.8],
        ),
    ];
    for (name, pos, tris, start, vel) in cases {
        let err = bounce_energy_error(&pos, &tris, start, vel);
        println!("{name}: relative kinetic energy change {err:e}");
        assert!(err <= 1e-4, "{name}: energy error {err}");
    }
}
