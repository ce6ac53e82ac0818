//! The coupling schedules end to end: coordinator + dem-node + fem-node as real processes over
//! zenoh on loopback (Ullrich ch. 3–4, REFERENCE A3).

use std::path::Path;

use cosim_tests::{cosim, root, run, run_scene, write_scene};

fn scene_text(name: &str) -> String {
    std::fs::read_to_string(root().join("scenes").join(name)).unwrap()
}

fn f(s: &serde_json::Value, key: &str) -> f64 {
    s["results"][key]
        .as_f64()
        .unwrap_or_else(|| panic!("{key} missing in {s}"))
}

/// The beam scene with `mass` kg of spheres, then a pure-FEM solve of the same beam under the
/// coupled run's total interface load as a uniform pressure on the top face.
fn beam_coupled_vs_pure_fem(mass: f64) -> (f64, f64) {
    let dir = tempfile::tempdir().unwrap();
    // one layer of 640 spheres r = 6.25 mm: density for the requested total mass
    let volume = 640.0 * 4.0 / 3.0 * std::f64::consts::PI * 0.00625f64.powi(3);
    let text = scene_text("beam-layer.toml").replace(
        "density = 77922.26",
        &format!("density = {}", mass / volume),
    );
    let coupled = run_scene(dir.path(), "beam.toml", &text);
    assert_eq!(coupled["status"], "completed");
    // the run drew its probe's time series next to the summary
    let png = dir.path().join("out-beam.toml/plots/probe.midspan.png");
    let bytes = std::fs::read(&png).unwrap_or_else(|e| panic!("{}: {e}", png.display()));
    assert_eq!(&bytes[..4], b"\x89PNG");
    let fz = f(&coupled, "fem.interface_force.z");
    assert!(
        (fz + mass * 9.81).abs() < 1e-3 * mass * 9.81,
        "the settled spheres weigh {fz} N"
    );
    let uz = f(&coupled, "fem.probe.midspan.uz");
    // the summary's own comparison (the FEM node's pure-FEM solve under the same total load)
    let own = f(&coupled, "fem.pressure_equivalent.probe.midspan.uz");
    let rel = f(&coupled, "fem.coupled_vs_pressure.probe.midspan.uz");
    assert!(
        (rel - (uz - own) / own.abs()).abs() < 1e-12 && rel.abs() < 0.01,
        "{rel}"
    );

    // pure FEM: the [fem] table alone, with the same total load as pressure on the top face
    let fem_table = &text[text.find("[fem]").unwrap()..];
    let pure = format!(
        "[scene]\nname = \"beam-fem\"\nend_time = 1.0\n[coupling]\nwindow = 1.0\n{fem_table}\n\
         [[fem.loads]]\ntype = \"pressure\"\non = {{ plane = {{ axis = \"z\", value = 0.1 }} }}\nvalue = {}\n",
        -fz / (1.0 * 0.1)
    );
    let pure = run_scene(dir.path(), "beam-fem.toml", &pure);
    (uz, f(&pure, "fem.probe.midspan.uz"))
}

#[test]
fn beam_51_kg_coupled_within_1_percent_of_pure_fem() {
    let (coupled, pure) = beam_coupled_vs_pure_fem(51.0);
    let rel = (coupled - pure).abs() / pure.abs();
    eprintln!(
        "51 kg: coupled {coupled:.6e} m, pure FEM {pure:.6e} m, difference {:.3} % (seed 0.38 %)",
        100.0 * rel
    );
    // REFERENCE A3: seed's pure FEM at 50 mm: −7.06e-7 m; full-integration hex8: −7.05e-7 m
    assert!((pure + 7.05e-7).abs() < 0.005 * 7.05e-7, "pure FEM {pure}");
    assert!(rel < 0.01, "{rel}");
}

#[test]
fn beam_72_kg_coupled_within_1_percent_of_pure_fem() {
    let (coupled, pure) = beam_coupled_vs_pure_fem(72.0);
    let rel = (coupled - pure).abs() / pure.abs();
    eprintln!(
        "72 kg: coupled {coupled:.6e} m, pure FEM {pure:.6e} m, difference {:.3} % (seed 0.85 %)",
        100.0 * rel
    );
    // linear elasticity: the deflection scales with the load (seed −9.97e-7 m at 72 kg)
    assert!(
        (pure + 7.05e-7 * 72.0 / 51.0).abs() < 0.005 * 9.95e-7,
        "pure FEM {pure}"
    );
    assert!(rel < 0.01, "{rel}");
}

