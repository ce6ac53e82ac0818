//! Counts and sizes from a scene are checked before anything is allocated: a scene that
//! needs more memory than the machine has, or more threads than it can use, is a scene
//! error naming the field, the estimate and the memory available — not an abort in the
//! allocator. Also the value checks of fields that had none, and the particle-file overlap
//! check. All through the scene parser (`parse_scene_section`) or `Engine::from_config` on
//! real files.

mod common;
use common::GRAIN;
use dem::{parse_scene_section, Engine};

fn scene(body: &str) -> String {
    format!("[dem]\ntime_step = 1e-5\n{GRAIN}\n{body}")
}

/// A scene with one lattice source of r = 1 mm grains, `count` as written in TOML.
fn lattice(count: &str) -> String {
    scene(&format!(
        "[[dem.particles]]\nkind = \"lattice\"\nmaterial = \"grain\"\nradius = 0.001\n\
         first = [0.0, 0.0, 0.0]\nspacing = 0.0025\ncount = {count}\n"
    ))
}

/// The error of a scene that must not parse, printed for the test log.
fn error_of(text: &str) -> dem::SceneError {
    let err = parse_scene_section(text).expect_err("the scene must be refused");
    println!("{err}");
    err
}

/// 1-based line of the first line of `text` that starts with `prefix`.
fn line_of(text: &str, prefix: &str) -> usize {
    text.lines().position(|l| l.starts_with(prefix)).unwrap() + 1
}

#[test]
fn a_lattice_of_1e12_particles_is_refused_naming_count_and_memory() {
    let text = lattice("[10000, 10000, 10000]");
    let err = error_of(&text);
    assert!(err.message.starts_with("dem.particles[0].count: "), "{err}");
    // 1e12 particles at 500 B each
    assert!(err.message.contains("1e12 particles"), "{err}");
    assert!(err.message.contains("needs ≈ 500 TB"), "{err}");
    assert!(err.message.contains("available on this machine"), "{err}");
    assert_eq!(err.line, line_of(&text, "count"), "{err}");
}

#[test]
fn a_lattice_count_whose_product_overflows_is_refused() {
    let text = lattice("[4294967296, 4294967296, 2]");
    let err = error_of(&text);
    assert!(
        err.message.starts_with("dem.particles[0].count: ") && err.message.contains("overflows"),
        "{err}"
    );
}

#[test]
fn a_fill_of_1e12_particles_by_count_or_by_mass_is_refused() {
    let fill = |amount: &str| {
        scene(&format!(
            r#"[[dem.particles]]
kind = "fill"
material = "grain"
min = [0.0, 0.0, 0.0]
max = [1.0, 1.0, 1.0]
{amount}
distribution = {{ kind = "constant", radius = 0.001 }}
"#
        ))
    };
    let text = fill("count = 1000000000000");
    let err = error_of(&text);
    assert!(
        err.message
            .starts_with("dem.particles[0].count: 1e12 particles needs ≈ 500 TB"),
        "{err}"
    );
    assert_eq!(err.line, line_of(&text, "count"), "{err}");

    // 4.19e3 kg of 1 mm grains of 1000 kg/m³ (4.19e-6 kg each) are 1e9 particles; 4.19e6 kg
    // are 1e12
    let text = fill("mass = 4.18879e6");
    let err = error_of(&text);
    assert!(
        err.message
            .starts_with("dem.particles[0].mass: at least 1e12 particles"),
        "{err}"
    );
    assert!(err.message.contains("needs ≈ 500 TB"), "{err}");
    assert_eq!(err.line, line_of(&text, "mass"), "{err}");
}

#[test]
fn sources_are_summed_before_the_memory_comparison() {
    let available = dem::resources::available_memory().expect("/proc/meminfo on Linux");
    // two fills each needing 60 % of the available memory: the first passes, the second not
    let n = (0.6 * available as f64 / dem::resources::BYTES_PER_PARTICLE as f64) as u64;
    let fill = format!(
        r#"[[dem.particles]]
kind = "fill"
material = "grain"
min = [0.0, 0.0, 0.0]
max = [1.0, 1.0, 1.0]
count = {n}
distribution = {{ kind = "constant", radius = 0.001 }}
"#
    );
    let err = error_of(&scene(&format!("{fill}\n{fill}")));
    assert!(
        err.message.starts_with("dem.particles[1].count: ")
            && err.message.contains("with the sources before"),
        "{err}"
    );
}

#[test]
fn absurd_thread_counts_are_refused_naming_the_field() {
    for threads in ["100000", "9223372036854775807"] {
        let text = scene("").replace(
            "time_step = 1e-5\n",
            &format!("time_step = 1e-5\nthreads = {threads}\n"),
        );
        let err = error_of(&text);
        assert!(err.message.starts_with("dem.threads: "), "{err}");
        assert!(err.message.contains("cores"), "{err}");
        assert_eq!(err.line, line_of(&text, "threads"), "{err}");
    }
    // the machine's own core count is fine
    let cores = std::thread::available_parallelism().unwrap().get();
    let text = scene("").replace(
        "time_step = 1e-5\n",
        &format!("time_step = 1e-5\nthreads = {cores}\n"),
    );
    parse_scene_section(&text).unwrap().unwrap();
}

