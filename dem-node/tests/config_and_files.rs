//! Scene parsing errors (line, column, field) and STL reading.
use dem::{parse_scene_section, Engine};

const GOOD: &str = r#"[scene]
name = "test"
[fem]
mesh = "beam.msh"

[dem]
time_step = 1e-5
[dem.materials.wheat]
youngs_modulus = 1e8
poisson_ratio = 0.3
density = 1242.0
restitution = 0.4
friction = 1.0
[[dem.particles]]
kind = "lattice"
material = "wheat"
radius = 0.002
first = [0.0, 0.0, 0.0]
spacing = 0.0045
count = [2, 2, 2]
"#;

#[test]
fn scene_without_dem_table_is_none_and_other_tables_are_ignored() {
    assert!(
        parse_scene_section("[scene]\nname = \"x\"\n[fem]\nfoo = 1\n")
            .unwrap()
            .is_none()
    );
    let cfg = parse_scene_section(GOOD).unwrap().unwrap();
    assert_eq!(cfg.time_step, 1e-5);
    assert_eq!(cfg.gravity, [0.0, 0.0, -9.81]);
    let e = Engine::from_config(&cfg, std::path::Path::new(".")).unwrap();
    assert_eq!(e.num_particles(), 8);
}

#[test]
fn unknown_field_error_names_line_and_field() {
    let text = GOOD.replace("radius = 0.002", "radiuss = 0.002");
    let err = parse_scene_section(&text).unwrap_err();
    println!("{err}");
    assert!(err.message.contains("radiuss"), "{err}");
    assert_eq!((err.line, err.column), (17, 1), "{err}");
    assert!(err
        .to_string()
        .starts_with(&format!("line {}, column {}: ", err.line, err.column)));

    let text = GOOD.replace("friction = 1.0", "friction = 1.0\nfriktion = 2.0");
    let err = parse_scene_section(&text).unwrap_err();
    println!("{err}");
    assert_eq!(err.line, 14, "{err}");
    assert!(err.message.contains("friktion"));
}

#[test]
fn bad_value_error_names_line_and_field_path() {
    let text = GOOD.replace("poisson_ratio = 0.3", "poisson_ratio = 0.6");
    let err = parse_scene_section(&text).unwrap_err();
    println!("{err}");
    assert_eq!((err.line, err.column), (10, 1), "{err}");
    assert!(
        err.message.contains("dem.materials.wheat.poisson_ratio"),
        "{err}"
    );

    let text = GOOD.replace("radius = 0.002", "radius = -0.002");
    let err = parse_scene_section(&text).unwrap_err();
    println!("{err}");
    assert_eq!(err.line, 17);
    assert!(err.message.contains("dem.particles[0].radius"), "{err}");

    let text = GOOD.replace("material = \"wheat\"\nradius", "material = \"rye\"\nradius");
    let err = parse_scene_section(&text).unwrap_err();
    println!("{err}");
    assert!(
        err.message.contains("unknown material `rye`") && err.line == 16,
        "{err}"
    );

    let text = GOOD.replace("time_step = 1e-5", "time_step = \"fast\"");
    let err = parse_scene_section(&text).unwrap_err();
    println!("{err}");
    assert_eq!(err.line, 7);
}

#[test]
fn time_step_above_rayleigh_fraction_is_refused_unless_allowed() {
    let text = GOOD.replace("time_step = 1e-5", "time_step = 2e-5");
    let cfg = parse_scene_section(&text).unwrap().unwrap();
    let err = Engine::from_config(&cfg, std::path::Path::new("."))
        .err()
        .expect("refused");
    println!("{err}");
    let msg = err.to_string();
    assert!(
        msg.contains("Rayleigh") && msg.contains("allow_large_time_step"),
        "{msg}"
    );
    let text = text.replace(
        "time_step = 2e-5",
        "time_step = 2e-5\nallow_large_time_step = true",
    );
    let cfg = parse_scene_section(&text).unwrap().unwrap();
    let e = Engine::from_config(&cfg, std::path::Path::new(".")).unwrap();
    // eq. 2.27 for r = 2 mm wheat
    let g = 1e8 / 2.6;
    let want = std::f64::consts::PI * 0.002 / (0.1631 * 0.3 + 0.8766) * (1242.0f64 / g).sqrt();
    assert!((e.rayleigh_time_step() - want).abs() < 1e-15 * want);
}

fn stl_scene(path: &str) -> String {
    format!(
        "[dem]\ntime_step = 1e-5\n[dem.materials.m]\nyoungs_modulus = 1e8\npoisson_ratio = 0.3\ndensity = 1000.0\n\
         restitution = 0.5\nfriction = 0.5\n[[dem.walls]]\nkind = \"stl\"\nmaterial = \"m\"\npath = \"{path}\"\n"
    )
}

