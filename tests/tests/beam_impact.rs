//! Wellmann §4.3.1: a steel ball strikes a simply supported steel beam at midspan
//! (`scenes/beam-impact.toml`, Timoshenko's 1913 data: R = 1 cm, beam 1 × 1 × 15.35 cm, 1 cm/s,
//! no gravity). The two-way coupled run — real dem-node and fem-node processes over zenoh, a
//! 1 µs predictive window, the beam in 10 quadratic hexahedra under Bossak (α_B = 0) — against
//! Timoshenko's semi-analytical solution (`cosim_tests::timoshenko`: modal Euler–Bernoulli
//! beam with Hertz contact): contact duration, peak force and rebound velocity within 2 %, the
//! largest midspan deflection within 5 %.

use cosim_tests::timoshenko::{self, Options};
use cosim_tests::{root, run_scene};

fn column(text: &str, name: &str) -> Vec<f64> {
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let c = header
        .iter()
        .position(|h| *h == name)
        .unwrap_or_else(|| panic!("{name} in {header:?}"));
    lines
        .map(|l| l.split(',').nth(c).unwrap().parse().unwrap())
        .collect()
}

#[test]
fn coupled_beam_impact_matches_timoshenko() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(root().join("scenes/beam-impact.toml")).unwrap();
    let s = run_scene(dir.path(), "beam-impact.toml", &text);
    assert_eq!(s["status"], "completed", "{s}");
    let out = dir.path().join("out-beam-impact.toml");

    // the reference
    let (beam, sphere) = timoshenko::timoshenko_1913();
    let reference = timoshenko::solve(
        &beam,
        &sphere,
        &Options {
            modes: 200,
            time_step: 1e-7,
            duration: 1e-3,
            sample_every: 10,
        },
    );
    let c0 = &reference.contacts[0];
    let w_max = reference
        .samples
        .iter()
        .map(|p| p.beam)
        .fold(f64::MIN, f64::max);

    // the coupled run: contact from the DEM's largest overlap (Hertz: P = k α^{3/2}, the law
    // the DEM applies), rebound from the final particle file, deflection from the FEM probe
    let dem = std::fs::read_to_string(out.join("dem/dem_timeseries.csv")).unwrap();
    let (time, overlap) = (column(&dem, "time"), column(&dem, "max_overlap"));
    let k = timoshenko::hertz_constant(&beam, &sphere);
    let touching: Vec<usize> = (0..time.len()).filter(|&i| overlap[i] > 0.0).collect();
    let (first, last) = (touching[0], *touching.last().unwrap());
    assert!(
        touching.iter().zip(&touching[1..]).all(|(a, b)| b - a == 1),
        "one contact, as in the reference ({} windows touching)",
        touching.len()
    );
    // the contact lasts from the window before the first overlap to the last one
    let duration = time[last] - time[first] + (time[1] - time[0]);
    let peak = overlap.iter().fold(0.0f64, |m, &a| m.max(k * a.powf(1.5)));
    let fin = std::fs::read_to_string(out.join("dem/particles_final.csv")).unwrap();
    let rebound = column(&fin, "vz")[0];
    let fem = std::fs::read_to_string(out.join("fem/fem_probes.csv")).unwrap();
    let sag = column(&fem, "probe.midspan.uz")
        .iter()
        .fold(0.0f64, |m, &u| m.max(-u));

    let rel = |a: f64, b: f64| (a - b) / b;
    eprintln!(
        "contact {:.4} ms (Timoshenko {:.4} ms, {:+.2} %), peak {:.4} N ({:.4} N, {:+.2} %), \
         rebound {:.4} cm/s ({:.4} cm/s, {:+.2} %), midspan deflection {:.4e} m ({:.4e} m, \
         {:+.2} %)",
        duration * 1e3,
        (c0.end - c0.start) * 1e3,
        100.0 * rel(duration, c0.end - c0.start),
        peak,
        c0.peak_force,
        100.0 * rel(peak, c0.peak_force),
        rebound * 100.0,
        -reference.final_sphere_velocity * 100.0,
        100.0 * rel(rebound, -reference.final_sphere_velocity),
        sag,
        w_max,
        100.0 * rel(sag, w_max)
    );
    assert_eq!(reference.contacts.len(), 1);
    assert!(rel(duration, c0.end - c0.start).abs() < 0.02);
    assert!(rel(peak, c0.peak_force).abs() < 0.02);
    assert!(rel(rebound, -reference.final_sphere_velocity).abs() < 0.02);
    assert!(rel(sag, w_max).abs() < 0.05);
}
