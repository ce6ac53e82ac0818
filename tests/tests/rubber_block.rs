//! Wellmann §4.3.3 at CI size (`scenes/rubber-block.toml`): a two-material rubber block
//! (Neo-Hooke tread, Mooney–Rivlin body: issue 17's materials per element set) pressed onto a
//! granular bed with 250 kPa and dragged at 8.33 m/s by a moving support, two-way coupled
//! through `cosim run` (real dem-node and fem-node processes over zenoh, Bossak with Newton
//! iterations on the FEM side).

use cosim_tests::{root, run_scene};

#[test]
fn rubber_block_is_pressed_and_dragged_over_the_bed() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(root().join("scenes/rubber-block.toml")).unwrap();
    let s = run_scene(dir.path(), "rubber-block.toml", &text);
    assert_eq!(s["status"], "completed", "{s}");
    let r = &s["results"];
    let f = |k: &str| {
        r[format!("fem.{k}")]
            .as_f64()
            .unwrap_or_else(|| panic!("fem.{k} in {r}"))
    };
    let (fx, fz) = (f("interface_force.x"), f("interface_force.z"));
    let (ux, uz) = (f("probe.front_bottom.ux"), f("probe.front_bottom.uz"));
    let contacts = r["dem.wall_contacts"].as_f64().unwrap();
    eprintln!(
        "grains on the block {contacts}; force of the bed on the block: x {fx:.2} N, z {fz:.2} N \
         (pressure 250 kPa × 200 mm² = 50 N); front bottom corner moved {:.2} mm forward, {:.2} \
         mm down; largest von Mises stress {:.2} MPa",
        ux * 1e3,
        -uz * 1e3,
        f("stress_von_mises.block") / 1e6
    );
    assert!(contacts > 50.0, "the block rests on grains: {contacts}");
    // the bed carries the pressure (dynamically: within a factor of two) ...
    assert!(fz > 25.0 && fz < 100.0, "{fz}");
    // ... and resists the drag, at most with the DE–FE friction coefficient 1
    assert!(fx < -1.0 && -fx < 1.0 * fz, "{fx}");
    // the block follows its top (12.5 mm), shearing: its front corner lags and digs in
    assert!(ux > 5e-3 && ux < 12.5e-3, "{ux}");
    assert!(uz < 0.0, "{uz}");
    // the VTU series shows both materials
    let out = dir.path().join("out-rubber-block.toml");
    let pvd = std::fs::read_to_string(out.join("fem/fem.pvd")).unwrap();
    let last = pvd
        .rsplit("file=\"")
        .next()
        .unwrap()
        .split('"')
        .next()
        .unwrap();
    let vtu = std::fs::read_to_string(out.join("fem").join(last)).unwrap();
    let at = vtu.find("Name=\"material\"").expect("material array");
    let body = &vtu[at..];
    let values: Vec<f64> = body[body.find('>').unwrap() + 1..body.find("</DataArray>").unwrap()]
        .split_whitespace()
        .map(|v| v.parse().unwrap())
        .collect();
    assert!(
        values.contains(&0.0) && values.contains(&1.0),
        "two materials: {values:?}"
    );
}

/// The same block on a bed of 800 superquadric grains (ε in Wellmann's [0.6, 1.2], elongated up
/// to 1.3, random orientations) poured by random addition — loose (solid fraction ≈ 0.35),
/// unlike the lattice: the block sinks deeper and the drag resistance is smaller, and the run
/// goes through the superquadric–mesh contacts of the coupled surface.
#[test]
fn rubber_block_on_superquadric_grains() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(root().join("scenes/rubber-block.toml")).unwrap();
    let start = text.find("[[dem.particles]]").unwrap();
    let end = text.find("[fem]").unwrap();
    let text = format!(
        "{}[[dem.particles]]\nkind = \"fill\"\nmaterial = \"sand\"\nmin = [0.0, 0.0, 0.0]\n\
         max = [0.06, 0.02, 0.008]\ncount = 800\n\
         distribution = {{ kind = \"uniform\", min = 0.8e-3, max = 1.0e-3 }}\n\
         shape = {{ kind = \"superquadric\", elongation = 1.3, exponent_range = [0.6, 1.2] }}\n\n{}",
        &text[..start],
        &text[end..]
    );
    let s = run_scene(dir.path(), "rubber-block-sq.toml", &text);
    assert_eq!(s["status"], "completed", "{s}");
    let r = &s["results"];
    let f = |k: &str| r[k].as_f64().unwrap_or_else(|| panic!("{k} in {r}"));
    let (fx, fz) = (f("fem.interface_force.x"), f("fem.interface_force.z"));
    let (ux, uz) = (
        f("fem.probe.front_bottom.ux"),
        f("fem.probe.front_bottom.uz"),
    );
    eprintln!(
        "superquadric grains on the block {}; bed force x {fx:.2} N, z {fz:.2} N; front corner \
         {:.2} mm forward, {:.2} mm down",
        f("dem.wall_contacts"),
        ux * 1e3,
        -uz * 1e3
    );
    assert!(f("dem.wall_contacts") > 20.0);
    assert!(fz > 25.0 && fz < 100.0, "{fz}");
    assert!(fx < 0.0 && -fx < fz, "{fx}");
    assert!(ux > 5e-3 && uz < 0.0, "{ux} {uz}");
}
