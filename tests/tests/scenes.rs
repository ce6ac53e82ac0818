//! Every shipped scene passes `cosim check` (real nodes read their tables, build their models
//! and report their limits), except the sleeper's later steps, which must name the bed file
//! the step before writes when it has not been run yet (sleeper-compact.toml reads
//! sleeper-bed's, sleeper.toml sleeper-compact's; the same for the -poly chain, the
//! triaxial cells' membrane steps, the triaxial cube's models and the pile). (plate-python.toml needs the Python node's
//! packages and is run by python_node.rs.)

use cosim_tests::{cosim, root, run};

#[test]
fn every_shipped_scene_checks() {
    let mut names: Vec<String> = std::fs::read_dir(root().join("scenes"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().to_string())
        // a running `cosim study` keeps its variants beside the scene as hidden files
        .filter(|n| n.ends_with(".toml") && !n.starts_with('.'))
        // needs the Python node's packages: tests/tests/python_node.rs covers it
        .filter(|n| n != "plate-python.toml")
        .collect();
    names.sort();
    assert!(names.len() >= 10, "{names:?}");
    // scenes that read what an earlier run wrote, and the field that names the file
    let needs = |name: &str| match name {
        "sleeper-compact.toml" => Some((
            "out/sleeper-bed/dem/particles_final.csv",
            "dem.particles[0].path",
        )),
        "sleeper.toml" => Some((
            "out/sleeper-compact/dem/particles_final.csv",
            "dem.particles[0].path",
        )),
        "sleeper-compact-poly.toml" => Some((
            "out/sleeper-bed-poly/dem/particles_final.csv",
            "dem.particles[0].path",
        )),
        "sleeper-poly.toml" | "sleeper-poly-window.toml" => Some((
            "out/sleeper-compact-poly/dem/particles_final.csv",
            "dem.particles[0].path",
        )),
        "ddem-irregular.toml"
        | "ddem-uniaxial.toml"
        | "ddem-uniaxial-dem.toml"
        | "ddem-biaxial.toml"
        | "ddem-shear.toml" => Some(("out/ddem-pack/dem/discs_final.csv", "dem.discs[0].path")),
        "triaxial-membrane-ci.toml" => Some((
            "out/triaxial-membrane-prep-ci/dem/particles_final.csv",
            "dem.particles[0].path",
        )),
        "triaxial-cube-de-ci.toml" | "triaxial-cube-dfl-ci.toml" => Some((
            "out/triaxial-cube-pack-ci/dem/particles_final.csv",
            "dem.particles[0].path",
        )),
        "pile-ci.toml" => Some((
            "out/pile-pack-ci/dem/particles_final.csv",
            "dem.particles[0].path",
        )),
        "pile.toml" => Some((
            "out/pile-pack/dem/particles_final.csv",
            "dem.particles[0].path",
        )),
        "triaxial-membrane.toml" | "triaxial-membrane-400.toml" => Some((
            "out/triaxial-membrane-prep/dem/particles_final.csv",
            "dem.particles[0].path",
        )),
        "ddem-wave.toml" | "ddem-shear-wave.toml" => Some((
            "out/ddem-wave-pack/dem/discs_final.csv",
            "dem.discs[0].path",
        )),
        _ => None,
    };
    for name in names {
        let mut c = cosim();
        c.arg("check").arg(format!("scenes/{name}"));
        let o = run(c);
        let stdout = String::from_utf8_lossy(&o.stdout);
        let stderr = String::from_utf8_lossy(&o.stderr);
        if let Some((bed, field)) = needs(&name).filter(|b| !root().join(b.0).exists()) {
            assert!(!o.status.success(), "{name}");
            let dir = bed.split('/').nth(1).unwrap();
            let file = bed.rsplit('/').next().unwrap();
            assert!(
                stderr.contains(dir) && stderr.contains(file) && stderr.contains(field),
                "{name}: {stderr}"
            );
            continue;
        }
        assert!(o.status.success(), "{name}: {stderr}");
        assert!(stdout.contains(": ok ("), "{name}: {stdout}");
    }
}
