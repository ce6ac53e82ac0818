//! The sheet of Ullrich ch. 5 as MITC4 shells against the same sheet as one layer of hex8i,
//! coupled to grains over zenoh (real nodes, real files): a bed of wheat dropped onto the
//! clamped sheet's free part settles, and the loaded deflection 60 mm from the free end must
//! agree. The shells' top surface (z = +t/2 along the director) is where the hex sheet's top
//! face is, so the grains see the same surface; the scenes differ only in `[fem]`. The whole
//! flow (scenes/sheet-shell-ci.toml, scenes/sheet-shell.toml) is compared in docs/full-size.md.

use cosim_tests::{csv_column, run_scene};

/// sheet-ci's sheet, materials and clamp; 0.02 kg of wheat filled 5–45 mm above the free
/// part, settling for 0.5 s; the sheet damped (Rayleigh a = 40 /s, ζ ≈ 0.4 at its 7.7 Hz).
fn scene(name: &str, (mesh, tables): (&str, &str)) -> String {
    format!(
        r#"[scene]
name = "{name}"
end_time = "0.5 s"

[coupling]
schedule = "predictive"
window = "100 us"
interfaces = ["sheet"]

[dem]
time_step = 1e-5
allow_large_time_step = true
gravity = [0.0, 0.0, -9.81]
interface_material = "steel"

[dem.materials.wheat]
youngs_modulus = 100e6
poisson_ratio = 0.3
density = 1242.0
restitution = 0.4
friction = 1.0

[dem.materials.steel]
youngs_modulus = 185e9
poisson_ratio = 0.3
density = 7850.0
restitution = 0.4
friction = 0.22

[[dem.interactions]]
materials = ["wheat", "steel"]
friction = 0.22

[[dem.particles]]
kind = "fill"
material = "wheat"
min = [0.2, 0.0, 0.005]
max = [0.34, 0.1, 0.045]
mass = 0.02
distribution = {{ kind = "uniform", min = 0.0015, max = 0.0025 }}

[dem.output]
vtk_every = 0

[fem]
{mesh}
material = {{ youngs_modulus = 185e9, poisson_ratio = 0.3, density = 7850.0 }}
analysis = {{ type = "dynamic", alpha_b = -0.1, rayleigh_a = 40.0 }}

[[fem.supports]]
on = {{ box = {{ min = [-0.001, -0.001, -0.001], max = [0.0601, 0.101, 0.001] }} }}

[fem.output]
vtu_every = 0

{tables}
"#
    )
}

#[test]
fn shells_and_hex8i_sheets_carry_a_settled_bed_alike() {
    let hex = (
        r#"mesh = { size = [0.34, 0.1, 0.00075], origin = [0.0, 0.0, -0.00075], divisions = [34, 10, 1], element = "hex8i" }"#,
        r#"[fem.interface]
on = { plane = { axis = "z", value = 0.0 } }
[[fem.probes]]
name = "measure"
point = [0.28, 0.05, -0.00075]"#,
    );
    let shell = (
        r#"mesh = { size = [0.34, 0.1, 0.0], origin = [0.0, 0.0, -0.000375], divisions = [34, 10, 0], element = "mitc4" }
shell = { thickness = 0.00075 }"#,
        r#"[fem.interface]
on = { set = "all" }
faces = "top"
[[fem.probes]]
name = "measure"
point = [0.28, 0.05, -0.000375]"#,
    );
    let dir = tempfile::tempdir().unwrap();
    let mut loaded = Vec::new();
    for (name, fem) in [("hex", hex), ("shell", shell)] {
        let s = run_scene(dir.path(), &format!("{name}.toml"), &scene(name, fem));
        assert_eq!(s["status"], "completed", "{s}");
        let csv = std::fs::read_to_string(
            dir.path()
                .join(format!("out-{name}.toml/fem/fem_probes.csv")),
        )
        .unwrap();
        let t: Vec<f64> = csv_column(&csv, "time")
            .iter()
            .map(|v| v.parse().unwrap())
            .collect();
        let w: Vec<f64> = csv_column(&csv, "probe.measure.uz")
            .iter()
            .map(|v| v.parse().unwrap())
            .collect();
        // the settled bed: the mean over the last 0.1 s
        let tail: Vec<f64> = t
            .iter()
            .zip(&w)
            .filter(|(t, _)| **t > 0.4)
            .map(|(_, w)| *w)
            .collect();
        let mean = tail.iter().sum::<f64>() / tail.len() as f64;
        let spread = tail.iter().fold(0.0f64, |a, w| a.max((w - mean).abs()));
        let fz = s["results"]["fem.interface_force.z"].as_f64().unwrap();
        eprintln!("{name}: deflection {mean:.4e} m (±{spread:.1e} over the last 0.1 s), interface force {fz:.4} N");
        assert!(
            mean < -1e-4,
            "{name}: the bed must bend the sheet down: {mean}"
        );
        // settled: the sheet no longer swings
        assert!(
            spread < 0.1 * mean.abs(),
            "{name}: still moving: ±{spread} about {mean}"
        );
        // what rests on the sheet weighs at most the 0.02 kg filled
        assert!(
            fz < 0.0 && -fz < 0.02 * 9.81 * 1.05,
            "{name}: interface force {fz}"
        );
        loaded.push((mean, fz));
    }
    // per newton of bed: the same compliance (the beds settle differently once the sheets
    // differ, so compare deflection per unit load, and the load itself loosely)
    let (hex_c, shell_c) = (loaded[0].0 / loaded[0].1, loaded[1].0 / loaded[1].1);
    eprintln!(
        "compliance hex8i {hex_c:.4e} m/N, shells {shell_c:.4e} m/N: {:+.2} %",
        100.0 * (shell_c / hex_c - 1.0)
    );
    assert!((shell_c / hex_c - 1.0).abs() < 0.02);
    assert!((loaded[1].1 / loaded[0].1 - 1.0).abs() < 0.05);
}
