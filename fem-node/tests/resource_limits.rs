//! Counts and sizes from a scene are checked before anything is allocated: a generated box
//! or a mesh file that needs more memory than the machine has is a scene error naming the
//! field, the estimate and the memory available — not an abort in the allocator. Also the
//! probe points outside the body, the fields that had no range check, and file errors
//! without a line. Through the scene parser (`parse_scene_section`) and `Model::from_config`
//! on real files.

use fem::Model;

const BEAM: &str = r#"[fem]
mesh = { size = [1.0, 0.1, 0.1], element_size = 0.05, element = "hex8" }
analysis = "static"

[fem.material]
youngs_modulus = 210e9
poisson_ratio = 0.3
density = 7800.0

[[fem.supports]]
on = { set = "xmin" }
"#;

fn error_of(text: &str) -> fem::config::SceneError {
    let err = fem::parse_scene_section(text).expect_err("the scene must be refused");
    println!("{err}");
    err
}

fn line_of(text: &str, prefix: &str) -> usize {
    text.lines().position(|l| l.starts_with(prefix)).unwrap() + 1
}

#[test]
fn a_box_of_1e15_elements_is_refused_naming_the_field_and_the_memory() {
    let text = BEAM.replace(
        "element_size = 0.05, element = \"hex8\"",
        "divisions = [100000, 100000, 100000], element = \"hex8\"",
    );
    let err = error_of(&text);
    assert!(err.message.starts_with("fem.mesh.divisions: "), "{err}");
    // more than u32::MAX grid points: refused before the memory is even estimated
    assert!(err.message.contains("grid points"), "{err}");
    assert_eq!(err.line, line_of(&text, "mesh"), "{err}");

    // 1000³ = 1e9 hex8 elements with 1001³ nodes fit the 32-bit indices but not the memory:
    // 1.003e9 nodes × 16 kB + 1e9 elements × 300 B
    let text = BEAM.replace(
        "element_size = 0.05, element = \"hex8\"",
        "divisions = [1000, 1000, 1000], element = \"hex8\"",
    );
    let err = error_of(&text);
    assert!(
        err.message
            .starts_with("fem.mesh.divisions: the generated box"),
        "{err}"
    );
    assert!(
        err.message.contains("1e9 hex8 elements, 1.003e9 nodes"),
        "{err}"
    );
    assert!(err.message.contains("needs ≈ 16 TB"), "{err}");
    assert!(err.message.contains("available on this machine"), "{err}");
}

#[test]
fn a_tiny_element_size_is_refused_naming_the_field() {
    for h in ["1e-6", "1e-300"] {
        let text = BEAM.replace("element_size = 0.05", &format!("element_size = {h}"));
        let err = error_of(&text);
        assert!(err.message.starts_with("fem.mesh.element_size: "), "{err}");
        assert_eq!(err.line, line_of(&text, "mesh"), "{err}");
    }
}

#[test]
fn divisions_whose_product_overflows_are_refused() {
    let text = BEAM.replace(
        "element_size = 0.05, element = \"hex8\"",
        "divisions = [4000000000, 4000000000, 4000000000], element = \"tet4\"",
    );
    let err = error_of(&text);
    assert!(
        err.message.starts_with("fem.mesh.divisions: ") && err.message.contains("overflows"),
        "{err}"
    );
}

#[test]
fn a_generate_range_longer_than_the_mesh_ends_at_its_first_missing_id() {
    let dir = tempfile::tempdir().unwrap();
    let deck = "*NODE\n1, 0, 0, 0\n2, 1, 0, 0\n3, 0, 1, 0\n4, 0, 0, 1\n\
                *ELEMENT, TYPE=C3D4\n1, 1, 2, 3, 4\n\
                *NSET, NSET=ALL, GENERATE\n1, 1000000000000000, 1\n";
    std::fs::write(dir.path().join("tet.inp"), deck).unwrap();
    let text = BEAM.replace(
        "mesh = { size = [1.0, 0.1, 0.1], element_size = 0.05, element = \"hex8\" }",
        "mesh = \"tet.inp\"",
    );
    let cfg = fem::parse_scene_section(&text).unwrap().unwrap();
    let err = Model::from_config(&cfg, dir.path())
        .err()
        .expect("refused")
        .to_string();
    println!("{err}");
    assert!(err.contains("tet.inp:9: "), "{err}");
    // the range's ids are not collected first: the first missing one ends it
    assert!(err.contains("*NSET ALL references missing node 5"), "{err}");
}

