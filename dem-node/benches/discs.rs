//! The 2-D disc engine (issue 23, Madan 2019): cost per disc-step of standard DEM and of the
//! DDEM (lagged and fixed-point), the cost of the ρ(B) check (Lanczos on the assembled
//! iteration matrix) on 1e4 and 1e5 discs, and the stability map of docs/ddem.md.
//!
//! `cargo bench -p dem-node --bench discs`. DISCS_SIDE (default 100: a 100 × 100 hexagonal
//! bonded lattice under a vertical load for the step costs), DISCS_STEPS (default 2000),
//! DISCS_MAP (file, default out/ddem/stability_map.csv: k_n/E_p at ρ(B) = 1 against ν_p for
//! the 180-disc SC and 110-disc HCP samples, the analytic lattices (3.43)/(3.78) and the
//! thesis' numerical limits, Tables 3.2/3.3; plot it with `cosim plot`).

mod common;
use common::env;
use dem::discs::{parse_scene_table, DiscEngine};
use std::path::Path;
use std::time::Instant;

/// A side × side hexagonal bonded lattice (R = 1 mm, k_n = 7e10) loaded by 1 kN per disc on
/// the top and bottom rows, E_p = 2e11, ν_p = 0.35 (when `ddem`).
fn lattice(side: usize, ddem: Option<&str>) -> String {
    let height = (side - 1) as f64 * 0.002 * 3f64.sqrt() / 2.0;
    let ddem = ddem
        .map(|scheme| {
            format!(
                "[dem.ddem]\nyoungs_modulus = 2e11\npoisson_ratio = 0.35\nscheme = \"{scheme}\"\n"
            )
        })
        .unwrap_or_default();
    format!(
        r#"
[dem]
model = "discs-2d"
time_step = 1e-7
density = 2000.0

[dem.contact]
normal_stiffness = 7e10
normal_damping = 0.1
bond_gap = 1e-9

{ddem}
[[dem.discs]]
kind = "lattice"
arrangement = "hexagonal"
radius = 0.001
spacing = 0.002
first = [0.0, 0.0]
count = [{side}, {side}]

[[dem.loads]]
region = {{ min = [-1.0, {top_lo}], max = [1.0, 1.0] }}
force = [0.0, -1e3]
ramp = 1e-5

[[dem.loads]]
region = {{ min = [-1.0, -1.0], max = [1.0, 0.0005] }}
force = [0.0, 1e3]
ramp = 1e-5

[dem.output]
csv_every = 1000000
"#,
        top_lo = height - 0.0005
    )
}

fn engine(text: &str) -> DiscEngine {
    let cfg = parse_scene_table(text, "dem").unwrap().unwrap();
    DiscEngine::from_config(&cfg, Path::new(".")).unwrap()
}

fn scene_file(name: &str) -> String {
    std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../scenes")
            .join(name),
    )
    .unwrap()
}

fn limit(e: &DiscEngine, name: &str) -> f64 {
    e.limits()
        .into_iter()
        .find(|(k, _)| k == name)
        .map_or(f64::NAN, |(_, v)| v)
}

fn main() {
    let side = env("DISCS_SIDE", 100);
    let steps = env("DISCS_STEPS", 2000) as u64;
    println!(
        "# cost per disc-step, {side} × {side} hexagonal bonded lattice, {steps} steps, one core"
    );
    let mut dem_cost = f64::NAN;
    for (name, ddem) in [
        ("standard DEM", None),
        ("DDEM lagged", Some("lagged")),
        ("DDEM fixed point", Some("fixed-point")),
    ] {
        let mut e = engine(&lattice(side, ddem));
        let n = e.num_discs() as f64;
        e.advance(10).unwrap();
        let t = Instant::now();
        e.advance(steps).unwrap();
        let per = t.elapsed().as_secs_f64() / (steps as f64 * n) * 1e9;
        if ddem.is_none() {
            dem_cost = per;
        }
        let its = e.iterations();
        println!(
            "{name:>18}: {per:8.1} ns per disc-step ({:.2} × standard){}",
            per / dem_cost,
            if its.1 > 0 {
                format!(
                    ", fixed-point iterations per step: last {}, most {}",
                    its.0, its.1
                )
            } else {
                String::new()
            }
        );
    }
    println!("# the ρ(B) check at set-up (Lanczos on the assembled iteration matrix)");
    for side in [100usize, 317] {
        let t = Instant::now();
        let plain = engine(&lattice(side, None));
        let t_plain = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let e = engine(&lattice(side, Some("lagged")));
        let t_ddem = t.elapsed().as_secs_f64();
        println!(
            "{:>7} discs, {:>7} contacts: set-up {t_plain:.3} s standard, {t_ddem:.3} s DDEM → ρ(B) check {:.3} s (ρ = {:.4}, lattice {:.4})",
            e.num_discs(),
            limit(&plain, "contacts_initial"),
            t_ddem - t_plain,
            limit(&e, "ddem_spectral_radius"),
            limit(&e, "ddem_spectral_radius_lattice"),
        );
    }
    // the stability map
    // relative paths from the workspace root (cargo runs benches in the package's folder)
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let path = root
        .join(std::env::var("DISCS_MAP").unwrap_or_else(|_| "out/ddem/stability_map.csv".into()));
    let path = path.as_path();
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).unwrap();
    }
    let sc_thesis = [
        0.761, 0.722, 0.693, 0.667, 0.636, 0.614, 0.588, 0.569, 0.551,
    ];
    let hcp_thesis = [
        0.569, 0.614, 0.673, 0.751, 0.850, 0.823, 0.793, 0.764, 0.738,
    ];
    let (sc, hcp) = (scene_file("ddem-sc.toml"), scene_file("ddem-hcp.toml"));
    let mut csv = String::from(
        "nu_p,SC analytic (3.43),SC sample (ours),SC thesis (Table 3.2),HCP analytic (3.78),HCP sample (ours),HCP thesis (Table 3.3)\n",
    );
    let mut nus: Vec<f64> = (1..=9).map(|k| k as f64 * 0.05).collect();
    nus.insert(4, 0.22);
    for nu in nus {
        let with =
            |t: &str| t.replacen("poisson_ratio = 0.35", &format!("poisson_ratio = {nu}"), 1);
        let (a, b) = (engine(&with(&sc)), engine(&with(&hcp)));
        let analytic =
            |e: &DiscEngine| limit(e, "ddem_kn_over_ep") / limit(e, "ddem_spectral_radius_lattice");
        let k = ((nu / 0.05).round() as usize).wrapping_sub(1);
        let exact = (nu / 0.05 - (nu / 0.05).round()).abs() < 1e-9;
        let cell = |v: Option<f64>| v.map(|v| format!("{v:.4}")).unwrap_or_default();
        csv.push_str(&format!(
            "{nu:.2},{:.4},{:.4},{},{:.4},{:.4},{}\n",
            analytic(&a),
            limit(&a, "ddem_kn_over_ep_limit"),
            cell(exact.then(|| sc_thesis[k])),
            analytic(&b),
            limit(&b, "ddem_kn_over_ep_limit"),
            cell(if exact {
                Some(hcp_thesis[k])
            } else {
                Some(0.791)
            }),
        ));
    }
    std::fs::write(path, &csv).unwrap();
    println!(
        "# stability map (k_n/E_p at ρ(B) = 1; refused above) → {}",
        path.display()
    );
    print!("{csv}");
}
