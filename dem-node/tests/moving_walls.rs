//! Static walls with a prescribed motion (`motion = { velocity, start, end }`) and removal
//! (`remove_at`): contacts use the wall velocity, the broad phase follows the wall.
mod common;
use common::*;

/// A 10 mm sphere resting at x = 0.05 on a 0.2 m plate that slides +x at 1 m/s from
/// t = 0.05 s to 0.45 s.
fn plate_scene() -> String {
    format!(
        r#"
[dem]
time_step = 1e-4
gravity = [0.0, 0.0, -9.81]
{GRAIN}{STEEL}
[[dem.walls]]
kind = "box"
material = "steel"
min = [-0.1, 0.0, -0.01]
max = [0.1, 0.1, 0.0]
motion = {{ velocity = [1.0, 0.0, 0.0], start = 0.05, end = 0.45 }}
[[dem.particles]]
kind = "list"
material = "grain"
spheres = [{{ position = [0.05, 0.05, 0.00999], radius = 0.01 }}]
"#
    )
}

#[test]
fn sphere_on_a_plate_that_slides_out_from_under_it_rolls_then_falls() {
    let mut e = engine(&plate_scene());
    e.advance(500).unwrap(); // t = 0.05: at rest on the plate
    let (x, v) = state_of(&e, 0);
    assert!(
        (x[2] - 0.01).abs() < 1e-4 && v[0].abs() < 1e-3,
        "rests: {x:?} {v:?}"
    );
    let plate_x = e.meshes()[0].positions[0].x;
    assert!(
        (plate_x + 0.1).abs() < 1e-12,
        "plate at rest before start: {plate_x}"
    );
    // the plate slides under the sphere: Coulomb friction μ m g along the wall velocity
    // accelerates it, v = μ g (t − start), while the slip V − v − ωr closes at 7/2 μ g
    let mu_g = 0.5 * 9.81;
    e.advance(500).unwrap(); // t = 0.1
    let (x, v) = state_of(&e, 0);
    println!("t = 0.1: x = {x:?}, v = {v:?}");
    assert!(
        (v[0] - mu_g * 0.05).abs() < 0.01 * mu_g * 0.05,
        "sliding: vx = {}",
        v[0]
    );
    let plate_x = e.meshes()[0].positions[0].x;
    assert!(
        (plate_x - (-0.1 + 0.05)).abs() < 1e-9,
        "plate moved v·(t − start): {plate_x}"
    );
    // no slip from t = 0.05 + 2/(7 μ g) = 0.108 s on: rolling at v = 2/7 V (impulse J:
    // m v = J, (2/5) m r² ω = J r, v + ω r = V)
    e.advance(500).unwrap(); // t = 0.15
    let (x, v) = state_of(&e, 0);
    println!("t = 0.15: x = {x:?}, v = {v:?}");
    assert!(
        (v[0] - 2.0 / 7.0).abs() < 0.01 * 2.0 / 7.0,
        "rolling: vx = {}",
        v[0]
    );
    assert!((x[2] - 0.01).abs() < 1e-4, "still on the plate");
    // the plate's left edge passes the sphere centre at about t = 0.25 s
    e.advance(3000).unwrap(); // t = 0.45: the plate stops at x = 0.3
    let (x, _) = state_of(&e, 0);
    println!("t = 0.45: x = {x:?}");
    assert!(x[2] < -0.05, "the sphere fell off the plate: z = {}", x[2]);
    let plate_x = e.meshes()[0].positions[0].x;
    assert!(
        (plate_x - 0.3).abs() < 1e-9,
        "plate stops at end: {plate_x}"
    );
    assert!(
        e.neighbour_list_builds() > 2,
        "lists follow the moving plate"
    );
}

#[test]
fn sphere_on_a_static_plate_stays() {
    // the same scene without the motion: the plate holds the sphere (control of the test above)
    let text = plate_scene().replace(
        "motion = { velocity = [1.0, 0.0, 0.0], start = 0.05, end = 0.45 }\n",
        "",
    );
    let mut e = engine(&text);
    e.advance(4500).unwrap();
    let (x, v) = state_of(&e, 0);
    assert!(
        (x[2] - 0.01).abs() < 1e-4 && v[0].abs() < 1e-9,
        "{x:?} {v:?}"
    );
}