#[test]
fn a_repose_sensor_with_a_tiny_bin_width_runs_without_allocating_its_bins() {
    // 1e300 bins of width 1e-300 m: only the occupied ones are stored
    let text = scene(
        r#"[[dem.particles]]
kind = "lattice"
material = "grain"
radius = 0.001
first = [0.0, 0.0, 0.001]
spacing = 0.003
count = [4, 1, 1]
[[dem.sensors]]
name = "heap"
kind = "repose"
centre = [0.0, 0.0]
r_min = 0.0
r_max = 1.0
bin_width = 1e-300
"#,
    );
    let cfg = parse_scene_section(&text).unwrap().unwrap();
    let dir = tempfile::tempdir().unwrap();
    let mut e = Engine::from_config(&cfg, dir.path()).unwrap();
    e.advance(2).unwrap();
    e.write_outputs(dir.path()).unwrap();
    let results = e.results();
    let angle = results
        .iter()
        .find(|(k, _)| k == "sensor.heap.last")
        .unwrap()
        .1;
    // four spheres at one height: a flat heap
    assert!(angle.abs() < 1e-6, "{angle}");
}

#[test]
fn fields_without_range_checks_are_checked_now() {
    let cases: [(String, &str); 6] = [
        (
            lattice("[2, 2, 2]").replace(
                "time_step = 1e-5\n",
                "time_step = 1e-5\nrayleigh_fraction = 5.0\n",
            ),
            "dem.rayleigh_fraction: ",
        ),
        (
            scene(
                r#"[[dem.walls]]
kind = "box"
material = "grain"
min = [0.0, 0.0, -inf]
max = [1.0, 1.0, 1.0]
"#,
            ),
            "dem.walls[0].min: must be finite",
        ),
        (
            scene(
                r#"[[dem.particles]]
kind = "fill"
material = "grain"
min = [0.0, 0.0, 0.0]
max = [1.0, 1.0, 1.0]
count = 0
distribution = { kind = "constant", radius = 0.001 }
"#,
            ),
            "dem.particles[0].count: must be >= 1",
        ),
        (
            scene(
                r#"[[dem.particles]]
kind = "fill"
material = "grain"
min = [0.0, 0.0, 0.0]
max = [1.0, 1.0, 1.0]
count = 10
distribution = { kind = "table", radius = [0.001, nan], cumulative = [0.0, 1.0] }
"#,
            ),
            "dem.particles[0].distribution.radius: must be finite",
        ),
        (
            scene(
                r#"[[dem.particles]]
kind = "fill"
material = "grain"
min = [0.0, 0.0, 0.0]
max = [1.0, 1.0, 1.0]
count = 10
distribution = { kind = "table", radius = [0.001, 0.002, 0.003], cumulative = [0.0, nan, 1.0] }
"#,
            ),
            "dem.particles[0].distribution.cumulative: ",
        ),
        (
            lattice("[2, 2, 2]").replace("spacing = 0.0025", "spacing = 0.0025\njitter = 0.0003"),
            // (0.0025 − 0.002) / 2 printed readably, not as 0.00024999999999999995
            "must be <= (spacing - 2 * radius) / 2 = 0.00025 m",
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

/// A particle file next to a scene that reads it, in a fresh folder.
fn file_scene(rows: &str) -> (tempfile::TempDir, String) {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("bed.csv"), format!("x,y,z,radius\n{rows}")).unwrap();
    let text = scene(
        r#"[[dem.particles]]
kind = "file"
material = "grain"
path = "bed.csv"
"#,
    )
    .replace(
        "time_step = 1e-5\n",
        "time_step = 1e-5\nallow_large_time_step = true\n",
    );
    (dir, text)
}

fn build(dir: &tempfile::TempDir, text: &str) -> Result<Engine, dem::DemError> {
    let cfg = parse_scene_section(text).unwrap().unwrap();
    Engine::from_config(&cfg, dir.path())
}

#[test]
fn coincident_spheres_in_a_particle_file_are_refused_naming_both_lines() {
    let (dir, text) = file_scene("0,0,0.01,0.001\n0.01,0,0.01,0.001\n\n0.01,0,0.01,0.001\n");
    let err = build(&dir, &text).err().expect("refused").to_string();
    println!("{err}");
    assert!(
        err.starts_with("dem.particles[0].path: particle file "),
        "{err}"
    );
    assert!(err.contains("bed.csv, line 3: "), "{err}");
    assert!(
        err.contains("lines 3 and 5 overlap by 2 of the smaller radius"),
        "{err}"
    );
}

#[test]
fn a_heavy_overlap_is_refused_and_a_settled_contact_is_accepted() {
    // centres 0.0015 m apart, radii 0.001 and 0.0005: overlap 0 — touching, accepted
    let (dir, text) = file_scene("0,0,0.01,0.001\n0.0015,0,0.01,0.0005\n");
    build(&dir, &text).expect("touching spheres load");
    // 3 % of r, as in a compacted bed written with 6 significant digits: accepted
    let (dir, text) = file_scene("0,0,0.01,0.001\n0.00197,0,0.01,0.001\n");
    build(&dir, &text).expect("a small overlap loads");
    // 0.6 of the smaller radius (0.0005): refused
    let (dir, text) = file_scene("0,0,0.01,0.001\n0.0012,0,0.01,0.0005\n");
    let err = build(&dir, &text).err().expect("refused").to_string();
    println!("{err}");
    assert!(
        err.contains("lines 2 and 3 overlap by 0.6 of the smaller radius"),
        "{err}"
    );
}

#[test]
fn a_kept_part_of_a_file_is_checked_not_the_spheres_left_out() {
    // the two coincident spheres lie above the cut and are not loaded
    let (dir, text) = file_scene("0,0,0.01,0.001\n0,0,0.5,0.001\n0,0,0.5,0.001\n");
    let text = text.replace(
        "path = \"bed.csv\"",
        "path = \"bed.csv\"\nkeep = { max = [1.0, 1.0, 0.1] }",
    );
    let e = build(&dir, &text).expect("the kept spheres do not overlap");
    assert_eq!(e.num_particles(), 1);
}

#[test]
fn a_value_of_the_wrong_type_names_its_field_and_a_unit_string_says_why() {
    let text = lattice("[2, 2, 2]").replace("radius = 0.001", "radius = \"big\"");
    let err = error_of(&text);
    assert!(
        err.message.starts_with("dem.particles[0].radius: "),
        "{err}"
    );
    assert_eq!(err.line, line_of(&text, "radius"), "{err}");

    let text = lattice("[2, 2, 2]").replace("radius = 0.001", "radius = \"3 kg\"");
    let err = error_of(&text);
    assert!(
        err.message.starts_with("dem.particles[0].radius: "),
        "{err}"
    );
    assert!(err.message.contains("plain numbers in SI units"), "{err}");

    let text = lattice("[2, 2, 2]").replace("time_step = 1e-5", "time_step = \"0.1 ms\"");
    let err = error_of(&text);
    assert!(err.message.starts_with("dem.time_step: "), "{err}");
    assert!(err.message.contains("plain numbers in SI units"), "{err}");
    assert_eq!(err.line, line_of(&text, "time_step"), "{err}");

    let text = lattice("[2, 2, 2]").replace("density = 1000.0", "density = \"heavy\"");
    let err = error_of(&text);
    assert!(
        err.message.starts_with("dem.materials.grain.density: "),
        "{err}"
    );
    assert!(!err.message.contains("SI units"), "{err}");
    assert_eq!(err.line, line_of(&text, "density"), "{err}");
}

#[test]
fn every_shipped_scene_still_passes_the_checks() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    let mut checked = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|x| x != "toml") {
            continue;
        }
        let text = std::fs::read_to_string(&path).unwrap();
        if dem::discs::scene_model(&text, "dem") == dem::discs::config::Model::Discs2d {
            // Madan's 2-D discs: their own table, their own checks
            let parsed = dem::discs::parse_scene_table(&text, "dem");
            assert!(
                matches!(parsed, Ok(Some(_))),
                "{}: {:?}",
                path.display(),
                parsed.err()
            );
            continue;
        }
        let parsed = parse_scene_section(&text);
        assert!(
            parsed.is_ok(),
            "{}: {}",
            path.display(),
            parsed.unwrap_err()
        );
        checked += parsed.unwrap().is_some() as usize;
    }
    assert!(checked >= 12, "only {checked} scenes with [dem]");
}

#[test]
fn a_list_source_with_a_sphere_written_twice_is_refused() {
    let text = scene(
        r#"[[dem.particles]]
kind = "list"
material = "grain"
spheres = [
  { position = [0.0, 0.0, 0.1], radius = 0.005 },
  { position = [0.02, 0.0, 0.1], radius = 0.005 },
  { position = [0.0, 0.0, 0.1], radius = 0.005 },
]
"#,
    );
    let err = error_of(&text);
    assert!(
        err.message
            .starts_with("dem.particles[0].spheres[2]: spheres 0 and 2 overlap by 2 of"),
        "{err}"
    );
    // touching spheres are fine
    let ok = text.replace(
        "{ position = [0.0, 0.0, 0.1], radius = 0.005 },\n]",
        "{ position = [0.0, 0.0, 0.11], radius = 0.005 },\n]",
    );
    assert!(parse_scene_section(&ok).is_ok());
}
