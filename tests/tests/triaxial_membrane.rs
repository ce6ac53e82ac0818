//! Wellmann's triaxial test of glass beads in an Ogden membrane (ch. 4.3.4) at CI size, over
//! zenoh with real processes: scenes/triaxial-membrane-prep-ci.toml pours the beads into a
//! rigid mould and presses them with 1 kPa; scenes/triaxial-membrane-ci.toml cuts the sample,
//! confines it in the membrane under a 100 kPa cell pressure and shears it by the top platen.
//! `TRIAXIAL_DIR=<dir>` keeps the outputs.

use cosim_tests::*;

fn column(text: &str, name: &str) -> Vec<f64> {
    csv_column(text, name)
        .iter()
        .map(|v| v.parse().unwrap())
        .collect()
}

/// σ₁/σ₃ and the share of the cell pressure p the grains carry on the membrane, from the
/// platen's contact force, the volume inside the membrane, the height of its top ring and the
/// grains' outward force on it over a lateral surface of `height`: the cross-section is the
/// volume over the ring's height.
fn cell_state(force: f64, volume: f64, ring: f64, outward: f64, height: f64, p: f64) -> (f64, f64) {
    let area = volume / ring;
    let lateral = outward / (p * 2.0 * (std::f64::consts::PI * area).sqrt() * height);
    (force / (area * p), lateral)
}

/// Means over consecutive blocks of `n` values.
fn means(v: &[f64], n: usize) -> Vec<f64> {
    v.chunks(n)
        .map(|c| c.iter().sum::<f64>() / c.len() as f64)
        .collect()
}

