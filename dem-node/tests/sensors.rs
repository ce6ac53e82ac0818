//! Sensors against hand-computable cases: mass through a flow plane, the weight of resting
//! columns on pressure sensors, the angle of a synthetic cone.
mod common;
use common::*;

fn sphere_mass(r: f64) -> f64 {
    1000.0 * 4.0 / 3.0 * std::f64::consts::PI * r.powi(3)
}

#[test]
fn lattice_moving_through_a_flow_plane_passes_its_mass() {
    // 4×4×2 spheres (r = 4 mm) moving down at 1 m/s through z = 0, layers crossing at
    // t = 0.015 s and 0.0275 s; one sphere (r = 6 mm) moving up through it at t = 0.005 s.
    // "all": net 32 m_4 − m_6; "half": only x < 0.025 (2 of 4 columns) → 16 m_4.
    let text = format!(
        r#"
[dem]
time_step = 5e-5
gravity = [0.0, 0.0, 0.0]
{GRAIN}
[[dem.particles]]
kind = "lattice"
material = "grain"
radius = 0.004
first = [0.00625, 0.00625, 0.015]
spacing = 0.0125
count = [4, 4, 2]
velocity = [0.0, 0.0, -1.0]
[[dem.particles]]
kind = "list"
material = "grain"
spheres = [{{ position = [0.2, 0.2, -0.005], radius = 0.006, velocity = [0.0, 0.0, 1.0] }}]
[[dem.sensors]]
name = "all"
kind = "flow"
axis = "z"
value = 0.0
[[dem.sensors]]
name = "half"
kind = "flow"
axis = "z"
value = 0.0
min = [0.0, 0.0]
max = [0.025, 0.05]
"#
    );
    let mut e = engine(&text);
    let dir = tempfile::tempdir().unwrap();
    let (m4, m6) = (sphere_mass(0.004), sphere_mass(0.006));
    for _ in 0..10 {
        e.advance(200).unwrap();
        e.write_outputs(dir.path()).unwrap();
    }
    e.write_outputs(dir.path()).unwrap(); // same time again: no new sample
    let close = |got: f64, want: f64| (got - want).abs() <= 1e-9 * want.abs();
    let all = result(&e, "sensor.all.mass");
    let half = result(&e, "sensor.half.mass");
    println!("all {all} kg (want {}), half {half} kg", 32.0 * m4 - m6);
    assert!(close(all, 32.0 * m4 - m6), "{all}");
    assert!(close(half, 16.0 * m4), "{half}");
    // the rates are per interval: the up-going sphere in the first, a layer in the 2nd and 3rd
    let csv = std::fs::read_to_string(dir.path().join("dem_sensors.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(lines.next().unwrap(), "time,all,all.mass,half,half.mass");
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), 10, "one row per output time");
    let mut t0 = 0.0;
    let mut integral = 0.0;
    for r in &rows {
        integral += r[1] * (r[0] - t0);
        t0 = r[0];
    }
    assert!(close(integral, all), "Σ rate Δt = mass: {integral}");
    let dt1 = rows[0][0];
    assert!(close(rows[0][1], -m6 / dt1), "{}", rows[0][1]);
    assert!(close(rows[1][1], 16.0 * m4 / (rows[1][0] - rows[0][0])));
    assert!(close(rows[1][3], 8.0 * m4 / (rows[1][0] - rows[0][0])));
    assert!(
        rows[3..].iter().all(|r| r[1] == 0.0),
        "nothing crosses later"
    );
    assert!(close(
        result(&e, "sensor.all.max"),
        rows[1][1].max(rows[2][1])
    ));
    assert_eq!(result(&e, "sensor.all.last"), 0.0);
    assert!(close(result(&e, "sensor.all.mean"), all / e.time()));
}

