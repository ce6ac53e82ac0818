//! Wellmann's periodic RVE (ch. 5) at CI size over the real path: `cosim run
//! scenes/rve-triaxial-ci.toml` (a dem-node process, the coordinator ending the run when the
//! cell's programme is done), then `cosim fit` on its output. `RVE_DIR=<dir>` keeps the
//! outputs.

use cosim_tests::*;

fn column(text: &str, name: &str) -> Vec<f64> {
    csv_column(text, name)
        .iter()
        .map(|v| v.parse().unwrap())
        .collect()
}

#[test]
fn an_rve_of_superquadric_sand_consolidates_shears_and_fits_a_mohr_coulomb_material() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = std::env::var("RVE_DIR").map_or(tmp.path().to_path_buf(), Into::into);
    std::fs::create_dir_all(&dir).unwrap();
    let text = std::fs::read_to_string(root().join("scenes/rve-triaxial-ci.toml")).unwrap();
    let s = run_scene(&dir, "rve.toml", &text);
    assert_eq!(s["status"], "completed", "{s}");
    let out = dir.join("out-rve.toml");
    let windows = std::fs::read_to_string(out.join("windows.csv")).unwrap();
    let t_end = *column(&windows, "t_end_s").last().unwrap();
    eprintln!("the programme ended the run at t = {t_end:.4} s (end_time 0.3 s)");
    assert!(t_end < 0.25, "the run went on to {t_end} s");

    let curves = std::fs::read_to_string(out.join("dem/periodic.csv")).unwrap();
    let stage = column(&curves, "stage");
    let phi = column(&curves, "solid_fraction");
    let ratio = column(&curves, "stress_ratio");
    let ez = column(&curves, "stage_strain_z");
    let ev = column(&curves, "stage_volumetric_strain");
    let sxx = column(&curves, "stress_xx");
    // consolidated at 1 kPa without friction: W Fig. 5.4's Φ_max = 0.722 at μ_gen = 0
    let consolidated = stage.iter().position(|&s| s == 2.0).unwrap();
    let phi_max = phi[consolidated];
    eprintln!("Φ at 1 kPa with μ_gen = 0: {phi_max:.4} (W: 0.722)");
    assert!((phi_max - 0.722).abs() < 0.02, "Φ = {phi_max}");
    // the shear: stage 3
    let shear: Vec<usize> = (0..stage.len()).filter(|&k| stage[k] == 3.0).collect();
    let (first, last) = (shear[0], *shear.last().unwrap());
    let peak = shear
        .iter()
        .copied()
        .max_by(|&a, &b| ratio[a].total_cmp(&ratio[b]))
        .unwrap();
    eprintln!(
        "shear: peak σ1/σ3 {:.3} at {:.2} % axial strain, {:.3} at {:.2} %; volumetric strain \
         {:.4} at the end, lateral stress {:.0} Pa",
        ratio[peak],
        -100.0 * ez[peak],
        ratio[last],
        -100.0 * ez[last],
        ev[last],
        sxx[last]
    );
    assert!(
        ez[last] <= -0.095 && ez[first] > -0.01,
        "{} … {}",
        ez[first],
        ez[last]
    );
    assert!(ratio[peak] > 2.0, "peak ratio {}", ratio[peak]);
    // a dense packing dilates: the volume grows after the peak
    assert!(ev[last] > ev[peak] + 0.005, "{} → {}", ev[peak], ev[last]);

    // the Mohr–Coulomb fit of the curve
    let mut c = cosim();
    c.arg("fit").arg(&out);
    let o = run(c);
    assert!(o.status.success());
    let table: toml::Table =
        toml::from_str(&std::fs::read_to_string(out.join("mohr_coulomb.toml")).unwrap()).unwrap();
    let m = &table["fem"]["materials"]["sand"];
    let get = |k: &str| m[k].as_float().unwrap();
    eprintln!("fit: {m}");
    assert_eq!(m["model"].as_str(), Some("mohr_coulomb"));
    let phi_fit = get("friction_angle");
    // (1 + sin φ)/(1 − sin φ) is the peak ratio (c = 15 Pa is negligible at 10 kPa; the fit
    // takes the row of the largest axial stress and the lateral stress of that row)
    let sin = phi_fit.to_radians().sin();
    assert!(
        ((1.0 + sin) / (1.0 - sin) / ratio[peak] - 1.0).abs() < 0.05,
        "φ = {phi_fit}° for a peak ratio {}",
        ratio[peak]
    );
    assert!(get("dilation_angle") > 0.0 && get("dilation_angle") < phi_fit);
    assert!(get("youngs_modulus") > 0.0);
    let nu = get("poisson_ratio");
    assert!(nu > 0.0 && nu < 0.5, "ν = {nu}");
    let rho = get("density");
    assert!(
        (rho / (2650.0 * phi[first]) - 1.0).abs() < 1e-3,
        "ρ = {rho}"
    );
    for png in [
        "mohr_coulomb_stress_ratio.png",
        "mohr_coulomb_volumetric_strain.png",
    ] {
        assert!(out.join(png).metadata().unwrap().len() > 1000, "{png}");
    }
}