/// The default scene (the README's first command): a random bed of 51 kg settles in several
/// layers, loads the beam, and the summary holds a real coupled-vs-pressure difference (not
/// round-off); the plots show data and ParaView gets a time series of every output.
#[test]
fn the_default_scene_settles_a_random_bed_and_shows_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("beam");
    let mut c = cosim();
    c.args(["run", "scenes/beam.toml", "--no-progress", "--out"])
        .arg(&out);
    let o = run(c);
    assert!(o.status.success());
    let s = cosim_tests::summary(&out);
    assert_eq!(s["status"], "completed");
    assert!(
        s["warnings"].as_array().unwrap().is_empty(),
        "settled in time, no warning: {s}"
    );
    let fz = f(&s, "fem.interface_force.z");
    assert!((fz + 51.0 * 9.81).abs() < 0.005 * 51.0 * 9.81, "{fz} N");
    // several layers, randomly packed
    assert!(f(&s, "dem.particles") > 1000.0);
    let pure = f(&s, "fem.pressure_equivalent.probe.midspan.uz");
    assert!((pure + 7.05e-7).abs() < 0.005 * 7.05e-7, "pure FEM {pure}");
    let rel = f(&s, "fem.coupled_vs_pressure.probe.midspan.uz");
    eprintln!(
        "default beam: coupled vs pressure {:.3} % (seed 0.38 %)",
        100.0 * rel
    );
    assert!(rel.abs() > 1e-4 && rel.abs() < 0.03, "{rel}");
    for png in ["plots/probe.midspan.png", "plots/kinetic_energy.png"] {
        let bytes = std::fs::read(out.join(png)).unwrap();
        assert_eq!(&bytes[..4], b"\x89PNG", "{png}");
    }
    let pvd = std::fs::read_to_string(out.join("dem/particles.pvd")).unwrap();
    assert!(pvd.matches("<DataSet").count() >= 5, "{pvd}");
    assert!(out.join("fem/fem.pvd").exists());
    let stdout = String::from_utf8_lossy(&o.stdout);
    let last = stdout.lines().last().unwrap_or_default();
    assert!(
        last.starts_with("look at:") && last.contains("particles.pvd"),
        "{stdout}"
    );
}

/// Rows of a trace CSV: window index → values.
fn trace(path: &Path) -> Vec<(u64, Vec<f64>)> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    text.lines()
        .skip(1)
        .map(|l| {
            let mut it = l.split(',');
            let w = it.next().unwrap().parse().unwrap();
            (w, it.filter_map(|v| v.parse().ok()).collect())
        })
        .collect()
}

fn plate(schedule: &str, averaging: bool) -> (tempfile::TempDir, serde_json::Value) {
    let dir = tempfile::tempdir().unwrap();
    let text = scene_text("plate.toml")
        .replace(
            "schedule = \"predictive\"",
            // JIT's window limit on this scene is 14 µs (cosim check); these tests check the
            // schedule's mechanics at the scene's 100 µs window
            &format!("schedule = \"{schedule}\"\nforce_averaging = {averaging}\nallow_beyond_limits = true"),
        )
        .replace(
            "end_time = \"30 ms\"",
            "end_time = \"10 ms\"\n[output]\ntrace_interfaces = true",
        );
    let s = run_scene(dir.path(), "plate.toml", &text);
    assert_eq!(s["status"], "completed");
    assert_eq!(s["windows_done"], 100);
    (dir, s)
}

#[test]
fn predictive_mesh_lands_on_fem_position_at_every_window_end() {
    let (dir, _) = plate("predictive", false);
    let out = dir.path().join("out-plate.toml");
    let dem = trace(&out.join("dem/trace_top_mesh.csv"));
    let fem = trace(&out.join("fem/trace_top_mesh.csv"));
    assert_eq!(dem.len(), 100);
    assert_eq!(fem.len(), 100);
    let n3 = dem[0].1.len() - 1;
    let mut worst: f64 = 0.0;
    let mut moved: f64 = 0.0;
    for ((wd, d), (wf, f)) in dem.iter().zip(&fem) {
        assert_eq!(wd, wf);
        // DEM row [t_end, x…]; FEM row [t_end, x…, v…, a…]
        assert!(
            (d[0] - f[0]).abs() < 1e-12,
            "window {wd}: DEM at t = {}, FEM at t = {}",
            d[0],
            f[0]
        );
        for (a, b) in d[1..].iter().zip(&f[1..1 + n3]) {
            worst = worst.max((a - b).abs());
        }
        let first = &fem[0].1[1..1 + n3];
        moved = moved.max(
            f[1..1 + n3]
                .iter()
                .zip(first)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max),
        );
    }
    eprintln!("predictive: largest DEM–FEM mesh gap at window ends {worst:.3e} m; the mesh moved up to {moved:.3e} m");
    assert!(
        moved > 1e-8,
        "the plate must move for this test to mean anything"
    );
    assert!(worst <= 1e-12, "{worst}");
}