#[test]
fn a_gmsh_node_count_larger_than_the_file_does_not_reach_the_allocator() {
    let dir = tempfile::tempdir().unwrap();
    let msh =
        "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 1000000000000000 1 1000000000000000\n\
               3 1 0 1000000000000000\n1\n";
    std::fs::write(dir.path().join("big.msh"), msh).unwrap();
    let err = fem::Mesh::read(&dir.path().join("big.msh"))
        .expect_err("refused")
        .to_string();
    println!("{err}");
    assert!(err.contains("big.msh:"), "{err}");
}

#[test]
fn a_file_error_without_a_line_does_not_print_line_0() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("part.stl"), "solid x\nendsolid x\n").unwrap();
    let err = fem::Mesh::read(&dir.path().join("part.stl"))
        .expect_err("refused")
        .to_string();
    println!("{err}");
    assert!(err.contains("part.stl: unknown mesh format"), "{err}");
    assert!(!err.contains(":0"), "{err}");
}

fn probe_scene(point: &str) -> String {
    format!("{BEAM}\n[[fem.probes]]\nname = \"tip\"\npoint = {point}\n")
}

fn model_error(text: &str) -> String {
    let cfg = fem::parse_scene_section(text).unwrap().unwrap();
    let err = Model::from_config(&cfg, std::path::Path::new("."))
        .err()
        .expect("refused")
        .to_string();
    println!("{err}");
    err
}

#[test]
fn a_probe_point_far_outside_the_body_is_refused_naming_the_nearest_node() {
    let err = model_error(&probe_scene("[2.0, 0.05, 0.05]"));
    assert!(
        err.contains("fem.probes[0] 'tip': point [2, 0.05, 0.05] lies outside the body"),
        "{err}"
    );
    // the nearest node is on the end face x = 1, 1 m away
    assert!(err.contains("at [1, 0.05, 0.05], 1 m away"), "{err}");
}

#[test]
fn probe_points_in_the_body_or_on_its_surface_are_accepted() {
    for point in [
        "[0.5, 0.05, 0.05]",     // a node
        "[0.512, 0.031, 0.077]", // inside an element, off the nodes
        "[1.0001, 0.05, 0.1]",   // on the end face, written with round-off (0.2 % of h)
    ] {
        let cfg = fem::parse_scene_section(&probe_scene(point))
            .unwrap()
            .unwrap();
        Model::from_config(&cfg, std::path::Path::new("."))
            .unwrap_or_else(|e| panic!("{point}: {e}"));
    }
    // 10 % of the element's diagonal off the top face: refused
    let err = model_error(&probe_scene("[0.5, 0.05, 0.109]"));
    assert!(err.contains("lies outside the body"), "{err}");
}

#[test]
fn fields_without_range_checks_are_checked_now() {
    let cases = [
        (
            probe_scene("[nan, 0.0, 0.0]"),
            "fem.probes[0].point: must be finite",
        ),
        (
            BEAM.replace(
                "on = { set = \"xmin\" }",
                "on = { plane = { axis = \"x\", value = inf } }",
            ),
            "fem.supports[0].on.plane.value: must be finite",
        ),
        (
            BEAM.replace(
                "on = { set = \"xmin\" }",
                "on = { plane = { axis = \"x\", value = 0.0, tol = inf } }",
            ),
            "fem.supports[0].on.plane.tol: must be finite",
        ),
    ];
    for (text, expected) in &cases {
        let err = error_of(text);
        assert!(
            err.message.contains(expected),
            "expected `{expected}` in: {err}"
        );
    }
}

#[test]
fn every_shipped_scene_still_passes_the_checks_and_builds() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    let mut built = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|x| x != "toml") {
            continue;
        }
        let text = std::fs::read_to_string(&path).unwrap();
        let cfg =
            fem::parse_scene_section(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        if let Some(cfg) = cfg {
            // the probes' points, the mesh's size: the structure (volume or shells) builds
            fem::build(&cfg, &dir).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            built += 1;
        }
    }
    assert!(built >= 8, "only {built} scenes with [fem]");
}
