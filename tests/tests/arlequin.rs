//! Arlequin volume coupling (Wellmann ch. 6) over the real path: a dem-node and a fem-node
//! process exchange a volume interface (the FE overlap's elements and weights at start-up, the
//! nodes' kinematics and the particles' penalty pull every window) for
//! `scenes/arlequin-column-ci.toml`, a column of grains standing in and on an elastic block.
//! `ARLEQUIN_DIR=<dir>` keeps the outputs.

use cosim_tests::*;

fn scene(end_time: &str, extra: &str) -> String {
    std::fs::read_to_string(root().join("scenes/arlequin-column-ci.toml"))
        .unwrap()
        .replace(
            "end_time = \"40 ms\"",
            &format!("end_time = \"{end_time}\"{extra}"),
        )
}

fn out_dir(tmp: &tempfile::TempDir) -> std::path::PathBuf {
    let dir = std::env::var("ARLEQUIN_DIR").map_or(tmp.path().to_path_buf(), Into::into);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// At rest, the penalty forces on the block carry exactly the grains' weighted weight Σ w m g
/// (the coupled system's equilibrium through the overlap), and the block settles by what that
/// load and its own weight make it: δ = (p h + ρ g h²/2) / E of a free column (measured
/// 0.08 % apart; 2 % allowed for the clamped base and the load spread over the overlap).
#[test]
fn grains_in_an_overlap_load_the_block_with_their_weighted_weight() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = out_dir(&tmp);
    let s = run_scene(&dir, "column.toml", &scene("60 ms", ""));
    assert_eq!(s["status"], "completed", "{s}");
    let dem = &s["nodes"]["dem"]["results"];
    let fem = &s["nodes"]["fem"]["results"];
    let get = |v: &serde_json::Value, k: &str| {
        v[k].as_f64()
            .unwrap_or_else(|| panic!("no result {k} in {v}"))
    };
    assert_eq!(get(dem, "volume.soil.coupled_particles"), 128.0);
    let ke = get(dem, "kinetic_energy");
    assert!(
        ke < 1e-15,
        "the column is not at rest: kinetic energy {ke:e} J"
    );
    let (force, weight) = (
        get(dem, "volume.soil.penalty_force_z"),
        get(dem, "volume.soil.weighted_gravity_z"),
    );
    eprintln!("penalty force on the block {force:.6e} N, weighted weight {weight:.6e} N");
    assert!(weight < 0.0);
    assert!(
        (force / weight - 1.0).abs() < 1e-3,
        "the block carries {force:e} N of the grains' {weight:e} N"
    );
    // the block: 10 mm, E = 60 MPa, ρ = 1500, loaded on 1 cm² by the grains
    let (h, e, rho, area) = (0.01, 6e7, 1500.0, 1e-4);
    let p = -force / area;
    let expected = (p * h + rho * 9.81 * h * h / 2.0) / e;
    let settled = get(fem, "max_displacement");
    eprintln!("block settlement {settled:.4e} m, free-column estimate {expected:.4e} m");
    assert!(
        (settled / expected - 1.0).abs() < 0.02,
        "settlement {settled:e} m vs {expected:e} m"
    );
    let windows = std::fs::read_to_string(dir.join("out-column.toml/windows.csv")).unwrap();
    assert_eq!(windows.lines().count(), 601);
}

/// The same column on a Mohr–Coulomb block (Wellmann's φ and ψ, with a cohesion of 10 kPa that
/// keeps this unconfined column elastic — with his 15 Pa it yields and settles 6.5 times as
/// much, measured): the Newton path carries the implicit penalty too, and the block settles
/// as the linear one does.
#[test]
fn a_mohr_coulomb_block_carries_the_grains_through_the_newton_path() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = out_dir(&tmp);
    let text = scene("40 ms", "")
        .replace(
            "material = { youngs_modulus = 6e7, poisson_ratio = 0.3, density = 1500.0 }\n",
            "",
        )
        .replace(
            "analysis = \"static\"\n",
            "analysis = \"static\"\n\n[fem.materials.sand]\nmodel = \"mohr_coulomb\"\n\
             youngs_modulus = 6e7\npoisson_ratio = 0.3\nfriction_angle = 23.15\n\
             dilation_angle = 5.17\ncohesion = 1e4\ndensity = 1500.0\n\n\
             [[fem.sections]]\nelements = \"all\"\nmaterial = \"sand\"\n",
        );
    assert!(text.contains("mohr_coulomb") && !text.contains("material = { youngs"));
    let s = run_scene(&dir, "column-mc.toml", &text);
    assert_eq!(s["status"], "completed", "{s}");
    let dem = &s["nodes"]["dem"]["results"];
    let force = dem["volume.soil.penalty_force_z"].as_f64().unwrap();
    let weight = dem["volume.soil.weighted_gravity_z"].as_f64().unwrap();
    assert!((force / weight - 1.0).abs() < 1e-3, "{force} vs {weight}");
    let settled = s["nodes"]["fem"]["results"]["max_displacement"]
        .as_f64()
        .unwrap();
    let expected = (-force / 1e-4 * 0.01 + 1500.0 * 9.81 * 1e-4 / 2.0) / 6e7;
    eprintln!("Mohr–Coulomb block settlement {settled:.4e} m, free column {expected:.4e} m");
    assert!(
        (settled / expected - 1.0).abs() < 0.02,
        "{settled} vs {expected}"
    );
}

