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
    // summary.json reports the programme's end — the last window-end state inside the shear,
    // not the held cell after it (which relaxes) — and the held ratio beside it
    let reported = s["results"]["dem.cell.stress_ratio"].as_f64().unwrap();
    // (the CSV prints 13 significant digits)
    assert!(
        (reported - ratio[last]).abs() <= 1e-11 * ratio[last].abs(),
        "reported {reported}, the last shear row's ratio {}",
        ratio[last]
    );
    assert!(
        s["results"]["dem.cell.held_stress_ratio"]
            .as_f64()
            .is_some(),
        "{s}"
    );
    assert_eq!(s["results"]["dem.cell.programme_finished"], 1.0);
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
    // `--modulus secant50 --out` into a folder that does not exist yet: made, the table and
    // its plots in it; E is E50 (the secant to half the peak deviator, below the initial
    // tangent of a hardening curve), every other value as in the default table
    let elsewhere = out.join("fits").join("dense");
    let mut c = cosim();
    c.arg("fit")
        .arg(&out)
        .args(["--modulus", "secant50", "--out"])
        .arg(elsewhere.join("sand.toml"));
    let o = run(c);
    assert!(o.status.success());
    let text = std::fs::read_to_string(elsewhere.join("sand.toml")).unwrap();
    assert!(text.contains("# E is E50"), "{text}");
    assert!(elsewhere.join("sand_stress_ratio.png").exists());
    let secant: toml::Table = toml::from_str(&text).unwrap();
    let s = &secant["fem"]["materials"]["sand"];
    let e50 = s["youngs_modulus"].as_float().unwrap();
    let tangent = get("youngs_modulus");
    assert!(
        e50 > 0.2 * tangent && e50 < tangent,
        "E50 {e50} against the tangent {tangent}"
    );
    for k in [
        "poisson_ratio",
        "friction_angle",
        "dilation_angle",
        "cohesion",
        "density",
    ] {
        assert_eq!(s[k].as_float(), m[k].as_float(), "{k}");
    }

    // the fitted single element (scenes/rve-triaxial-element.toml) through the same drained
    // test in the FEM, with this fit and this run's lateral stress
    let lateral = -shear.iter().map(|&k| sxx[k]).sum::<f64>() / shear.len() as f64;
    let template =
        std::fs::read_to_string(root().join("scenes/rve-triaxial-element.toml")).unwrap();
    let cut = template.find("# the fit of out/rve-triaxial").unwrap();
    let (e_mod, nu, c) = (get("youngs_modulus"), nu, get("cohesion"));
    // the axial face follows the isotropic elastic strain while the lateral stress comes on
    let u_iso = -0.01 * lateral * (1.0 - 2.0 * nu) / e_mod;
    let scene = template[..cut]
        .replace("value = 25e3", &format!("value = {lateral:e}"))
        .replace(
            "points = [[0.0, 0.0], [0.001, -2.958333e-6], [0.021, -2.002958333e-3]]",
            &format!(
                "points = [[0.0, 0.0], [0.001, {u_iso:e}], [0.021, {:e}]]",
                u_iso - 0.002
            ),
        )
        + &std::fs::read_to_string(out.join("mohr_coulomb.toml")).unwrap();
    assert!(
        scene.contains(&format!("{u_iso:e}")),
        "the template's history changed"
    );
    let s = run_scene(&dir, "element.toml", &scene);
    assert_eq!(s["status"], "completed", "{s}");
    let probes = std::fs::read_to_string(dir.join("out-element.toml/fem/fem_probes.csv")).unwrap();
    let time = column(&probes, "time");
    let (ux, uy, uz) = (
        column(&probes, "probe.corner.ux"),
        column(&probes, "probe.corner.uy"),
        column(&probes, "probe.corner.uz"),
    );
    let rz = column(&probes, "reaction.top.z");
    let l = 0.01;
    let start = time.iter().position(|t| (t - 1e-3).abs() < 1e-9).unwrap();
    let ev = |k: usize| -(ux[k] + uy[k] + uz[k]) / l; // compaction positive
                                                      // the closed form of the fitted element (W §5.4): σa from p with E to N_φ p + 2c√N_φ,
                                                      // then perfectly plastic, dilating at 2 sin ψ / (1 − sin ψ)
    let (sp, spsi) = (
        phi_fit.to_radians().sin(),
        get("dilation_angle").to_radians().sin(),
    );
    let n_phi = (1.0 + sp) / (1.0 - sp);
    let yield_sa = lateral * n_phi + 2.0 * c * n_phi.sqrt();
    let sa0 = lateral;
    let e_yield = (yield_sa - sa0) / e_mod;
    let rate = 2.0 * spsi / (1.0 - spsi);
    let (mut worst_sa, mut worst_ev) = (0.0f64, 0.0f64);
    for k in start..time.len() {
        let e = -(uz[k] - uz[start]) / l;
        let (sa, dv) = if e <= e_yield {
            (sa0 + e_mod * e, (1.0 - 2.0 * nu) * e)
        } else {
            (yield_sa, (1.0 - 2.0 * nu) * e_yield - rate * (e - e_yield))
        };
        worst_sa = worst_sa.max((-rz[k] / (l * l) / sa - 1.0).abs());
        worst_ev = worst_ev.max((ev(k) - ev(start) - dv).abs());
    }
    let last = time.len() - 1;
    let element_ratio = -rz[last] / (l * l) / lateral;
    eprintln!(
        "fitted element: σa/σl {element_ratio:.4} (RVE peak {:.4}), dilation rate {:.4} (fit {rate:.4}); against the closed form: σa within {worst_sa:.1e}, εV within {worst_ev:.1e}",
        ratio[peak],
        (ev(last - 20) - ev(last)) / (uz[last - 20] - uz[last]) * l,
    );
    assert!(worst_sa < 1e-8 && worst_ev < 1e-8, "{worst_sa} {worst_ev}");
    // it carries the RVE's peak ratio (the fit's φ) and dilates at the fitted rate
    assert!(
        (element_ratio / ratio[peak] - 1.0).abs() < 0.05,
        "{element_ratio}"
    );
    let element_rate = (ev(last - 20) - ev(last)) / (uz[last - 20] - uz[last]) * l;
    assert!(
        (element_rate / rate - 1.0).abs() < 1e-3,
        "{element_rate} vs {rate}"
    );
}
