//! Stability at the extremes (issue: "extreme inputs each either run stably or are refused up
//! front with the limit named — never a silent NaN"). Each case edits the two-way plate scene
//! (or the DEM-only minimal scene) and runs `cosim run`: it must either complete with finite
//! results, or fail before its first window with an error that names the limit and a number.

use std::path::Path;

use cosim_tests::{cosim, root, run, summary, write_scene};

/// What happened to one extreme case.
#[derive(Debug)]
enum Verdict {
    /// Completed; every result finite.
    Ran,
    /// Refused before the first window; the error text.
    Refused(String),
}

fn scene(name: &str) -> String {
    std::fs::read_to_string(root().join("scenes").join(name)).unwrap()
}

/// The plate scene shortened to 5 ms.
fn plate() -> String {
    scene("plate.toml").replace("end_time = \"30 ms\"", "end_time = \"5 ms\"")
}

fn attempt(dir: &Path, name: &str, text: &str) -> Verdict {
    let path = write_scene(dir, name, text);
    let out = dir.join(format!("out-{name}"));
    let mut c = cosim();
    c.arg("run")
        .arg(&path)
        .arg("--no-progress")
        .arg("--out")
        .arg(&out);
    let o = run(c);
    let s = summary(&out);
    if o.status.success() {
        assert_eq!(s["status"], "completed", "{name}: {s}");
        for (k, v) in s["results"].as_object().unwrap() {
            assert!(
                v.as_f64().is_some_and(f64::is_finite),
                "{name}: result {k} = {v} is not finite"
            );
        }
        Verdict::Ran
    } else {
        let err = String::from_utf8_lossy(&o.stderr).to_string();
        assert_eq!(
            s["windows_done"], 0,
            "{name}: a run that fails must fail before its first window: {err}"
        );
        assert_ne!(s["status"], "unstable", "{name}: {err}");
        assert!(
            err.chars().any(|c| c.is_ascii_digit()),
            "{name}: the refusal gives no number: {err}"
        );
        Verdict::Refused(err)
    }
}

fn refused_naming(v: &Verdict, words: &[&str]) {
    match v {
        Verdict::Refused(e) => assert!(
            words.iter().any(|w| e.contains(w)),
            "the refusal should name one of {words:?}: {e}"
        ),
        Verdict::Ran => panic!("expected a refusal naming {words:?}"),
    }
}

/// Rayleigh step of the plate's beads (A1, eq. 2.27): E = 5e7, ν = 0.3, ρ = 2000, R = 4 mm.
fn bead_rayleigh() -> f64 {
    let (e, nu, rho, r) = (5e7f64, 0.3f64, 2000.0f64, 0.004f64);
    let g = e / (2.0 * (1.0 + nu));
    std::f64::consts::PI * r / (0.1631 * nu + 0.8766) * (rho / g).sqrt()
}

#[test]
fn dem_time_step_at_half_one_and_two_rayleigh_steps_is_refused_with_the_limit() {
    let dir = tempfile::tempdir().unwrap();
    for f in [0.5, 1.0, 2.0] {
        let dt = f * bead_rayleigh();
        let text = plate()
            .replace("time_step = 1e-5", &format!("time_step = {dt:e}"))
            .replace("window = \"0.1 ms\"", &format!("window = {:e}", 10.0 * dt))
            .replace(
                "end_time = \"5 ms\"",
                &format!("end_time = {:e}", 40.0 * dt),
            );
        let v = attempt(dir.path(), &format!("dt{f}.toml"), &text);
        refused_naming(&v, &["Rayleigh"]);
    }
}

#[test]
fn particle_stiffness_from_1_mpa_to_1_tpa_runs_or_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let soft = plate().replace("youngs_modulus = 5e7", "youngs_modulus = 1e6");
    assert!(matches!(
        attempt(dir.path(), "soft.toml", &soft),
        Verdict::Ran
    ));
    let stiff = plate().replace("youngs_modulus = 5e7", "youngs_modulus = 1e12");
    refused_naming(&attempt(dir.path(), "stiff.toml", &stiff), &["Rayleigh"]);
}

#[test]
fn nearly_incompressible_fem_runs_without_blowing_up() {
    let dir = tempfile::tempdir().unwrap();
    let text = plate().replace(
        "material = { youngs_modulus = 70e9, poisson_ratio = 0.33",
        "material = { youngs_modulus = 70e9, poisson_ratio = 0.499",
    );
    assert!(text.contains("0.499"));
    let v = attempt(dir.path(), "nu.toml", &text);
    match v {
        Verdict::Ran => {
            let s = summary(&dir.path().join("out-nu.toml"));
            let uz = s["results"]["fem.probe.centre.uz"].as_f64().unwrap();
            // a 4 mm plate under 200 beads: micrometres, not metres
            assert!(uz.abs() < 1e-3, "uz = {uz}");
        }
        Verdict::Refused(e) => assert!(e.contains("poisson"), "{e}"),
    }
}

#[test]
fn tiny_and_huge_particles_run_or_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let one = |r: f64| {
        let list = format!(
            "[[dem.particles]]\nkind = \"list\"\nmaterial = \"bead\"\nspheres = [{{ position = [0.06, 0.06, {z}], radius = {r:e}, velocity = [0.0, 0.0, -1.0] }}]\n",
            z = 0.004 + r + 1e-3
        );
        let text = plate();
        let a = text.find("[[dem.particles]]").unwrap();
        let b = text.find("[fem]").unwrap();
        format!("{}{list}\n{}", &text[..a], &text[b..])
    };
    refused_naming(&attempt(dir.path(), "tiny.toml", &one(1e-5)), &["Rayleigh"]);
    let v = attempt(dir.path(), "huge.toml", &one(1.0));
    if let Verdict::Refused(e) = &v {
        assert!(
            e.contains("coupling window") || e.contains("Rayleigh"),
            "{e}"
        );
    }
}

#[test]
fn particle_to_structure_mass_ratios_of_1e6_and_1e_minus_6_run_or_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    // the beads (5.4e-4 kg) and the plate's nodes (~4.6e-4 kg) weigh about the same
    for (name, density) in [("heavy.toml", 2000.0 * 1e6), ("light.toml", 2000.0 * 1e-6)] {
        let text = plate().replacen("density = 2000.0", &format!("density = {density:e}"), 1);
        let v = attempt(dir.path(), name, &text);
        if let Verdict::Refused(e) = &v {
            assert!(
                e.contains("Rayleigh") || e.contains("coupling window"),
                "{e}"
            );
        }
    }
}

#[test]
fn coupling_windows_of_one_and_ten_thousand_dem_steps_run_or_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let one = plate().replace("window = \"0.1 ms\"", "window = \"10 us\"");
    assert!(matches!(attempt(dir.path(), "w1.toml", &one), Verdict::Ran));
    let many = plate()
        .replace("window = \"0.1 ms\"", "window = \"0.1 s\"")
        .replace("end_time = \"5 ms\"", "end_time = \"0.1 s\"");
    refused_naming(
        &attempt(dir.path(), "w1e4.toml", &many),
        &["coupling window"],
    );
}