/// A run killed after a checkpoint and resumed ends in the same final state, bit for bit, as
/// an uninterrupted one: both nodes restore the volume interface (the DEM its overlap and
/// coupled particles in their reference configuration, the FEM its weighted operator).
#[test]
fn a_volume_coupled_run_resumes_bitwise() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = out_dir(&tmp);
    let text = scene(
        "12 ms",
        "\n[output]\ncheckpoint_every = 10\nfinal_state = true",
    );
    let path = write_scene(&dir, "resume.toml", &text);
    let whole = dir.join("whole");
    let mut c = cosim();
    c.arg("run")
        .arg(&path)
        .args(["--no-progress", "--overwrite", "--out"])
        .arg(&whole);
    assert!(run(c).status.success());

    let broken = dir.join("broken");
    let run_id = format!("arlequin-resume-{}", std::process::id());
    let mut child = spawn_run(&path, &run_id, &broken);
    wait_for_checkpoint(&broken, 49, &mut child);
    let pid = pid_of(&["dem-node", &run_id]).expect("the DEM node runs");
    kill(pid);
    assert!(
        !child.wait().unwrap().success(),
        "the interrupted run must fail"
    );
    let mut c = cosim();
    c.arg("resume").arg(&broken).arg("--no-progress");
    assert!(run(c).status.success());
    let s = summary(&broken);
    assert_eq!(s["status"], "completed", "{s}");
    assert!(s["resumed_after_window"].as_u64().unwrap() >= 49, "{s}");
    for node in ["dem", "fem"] {
        let a = std::fs::read(whole.join(format!("final/{node}.state"))).unwrap();
        let b = std::fs::read(broken.join(format!("final/{node}.state"))).unwrap();
        assert!(
            a == b,
            "{node}: the resumed final state differs from the uninterrupted run"
        );
    }
}

/// A scene that declares a volume interface whose FEM has no overlap, or an overlap that is
/// declared a surface, is refused at start-up naming the fix.
#[test]
fn volume_and_surface_declarations_must_match_the_fem_model() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = out_dir(&tmp);
    for (name, text, needle) in [
        (
            "no-overlap.toml",
            scene("1 ms", "").replace("[fem.overlap]", "[fem.not_overlap]"),
            "",
        ),
        (
            "surface.toml",
            scene("1 ms", "").replace(
                "interfaces = [{ name = \"soil\", kind = \"volume\" }]",
                "interfaces = [\"soil\"]",
            ),
            "give it kind = \"volume\"",
        ),
    ] {
        let text = if name == "no-overlap.toml" {
            // drop the overlap table entirely
            let cut = text.find("[fem.not_overlap]").unwrap();
            let end = text[cut..].find("\n\n").map_or(text.len(), |e| cut + e);
            format!("{}{}", &text[..cut], &text[end..])
        } else {
            text
        };
        let p = write_scene(&dir, name, &text);
        let mut c = cosim();
        c.arg("run")
            .arg(&p)
            .args(["--no-progress", "--overwrite", "--out"])
            .arg(dir.join(format!("out-{name}")));
        let o = run(c);
        assert!(!o.status.success(), "{name} ran");
        let err = String::from_utf8_lossy(&o.stderr);
        let needle = if needle.is_empty() {
            "is a volume interface but the FEM model has no [fem.overlap]"
        } else {
            needle
        };
        assert!(err.contains(needle), "{name}: {err}");
    }
}