/// 3×3 columns of 6 spheres (r = 5 mm, 10.1 mm apart) resting on a floor: a plane, or the
/// top face of a box mesh.
fn columns(floor: &str) -> String {
    format!(
        r#"
[dem]
time_step = 5e-5
gravity = [0.0, 0.0, -9.81]
{GRAIN}
[dem.materials.steel]
youngs_modulus = 2e8
poisson_ratio = 0.3
density = 7800.0
restitution = 0.5
friction = 0.3
{floor}
[[dem.particles]]
kind = "lattice"
material = "grain"
radius = 0.005
first = [0.005, 0.005, 0.005]
spacing = 0.0101
count = [3, 3, 6]
[[dem.sensors]]
name = "floor"
kind = "pressure"
axis = "z"
value = 0.002
min = [0.0, 0.0]
max = [0.0303, 0.0303]
[[dem.sensors]]
name = "middle"
kind = "pressure"
axis = "z"
value = 0.03025
min = [0.0, 0.0]
max = [0.0303, 0.0303]
[[dem.sensors]]
name = "corner"
kind = "pressure"
axis = "z"
value = 0.002
min = [0.0, 0.0]
max = [0.008, 0.008]
"#
    )
}

const PLANE_FLOOR: &str = r#"[[dem.walls]]
kind = "plane"
material = "steel"
point = [0.0, 0.0, 0.0]
normal = [0.0, 0.0, 1.0]"#;

const BOX_FLOOR: &str = r#"[[dem.walls]]
kind = "box"
material = "steel"
min = [-0.05, -0.05, -0.01]
max = [0.08, 0.08, 0.0]"#;

#[test]
fn resting_columns_press_their_weight_on_pressure_sensors() {
    let (m, g) = (sphere_mass(0.005), 9.81);
    for floor in [PLANE_FLOOR, BOX_FLOOR] {
        let mut e = engine(&columns(floor));
        // 0.3 s: the slow mode of the stacks on their soft contacts has decayed below 0.1 %
        e.advance(6000).unwrap();
        let dir = tempfile::tempdir().unwrap();
        e.write_outputs(dir.path()).unwrap();
        let ke = e.kinetic_energy();
        let whole = 0.0303f64.powi(2);
        let checks = [
            ("floor", 54.0 * m * g / whole),
            ("middle", 27.0 * m * g / whole),
            ("corner", 6.0 * m * g / 0.008f64.powi(2)),
        ];
        for (name, want) in checks {
            let got = result(&e, &format!("sensor.{name}.last"));
            println!("{name}: {got:.3} Pa, weight/area {want:.3} Pa (KE {ke:e} J)");
            assert!((got - want).abs() < 0.005 * want, "{name}: {got} vs {want}");
        }
    }
}

#[test]
fn synthetic_cone_gives_its_cone_angle() {
    // spheres (r = 2 mm) whose tops lie on the cone z = 0.1 − ρ tan 30°, each with a second
    // sphere 10 mm lower; six azimuths per radius
    let (r, h, tan) = (0.002, 0.1, 30f64.to_radians().tan());
    let mut spheres = Vec::new();
    for k in 0..36 {
        let rho = 0.01 + 0.004 * k as f64;
        for a in 0..6 {
            let phi = a as f64 * std::f64::consts::PI / 3.0 + 0.1 * k as f64;
            let z = h - rho * tan - r;
            for dz in [0.0, -0.01] {
                spheres.push(format!(
                    "{{ position = [{}, {}, {}], radius = {r} }}",
                    0.3 + rho * phi.cos(),
                    0.2 + rho * phi.sin(),
                    z + dz
                ));
            }
        }
    }
    let text = format!(
        r#"
[dem]
time_step = 1e-5
gravity = [0.0, 0.0, 0.0]
{GRAIN}
[[dem.particles]]
kind = "list"
material = "grain"
spheres = [{}]
[[dem.sensors]]
name = "heap"
kind = "repose"
centre = [0.3, 0.2]
r_min = 0.02
r_max = 0.14
bin_width = 0.01
[[dem.sensors]]
name = "empty"
kind = "repose"
centre = [0.3, 0.2]
r_min = 0.5
r_max = 0.6
"#,
        spheres.join(",\n")
    );
    let mut e = engine(&text);
    let angle = result(&e, "sensor.heap.last");
    println!("angle of repose {angle}°");
    assert!((angle - 30.0).abs() < 1e-9, "{angle}");
    assert!(result(&e, "sensor.empty.last").is_nan(), "no heap there");
    let dir = tempfile::tempdir().unwrap();
    e.write_outputs(dir.path()).unwrap();
    let csv = std::fs::read_to_string(dir.path().join("dem_sensors.csv")).unwrap();
    assert!(csv.starts_with("time,heap,empty\n"), "{csv}");
    let row: Vec<&str> = csv.lines().nth(1).unwrap().split(',').collect();
    assert!((row[1].parse::<f64>().unwrap() - 30.0).abs() < 1e-9);
    assert_eq!(
        result(&e, "sensor.heap.mean"),
        result(&e, "sensor.heap.last")
    );
}