/// Both nodes publish their interface data before writing their outputs and say how long
/// the writing took; the coordinator's critical path leaves the smaller of the two out.
#[test]
fn the_critical_path_leaves_out_what_the_nodes_do_after_their_data_left() {
    let (_dir, s) = plate("predictive", false);
    let at = |p: &str| {
        s.pointer(p)
            .and_then(|v| v.as_f64())
            .unwrap_or_else(|| panic!("{p} missing in {s}"))
    };
    let node = |n: &str, k: &str| at(&format!("/nodes/{n}/{k}"));
    let (dem, fem) = (node("dem", "compute_s"), node("fem", "compute_s"));
    let (dem_after, fem_after) = (node("dem", "after_output_s"), node("fem", "after_output_s"));
    // the DEM appends its time series and sums its monitor values after the forces left, the
    // FEM its probes and the energy audit after the kinematics (every window: traces on)
    assert!(dem_after > 0.0 && dem_after < dem, "{dem_after} of {dem}");
    assert!(fem_after > 0.0 && fem_after < fem, "{fem_after} of {fem}");
    // windows announced ahead (the default): both tails are off the path, but a window is
    // never shorter than either node's whole compute
    let critical = at("/timing/critical_path_s");
    let lowest = dem + fem - dem_after - fem_after;
    assert!(
        critical < dem + fem && critical >= lowest * (1.0 - 1e-9),
        "critical path {critical} s, whole compute {} s, up to the data {lowest} s",
        dem + fem
    );
    assert!(critical >= dem.max(fem));
    let wall = at("/timing/windows_wall_s");
    let overhead = at("/timing/coupling_overhead_s");
    assert!((overhead - (wall - critical).max(0.0)).abs() <= 1e-9 * wall);
}

#[test]
fn jit_moves_the_dem_mesh_by_the_last_fem_kinematics() {
    let (dir, s) = plate("jit", false);
    let out = dir.path().join("out-plate.toml");
    let dem = trace(&out.join("dem/trace_top_mesh.csv"));
    let fem = trace(&out.join("fem/trace_top_mesh.csv"));
    let n3 = dem[0].1.len() - 1;
    let dt = 1e-4;
    // Ullrich ch. 3.3: in window k the DEM mesh moves x = P + Vτ + ½Aτ² with the FEM state at
    // the end of window k − 1; at τ = Δt^C it must be exactly there.
    let (mut worst, mut gap_to_fem): (f64, f64) = (0.0, 0.0);
    for k in 1..dem.len() {
        let prev = &fem[k - 1].1;
        let (p, v, a) = (
            &prev[1..1 + n3],
            &prev[1 + n3..1 + 2 * n3],
            &prev[1 + 2 * n3..1 + 3 * n3],
        );
        for i in 0..n3 {
            let expected = p[i] + v[i] * dt + 0.5 * a[i] * dt * dt;
            worst = worst.max((dem[k].1[1 + i] - expected).abs());
            gap_to_fem = gap_to_fem.max((dem[k].1[1 + i] - fem[k].1[1 + i]).abs());
        }
    }
    eprintln!("jit: DEM mesh vs P + VΔt + ½AΔt²: {worst:.3e} m; vs the FEM's own end position: {gap_to_fem:.3e} m");
    assert!(worst <= 1e-12, "{worst}");
    // the beads did load the plate
    let received = trace(&out.join("fem/trace_top_received_forces.csv"));
    let peak = received.iter().map(|(_, r)| -r[2]).fold(0.0, f64::max);
    assert!(peak > 0.1, "largest downward load {peak} N");
    assert_eq!(s["status"], "completed");
}

