//! Madan's 2-D disc engine through `cosim` (real dem-node processes over zenoh): the SC
//! sample's moduli in the summary, `cosim check` refusing a DDEM scene past ρ(B) = 1 (and the
//! run stopping when the refusal is overridden), and a killed run resumed bit for bit.

use cosim_tests::{cosim, root, run, run_scene, summary, write_scene};

fn sc() -> String {
    std::fs::read_to_string(root().join("scenes/ddem-sc.toml")).unwrap()
}

#[test]
fn the_sc_sample_runs_through_cosim_with_its_moduli_and_outputs() {
    let dir = tempfile::tempdir().unwrap();
    let s = run_scene(dir.path(), "ddem-sc.toml", &sc());
    assert_eq!(s["status"], "completed", "{s}");
    let r = &s["results"];
    // Table 4.1, k_n/E_p = 0.35: E = 50.32 GPa, ν = 0.151
    let e = r["dem.youngs_modulus"].as_f64().unwrap();
    let nu = r["dem.poisson_ratio"].as_f64().unwrap();
    assert!((e / 1e9 - 50.32).abs() < 0.01, "{e}");
    assert!((nu - 0.151).abs() < 0.0005, "{nu}");
    let out = dir.path().join("out-ddem-sc.toml");
    // a CSV row every 10 steps and the state at t = 0: 15,000 steps → 1,501 rows
    let csv = std::fs::read_to_string(out.join("dem/discs.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + 1501);
    // ParaView: the discs with their strain tensors, the contacts with their forces
    let vtk = std::fs::read_to_string(out.join("dem/discs_000015000.vtk")).unwrap();
    assert!(vtk.contains("POINTS 180 double") && vtk.contains("TENSORS strain double"));
    let contacts = std::fs::read_to_string(out.join("dem/contacts_000015000.vtk")).unwrap();
    assert!(contacts.contains("SCALARS normal_force double"));
    assert!(std::fs::read_to_string(out.join("dem/discs.pvd"))
        .unwrap()
        .contains("discs_000015000.vtk"));
    for png in ["energies.png", "strains.png", "stress_strain.png"] {
        assert!(out.join("plots").join(png).exists(), "{png}");
    }
}

#[test]
fn check_refuses_a_ddem_scene_past_the_convergence_limit() {
    let dir = tempfile::tempdir().unwrap();
    // E_p = 1e11: k_n/E_p = 0.7, ρ(B) = 1.18 for this sample (limit 0.5925)
    let text = sc().replacen("youngs_modulus = 2e11", "youngs_modulus = 1e11", 1);
    let scene = write_scene(dir.path(), "soft.toml", &text);
    let mut c = cosim();
    c.arg("check").arg(&scene);
    let o = run(c);
    let err = String::from_utf8_lossy(&o.stderr).to_string() + &String::from_utf8_lossy(&o.stdout);
    assert!(!o.status.success());
    for words in [
        "DDEM convergence",
        "k_n/E_p = 0.7000",
        "ν_p = 0.35",
        "ρ(B) = 1.18",
        "0.5925",
    ] {
        assert!(err.contains(words), "`{words}` missing: {err}");
    }
    // overridden, the run starts, and the engine stops it as the lagged scheme diverges
    let text = text.replacen(
        "window = \"10 us\"",
        "window = \"10 us\"\nallow_beyond_limits = true",
        1,
    );
    let scene = write_scene(dir.path(), "soft.toml", &text);
    let out = dir.path().join("out");
    let mut c = cosim();
    c.arg("run")
        .arg(&scene)
        .arg("--no-progress")
        .arg("--out")
        .arg(&out);
    let o = run(c);
    assert!(!o.status.success());
    let s = summary(&out);
    let text = s.to_string();
    assert!(
        text.contains("diverges") && text.contains("ρ(B) = 1.18"),
        "{text}"
    );
    // a time step past the critical one is refused naming it
    let text = sc().replacen("time_step = 1e-8", "time_step = 5e-8", 1);
    let scene = write_scene(dir.path(), "coarse.toml", &text);
    let mut c = cosim();
    c.arg("check").arg(&scene);
    let o = run(c);
    let err = String::from_utf8_lossy(&o.stderr).to_string() + &String::from_utf8_lossy(&o.stdout);
    assert!(!o.status.success());
    assert!(
        err.contains("disc critical time step") && err.contains("2.1210e-8"),
        "{err}"
    );
}

#[test]
fn a_killed_disc_run_resumes_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    // 0.6 ms: 60 windows of 10 µs, a checkpoint every 10
    let text = sc()
        .replacen("end_time = \"0.15 ms\"", "end_time = \"0.6 ms\"", 1)
        .replacen(
            "[coupling]",
            "[output]\ncheckpoint_every = 10\nfinal_state = true\n\n[coupling]",
            1,
        );
    let scene = write_scene(dir.path(), "sc.toml", &text);
    let (whole, broken, _) =
        cosim_tests::whole_and_resumed(dir.path(), &scene, "ddem-resume", 19, "dem");
    let s = summary(&broken);
    assert_eq!(s["status"], "completed");
    assert!(s["resumed_after_window"].as_u64().unwrap() >= 19, "{s}");
    let read = |p: std::path::PathBuf| std::fs::read(&p).unwrap_or_else(|e| panic!("{p:?}: {e}"));
    assert!(
        read(whole.join("final/dem.state")) == read(broken.join("final/dem.state")),
        "the resumed final state differs"
    );
    assert!(
        read(whole.join("dem/discs.csv")) == read(broken.join("dem/discs.csv")),
        "the resumed discs.csv differs"
    );
}