#[test]
fn floor_removed_at_t_lets_the_sphere_fall_freely() {
    let text = format!(
        r#"
[dem]
time_step = 1e-4
{GRAIN}{STEEL}
[[dem.walls]]
kind = "plane"
material = "steel"
point = [0.0, 0.0, 0.0]
normal = [0.0, 0.0, 1.0]
remove_at = 0.05
[[dem.particles]]
kind = "list"
material = "grain"
spheres = [{{ position = [0.05, 0.05, 0.00999], radius = 0.01 }}]
"#
    );
    let mut e = engine(&text);
    e.advance(500).unwrap();
    let (z0, _) = state_of(&e, 0);
    assert!(
        (z0[2] - 0.01).abs() < 1e-4,
        "rests on the floor until 0.05 s"
    );
    e.advance(1000).unwrap(); // 0.1 s of free fall
    let (z1, v1) = state_of(&e, 0);
    let drop = z0[2] - z1[2];
    let want = 0.5 * 9.81 * 0.1f64.powi(2);
    println!("drop {drop} m (free fall {want} m), vz {}", v1[2]);
    assert!((drop - want).abs() < 0.01 * want, "{drop} vs {want}");
    assert_eq!(e.num_wall_contacts(), 0);
}

/// A chamber open at the bottom over a gate that slides +x at 0.5 m/s from t = 0.05 s, a flow
/// sensor below.
fn gate_scene(extra: &str) -> String {
    gate_scene_with(extra, "count = [5, 5, 4]", 0.018)
}

fn gate_scene_with(extra: &str, count: &str, spacing: f64) -> String {
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
min = [0.0, 0.0, 0.05]
max = [0.1, 0.1, 0.3]
open = ["-z", "+z"]
[[dem.walls]]
kind = "box"
material = "steel"
min = [-0.01, -0.01, 0.04]
max = [0.11, 0.11, 0.05]
motion = {{ velocity = [0.5, 0.0, 0.0], start = 0.05 }}
[[dem.particles]]
kind = "lattice"
material = "grain"
radius = 0.004
first = [0.0055, 0.0055, 0.06]
spacing = {spacing}
{count}
[[dem.sensors]]
name = "outlet"
kind = "flow"
axis = "z"
value = 0.0
"#
    )
}

#[test]
fn gate_sliding_over_the_outlet_lets_particles_out_only_after_it_opened() {
    let mut e = engine(&gate_scene(""));
    let total: f64 = e.particles().mass.iter().sum();
    let dir = tempfile::tempdir().unwrap();
    let mut first_flow = None;
    for k in 1..=60 {
        e.advance(200).unwrap(); // 0.01 s
        e.write_outputs(dir.path()).unwrap();
        let mass = result(&e, "sensor.outlet.mass");
        if mass > 0.0 && first_flow.is_none() {
            first_flow = Some(k as f64 * 0.01);
        }
        if k == 5 {
            // t = 0.05: the bed has settled on the closed gate
            let zmin = e
                .particles()
                .position
                .iter()
                .map(|x| x.z)
                .fold(f64::MAX, f64::min);
            assert!(
                zmin > 0.05,
                "all particles held in the chamber, lowest {zmin}"
            );
        }
    }
    let first = first_flow.expect("particles flowed out");
    let passed = result(&e, "sensor.outlet.mass");
    println!("first flow at {first} s, {passed} of {total} kg passed by 0.6 s");
    // the gap must exceed a particle diameter (8 mm at 0.5 m/s: 16 ms) and the particles fall
    // 0.05 m to the sensor (~0.1 s)
    assert!(first > 0.1, "no flow before the gate opened: {first}");
    assert!(
        passed > 0.9 * total,
        "the opened chamber empties: {passed} of {total}"
    );
    assert!(passed <= total * (1.0 + 1e-12));
}

#[test]
fn moving_gate_is_bitwise_equal_for_one_and_two_threads_and_after_restore() {
    // 1620 particles: two force blocks
    let scene = |extra: &str| gate_scene_with(extra, "count = [9, 9, 20]", 0.0105);
    let run = |threads: usize| {
        let mut e = engine(&scene(&format!("threads = {threads}")));
        assert!(e.num_particles() > 1024);
        e.advance(2400).unwrap();
        (e.snapshot(), e.meshes()[1].positions[0].x)
    };
    let (a, gate_a) = run(1);
    let (b, gate_b) = run(2);
    println!("gate moved {gate_a} m");
    assert!(gate_a > -0.01 + 0.02, "the gate moved during the run");
    assert!(a == b, "engine state differs between 1 and 2 threads");
    assert_eq!(gate_a, gate_b);

    let mut e = engine(&scene(""));
    e.advance(1200).unwrap();
    let snap = e.snapshot();
    e.advance(1200).unwrap();
    let mut f = engine(&scene(""));
    f.restore(&snap).unwrap();
    f.advance(1200).unwrap();
    assert!(
        f.snapshot() == e.snapshot(),
        "continuation after restore differs"
    );
    assert!(f.snapshot() == a, "the engine pool gives the same bits");
}

