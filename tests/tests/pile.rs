//! Wellmann's plane-strain flat pile (ch. 6.4.3, SEED-SPEC §4.5) at CI size over the real path
//! (cosim with dem-node and fem-node processes exchanging a volume interface over zenoh):
//! scenes/pile-pack-ci.toml settles the sand of the pile's vicinity, scenes/pile-ci.toml drives
//! a flat pile 5 mm into it while a Mohr–Coulomb continuum with a carved pocket models the rest
//! of the box. `PILE_DIR=<dir>` keeps the outputs.

use cosim_tests::*;
use std::path::{Path, PathBuf};

const PACKING: &str = "../out/pile-pack-ci/dem/particles_final.csv";
/// The box of the continuum (x, y, z extents, m), the grains' region (pocket and overlap) and
/// the grains' density (kg/m³).
const BOX: [f64; 3] = [0.04, 0.003, 0.04];
const GRAINS: [f64; 3] = [0.03, 0.003, 0.0395 - 0.0125];
const RHO: f64 = 2650.0;

fn out_dir(tmp: &tempfile::TempDir) -> PathBuf {
    let dir = std::env::var("PILE_DIR").map_or(tmp.path().to_path_buf(), Into::into);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// (x, z, radius) of each grain of a particle file, in file order (= particle id order).
fn grains(path: &Path) -> Vec<[f64; 3]> {
    let text = std::fs::read_to_string(path).unwrap();
    let (x, z, r) = (
        csv_f64(&text, "x"),
        csv_f64(&text, "z"),
        csv_f64(&text, "radius"),
    );
    (0..x.len()).map(|i| [x[i], z[i], r[i]]).collect()
}

/// The pile: the grains beside it rise, those under it are carried down, the continuum
/// carries the load the grains hand it (its base reaction is its own weighted weight plus the
/// penalty forces the grains exert), no coupled grain leaves its element (the run would stop),
/// and the coordination stays a small share of the wall time. Prints what the test measured:
/// the pile force, the displacement field's zones, the coupling share and the particle count
/// a pure-DE model of the whole box would need.
#[test]
fn flat_pile_driven_into_grains_coupled_to_a_continuum() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = out_dir(&tmp);
    let text = std::fs::read_to_string(root().join("scenes/pile-pack-ci.toml")).unwrap();
    let s = run_scene(&dir, "pack.toml", &text);
    assert_eq!(s["status"], "completed", "{s}");
    let packing = dir.join("out-pack.toml/dem/particles_final.csv");
    let text = std::fs::read_to_string(root().join("scenes/pile-ci.toml")).unwrap();
    assert!(text.contains(PACKING) && text.contains("vtk_every = 0"));
    let text = text
        .replace(PACKING, packing.to_str().unwrap())
        .replace("vtk_every = 0", "vtk_every = 0\nfinal_particles = true");
    let s = run_scene(&dir, "pile.toml", &text);
    assert_eq!(s["status"], "completed", "{s}");
    let r = |k: &str| -> f64 {
        s["results"][k]
            .as_f64()
            .unwrap_or_else(|| panic!("no result {k}"))
    };
    let out = dir.join("out-pile.toml");

    // the grains the pile run started with (the packing below 39.5 mm, in id order) and
    // where they ended
    let start: Vec<[f64; 3]> = grains(&packing)
        .into_iter()
        .filter(|g| g[1] <= 0.0395)
        .collect();
    let end = grains(&out.join("dem/particles_final.csv"));
    assert_eq!(start.len(), end.len());
    let mean_dz = |sel: &dyn Fn(&[f64; 3]) -> bool| -> (f64, usize) {
        let v: Vec<f64> = (start.iter().zip(&end))
            .filter(|(a, _)| sel(a))
            .map(|(a, b)| b[1] - a[1])
            .collect();
        (v.iter().sum::<f64>() / v.len() as f64, v.len())
    };
    // carried down: the grains in the pile's path, within 3 mm below the surface
    let (down, n_down) = mean_dz(&|g| g[0].abs() < 0.0025 && g[1] > 0.0365);
    // heave: the surface grains one to three pile widths from the axis
    let (heave, n_heave) = mean_dz(&|g| (0.005..0.015).contains(&g[0].abs()) && g[1] > 0.037);
    // far below the tip (the tip ends at 35.1 mm): nearly still
    let (deep, n_deep) = mean_dz(&|g| g[1] < 0.02);
    let pile = r("dem.pile.force_z");
    let penalty = -r("dem.volume.sand.penalty_force_z");
    let base = r("fem.reaction.base.z");
    let t = &s["timing"];
    let share = t["coupling_overhead_fraction"].as_f64().unwrap();
    // a pure-DE model of the whole box at the packing's number density
    let density = start.len() as f64 / (GRAINS[0] * GRAINS[1] * GRAINS[2]);
    let pure_de = density * BOX[0] * BOX[1] * BOX[2];
    let mass: f64 = start
        .iter()
        .map(|g| RHO * 4.0 / 3.0 * std::f64::consts::PI * g[2].powi(3))
        .sum();
    eprintln!(
        "pile: {} grains ({} coupled), force at 5 mm {pile:.4} N; grains in its path moved \
         {:+.3} mm ({n_down}), beside it the surface {:+.3} mm ({n_heave}), deep grains {:+.4} \
         mm ({n_deep}); penalty {penalty:.4} N on the continuum, base reaction {base:.4} N, \
         grains' weight {:.4} N; coordination {:.1} % of the wall time ({:.1} s DEM, {:.1} s FEM); \
         a pure-DE box would need {pure_de:.0} grains ({:.1} ×)",
        start.len(),
        r("dem.volume.sand.coupled_particles"),
        down * 1e3,
        heave * 1e3,
        deep * 1e3,
        mass * 9.81,
        share * 100.0,
        t["dem_compute_s"].as_f64().unwrap(),
        t["fem_compute_s"].as_f64().unwrap(),
        pure_de / start.len() as f64,
    );
    assert!(n_down > 5 && n_heave > 20 && n_deep > 100);
    assert!(
        down < -1e-3,
        "grains in the pile's path carried down {down}"
    );
    assert!(heave > 2e-4, "surface beside the pile heaves {heave}");
    assert!(deep.abs() < 1e-4, "deep grains nearly still {deep}");
    assert!(pile > 0.0, "the sand resists the pile: {pile}");
    // the continuum's base carries the penalty forces plus its own (1 − w)-weighted weight,
    // which lies between nothing and the whole box's continuum weight
    let continuum = base - penalty;
    let box_weight = 1600.0 * 9.81 * BOX[0] * BOX[1] * BOX[2];
    assert!(
        continuum > 0.5 * box_weight * 0.5 && continuum < box_weight,
        "continuum's own weight {continuum} N (box {box_weight} N)"
    );
    assert!(share < 0.1, "coordination share {share}");
}