#[test]
fn glass_beads_in_a_membrane_carry_the_cell_pressure_and_gain_strength_when_sheared() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = std::env::var("TRIAXIAL_DIR").map_or(tmp.path().to_path_buf(), Into::into);
    std::fs::create_dir_all(&dir).unwrap();
    let scenes = root().join("scenes");

    // 1. the sample in the mould at 1 kPa
    let prep = std::fs::read_to_string(scenes.join("triaxial-membrane-prep-ci.toml")).unwrap();
    let s = run_scene(&dir, "prep.toml", &prep);
    assert_eq!(s["status"], "completed", "{s}");
    let prep_out = dir.join("out-prep.toml/dem");
    let series = std::fs::read_to_string(prep_out.join("dem_timeseries.csv")).unwrap();
    let force = *column(&series, "platen.contact_force").last().unwrap();
    let ke = *column(&series, "kinetic_energy").last().unwrap();
    eprintln!("prepared: platen force {force:.4} N (1 kPa: 0.452 N), kinetic energy {ke:e} J");
    assert!(
        (force - 0.452).abs() < 0.1 * 0.452,
        "platen force {force} N"
    );
    assert!(ke < 1e-5, "not settled: {ke} J");

    // 2. cut, confined, sheared
    let beads = prep_out.join("particles_final.csv");
    let text = std::fs::read_to_string(scenes.join("triaxial-membrane-ci.toml"))
        .unwrap()
        .replace(
            "../out/triaxial-membrane-prep-ci/dem/particles_final.csv",
            beads.to_str().unwrap(),
        );
    let s = run_scene(&dir, "triaxial.toml", &text);
    assert_eq!(s["status"], "completed", "{s}");
    let out = dir.join("out-triaxial.toml");
    let dem = std::fs::read_to_string(out.join("dem/dem_timeseries.csv")).unwrap();
    let fem = std::fs::read_to_string(out.join("fem/fem_probes.csv")).unwrap();
    let (t, u, f) = (
        column(&dem, "time"),
        column(&dem, "platen.displacement"),
        column(&dem, "platen.contact_force"),
    );
    let (volume, outward, bulge, ring) = (
        column(&fem, "volume"),
        column(&fem, "outward_force"),
        column(&fem, "probe.middle.ux"),
        column(&fem, "top_ring_z"),
    );
    let last_volume = *volume.last().unwrap();
    assert_eq!(t.len(), volume.len(), "one row per window on both sides");
    // 2 ms means (100 windows): the platen's force rattles with the few beads under it
    let n = 100;
    let (t, u, f, volume, outward, bulge, ring) = (
        means(&t, n),
        means(&u, n),
        means(&f, n),
        means(&volume, n),
        means(&outward, n),
        means(&bulge, n),
        means(&ring, n),
    );
    let p = 100e3;
    let start = t.iter().position(|&x| x > 0.03).unwrap(); // the first block of shearing
    let h0 = 0.045 + u[start - 1];
    let mut peak: f64 = 0.0;
    for k in 0..t.len() {
        let h = 0.045 + u[k];
        // the mean cross-section: the volume is closed by the plane of the membrane's top
        // ring, which floats while the platen settles and then moves with it
        let (ratio, lateral) = cell_state(f[k], volume[k], ring[k], outward[k], h, p);
        let strain = (h0 - h) / h0;
        eprintln!(
            "t = {:.4} s  axial strain {:+.4}  σ₁/σ₃ = {ratio:.3}  volume {:.0} mm³  grains' \
             outward force / (p × lateral area) = {lateral:.3}  bulge {:.3e} m",
            t[k],
            strain,
            volume[k] * 1e9,
            bulge[k]
        );
        if k >= start {
            peak = peak.max(ratio);
            // the grains hold the membrane out against the cell pressure (the clamped rings
            // take the rest)
            assert!(
                (0.8..=1.0).contains(&lateral),
                "t = {}: the grains carry {lateral} of the cell pressure",
                t[k]
            );
        }
        if k == start - 1 {
            // consolidated isotropically: σ₁ ≈ σ₃
            assert!(
                (0.85..=1.25).contains(&ratio),
                "consolidated at σ₁/σ₃ = {ratio}"
            );
        }
    }
    let last = t.len() - 1;
    let strain = (h0 - 0.045 - u[last]) / h0;
    eprintln!("sheared to {strain:.4}; peak σ₁/σ₃ {peak:.3}");
    assert!(strain > 0.055, "sheared to {strain}");
    assert!(
        (1.25..3.5).contains(&peak),
        "σ₁/σ₃ peaks at {peak} (W: ≈ 2.5 at full size)"
    );
    // the membrane bulges out at mid-height as the sample shortens
    assert!(
        bulge[last] > bulge[start - 1] + 1e-5,
        "mid-height radius {:e} → {:e}",
        bulge[start - 1],
        bulge[last]
    );
    let results = &s["nodes"]["fem"]["results"];
    let v = results["volume"].as_f64().unwrap();
    assert!(
        (v - last_volume).abs() < 1e-8 * v,
        "{v} vs the CSV's {last_volume}"
    );

    // 3. `cosim study` over the cell pressure: the membrane's pressure and the platen's force
    // vary together (linked keys), here through consolidation only, at 25 and 250 kPa
    let consolidate = text.replace("end_time = \"0.052 s\"", "end_time = \"0.03 s\"");
    assert_ne!(consolidate, text);
    let scene = write_scene(&dir, "consolidate.toml", &consolidate);
    let area = std::f64::consts::PI * 0.012f64.powi(2);
    let weight = 0.02 * 9.81;
    let force = |p: f64| -(p * area - weight);
    let study = dir.join("study");
    let mut c = cosim();
    c.arg("study")
        .arg(&scene)
        .args([
            "--vary",
            &format!(
                "fem.loads.0.value+dem.walls.1.load.force=25e3:{},250e3:{}",
                force(25e3),
                force(250e3)
            ),
            "--metric",
            "fem.interface_force.outward",
            "--jobs",
            "1",
            "--out",
        ])
        .arg(&study);
    let o = run(c);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let table = std::fs::read_to_string(study.join("study.csv")).unwrap();
    assert!(
        table.starts_with("run,fem.loads.0.value,dem.walls.1.load.force,status"),
        "{table}"
    );
    for (k, p) in [(0, 25e3), (1, 250e3)] {
        let run_dir = study.join(format!("run{k:03}"));
        let dem = std::fs::read_to_string(run_dir.join("dem/dem_timeseries.csv")).unwrap();
        let fem = std::fs::read_to_string(run_dir.join("fem/fem_probes.csv")).unwrap();
        // the last 2 ms
        let tail = |v: Vec<f64>| means(&v[v.len() - 100..], 100)[0];
        let ring = tail(column(&fem, "top_ring_z"));
        let (ratio, lateral) = cell_state(
            tail(column(&dem, "platen.contact_force")),
            tail(column(&fem, "volume")),
            ring,
            tail(column(&fem, "outward_force")),
            ring,
            p,
        );
        eprintln!("p = {p} Pa consolidated: σ₁/σ₃ = {ratio:.3}, lateral share {lateral:.3}");
        // near 1 for both (had only one key changed, σ₁/σ₃ would be 0.25 or 2.5); the higher
        // the pressure, the deeper the membrane presses into the surface voids and the
        // smaller the cross-section under the platen's p π R² (1.02 at 25 kPa, 1.23 at 250)
        assert!((0.9..=1.35).contains(&ratio), "p = {p}: σ₁/σ₃ = {ratio}");
        assert!(
            (0.75..=1.0).contains(&lateral),
            "p = {p}: lateral share {lateral}"
        );
    }
}