#[test]
fn bad_motion_and_remove_at_name_the_field_and_line() {
    let line_of = |text: &str, start: &str| {
        text.lines()
            .position(|l| l.starts_with(start))
            .expect("line exists")
            + 1
    };
    let text = plate_scene().replace("end = 0.45", "end = 0.01");
    let err = dem::parse_scene_section(&text).unwrap_err();
    println!("{err}");
    assert!(err.message.contains("dem.walls[0].motion.end"), "{err}");
    assert_eq!(err.line, line_of(&text, "motion"), "{err}");
    let text = plate_scene().replace("velocity = [1.0, 0.0, 0.0]", "velocity = [1.0, 0.0]");
    let err = dem::parse_scene_section(&text).unwrap_err();
    println!("{err}");
    // type errors inside an internally tagged table (`kind = ...`) point at the table
    assert_eq!(err.line, line_of(&text, "[[dem.walls]]"), "{err}");
    assert!(err.message.contains("length 3"), "{err}");
    let text = plate_scene().replace("start = 0.05,", "begin = 0.05,");
    let err = dem::parse_scene_section(&text).unwrap_err();
    println!("{err}");
    assert!(err.message.contains("begin"), "{err}");
    let text = plate_scene().replace(
        "max = [0.1, 0.1, 0.0]\n",
        "max = [0.1, 0.1, 0.0]\nremove_at = -1.0\n",
    );
    let err = dem::parse_scene_section(&text).unwrap_err();
    println!("{err}");
    assert!(err.message.contains("dem.walls[0].remove_at"), "{err}");
    assert_eq!(err.line, line_of(&text, "remove_at"), "{err}");
}

/// A floor oscillating vertically (A = 0.1 mm, 20 Hz: peak acceleration A ω² = 1.6 m/s² < g)
/// carries a resting sphere with it: the sphere's height follows u(τ) = A sin(ωτ), and from
/// `end` on the floor stands still where the sine left it.
#[test]
fn oscillating_floor_carries_a_resting_sphere_and_stops_at_end() {
    let text = format!(
        r#"
[dem]
time_step = 1e-5
gravity = [0.0, 0.0, -9.81]
{GRAIN}{STEEL}
[[dem.walls]]
kind = "plane"
material = "steel"
point = [0.0, 0.0, 0.0]
normal = [0.0, 0.0, 1.0]
motion = {{ amplitude = [0.0, 0.0, 1e-4], frequency = 20.0, start = 0.05, end = 0.1625 }}
[[dem.particles]]
kind = "list"
material = "grain"
spheres = [{{ position = [0.05, 0.05, 0.00999], radius = 0.01 }}]
"#
    );
    let mut e = engine(&text);
    e.advance(5000).unwrap(); // 0.05 s: at rest on the floor
    let (z_rest, _) = state_of(&e, 0);
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    let mut worst: f64 = 0.0;
    for k in 1..=10_000 {
        e.advance(1).unwrap(); // 0.1 s = two periods
        let t = 0.05 + k as f64 * 1e-5;
        let (z, _) = state_of(&e, 0);
        let floor = 1e-4 * (2.0 * std::f64::consts::PI * 20.0 * (t - 0.05)).sin();
        worst = worst.max((z[2] - z_rest[2] - floor).abs());
        lo = lo.min(z[2]);
        hi = hi.max(z[2]);
    }
    println!(
        "sphere swing {:.4e} m (2A = 2e-4), worst lag {worst:.2e} m",
        hi - lo
    );
    assert!(((hi - lo) / 2e-4 - 1.0).abs() < 0.1, "{}", hi - lo);
    assert!(worst < 2e-5, "{worst}");
    // end = 0.1625 s: 2.25 periods, the sine at its crest; the floor stays at +A
    e.advance(5000).unwrap();
    let (z_end, v_end) = state_of(&e, 0);
    println!("after the end: z − z_rest = {:.4e}", z_end[2] - z_rest[2]);
    assert!(
        (z_end[2] - z_rest[2] - 1e-4).abs() < 2e-6,
        "{}",
        z_end[2] - z_rest[2]
    );
    assert!(v_end[2].abs() < 1e-3);
    // an amplitude needs a frequency
    let err = dem::parse_scene_section(&text.replace("frequency = 20.0, ", "")).unwrap_err();
    println!("{err}");
    assert!(
        err.message.contains("dem.walls[0].motion.frequency"),
        "{err}"
    );
}

