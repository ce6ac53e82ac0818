//! Madan's irregular sample (§4.5) at CI size: a random packing pressed together by four
//! servo plates (scenes/ddem-pack.toml with 400 discs), written as a disc file, read back as
//! a bonded sample, and its DDEM stability limit (Table 4.4) and critical step (4.30).

use dem::discs::{parse_scene_table, DiscEngine};
use std::path::Path;

fn scenes() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes"))
}

fn engine(text: &str, base: &Path) -> DiscEngine {
    let cfg = parse_scene_table(text, "dem")
        .unwrap_or_else(|e| panic!("{e}"))
        .expect("[dem]");
    DiscEngine::from_config(&cfg, base).unwrap_or_else(|e| panic!("{e}"))
}

fn value(list: Vec<(String, f64)>, name: &str) -> f64 {
    list.into_iter()
        .find(|(k, _)| k == name)
        .unwrap_or_else(|| panic!("no {name}"))
        .1
}

/// scenes/ddem-pack.toml with `count` discs in a box of solid fraction 0.5.
fn pack_scene(count: usize) -> String {
    let text = std::fs::read_to_string(scenes().join("ddem-pack.toml")).unwrap();
    // mean R² of the triangular distribution: 1.469e-7 m²
    let side = (count as f64 * std::f64::consts::PI * 1.469e-7 / 0.5).sqrt();
    text.replace("count = 4979", &format!("count = {count}"))
        .replace("max = [0.068, 0.068]", &format!("max = [{side}, {side}]"))
        .replace("point = [0.0, 0.068]", &format!("point = [0.0, {side}]"))
        .replace("point = [0.068, 0.0]", &format!("point = [{side}, 0.0]"))
        .replace("length = 0.05", &format!("length = {}", 0.8 * side))
}

/// The bonded DDEM sample of a disc file: k_n = 7e10, k_t = 0, bonds that never break
/// (bond gap 1e-7 m), non-viscous damping 0.2 (M §4.5's stability runs), pressed by the top
/// plate at 5 mm/s onto the fixed bottom one, both touching the sample at t = 0.
fn sample(file: &Path, ep: f64, nu: f64) -> String {
    format!(
        r#"
[dem]
model = "discs-2d"
time_step = 4e-8
density = 2000.0
[dem.contact]
normal_stiffness = 7e10
bond_gap = 1e-7
[dem.damping]
translational = 0.2
rotational = 0.2
[dem.ddem]
youngs_modulus = {ep:e}
poisson_ratio = {nu}
[[dem.discs]]
kind = "file"
path = "{}"
[[dem.walls]]
name = "bottom"
point = [0.0, -1.0]
normal = [0.0, 1.0]
touch = true
[[dem.walls]]
name = "top"
point = [0.0, 1.0]
normal = [0.0, -1.0]
velocity = [0.0, -0.005]
touch = true
"#,
        file.display()
    )
}

#[test]
fn an_irregular_packing_by_servo_plates_has_the_stability_limit_of_table_4_4() {
    let dir = tempfile::tempdir().unwrap();
    // 400 discs dropped into a box at solid fraction 0.5, pressed by four plates to 1 MPa
    let mut pack = engine(&pack_scene(400), scenes());
    pack.advance(250_000).unwrap(); // 10 ms
    let r = pack.results();
    let side = (400.0 * std::f64::consts::PI * 1.469e-7 / 0.5f64).sqrt();
    let target = 1e6 * 0.8 * side;
    for wall in ["bottom", "top", "left", "right"] {
        let f = value(r.clone(), &format!("{wall}.force"));
        assert!(
            (f / target - 1.0).abs() < 0.02,
            "{wall}: {f} N vs {target} N"
        );
    }
    assert!(pack.kinetic_energy() < 1e-4, "{}", pack.kinetic_energy());
    pack.write_final(dir.path()).unwrap();
    let file = dir.path().join("discs_final.csv");
    // read back: the same discs, to the bit
    let e = engine(&sample(&file, 1.06e11, 0.45), dir.path());
    assert_eq!(e.positions(), pack.positions());
    assert_eq!(e.radii(), pack.radii());
    let l = e.limits();
    let solid = value(l.clone(), "solid_fraction_initial");
    let coordination = value(l.clone(), "coordination_initial");
    assert!(solid > 0.8, "{solid}");
    // ν_p = 0.45: Table 4.4's limit k_n/E_p = 0.660 (E_p = 1.06e11 stable, 1.05e11 not); this
    // sample (coordination ~3.3, frictionless compaction; the thesis' 5.8) within 5 %
    let limit = value(l.clone(), "ddem_kn_over_ep_limit");
    println!("solid fraction {solid:.3}, coordination {coordination:.2}, k_n/E_p limit {limit:.4} (Table 4.4: 0.660)");
    assert!((limit / 0.660 - 1.0).abs() < 0.05, "{limit}");
    // the lagged scheme under the moving plate: stable 3 % below the limit, diverging 3 % above
    for (factor, stable) in [(0.97, true), (1.03, false)] {
        let ep = 7e10 / (factor * limit);
        let mut e = engine(&sample(&file, ep, 0.45), dir.path());
        let rho = value(e.limits(), "ddem_spectral_radius");
        let run = e.advance(25_000);
        println!(
            "k_n/E_p = {factor} × limit: ρ = {rho:.4}, {:?}",
            run.as_ref().err().map(|e| e.to_string())
        );
        assert_eq!(run.is_ok(), stable, "ρ = {rho}: {run:?}");
    }
}