const ASCII_STL: &str = "solid square\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n   vertex 1 0 0\n   vertex 1 1 0\n  endloop\n endfacet\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n   vertex 1 1 0\n   vertex 0 1 0\n  endloop\n endfacet\nendsolid square\n";

#[test]
fn stl_ascii_and_binary_read_and_errors_name_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("sq.stl"), ASCII_STL).unwrap();
    let mut bin = vec![0u8; 80];
    bin.extend_from_slice(&2u32.to_le_bytes());
    for tri in [
        [[0f32, 0., 0.], [1., 0., 0.], [1., 1., 0.]],
        [[0., 0., 0.], [1., 1., 0.], [0., 1., 0.]],
    ] {
        bin.extend_from_slice(&[0u8; 12]);
        for v in tri {
            for c in v {
                bin.extend_from_slice(&c.to_le_bytes());
            }
        }
        bin.extend_from_slice(&[0u8; 2]);
    }
    std::fs::write(dir.path().join("sq_bin.stl"), &bin).unwrap();
    for name in ["sq.stl", "sq_bin.stl"] {
        let cfg = parse_scene_section(&stl_scene(name)).unwrap().unwrap();
        let e = Engine::from_config(&cfg, dir.path()).unwrap();
        let m = &e.meshes()[0];
        assert_eq!(
            (m.positions.len(), m.triangles.len()),
            (4, 2),
            "{name}: welded square"
        );
        assert_eq!(
            m.patch,
            vec![0, 0],
            "{name}: coplanar triangles form one patch"
        );
    }
    std::fs::write(
        dir.path().join("bad.stl"),
        ASCII_STL.replace(
            "vertex 1 1 0\n  endloop\n endfacet\n facet",
            "vertex 1 x 0\n  endloop\n endfacet\n facet",
        ),
    )
    .unwrap();
    let cfg = parse_scene_section(&stl_scene("bad.stl")).unwrap().unwrap();
    let err = Engine::from_config(&cfg, dir.path())
        .err()
        .unwrap()
        .to_string();
    println!("{err}");
    assert!(
        err.contains("bad.stl") && err.contains("line 6") && err.contains("`x`"),
        "{err}"
    );
    std::fs::write(dir.path().join("short.stl"), &bin[..120]).unwrap();
    let cfg = parse_scene_section(&stl_scene("short.stl"))
        .unwrap()
        .unwrap();
    let err = Engine::from_config(&cfg, dir.path())
        .err()
        .unwrap()
        .to_string();
    println!("{err}");
    assert!(
        err.contains("short.stl") && err.contains("byte 120"),
        "{err}"
    );
}

#[test]
fn dense_bed_example_scene_builds_24696_particles() {
    let text = include_str!("data/dense_bed.toml");
    let cfg = parse_scene_section(text).unwrap().unwrap();
    let e = Engine::from_config(&cfg, std::path::Path::new(".")).unwrap();
    assert_eq!(e.num_particles(), 24_696);
    assert!(e.time_step() <= 0.3 * e.rayleigh_time_step());
}

#[test]
fn write_outputs_writes_csv_rows_and_vtk_files() {
    let text = include_str!("data/dense_bed.toml")
        .replace("count = [21, 21, 56]", "count = [3, 3, 3]")
        .replace("vtk_every = 10000", "vtk_every = 10");
    let cfg = parse_scene_section(&text).unwrap().unwrap();
    let mut e = Engine::from_config(&cfg, std::path::Path::new(".")).unwrap();
    let dir = tempfile::tempdir().unwrap();
    for _ in 0..3 {
        e.advance(10).unwrap();
        e.write_outputs(dir.path()).unwrap();
    }
    let csv = std::fs::read_to_string(dir.path().join("dem_timeseries.csv")).unwrap();
    assert_eq!(csv.lines().count(), 4, "header + 3 rows");
    assert!(csv
        .lines()
        .next()
        .unwrap()
        .starts_with("time,step,particles,kinetic_energy,contacts"));
    let vtk: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .filter_map(|f| f.ok())
        .map(|f| f.file_name().into_string().unwrap())
        .filter(|n| n.starts_with("particles_"))
        .collect();
    assert_eq!(vtk.len(), 3);
    let body = std::fs::read_to_string(dir.path().join("particles_000000010.vtk")).unwrap();
    assert!(body.contains("POINTS 27 double") && body.contains("SCALARS radius double 1"));
}
