//! Walls moved by a load (`load = { mass, force, amplitude, frequency, start, end, release }`):
//! a rigid body along one axis under the particles' contact forces, its weight and an applied
//! force (the compaction plate of Ullrich §6.2 run as a vibratory compactor).
mod common;
use common::*;

/// A plane plate facing down (normal −z) at z = `z`, with the given `load` table, over an
/// optional floor and `particles`.
fn plate_scene(gravity: f64, z: f64, load: &str, particles: &str) -> String {
    format!(
        r#"
[dem]
time_step = 1e-4
gravity = [0.0, 0.0, {gravity}]
{GRAIN}{STEEL}
[[dem.walls]]
kind = "plane"
material = "steel"
point = [0.0, 0.0, {z}]
normal = [0.0, 0.0, -1.0]
load = {{ {load} }}
{particles}
"#
    )
}

/// A floor at z = 0 and one 10 mm sphere resting on it.
const SPHERE_ON_FLOOR: &str = r#"
[[dem.walls]]
kind = "plane"
material = "steel"
point = [0.0, 0.0, 0.0]
normal = [0.0, 0.0, 1.0]
[[dem.particles]]
kind = "list"
material = "grain"
spheres = [{ position = [0.0, 0.0, 0.01], radius = 0.01 }]
"#;

#[test]
fn a_free_plate_is_held_until_start_then_falls_under_weight_and_load_exactly() {
    // no contacts: u(t) = ½ (g + F/m) (t − start)². Velocity Verlet applies the force that
    // switches on at the step t_n = start over [t_n − Δt/2, t_n + Δt/2] (the half kick at
    // t_n), so the discrete motion is exactly u = ½ a τ (τ + Δt), v = a (τ + Δt/2)
    let load = "name = \"plate\", mass = 2.0, force = -3.0, start = 0.05";
    let mut e = engine(&plate_scene(-9.81, 1.0, load, ""));
    e.advance(400).unwrap(); // t = 0.04
    assert_eq!(result(&e, "plate.displacement"), 0.0, "held before start");
    assert_eq!(result(&e, "plate.velocity"), 0.0);
    e.advance(1100).unwrap(); // t = 0.15
    let (tau, a) = (0.1, -9.81 - 3.0 / 2.0);
    let u = result(&e, "plate.displacement");
    let v = result(&e, "plate.velocity");
    println!("u = {u}, v = {v}");
    let dt = 1e-4;
    assert!((u - 0.5 * a * tau * (tau + dt)).abs() < 1e-12, "u = {u}");
    assert!((v - a * (tau + 0.5 * dt)).abs() < 1e-12, "v = {v}");
    assert_eq!(result(&e, "plate.contact_force"), 0.0);
}

#[test]
fn a_harmonic_load_moves_the_plate_as_integrated_and_the_release_ramps_it_off() {
    // no gravity, F = A sin ωτ: v = A/(mω) (1 − cos ωτ), u = A/(mω) (τ − sin(ωτ)/ω)
    let (m, amp, f) = (2.0, 4.0, 5.0);
    let w = 2.0 * std::f64::consts::PI * f;
    let load = format!("mass = {m}, amplitude = {amp}, frequency = {f}, end = 0.3, release = 0.1");
    let mut e = engine(&plate_scene(0.0, 1.0, &load, ""));
    e.advance(2500).unwrap(); // t = 0.25
    let tau: f64 = 0.25;
    let u = result(&e, "wall0.displacement");
    let v = result(&e, "wall0.velocity");
    let u_exact = amp / (m * w) * (tau - (w * tau).sin() / w);
    let v_exact = amp / (m * w) * (1.0 - (w * tau).cos());
    println!("u = {u} ({u_exact}), v = {v} ({v_exact})");
    assert!((u - u_exact).abs() < 1e-4 * u_exact.abs(), "u = {u}");
    assert!((v - v_exact).abs() < 1e-4 * v_exact.abs(), "v = {v}");
    // from t = 0.4 on the load is off: the plate coasts
    e.advance(1600).unwrap(); // t = 0.41
    let v1 = result(&e, "wall0.velocity");
    e.advance(1000).unwrap(); // t = 0.51
    let v2 = result(&e, "wall0.velocity");
    assert_eq!(v1, v2, "no force after end + release");
    // during the release the velocity changed: the ramp is not a step
    let mut g = engine(&plate_scene(0.0, 1.0, &load, ""));
    g.advance(3000).unwrap();
    let v_end = result(&g, "wall0.velocity");
    assert!((v_end - v1).abs() > 1e-3 * v_exact.abs(), "{v_end} vs {v1}");
}