/// A wall motion in stages (`motion.then`) adds each stage's displacement, and a named wall
/// (`motion.name`) reports the particles' force on it and its displacement: a sphere resting
/// on a floor presses it with its weight, the floor lifts it by 2 mm (20 mm/s for 0.1 s from
/// t = 0.2 s) and lowers it by 1 mm (−10 mm/s from t = 0.3 s, until 0.4 s), where the sphere
/// rests on it again.
#[test]
fn a_named_wall_moves_in_stages_and_reports_the_force_on_it() {
    let mut e = engine(&format!(
        r#"
[dem]
time_step = 1e-4
gravity = [0.0, 0.0, -9.81]
{GRAIN}{STEEL}
[[dem.walls]]
kind = "plane"
material = "steel"
point = [0.0, 0.0, 0.0]
normal = [0.0, 0.0, 1.0]
motion = {{ name = "floor", then = [{{ velocity = [0.0, 0.0, 0.02], start = 0.2, end = 0.3 }}, {{ velocity = [0.0, 0.0, -0.01], start = 0.3, end = 0.4 }}] }}
[[dem.particles]]
kind = "list"
material = "grain"
spheres = [{{ position = [0.0, 0.0, 0.00999], radius = 0.01 }}]
"#
    ));
    let weight = 1000.0 * 4.0 / 3.0 * std::f64::consts::PI * 1e-6 * 9.81;
    e.advance(2000).unwrap(); // t = 0.2: at rest
    assert!(result(&e, "floor.displacement_z").abs() < 1e-12);
    let f = result(&e, "floor.force_z");
    assert!((f + weight).abs() < 0.01 * weight, "{f} vs −{weight}");
    e.advance(1000).unwrap(); // t = 0.3: lifted by 2 mm
    let u = result(&e, "floor.displacement_z");
    assert!((u - 2e-3).abs() < 1e-12, "{u}");
    e.advance(2000).unwrap(); // t = 0.5: lowered by 1 mm, at rest again
    let u = result(&e, "floor.displacement_z");
    assert!((u - 1e-3).abs() < 1e-12, "{u}");
    let (x, _) = state_of(&e, 0);
    assert!(
        (x[2] - 0.011).abs() < 1e-4,
        "the sphere rides on the floor: {x:?}"
    );
    let f = result(&e, "floor.force_z");
    assert!((f + weight).abs() < 0.02 * weight, "{f} vs −{weight}");
    assert_eq!(result(&e, "floor.force_x"), 0.0);
}

/// Two walls reporting under one name, and a stage that ends before it starts, are refused
/// naming the field.
#[test]
fn wall_report_names_are_unique_and_stages_are_checked() {
    let scene = |second: &str| {
        format!(
            r#"
[dem]
time_step = 1e-4
{STEEL}
[[dem.walls]]
kind = "plane"
material = "steel"
point = [0.0, 0.0, 0.0]
normal = [0.0, 0.0, 1.0]
motion = {{ name = "floor" }}
[[dem.walls]]
kind = "plane"
material = "steel"
point = [0.0, 0.0, 1.0]
normal = [0.0, 0.0, -1.0]
{second}
"#
        )
    };
    let err = |text: &str| match dem::parse_scene_section(text) {
        Err(e) => e.to_string(),
        Ok(_) => panic!("accepted: {text}"),
    };
    let e = err(&scene("motion = { name = \"floor\" }"));
    assert!(
        e.contains("dem.walls[1].motion.name") && e.contains("already names"),
        "{e}"
    );
    let e = err(&scene("load = { name = \"floor\", mass = 1.0 }"));
    assert!(e.contains("dem.walls[1].load.name"), "{e}");
    let e = err(&scene(
        "motion = { then = [{ velocity = [0.0, 0.0, 1.0], start = 0.2, end = 0.1 }] }",
    ));
    assert!(e.contains("dem.walls[1].motion.then[0].end"), "{e}");
    assert!(dem::parse_scene_section(&scene("motion = { name = \"roof\" }")).is_ok());
}
