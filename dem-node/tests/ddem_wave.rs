//! Madan ch. 5 at its own size: a sample of 682 bonded discs (R 0.1–0.145 mm, k_n = 1e10 N/m,
//! ρ_p = 2000 kg/m³; Table 5.1), waves started by an initial displacement pulse (5.5) and
//! their speeds from the peak times of layers of discs: a longitudinal wave in the sample as a
//! bar (free sides) against c_l = √(E/ρ) (5.1), and a shear wave with the sides periodic
//! against c_s = √(G/ρ) (5.2), E and G of the same sample in quasi-static compression and
//! simple shear; standard DEM and DDEM (k_n/E_p = 0.18, ν_p = 0.45 as the thesis' Figs. 5.4
//! and 5.6; k_t/k_n = 0.5). The sample stands along y; its top discs are held along the
//! pulse's displacement (the thesis' fixed right edge).

mod common;
use common::{disc_engine as engine, disc_plate, value};
use std::path::Path;

/// The period of the slab (m), the thesis' sample width.
const WIDTH: f64 = 0.0023;

/// 682 discs dropped at random into a 2.3 mm wide cell periodic along x (26 mm high, solid
/// fraction 0.54) and pressed together by a top and a bottom plate servo-controlled to 1 MPa
/// for 16 ms; written to `dir`/discs_final.csv.
fn slab(dir: &Path) -> std::path::PathBuf {
    let servo = "pressure = 1e6\nlength = 0.0023\nmax_speed = 2.0\ngain = 0.8\n";
    let text = format!(
        r#"
[dem]
model = "discs-2d"
time_step = 4e-8
density = 2000.0
[dem.periodic]
x = [0.0, {WIDTH}]
[dem.contact]
normal_stiffness = 1e10
[dem.damping]
translational = 0.2
rotational = 0.2
[dem.output]
final_discs = true
[[dem.discs]]
kind = "random"
count = 682
min = [0.0, 0.0]
max = [{WIDTH}, 0.026]
radius = {{ min = 0.0001, max = 0.000145, mode = 0.0001225 }}
seed = 5
[[dem.walls]]
name = "bottom"
point = [0.0, 0.0]
normal = [0.0, 1.0]
{servo}[[dem.walls]]
name = "top"
point = [0.0, 0.026]
normal = [0.0, -1.0]
{servo}"#
    );
    let mut e = engine(&text, dir);
    e.advance(400_000).unwrap();
    assert!(e.kinetic_energy() < 1e-5, "{}", e.kinetic_energy());
    for (name, force, _) in e.wall_readings() {
        assert!((force / 2300.0 - 1.0).abs() < 1e-3, "{name}: {force} N");
    }
    e.write_final(dir).unwrap();
    dir.join("discs_final.csv")
}

/// The bonded sample: neighbours up to 2 µm apart bonded at rest, k_t/k_n = 0.5, no damping;
/// `ddem`: the `[dem.ddem]` table or nothing; `rest`: periodicity, walls, pulse, probes,
/// measure.
fn sample(file: &Path, dt: f64, ddem: &str, rest: &str) -> String {
    format!(
        r#"
[dem]
model = "discs-2d"
time_step = {dt:e}
density = 2000.0
[dem.contact]
normal_stiffness = 1e10
tangential_stiffness = 5e9
bond_gap = 2e-6
bond_at_rest = true
{ddem}
[[dem.discs]]
kind = "file"
path = "{}"
[dem.output]
csv_every = 1
{rest}"#,
        file.display()
    )
}

/// The least-squares slope of y over x.
fn slope(x: &[f64], y: &[f64]) -> f64 {
    let n = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let sxy: f64 = x.iter().zip(y).map(|(a, b)| (a - mx) * (b - my)).sum();
    let sxx: f64 = x.iter().map(|a| (a - mx).powi(2)).sum();
    sxy / sxx
}