#[test]
fn a_loaded_plate_on_a_sphere_settles_at_the_hertz_overlaps_of_its_load() {
    // a 10 g plate with 10 N pressing on a 10 mm sphere on the floor: at rest the plate's
    // contact force balances weight + load, and the plate sank by the two Hertz overlaps
    // δ = (F / (4/3 E* √R))^(2/3) (Ullrich eq. 2.6; sphere–plane R* = R). (The contact
    // damping acts with the sphere's mass, eq. 2.12: a plate much heavier than the sphere
    // rings for long.)
    let load = "name = \"plate\", mass = 0.01, force = -10.0";
    let mut e = engine(&plate_scene(-9.81, 0.02, load, SPHERE_ON_FLOOR));
    e.advance(20_000).unwrap(); // 2 s: the oscillation (period ≈ 5 ms) has died out
    let fc = result(&e, "plate.contact_force");
    let u = result(&e, "plate.displacement");
    let f_top = 0.01 * 9.81 + 10.0;
    let sphere_weight = 1000.0 * 4.0 / 3.0 * std::f64::consts::PI * 1e-6 * 9.81;
    let e_star = 1.0 / (2.0 * (1.0 - 0.09) / 1e7);
    let delta = |f: f64| (f / (4.0 / 3.0 * e_star * 0.01f64.sqrt())).powf(2.0 / 3.0);
    let u_exact = -(delta(f_top) + delta(f_top + sphere_weight));
    println!("contact force {fc} N (weight + load {f_top}), u = {u} (Hertz {u_exact})");
    assert!((fc - f_top).abs() < 1e-6 * f_top, "force balance: {fc}");
    assert!((u - u_exact).abs() < 1e-6 * u_exact.abs(), "u = {u}");
    assert!(result(&e, "plate.velocity").abs() < 1e-8);
}

#[test]
fn a_removed_plate_stops_acting_and_moving() {
    let load = "name = \"plate\", mass = 0.01, force = -10.0";
    let text = plate_scene(-9.81, 0.02, load, SPHERE_ON_FLOOR)
        .replace("load = {", "remove_at = 0.5\nload = {");
    let mut e = engine(&text);
    e.advance(4990).unwrap(); // t = 0.499: pressed
    let u = result(&e, "plate.displacement");
    assert!(u < -1e-3, "the plate pressed the sphere: {u}");
    let plate_z = 0.02 + u;
    // removed at 0.5: the sphere, no longer pressed, springs up through where the plate was
    let mut highest = f64::MIN;
    for _ in 0..100 {
        e.advance(10).unwrap();
        highest = highest.max(state_of(&e, 0).0[2] + 0.01);
    }
    println!("plate bottom at {plate_z}, sphere top reached {highest}");
    assert!(highest > plate_z + 1e-3, "{highest} vs plate {plate_z}");
    assert_eq!(result(&e, "plate.velocity"), 0.0);
    assert_eq!(result(&e, "plate.contact_force"), 0.0);
    let u1 = result(&e, "plate.displacement");
    assert!((u1 - u).abs() < 1e-3, "stopped at removal: {u1} vs {u}");
    e.advance(100).unwrap();
    assert_eq!(
        result(&e, "plate.displacement"),
        u1,
        "a removed plate stays put"
    );
}

/// A plate over a small bed in a box (576 spheres poured from a jittered lattice, about
/// 15 cm deep once settled).
fn bed_scene(load: &str, extra: &str) -> String {
    format!(
        r#"
[dem]
time_step = 5e-5
gravity = [0.0, 0.0, -9.81]
{extra}
{GRAIN}{STEEL}
[[dem.walls]]
kind = "box"
material = "steel"
min = [0.0, 0.0, 0.0]
max = [0.05, 0.05, 0.6]
open = ["+z"]
[[dem.walls]]
kind = "plane"
material = "steel"
point = [0.0, 0.0, 0.5]
normal = [0.0, 0.0, -1.0]
remove_at = 0.75
load = {{ name = "plate", {load} }}
[[dem.particles]]
kind = "lattice"
material = "grain"
radius = 0.0045
first = [0.006, 0.006, 0.006]
spacing = 0.0125
count = [4, 4, 36]
jitter = 0.001
"#
    )
}

