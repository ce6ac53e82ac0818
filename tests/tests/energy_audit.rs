//! The interface energy audit (PROTOCOL.md §6, docs/coupling.md): every window the DEM
//! reports the work its contact forces did on each coupled mesh (Σ_steps Δt Σ_nodes f·v on the
//! mesh motion it was given), the FEM the work of the loads it held over its step (f·Δx) and
//! the work of the forces it received over the displacement of the window they were computed
//! in; windows.csv lists all three per interface and summary.json sums them.

use cosim_tests::{root, run_scene};

struct Audit {
    dem: Vec<f64>,
    fem: Vec<f64>,
    received: Vec<Option<f64>>,
    summary: serde_json::Value,
}

fn audit(schedule: &str, averaging: bool, window: &str) -> Audit {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(root().join("scenes/plate.toml"))
        .unwrap()
        .replace(
            "schedule = \"predictive\"",
            &format!("schedule = \"{schedule}\"\nforce_averaging = {averaging}"),
        )
        .replace("window = \"0.1 ms\"", &format!("window = \"{window}\""));
    let s = run_scene(dir.path(), "plate.toml", &text);
    assert_eq!(s["status"], "completed", "{s}");
    let csv = std::fs::read_to_string(dir.path().join("out-plate.toml/windows.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| {
        header
            .iter()
            .position(|h| *h == name)
            .unwrap_or_else(|| panic!("no column {name} in {header:?}"))
    };
    let (cd, cf, cr) = (
        col("interface_work_dem.top_j"),
        col("interface_work_fem.top_j"),
        col("interface_work_received.top_j"),
    );
    let mut a = Audit {
        dem: vec![],
        fem: vec![],
        received: vec![],
        summary: s,
    };
    for l in lines {
        let v: Vec<&str> = l.split(',').collect();
        assert_eq!(v.len(), header.len(), "{l}");
        a.dem.push(v[cd].parse().unwrap());
        a.fem.push(v[cf].parse().unwrap());
        a.received.push(v[cr].parse().ok());
    }
    a
}

#[test]
fn predictive_with_force_averaging_pairs_the_two_sides_work_to_round_off() {
    let a = audit("predictive", true, "0.1 ms");
    // the summary's totals are the columns' sums, and its energy error their difference
    let t = &a.summary["interface_work"]["top"];
    let (d, f) = (a.dem.iter().sum::<f64>(), a.fem.iter().sum::<f64>());
    let scale = a
        .dem
        .iter()
        .chain(&a.fem)
        .fold(0.0f64, |m, w| m.max(w.abs()));
    assert!(scale > 1e-4, "the beads do work on the plate: {scale} J");
    let near = |x: f64, y: f64| (x - y).abs() <= 1e-8 * scale * a.dem.len() as f64;
    assert!(near(t["dem_j"].as_f64().unwrap(), d), "{t}");
    assert!(near(t["fem_j"].as_f64().unwrap(), f), "{t}");
    assert!(near(t["energy_error_j"].as_f64().unwrap(), d - f), "{t}");
    assert_eq!(t["windows"], a.summary["windows_done"]);
    // by construction: the DEM's mesh moves at the constant predictive velocity from P_k to
    // P_{k+1}, so its Σ Δt f·v is the mean force times the FEM's displacement — the work the
    // FEM computes for those forces when it receives them a window later
    let mut pairs = 0;
    for k in 1..a.dem.len() {
        if let Some(r) = a.received[k] {
            assert!(
                (a.dem[k - 1] - r).abs() <= 1e-9 * scale,
                "window {}: DEM {} J vs FEM's account of the same forces {r} J",
                k - 1,
                a.dem[k - 1]
            );
            pairs += 1;
        }
    }
    assert!(pairs + 2 >= a.dem.len(), "{pairs} pairs");
    // the energy error of the schedule is the lag, W_DEM(k) − W_FEM(k) = (f̄_k − f̄_{k−1})·Δx_k:
    // small over the run against the work exchanged
    let exchanged: f64 = a.dem.iter().map(|w| w.abs()).sum();
    eprintln!(
        "predictive, averaged: DEM {d:.4e} J, FEM {f:.4e} J, energy error {:.4e} J ({:.1} % of the {exchanged:.4e} J exchanged)",
        d - f,
        100.0 * (d - f).abs() / exchanged
    );
    assert!((d - f).abs() < 0.2 * exchanged);
    assert!(t["growth_warning_window"].is_null(), "{t}");
}

#[test]
fn without_averaging_or_with_just_in_time_the_sides_differ_and_say_so() {
    // just in time within its window limit on this scene (0.04 T_c)
    for (schedule, averaging, window) in [("predictive", false, "0.1 ms"), ("jit", true, "0.01 ms")]
    {
        let a = audit(schedule, averaging, window);
        let scale = a.dem.iter().fold(0.0f64, |m, w| m.max(w.abs()));
        // the pairing no longer holds: the FEM receives the last substep's forces (or, just in
        // time, forces of a motion extrapolated from the window start)
        let worst = (1..a.dem.len())
            .filter_map(|k| {
                let r = if schedule == "jit" {
                    a.received[k - 1]
                } else {
                    a.received[k]
                }?;
                Some((a.dem[k - 1] - r).abs())
            })
            .fold(0.0f64, f64::max);
        let t = &a.summary["interface_work"]["top"];
        eprintln!(
            "{schedule}, averaging {averaging}: DEM {:.4e} J, FEM {:.4e} J, largest window pairing gap {worst:.3e} J",
            t["dem_j"].as_f64().unwrap(),
            t["fem_j"].as_f64().unwrap()
        );
        assert!(worst > 1e-3 * scale, "{schedule}: {worst} vs {scale}");
        // just in time: the FEM's received forces are this window's, paired with this step
        if schedule == "jit" {
            for k in 0..a.fem.len() {
                if let Some(r) = a.received[k] {
                    assert_eq!(r, a.fem[k], "window {k}");
                }
            }
        }
    }
}