/// The time of the largest value of `u` (a parabola through the largest sample and its
/// neighbours), in steps.
fn peak(u: &[f64]) -> f64 {
    let k = (1..u.len() - 1)
        .max_by(|&a, &b| u[a].total_cmp(&u[b]))
        .unwrap();
    let (a, b, c) = (u[k - 1], u[k], u[k + 1]);
    k as f64 + 0.5 * (a - c) / (a - 2.0 * b + c)
}

/// A pulse of 10 µm along `along` over the bottom 5 mm (a half-bell, L = 10 mm), the top
/// discs held along it, and seven layers 0.3 mm thick 7 to 13 mm above the bottom as probes;
/// runs `steps` steps of 1e-8 s and returns the speed of a straight line through the layers'
/// peak times (the thesis averages five pairs of discs), checked against the engine's own
/// `wave_speed`.
fn wave(
    file: &Path,
    ddem: &str,
    periodic: &str,
    along: [f64; 2],
    bottom: f64,
    steps: usize,
) -> f64 {
    let dir = file.parent().unwrap();
    let fix = if along[0] != 0.0 { "x" } else { "y" };
    let mut text = format!(
        "{periodic}[[dem.constraints]]\nregion = {{ edge = \"top\", width = 1e-4 }}\nfix = [\"{fix}\"]\n\
         [dem.pulse]\ndirection = [0.0, 1.0]\ndisplacement = {along:?}\namplitude = 1e-5\nwavelength = 0.01\n"
    );
    for k in 0..7 {
        let y = bottom + 0.007 + 0.001 * k as f64;
        text += &format!(
            "[[dem.probes]]\nname = \"L{k}\"\nregion = {{ min = [-1.0, {}], max = [1.0, {}] }}\n",
            y - 1.5e-4,
            y + 1.5e-4
        );
    }
    let mut e = engine(&sample(file, 1e-8, ddem, &text), dir);
    let heights: Vec<f64> = e.probe_readings().iter().map(|p| p.1[1]).collect();
    let k = if along[0] != 0.0 { 0 } else { 1 };
    let mut u = vec![Vec::new(); heights.len()];
    for _ in 0..steps {
        e.advance(1).unwrap();
        for (uk, p) in u.iter_mut().zip(e.probe_readings()) {
            uk.push(p.2[k]);
        }
    }
    let times: Vec<f64> = u.iter().map(|uk| (peak(uk) + 1.0) * 1e-8).collect();
    let c = slope(&times, &heights);
    let (engine_says, r2) = e.wave_speed().expect("the probes saw the pulse");
    assert!((engine_says / c - 1.0).abs() < 1e-9, "{engine_says} vs {c}");
    assert!(r2 > 0.999, "one pulse at one speed: r² = {r2}");
    c
}