#[test]
fn force_averaging_gives_fem_the_mean_of_the_substep_forces() {
    let (dir, _) = plate("jit", true);
    let out = dir.path().join("out-plate.toml");
    let substeps = trace(&out.join("dem/trace_top_substep_forces.csv"));
    let received = trace(&out.join("fem/trace_top_received_forces.csv"));
    assert_eq!(received.len(), 100);
    let mut loaded = 0;
    for (w, r) in &received {
        let rows: Vec<&Vec<f64>> = substeps
            .iter()
            .filter(|(k, _)| k == w)
            .map(|(_, v)| v)
            .collect();
        assert_eq!(rows.len(), 10, "window {w}");
        // received row: [fx, fy, fz] (the `averaged` column does not parse as a number)
        for axis in 0..3 {
            // substep rows: [substep, fx, fy, fz]
            let mean = rows.iter().map(|v| v[1 + axis]).sum::<f64>() / rows.len() as f64;
            let last = rows.last().unwrap()[1 + axis];
            let got = r[axis];
            assert!(
                (got - mean).abs() <= 1e-12 * mean.abs().max(1e-9),
                "window {w} axis {axis}: FEM got {got}, mean {mean}"
            );
            if (mean - last).abs() > 1e-6 * mean.abs() {
                loaded += 1;
            }
        }
    }
    assert!(
        loaded > 0,
        "the mean must differ from the last substep somewhere for this test to mean anything"
    );
}

#[test]
fn a_coupling_window_that_is_not_a_whole_number_of_dem_steps_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let text = scene_text("plate.toml").replace("time_step = 1e-5", "time_step = 3e-5");
    let scene = write_scene(dir.path(), "plate.toml", &text);
    let mut c = cosim();
    c.arg("check").arg(&scene);
    let o = run(c);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("not a whole multiple"), "{err}");
    assert!(
        err.contains("Δt^C = 100 µs") && err.contains("Δt^D = 30 µs"),
        "{err}"
    );
}

/// The same layer of spheres, one way, on a 10 mm steel plate of MITC4 shells clamped at both
/// ends (the grains see both faces by default; its top face at z = 0.1 as the beam's): the
/// node's pure-FEM reference loads the shells with the settled weight as a pressure against
/// the directors' side, and the coupled deflection lies within 1 % of it.
#[test]
fn shell_plate_one_way_matches_its_pure_fem_reference() {
    let dir = tempfile::tempdir().unwrap();
    let text = scene_text("beam-layer.toml");
    let fem = text.find("[fem]").unwrap();
    let shells = format!(
        "{}[fem]\nmesh = {{ size = [1.0, 0.1, 0.0], origin = [0.0, 0.0, 0.095], divisions = [40, 4, 0], element = \"mitc4\" }}\n\
         shell = {{ thickness = 0.01 }}\n\
         material = {{ youngs_modulus = 210e9, poisson_ratio = 0.3, density = 7800.0 }}\n\
         analysis = \"static\"\n\
         [[fem.supports]]\non = {{ plane = {{ axis = \"x\", value = 0.0 }} }}\n\
         [[fem.supports]]\non = {{ plane = {{ axis = \"x\", value = 1.0 }} }}\n\
         [fem.interface]\non = {{ set = \"all\" }}\n\
         [[fem.probes]]\nname = \"midspan\"\npoint = [0.5, 0.05, 0.095]\n",
        &text[..fem]
    );
    let s = run_scene(dir.path(), "plate.toml", &shells);
    assert_eq!(s["status"], "completed");
    let fz = f(&s, "fem.interface_force.z");
    let pressure = f(&s, "fem.pressure_equivalent.pressure");
    eprintln!("settled weight {fz} N, reference pressure {pressure} Pa");
    // the weight spread over the plate's 0.1 m², pushing down against the +z directors
    assert!(fz < 0.0 && (pressure + fz / 0.1).abs() < 1e-9 * pressure.abs());
    let uz = f(&s, "fem.probe.midspan.uz");
    let rel = f(&s, "fem.coupled_vs_pressure.probe.midspan.uz");
    eprintln!("coupled {uz} m, against the pressure {rel:+.4}");
    assert!(uz < 0.0 && rel.abs() < 0.01, "{rel}");
}

/// Every file under `dir` (relative path → bytes), CSV and VTK outputs of the nodes.
fn outputs(dir: &Path) -> std::collections::BTreeMap<String, Vec<u8>> {
    let mut out = std::collections::BTreeMap::new();
    for node in ["dem", "fem"] {
        let mut stack = vec![dir.join(node)];
        while let Some(d) = stack.pop() {
            for e in std::fs::read_dir(&d).unwrap().flatten() {
                let p = e.path();
                if p.is_dir() {
                    stack.push(p);
                } else {
                    let rel = p.strip_prefix(dir).unwrap().display().to_string();
                    out.insert(rel, std::fs::read(&p).unwrap());
                }
            }
        }
    }
    out
}

