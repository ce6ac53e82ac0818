//! Mesh input: Gmsh 4.1 ASCII written by gmsh itself (tests/data/*.msh, from the .geo files
//! next to them) and an Abaqus deck exported by gmsh plus hand-added sets; malformed files.
#![allow(
    clippy::neg_cmp_op_on_partial_ord,
    clippy::needless_range_loop,
    clippy::nonminimal_bool
)]

mod common;
use common::*;
use fem::{Mesh, Model};
use std::path::Path;

fn data(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

/// Uniaxial tension σ = 1 MPa along x on the 0.2 × 0.1 × 0.05 m box with symmetry supports:
/// u = (σx/E, −νσy/E, −νσz/E) exactly for any of our elements.
fn uniaxial_error(file: &str) -> (f64, Model) {
    let text = format!(
        r#"
[fem]
mesh = "{}"
{STEEL}
[[fem.supports]]
on = {{ plane = {{ axis = "x", value = 0.0 }} }}
fix = ["x"]
[[fem.supports]]
on = {{ plane = {{ axis = "y", value = 0.0 }} }}
fix = ["y"]
[[fem.supports]]
on = {{ plane = {{ axis = "z", value = 0.0 }} }}
fix = ["z"]
[[fem.loads]]
type = "pressure"
on = {{ plane = {{ axis = "x", value = 0.2 }} }}
value = -1e6
"#,
        data(file).display()
    );
    let cfg = config(&text);
    let mut m = Model::from_config(&cfg, Path::new("/")).unwrap_or_else(|e| panic!("{e}"));
    m.solve_static().unwrap();
    let (e, nu, s) = (210e9, 0.3, 1e6);
    let mut err: f64 = 0.0;
    for (n, x) in m.mesh().nodes.iter().enumerate() {
        let exact = [s * x[0] / e, -nu * s * x[1] / e, -nu * s * x[2] / e];
        for c in 0..3 {
            err = err.max((m.displacements()[3 * n + c] - exact[c]).abs());
        }
    }
    (err / (s * 0.2 / e), m)
}

#[test]
fn gmsh_tet10_file_reads_with_physical_groups_and_solves_exactly() {
    let mesh = Mesh::read(&data("box_tet10.msh")).unwrap();
    assert!(mesh.kinds.iter().all(|k| *k == fem::ElementKind::Tet10));
    for s in ["bottom", "top", "left"] {
        assert!(!mesh.node_sets[s].is_empty(), "{s}");
    }
    assert_eq!(mesh.elem_sets["body"].len(), mesh.num_elements());
    for &n in &mesh.node_sets["top"] {
        assert!((mesh.nodes[n as usize][2] - 0.05).abs() < 1e-12);
    }
    let (err, m) = uniaxial_error("box_tet10.msh");
    println!(
        "tet10 .msh: {} elements, relative error {err:.2e}",
        m.mesh().num_elements()
    );
    assert!(err < 1e-10);
}

#[test]
fn gmsh_hex20_file_solves_exactly() {
    let (err, m) = uniaxial_error("box_hex20.msh");
    assert_eq!(m.mesh().num_elements(), 8);
    assert!(m.mesh().kinds.iter().all(|k| *k == fem::ElementKind::Hex20));
    println!("hex20 .msh: relative error {err:.2e}");
    assert!(err < 1e-10);
}

#[test]
fn abaqus_deck_reads_sets_and_matches_gmsh_file() {
    let mesh = Mesh::read(&data("box_hex20.inp")).unwrap();
    assert_eq!(mesh.num_elements(), 8);
    // ELSETs of the CPS8 faces become node sets; GENERATE ranges expand
    assert_eq!(mesh.node_sets["left"].len(), 21);
    assert_eq!(mesh.node_set("first_nodes").unwrap().len(), 5);
    assert_eq!(mesh.elem_set("vol_gen").unwrap().len(), 8);
    for &n in &mesh.node_sets["right"] {
        assert!((mesh.nodes[n as usize][0] - 0.2).abs() < 1e-12);
    }
    let (err_inp, mi) = uniaxial_error("box_hex20.inp");
    let (_, mg) = uniaxial_error("box_hex20.msh");
    assert!(err_inp < 1e-10, "{err_inp:e}");
    let gi = mg.mesh().node_index_map();
    for (n, id) in mi.mesh().node_ids.iter().enumerate() {
        let g = gi[id] as usize;
        for c in 0..3 {
            assert!((mi.displacements()[3 * n + c] - mg.displacements()[3 * g + c]).abs() < 1e-18);
        }
    }
}

fn inp_error(text: &str) -> String {
    Mesh::parse(text, "inp", "deck.inp")
        .unwrap_err()
        .to_string()
}

const NODES: &str = "*NODE\n1, 0, 0, 0\n2, 1, 0, 0\n3, 0, 1, 0\n4, 0, 0, 1\n";

#[test]
fn malformed_abaqus_decks_name_file_line_and_problem() {
    let ok = format!("{NODES}*ELEMENT, TYPE=C3D4\n1, 1, 2, 3, 4\n");
    assert!(Mesh::parse(&ok, "inp", "deck.inp").is_ok());

    let e = inp_error(&format!(
        "{NODES}*ELEMENT, TYPE=C3D6\n1, 1, 2, 3, 4, 1, 2\n"
    ));
    assert!(
        e.starts_with("deck.inp:6:") && e.contains("unknown element type 'C3D6'"),
        "{e}"
    );

    let e = inp_error(&format!("{NODES}*ELEMENT, TYPE=C3D4\n1, 1, 2, 3, 9\n"));
    assert!(
        e.starts_with("deck.inp:7:") && e.contains("missing node 9"),
        "{e}"
    );

    let e = inp_error(&format!(
        "{NODES}3, 5, 5, 5\n*ELEMENT, TYPE=C3D4\n1, 1, 2, 3, 4\n"
    ));
    assert!(
        e.starts_with("deck.inp:6:") && e.contains("duplicate node id 3"),
        "{e}"
    );

    let e = inp_error(&format!(
        "{NODES}*ELEMENT, TYPE=C3D4\n1, 1, 2, 3, 4\n1, 2, 1, 3, 4\n"
    ));
    assert!(
        e.starts_with("deck.inp:8:") && e.contains("duplicate element id 1"),
        "{e}"
    );

    let e = inp_error(&format!("{NODES}*ELEMENT, TYPE=C3D4\n7, 2, 1, 3, 4\n"));
    assert!(
        e.starts_with("deck.inp:7:") && e.contains("element 7") && e.contains("inverted"),
        "{e}"
    );

    let e = inp_error(&format!(
        "{NODES}5, 1, 1, 0\n*ELEMENT, TYPE=C3D4\n8, 1, 2, 5, 3\n"
    ));
    assert!(
        e.starts_with("deck.inp:8:") && e.contains("degenerate"),
        "{e}"
    );

    let e = inp_error(&format!("{NODES}*ELEMENT, TYPE=C3D4\n1, 1, 2, 3\n"));
    assert!(
        e.contains("deck.inp:7:") && !e.contains("1 nodes given") && e.contains("3 nodes given"),
        "{e}"
    );

    let e = inp_error(&format!(
        "{NODES}*ELEMENT, TYPE=C3D4\n1, 1, 2, 3, 4\n*NSET, NSET=a, GENERATE\n1, 10\n"
    ));
    assert!(
        e.starts_with("deck.inp:9:") && e.contains("missing node 5"),
        "{e}"
    );
}

#[test]
fn malformed_gmsh_files_name_file_line_and_problem() {
    let good = std::fs::read_to_string(data("box_hex20.msh")).unwrap();
    assert!(Mesh::parse(&good, "msh", "box.msh").is_ok());
    let lines: Vec<&str> = good.lines().collect();
    let elem_hdr = lines.iter().position(|l| *l == "$Elements").unwrap();
    // first volume block: find "3 1 17 8"
    let blk = lines.iter().position(|l| l.starts_with("3 1 17 ")).unwrap();

    // unknown element type number
    let mut v = lines.clone();
    let bad = lines[blk].replace("3 1 17", "3 1 99");
    v[blk] = &bad;
    let e = Mesh::parse(&v.join("\n"), "msh", "box.msh")
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with(&format!("box.msh:{}:", blk + 1))
            && e.contains("unknown Gmsh element type 99"),
        "{e}"
    );

    // missing node in an element
    let mut v = lines.clone();
    let mut toks: Vec<String> = lines[blk + 1]
        .split_whitespace()
        .map(String::from)
        .collect();
    toks[3] = "100000".into();
    let bad = toks.join(" ");
    v[blk + 1] = &bad;
    let e = Mesh::parse(&v.join("\n"), "msh", "box.msh")
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with(&format!("box.msh:{}:", blk + 2)) && e.contains("missing node 100000"),
        "{e}"
    );

    // inverted element: mirror top and bottom (corners 0-3 ↔ 4-7 and, in Gmsh's edge order,
    // the mid-side nodes 8↔16, 9↔17, 11↔18, 13↔19)
    let mut v = lines.clone();
    let toks: Vec<&str> = lines[blk + 1].split_whitespace().collect();
    let mut perm: Vec<usize> = (0..20).collect();
    for (a, b) in [
        (0, 4),
        (1, 5),
        (2, 6),
        (3, 7),
        (8, 16),
        (9, 17),
        (11, 18),
        (13, 19),
    ] {
        perm.swap(a, b);
    }
    let mut sw: Vec<&str> = vec![toks[0]];
    sw.extend(perm.iter().map(|&k| toks[1 + k]));
    let bad = sw.join(" ");
    v[blk + 1] = &bad;
    let e = Mesh::parse(&v.join("\n"), "msh", "box.msh")
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with(&format!("box.msh:{}:", blk + 2)) && e.contains("inverted"),
        "{e}"
    );

    // truncated file
    let e = Mesh::parse(&lines[..elem_hdr + 3].join("\n"), "msh", "box.msh")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("box.msh:") && e.contains("unexpected end of file"),
        "{e}"
    );

    // binary / old format
    let e = Mesh::parse("$MeshFormat\n2.2 0 8\n$EndMeshFormat\n", "msh", "old.msh")
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("old.msh:2:") && e.contains("version 4.1"),
        "{e}"
    );
}

/// Mesh files resolve relative to the scene directory; a missing file names the path.
#[test]
fn missing_mesh_file_is_named() {
    let cfg = config(&format!("[fem]\nmesh = \"nope/beam.inp\"\n{STEEL}"));
    let e = Model::from_config(&cfg, Path::new("/tmp"))
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("/tmp/nope/beam.inp"), "{e}");
}