#[test]
fn waves_in_the_bonded_sample_run_at_the_static_bar_and_shear_speeds() {
    let dir = tempfile::tempdir().unwrap();
    let file = slab(dir.path());
    let periodic = format!("[dem.periodic]\nx = [0.0, {WIDTH}]\n");
    let ddem = "[dem.ddem]\nyoungs_modulus = 5.556e10\npoisson_ratio = 0.45\n";
    let (lo, hi) = {
        let e = engine(&sample(&file, 4e-8, "", ""), dir.path());
        dem::discs::config::span(e.positions(), e.radii())
    };
    let mass: f64 = {
        let e = engine(&sample(&file, 4e-8, "", ""), dir.path());
        e.radii()
            .iter()
            .map(|r| 2000.0 * std::f64::consts::PI * r * r)
            .sum()
    };
    // the sample's mean density: the discs' mass over the period times the height
    let rho = mass / (WIDTH * (hi[1] - lo[1]));
    println!(
        "sample {:.3} (period {:.3}) × {:.3} mm, ρ = {rho:.1} kg/m³",
        1e3 * (hi[0] - lo[0]),
        1e3 * WIDTH,
        1e3 * (hi[1] - lo[1])
    );
    let band = |edge: &str| format!("{{ edge = \"{edge}\", width = 3e-4 }}");
    let mut found = Vec::new();
    for (name, table) in [("standard DEM", ""), ("DDEM", ddem)] {
        // E of the bar: the top plate at 5 mm/s onto the bottom one for 1 ms, sides free; the
        // strain from the mean centres of the end and side bands, the stress the plate's
        // force over the period (4.19)–(4.22)
        let load = format!(
            "{}{}[dem.measure]\nplate = \"top\"\nsection = {WIDTH}\nfit = [0.2, 0.5]\ntop = {}\nbottom = {}\nleft = {}\nright = {}\n",
            disc_plate("bottom", [0.0, 1.0], 0.0),
            disc_plate("top", [0.0, -1.0], 0.005),
            band("top"),
            band("bottom"),
            band("left"),
            band("right"),
        );
        let mut e = engine(&sample(&file, 4e-8, table, &load), dir.path());
        e.advance(25_000).unwrap();
        let r = e.results();
        let (young, poisson) = (value(&r, "youngs_modulus"), value(&r, "poisson_ratio"));
        // G of the slab (sides periodic): simple shear, the bottom band held, the top band
        // moved along x at 5 mm/s for 1 ms; γ from the bands' mean centres, τ the macroscopic
        // σ_xy (4.3)
        let thin = |edge: &str| format!("{{ edge = \"{edge}\", width = 1e-4 }}");
        let load = format!(
            "{periodic}[[dem.constraints]]\nregion = {}\nfix = [\"x\", \"y\"]\n\
             [[dem.constraints]]\nregion = {}\nfix = [\"x\", \"y\"]\nvelocity = [0.005, 0.0]\n\
             [dem.measure]\ntest = \"shear\"\nfit = [0.2, 0.5]\ntop = {}\nbottom = {}\n",
            thin("bottom"),
            thin("top"),
            thin("top"),
            thin("bottom"),
        );
        let mut e = engine(&sample(&file, 4e-8, table, &load), dir.path());
        e.advance(25_000).unwrap();
        let shear = value(&e.results(), "shear_modulus");
        let (cl_static, cs_static) = ((young / rho).sqrt(), (shear / rho).sqrt());
        let cl = wave(&file, table, "", [0.0, 1.0], lo[1], 1000);
        let cs = wave(&file, table, &periodic, [1.0, 0.0], lo[1], 1500);
        println!(
            "{name}: E = {young:.4e} Pa, ν = {poisson:.4}, G = {shear:.4e} Pa; c_l = {cl:.1} m/s against √(E/ρ) = {cl_static:.1} ({:+.1} %), c_s = {cs:.1} m/s against √(G/ρ) = {cs_static:.1} ({:+.1} %); c_l/c_s = {:.4}, √(2(1 + ν)) = {:.4}",
            100.0 * (cl / cl_static - 1.0),
            100.0 * (cs / cs_static - 1.0),
            cl / cs,
            (2.0 * (1.0 + poisson)).sqrt()
        );
        // both pulses run at the static speeds (5.1), (5.2)
        assert!(
            (cl / cl_static - 1.0).abs() < 0.03,
            "{name}: {cl} vs {cl_static}"
        );
        assert!(
            (cs / cs_static - 1.0).abs() < 0.03,
            "{name}: {cs} vs {cs_static}"
        );
        found.push((cl, cs, young, shear));
    }
    // the deformable discs slow each wave as much as they soften its modulus
    let (dem, ddem) = (found[0], found[1]);
    let (rl, rs) = (dem.0 / ddem.0, dem.1 / ddem.1);
    let (want_l, want_s) = ((dem.2 / ddem.2).sqrt(), (dem.3 / ddem.3).sqrt());
    println!(
        "DEM/DDEM speeds: longitudinal {rl:.4} (√(E_DEM/E_DDEM) = {want_l:.4}; the thesis' peak-to-peak ratio 2.283/2.021 = 1.130), shear {rs:.4} (√(G_DEM/G_DDEM) = {want_s:.4}; the thesis' 3.591/3.543 = 1.0135)"
    );
    assert!(rl > 1.02 && rs > 1.02, "{rl} {rs}");
    assert!((rl / want_l - 1.0).abs() < 0.02, "{rl} vs {want_l}");
    assert!((rs / want_s - 1.0).abs() < 0.02, "{rs} vs {want_s}");
}
