//! Superquadric grains in a coupled run (issue 16): `scenes/plate-superquadric.toml` through
//! `cosim run` (real dem-node and fem-node processes over zenoh) and `cosim study`.

use cosim_tests::{cosim, root, run, run_scene};

fn scene_text() -> String {
    std::fs::read_to_string(root().join("scenes/plate-superquadric.toml")).unwrap()
}

/// The grains fall onto the plate, touch its coupled mesh (DEM wall contacts), press it
/// through the interface so that it bends downwards (FEM probe), and bounce; the DEM writes
/// the bodies' surfaces for ParaView.
#[test]
fn superquadric_grains_load_a_coupled_plate() {
    let dir = tempfile::tempdir().unwrap();
    let text = scene_text().replace("[fem]", "[dem.output]\nvtk_every = 1000\n\n[fem]");
    let s = run_scene(dir.path(), "plate-superquadric.toml", &text);
    assert_eq!(s["status"], "completed", "{s}");
    let out = dir.path().join("out-plate-superquadric.toml");
    let column_max = |file: &str, column: &str, sign: f64| {
        let text = std::fs::read_to_string(out.join(file)).unwrap();
        let mut lines = text.lines();
        let header: Vec<&str> = lines.next().unwrap().split(',').collect();
        let c = header.iter().position(|h| *h == column).unwrap();
        lines
            .map(|l| sign * l.split(',').nth(c).unwrap().parse::<f64>().unwrap())
            .fold(f64::MIN, f64::max)
    };
    let contacts = column_max("dem/dem_timeseries.csv", "wall_contacts", 1.0);
    let sag = column_max("fem/fem_probes.csv", "probe.centre.uz", -1.0);
    eprintln!("most wall contacts {contacts}, largest downward deflection {sag:e} m");
    assert!(
        contacts >= 10.0,
        "the grains must land on the plate: {contacts}"
    );
    assert!(
        sag > 1e-7,
        "the plate must bend down under the grains: {sag:e} m"
    );
    assert!(
        out.join("dem/superquadrics.pvd").exists(),
        "no surfaces written"
    );
}

/// `cosim study` sweeps the DEM time step of the superquadric scene: both runs complete and
/// the table compares them.
#[test]
fn superquadric_scene_runs_in_a_study() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("plate-superquadric.toml");
    std::fs::write(
        &scene,
        scene_text().replace("end_time = \"30 ms\"", "end_time = \"10 ms\""),
    )
    .unwrap();
    let out = dir.path().join("study");
    let mut c = cosim();
    c.arg("study")
        .arg(&scene)
        .args([
            "--vary",
            "dem.time_step=5e-6,1e-5",
            "--metric",
            "fem.interface_force.z",
            "--out",
        ])
        .arg(&out);
    let o = run(c);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let csv = std::fs::read_to_string(out.join("study.csv")).unwrap();
    let done = csv
        .lines()
        .skip(1)
        .filter(|l| l.contains(",completed,"))
        .count();
    assert_eq!(done, 2, "{csv}");
}
