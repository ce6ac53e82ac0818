//! Several structures under one granular bed: each FEM structure is its own node with its own
//! table, interface and output folder (contract v2, PROTOCOL.md §6), coupled with one DEM node.

use cosim_tests::{cosim, root, run, run_scene, write_scene};

const BEAD_RADIUS: f64 = 0.004;
const BEAD_DENSITY: f64 = 2000.0;
const G: f64 = 9.81;

/// The DEM table shared by the scenes below, with the given `[[dem.particles]]` blocks.
fn dem_table(particles: &str) -> String {
    format!(
        r#"[dem]
time_step = 1e-5
gravity = [0.0, 0.0, -9.81]
interface_material = "aluminium"

[dem.materials.bead]
youngs_modulus = 5e7
poisson_ratio = 0.3
density = {BEAD_DENSITY}
restitution = 0.3
friction = 0.4

[dem.materials.aluminium]
youngs_modulus = 70e9
poisson_ratio = 0.33
density = 2700.0
restitution = 0.3
friction = 0.4

[dem.output]
final_particles = true
{particles}
"#
    )
}

/// A resting square lattice of `nx` × `ny` beads, one layer, starting at (x0, y0).
fn layer(x0: f64, y0: f64, nx: usize, ny: usize) -> String {
    format!(
        "\n[[dem.particles]]\nkind = \"lattice\"\nmaterial = \"bead\"\nradius = {BEAD_RADIUS}\nfirst = [{x0}, {y0}, 0.0085]\nspacing = 0.0125\ncount = [{nx}, {ny}, 1]\n"
    )
}

/// A 60 mm square aluminium plate `table` whose lower left corner is at (x0, 0, 0), top at
/// z = 4 mm, clamped on its two x edges.
fn plate(table: &str, x0: f64) -> String {
    format!(
        r#"
[{table}]
mesh = {{ size = [0.06, 0.06, 0.004], origin = [{x0}, 0.0, 0.0], divisions = [6, 6, 1], element = "hex8i" }}
material = {{ youngs_modulus = 70e9, poisson_ratio = 0.33, density = 2700.0 }}
analysis = {{ type = "dynamic", alpha_b = -0.1 }}
[[{table}.supports]]
on = {{ plane = {{ axis = "x", value = {x0} }} }}
[[{table}.supports]]
on = {{ plane = {{ axis = "x", value = {x1} }} }}
[{table}.interface]
on = {{ plane = {{ axis = "z", value = 0.004 }} }}
[[{table}.probes]]
name = "centre"
point = [{xc}, 0.03, 0.0]
[{table}.output]
vtu_every = 0
"#,
        x1 = x0 + 0.06,
        xc = x0 + 0.03
    )
}

fn bead_weight() -> f64 {
    BEAD_DENSITY * 4.0 / 3.0 * std::f64::consts::PI * BEAD_RADIUS.powi(3) * G
}

fn result(s: &serde_json::Value, key: &str) -> f64 {
    s["results"][key]
        .as_f64()
        .unwrap_or_else(|| panic!("{key} missing in {s}"))
}

#[test]
fn two_structures_under_one_bed_each_carry_the_weight_resting_on_them() {
    let dir = tempfile::tempdir().unwrap();
    // 16 beads rest on the left plate, 12 on the right one (5 mm apart); the bed settles on the
    // fixed meshes, then each FEM node solves statically with the forces on its own interface
    let text = format!(
        r#"[scene]
name = "two-plates-resting"
end_time = "0.5 s"
[coupling]
schedule = "one-way"
window = "1 ms"
steady_kinetic_energy = 1e-12
steady_windows = 10
interfaces = [{{ name = "left_top", provider = "left" }}, {{ name = "right_top", provider = "right" }}]
[nodes.left]
kind = "fem"
[nodes.right]
kind = "fem"
{}{}{}"#,
        dem_table(&(layer(0.0112, 0.0112, 4, 4) + &layer(0.0762, 0.0112, 3, 4))),
        plate("left", 0.0),
        plate("right", 0.065)
    );
    let s = run_scene(dir.path(), "two-plates-resting.toml", &text);
    assert_eq!(s["status"], "completed", "{s}");
    let w = bead_weight();
    for (node, beads) in [("left", 16.0), ("right", 12.0)] {
        let fz = result(&s, &format!("{node}.interface_force.z"));
        eprintln!(
            "{node}: interface force {fz:.6e} N, weight of its {beads} beads {:.6e} N",
            beads * w
        );
        assert!(
            (fz + beads * w).abs() < 2e-4 * beads * w,
            "{node} carries {fz} N, its beads weigh {} N",
            beads * w
        );
        // the plate sags under it, and its outputs are in its own folder
        assert!(result(&s, &format!("{node}.probe.centre.uz")) < 0.0);
        let out = dir.path().join("out-two-plates-resting.toml");
        assert!(out.join(node).join("fem_probes.csv").exists(), "{node}");
        assert!(s["nodes"][node]["compute_s"].as_f64().unwrap() > 0.0);
    }
    let csv = std::fs::read_to_string(
        dir.path()
            .join("out-two-plates-resting.toml")
            .join("windows.csv"),
    )
    .unwrap();
    assert!(
        csv.starts_with(
            "window,t_end_s,wall_s,dem_compute_s,fem_compute_s,left_compute_s,right_compute_s,overhead_s,"
        ),
        "{csv}"
    );
}