#[test]
fn synthetic_wedge_gives_its_slope_along_an_axis() {
    // a pile on a hand-slide: tops on z = 0.05 − (0.2 − x) tan 26° for x ∈ [0.12, 0.2],
    // filling the width y ∈ [0, 0.03]; the outlet edge is at x = 0.2
    let (r, tan) = (0.002, 26f64.to_radians().tan());
    let mut spheres = Vec::new();
    for k in 0..20 {
        let x = 0.122 + 0.004 * k as f64;
        for j in 0..7 {
            let y = 0.002 + 0.004 * j as f64;
            let z = 0.05 - (0.2 - x) * tan - r - 0.001 * j as f64;
            spheres.push(format!("{{ position = [{x}, {y}, {z}], radius = {r} }}"));
        }
    }
    let sensor = |along: &str| {
        format!(
            r#"
[dem]
time_step = 1e-5
gravity = [0.0, 0.0, 0.0]
{GRAIN}
[[dem.particles]]
kind = "list"
material = "grain"
spheres = [{}]
[[dem.sensors]]
name = "slide"
kind = "repose"
centre = [0.2, 0.0]
r_min = 0.005
r_max = 0.08
bin_width = 0.004
{along}
"#,
            spheres.join(",\n")
        )
    };
    let angle = result(&engine(&sensor("along = \"x\"")), "sensor.slide.last");
    println!("wedge slope along x: {angle}°");
    assert!((angle - 26.0).abs() < 1e-9, "{angle}");
    // the radial (cone) measure mixes in the y offsets and reads a different angle
    let radial = result(&engine(&sensor("")), "sensor.slide.last");
    println!("radial measure of the same wedge: {radial}°");
    assert!((radial - 26.0).abs() > 0.1, "{radial}");
    let err = dem::parse_scene_section(&sensor("along = \"z\"")).unwrap_err();
    println!("{err}");
    assert!(err.message.contains("dem.sensors[0].along"), "{err}");
}

#[test]
fn bad_sensor_definitions_name_the_field() {
    let base = format!(
        "[dem]\ntime_step = 1e-5\n{GRAIN}\n[[dem.sensors]]\nname = \"p\"\nkind = \"pressure\"\n\
         axis = \"z\"\nvalue = 0.1\nmin = [0.0, 0.0]\nmax = [0.2, 0.2]\n"
    );
    assert!(dem::parse_scene_section(&base).is_ok());
    let cases = [
        (base.replace("max = [0.2, 0.2]", "max = [0.2, -0.2]"), "dem.sensors[0].max", "max"),
        (base.replace("axis = \"z\"", "axis = \"w\""), "unknown variant `w`", "axis"),
        (base.replace("name = \"p\"", "name = \"p q\""), "dem.sensors[0].name", "name"),
        (
            format!("{base}[[dem.sensors]]\nname = \"p\"\nkind = \"repose\"\ncentre = [0.0, 0.0]\nr_min = 0.0\nr_max = 0.1\n"),
            "duplicate sensor name `p`",
            "name = \"p\"\nkind = \"repose\"",
        ),
        (
            format!("{base}[[dem.sensors]]\nname = \"f\"\nkind = \"flow\"\naxis = \"z\"\nvalue = 0.0\nmin = [0.0, 0.0]\n"),
            "dem.sensors[1].min",
            "min = [0.0, 0.0]\n",
        ),
    ];
    for (text, message, at) in cases {
        let err = dem::parse_scene_section(&text).unwrap_err();
        println!("{err}");
        assert!(err.message.contains(message), "{err}");
        let line = text[..text.rfind(at).unwrap()].matches('\n').count() + 1;
        assert_eq!(err.line, line, "{err}");
    }
}