/// On one host the processes talk over zenoh's low-latency links (proto/PROTOCOL.md §1):
/// the same run over ordinary links (`COSIM_LOWLATENCY=0`) gives every output bit for bit,
/// and `summary.json` says which links the run used.
#[test]
fn low_latency_and_ordinary_links_give_the_same_results_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let text = scene_text("plate.toml").replace(
        "end_time = \"30 ms\"",
        "end_time = \"5 ms\"\n[output]\ntrace_interfaces = true",
    );
    let fast = run_scene(dir.path(), "fast.toml", &text);
    let scene = write_scene(dir.path(), "plain.toml", &text);
    let out = dir.path().join("out-plain.toml");
    let mut c = cosim();
    c.env("COSIM_LOWLATENCY", "off")
        .arg("run")
        .arg(&scene)
        .arg("--no-progress")
        .arg("--out")
        .arg(&out);
    let o = run(c);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let plain = cosim_tests::summary(&out);
    for s in [&fast, &plain] {
        assert_eq!(s["status"], "completed");
        assert_eq!(s["windows_done"], 50);
    }
    let host_allows = proto::LinkConfig::loopback_peer(Some(7000), &[]).lowlatency();
    assert_eq!(fast["lowlatency_links"], host_allows, "{fast}");
    assert_eq!(plain["lowlatency_links"], false, "{plain}");
    let a = outputs(&dir.path().join("out-fast.toml"));
    let b = outputs(&out);
    assert!(a.keys().any(|k| k.contains("trace")), "{:?}", a.keys());
    assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>());
    for (name, bytes) in &a {
        assert!(bytes == &b[name], "{name} differs");
    }
}

/// The coordinator announces windows ahead (`coupling.lookahead`, default 2) in the explicit
/// schedules: the nodes compute the same windows with the same data, so every output is the
/// same bit for bit as in lockstep, checkpoints included (none is announced past).
#[test]
fn windows_announced_ahead_give_the_same_results_bit_for_bit_as_lockstep() {
    for schedule in ["jit", "predictive", "concurrent"] {
        let dir = tempfile::tempdir().unwrap();
        let text = |lookahead: &str, checkpoints: u32| {
            scene_text("plate.toml")
                .replace(
                    "schedule = \"predictive\"",
                    &format!(
                        "schedule = \"{schedule}\"\nallow_beyond_limits = true\n{lookahead}"
                    ),
                )
                .replace(
                    "end_time = \"30 ms\"",
                    &format!(
                        "end_time = \"5 ms\"\n[output]\ntrace_interfaces = true\ncheckpoint_every = {checkpoints}"
                    ),
                )
        };
        let lockstep = run_scene(dir.path(), "lockstep.toml", &text("lookahead = 0", 0));
        let ahead = run_scene(dir.path(), "ahead.toml", &text("", 7));
        for s in [&lockstep, &ahead] {
            assert_eq!(s["status"], "completed", "{schedule}");
            assert_eq!(s["windows_done"], 50, "{schedule}");
        }
        assert_eq!(lockstep["lookahead"], 0, "{schedule}");
        assert_eq!(ahead["lookahead"], 2, "{schedule}: the default");
        // the windows really went out ahead (else this compares lockstep with lockstep)
        assert_eq!(lockstep["windows_announced_ahead"], 0, "{schedule}");
        let announced = ahead["windows_announced_ahead"].as_u64().unwrap();
        assert!(
            announced >= 40,
            "{schedule}: {announced} of 50 windows announced ahead"
        );
        let a = outputs(&dir.path().join("out-lockstep.toml"));
        let b = outputs(&dir.path().join("out-ahead.toml"));
        assert!(
            a.keys().any(|k| k.contains("trace")),
            "{schedule}: the traces are compared: {:?}",
            a.keys()
        );
        assert_eq!(
            a.keys().collect::<Vec<_>>(),
            b.keys().collect::<Vec<_>>(),
            "{schedule}"
        );
        for (name, bytes) in &a {
            assert!(bytes == &b[name], "{schedule}: {name} differs");
        }
        // the run ahead checkpointed after every 7th window (resuming from such a checkpoint
        // is tested in resume.rs, at the default lookahead)
        let latest: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(
                dir.path()
                    .join("out-ahead.toml")
                    .join("checkpoints/latest.json"),
            )
            .unwrap(),
        )
        .unwrap();
        assert_eq!(latest["window"], 48, "{schedule}: {latest}");
    }
}