#[test]
fn a_structure_away_from_the_bed_leaves_the_dem_result_unchanged() {
    // beads dropped on one plate, coupled both ways (predictive); a second plate 1 m away takes
    // part in every window but touches nothing: the DEM and the first plate compute exactly
    // what they compute in the one-structure scene
    let dir = tempfile::tempdir().unwrap();
    let particles = "\n[[dem.particles]]\nkind = \"lattice\"\nmaterial = \"bead\"\nradius = 0.004\nfirst = [0.01, 0.01, 0.0085]\nspacing = 0.0101\ncount = [5, 5, 2]\nvelocity = [0.0, 0.0, -0.5]\n";
    let head = "[scene]\nend_time = \"8 ms\"\n[coupling]\nschedule = \"predictive\"\nwindow = \"0.1 ms\"\n";
    let two = format!(
        "{head}interfaces = [{{ name = \"near\", provider = \"near\" }}, {{ name = \"far\", provider = \"far\" }}]\n[nodes.near]\nkind = \"fem\"\n[nodes.far]\nkind = \"fem\"\n{}{}{}",
        dem_table(particles),
        plate("near", 0.0),
        plate("far", 1.0)
    );
    let one = format!("{head}{}{}", dem_table(particles), plate("fem", 0.0));
    let s2 = run_scene(dir.path(), "two.toml", &two);
    let s1 = run_scene(dir.path(), "one.toml", &one);
    assert_eq!(
        (&s1["status"], &s2["status"]),
        (&"completed".into(), &"completed".into())
    );
    let read = |out: &str, file: &str| {
        std::fs::read_to_string(dir.path().join(out).join(file))
            .unwrap_or_else(|e| panic!("{out}/{file}: {e}"))
    };
    let (p1, p2) = (
        read("out-one.toml", "dem/particles_final.csv"),
        read("out-two.toml", "dem/particles_final.csv"),
    );
    assert!(p1.lines().count() > 50);
    assert_eq!(p1, p2, "the DEM's final particles differ");
    assert_eq!(
        read("out-one.toml", "fem/fem_probes.csv"),
        read("out-two.toml", "near/fem_probes.csv"),
        "the loaded plate's probe history differs"
    );
    // the plate under the beads was loaded, the far one not
    assert!(result(&s2, "near.probe.centre.uz") < -1e-9);
    assert_eq!(result(&s2, "far.interface_force.z"), 0.0);
    assert_eq!(
        result(&s1, "fem.probe.centre.uz"),
        result(&s2, "near.probe.centre.uz")
    );
}

#[test]
fn cosim_check_reports_each_structures_limits_and_scene_errors_name_the_node() {
    let dir = tempfile::tempdir().unwrap();
    let mut c = cosim();
    c.arg("check")
        .arg(root().join("scenes/two-plates.toml"))
        .arg("--out")
        .arg(dir.path().join("check"));
    let o = run(c);
    assert!(o.status.success());
    let stdout = String::from_utf8_lossy(&o.stdout);
    for node in ["left", "right"] {
        assert!(
            stdout.contains(&format!("coupling window (node `{node}`): ")),
            "{stdout}"
        );
        assert!(stdout.contains(&format!("  {node}.dofs = ")), "{stdout}");
    }
    // the DEM's own limits once
    assert_eq!(stdout.matches("DEM Rayleigh step").count(), 1, "{stdout}");

    // an error in a structure's table names that table's line and field
    let text = std::fs::read_to_string(root().join("scenes/two-plates.toml"))
        .unwrap()
        .replace(
            "[right.interface]\non = { plane = { axis = \"z\", value = 0.004 } }",
            "[right.interface]\non = { plane = { axis = \"z\", value = 0.004 } }\nthickness = 1",
        );
    let scene = write_scene(dir.path(), "bad.toml", &text);
    let mut c = cosim();
    c.arg("check")
        .arg(&scene)
        .arg("--out")
        .arg(dir.path().join("bad"));
    let o = run(c);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    let line = text.lines().position(|l| l == "thickness = 1").unwrap() + 1;
    assert!(
        err.contains(&format!("line {line}")) && err.contains("right.interface.thickness"),
        "{err}"
    );
    assert!(err.contains("node `right`"), "{err}");
}