#[test]
fn a_vibrating_plate_compacts_a_bed_more_than_its_static_load_and_leaves_it_quiet() {
    // 0.5 kg plate released at 0.1 s onto the poured bed, pressing with 20 N (+ 40 N at 50 Hz);
    // load and weight ramp off over 0.6–0.7 s, the plate is removed at 0.75 s
    let run = |load: &str| {
        let mut e = engine(&bed_scene(load, ""));
        e.advance(12_000).unwrap(); // t = 0.6: end of the load (sin(2π·50·0.5) = 0)
        let loaded = result(&e, "plate.displacement");
        let mut ke_unloading = 0.0f64;
        for _ in 0..60 {
            e.advance(50).unwrap(); // to t = 0.75
            ke_unloading = ke_unloading.max(result(&e, "kinetic_energy"));
        }
        let rebound = result(&e, "plate.displacement") - loaded;
        e.advance(2000).unwrap(); // t = 0.85
        (loaded, rebound, ke_unloading, result(&e, "kinetic_energy"))
    };
    let common = "mass = 0.5, start = 0.1, end = 0.6, release = 0.1, force = -20.0";
    let (u0, r0, k0, q0) = run(common);
    let (u1, r1, k1, q1) = run(&format!("{common}, amplitude = 40.0, frequency = 50.0"));
    println!("static: u = {u0} m, rebound {r0} m, KE ≤ {k0} J while unloading, {q0} J at the end");
    println!(
        "vibrating: u = {u1} m, rebound {r1} m, KE ≤ {k1} J while unloading, {q1} J at the end"
    );
    assert!(u0 < -0.3, "the plate came down onto the bed: {u0}");
    assert!(u1 < u0 - 2e-3, "vibration compacts further: {u1} vs {u0}");
    // the bed gives back the energy its load stored, (weight + load) × rebound at most,
    // quasi-statically: under 1 % of it becomes motion, and the bed ends quiet (one sphere's
    // weight times its radius is 1.7e-5 J)
    let load = 0.5 * 9.81 + 20.0;
    for (rebound, ke, quiet) in [(r0, k0, q0), (r1, k1, q1)] {
        assert!(rebound > 0.0, "the bed springs back as the load comes off");
        assert!(ke < 0.01 * load * rebound, "{ke} J vs {} J", load * rebound);
        assert!(quiet < 1e-5, "quiet: {quiet} J");
    }
}

#[test]
fn a_loaded_plate_is_bitwise_equal_for_step_advance_threads_and_restore() {
    let load = "mass = 0.5, start = 0.02, force = -20.0, amplitude = 40.0, frequency = 50.0";
    let run = |threads: usize, fused: bool| {
        let mut e = engine(&bed_scene(load, &format!("threads = {threads}")));
        if fused {
            e.advance(3000).unwrap();
        } else {
            for _ in 0..3000 {
                e.step().unwrap();
            }
        }
        e.snapshot()
    };
    let a = run(1, true);
    assert!(a == run(2, true), "1 vs 2 threads");
    assert!(a == run(1, false), "advance vs step");
    let mut e = engine(&bed_scene(load, ""));
    e.advance(1500).unwrap();
    let snap = e.snapshot();
    let mut f = engine(&bed_scene(load, ""));
    f.restore(&snap).unwrap();
    f.advance(1500).unwrap();
    assert!(f.snapshot() == a, "continuation after restore");
    assert!(result(&f, "plate.displacement") < -0.1, "the plate moved");
}

#[test]
fn bad_loads_name_the_field() {
    let check = |load: &str, field: &str| {
        let text = plate_scene(-9.81, 1.0, load, "");
        let err = dem::parse_scene_section(&text).unwrap_err();
        println!("{err}");
        assert!(err.message.contains(field), "{field}: {err}");
    };
    check("mass = 0.0", "dem.walls[0].load.mass");
    check("mass = 1.0, amplitude = 5.0", "dem.walls[0].load.frequency");
    check(
        "mass = 1.0, start = 0.5, end = 0.2",
        "dem.walls[0].load.end",
    );
    check("mass = 1.0, release = -1.0", "dem.walls[0].load.release");
    check("mass = 1.0, name = \"a b\"", "dem.walls[0].load.name");
    check("mass = 1.0, axis = \"w\"", "unknown variant `w`");
    check("force = 1.0", "mass");
    let text = plate_scene(-9.81, 1.0, "mass = 1.0", "").replace(
        "load = {",
        "motion = { velocity = [0.0, 0.0, 1.0] }\nload = {",
    );
    let err = dem::parse_scene_section(&text).unwrap_err();
    println!("{err}");
    assert!(err.message.contains("dem.walls[0].load"), "{err}");
    assert!(err.message.contains("not both"), "{err}");
}

#[test]
fn a_driven_plate_leaves_force_control_and_moves_at_its_velocity_from_where_it_is() {
    // falls freely under its weight until 0.05 s, then is driven up at 0.2 m/s whatever the
    // forces: u(t) = u(0.05) + 0.2 (t − 0.05)
    let load = "name = \"plate\", mass = 2.0, drive = { velocity = 0.2, start = 0.05 }";
    let mut e = engine(&plate_scene(-9.81, 1.0, load, ""));
    e.advance(500).unwrap(); // t = 0.05
    let u0 = result(&e, "plate.displacement");
    assert!(u0 < -0.01, "fell: {u0}");
    e.advance(1000).unwrap(); // t = 0.15
    let u = result(&e, "plate.displacement");
    assert!((u - u0 - 0.2 * 0.1).abs() < 1e-12, "u = {u}, from {u0}");
    assert_eq!(result(&e, "plate.velocity"), 0.2);
    // refused: a drive before the load's start
    let bad = plate_scene(
        -9.81,
        1.0,
        "mass = 2.0, start = 0.1, drive = { velocity = 0.2, start = 0.05 }",
        "",
    );
    let err = config_error(&bad);
    assert!(err.contains("load.drive.start"), "{err}");
}

#[test]
fn a_cylinder_wall_holds_a_fill_inside_its_radius() {
    // spheres filled into a cylinder of radius 20 mm, settling on a floor; the mould's
    // facets face the axis, so every sphere stays inside
    let scene = format!(
        r#"
[dem]
time_step = 2e-5
gravity = [0.0, 0.0, -9.81]
{GRAIN}{STEEL}
[[dem.walls]]
kind = "plane"
material = "steel"
point = [0.0, 0.0, 0.0]
normal = [0.0, 0.0, 1.0]
[[dem.walls]]
kind = "cylinder"
material = "steel"
centre = [0.0, 0.0, 0.0]
radius = 0.02
height = 0.1
segments = 32
[[dem.particles]]
kind = "fill"
material = "grain"
min = [-0.02, -0.02, 0.0]
max = [0.02, 0.02, 0.08]
radius = 0.02
count = 60
distribution = {{ kind = "uniform", min = 0.003, max = 0.004 }}
"#
    );
    let mut e = engine(&scene);
    let p = e.particles();
    assert_eq!(p.position.len(), 60);
    for (x, r) in p.position.iter().zip(&p.radius) {
        assert!(
            (x.x * x.x + x.y * x.y).sqrt() <= 0.02 - r + 1e-12,
            "{x:?} outside"
        );
    }
    e.advance(10_000).unwrap(); // 0.2 s: settled
    let apothem = 0.02 * (std::f64::consts::PI / 32.0).cos();
    let p = e.particles();
    for (x, r) in p.position.iter().zip(&p.radius) {
        let d = (x.x * x.x + x.y * x.y).sqrt();
        assert!(
            d + r < apothem + 0.05 * r,
            "a sphere at {d} m left the mould"
        );
        assert!(x.z > 0.0);
    }
    // the facets face the axis (the DEM's patch test reads the orientation)
    let (pos, tris) = dem::walls::cylinder_mesh(nalgebra::Vector3::zeros(), 0.02, 0.1, 32);
    for t in &tris {
        let [a, b, c] = t.map(|k| pos[k as usize]);
        let n = (b - a).cross(&(c - a));
        let centre = (a + b + c) / 3.0;
        assert!(
            n.x * centre.x + n.y * centre.y < 0.0,
            "a facet faces outwards"
        );
        assert!(n.z.abs() < 1e-12 * n.norm());
    }
    let bad = scene.replace("segments = 32", "segments = 3");
    assert!(config_error(&bad).contains("segments"));
}

fn config_error(text: &str) -> String {
    dem::parse_scene_section(text).unwrap_err().to_string()
}
