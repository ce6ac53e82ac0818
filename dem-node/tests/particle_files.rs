//! Particle files: `[[dem.particles]] kind = "file"` and `[dem.output] final_particles`, so a
//! settled bed from one run starts the next.
mod common;
use common::GRAIN;
use dem::{parse_scene_section, Engine};
use std::path::Path;

fn scene(particles: &str, output: &str) -> String {
    format!(
        r#"
[dem]
time_step = 2e-5
{GRAIN}
[[dem.walls]]
kind = "box"
material = "grain"
min = [0.0, 0.0, 0.0]
max = [0.05, 0.05, 0.2]
open = ["+z"]
{particles}
{output}
"#
    )
}

const FILL: &str = r#"[[dem.particles]]
kind = "fill"
material = "grain"
min = [0.0, 0.0, 0.0]
max = [0.05, 0.05, 0.1]
count = 200
distribution = { kind = "uniform", min = 0.002, max = 0.004 }"#;

fn build(text: &str, dir: &Path) -> Result<Engine, dem::DemError> {
    let cfg = parse_scene_section(text).unwrap().unwrap();
    Engine::from_config(&cfg, dir)
}

/// (position, velocity, radius) in id order.
fn by_id(e: &Engine) -> Vec<([f64; 3], [f64; 3], f64)> {
    let p = e.particles();
    let mut k: Vec<usize> = (0..p.len()).collect();
    k.sort_by_key(|&k| p.id[k]);
    k.into_iter()
        .map(|k| {
            let (x, v) = (p.position[k], p.velocity[k]);
            ([x.x, x.y, x.z], [v.x, v.y, v.z], p.radius[k])
        })
        .collect()
}

#[test]
fn final_particles_start_the_next_run_where_the_last_stopped() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let mut first = build(
        &scene(FILL, "[dem.output]\nfinal_particles = true"),
        dir.path(),
    )
    .unwrap();
    first.advance(2500).unwrap(); // 0.05 s of settling
    let written = first.write_final_particles(&out).unwrap().expect("enabled");
    assert_eq!(written, out.join("particles_final.csv"));
    let text = std::fs::read_to_string(&written).unwrap();
    assert!(text.starts_with("x,y,z,radius,vx,vy,vz\n"));
    assert_eq!(text.lines().count(), 201);

    std::fs::copy(&written, dir.path().join("bed.csv")).unwrap();
    let next = build(
        &scene(
            "[[dem.particles]]\nkind = \"file\"\nmaterial = \"grain\"\npath = \"bed.csv\"",
            "",
        ),
        dir.path(),
    )
    .unwrap();
    let (a, b) = (by_id(&first), by_id(&next));
    assert_eq!(a.len(), b.len());
    assert!(a == b, "positions, velocities and radii round-trip bitwise");
    let masses = |e: &Engine| e.particles().mass.iter().sum::<f64>();
    assert!((masses(&first) - masses(&next)).abs() < 1e-12 * masses(&first));
    // without the option nothing is written
    assert!(next
        .write_final_particles(&dir.path().join("none"))
        .unwrap()
        .is_none());
    assert!(!dir.path().join("none").exists());
}

#[test]
fn bad_particle_files_name_the_field_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("bed.csv"),
        "x,y,z,radius\n0.01,0.01,0.01,0.002\n0.02,0.02,oops,0.002\n",
    )
    .unwrap();
    let text = scene(
        "[[dem.particles]]\nkind = \"file\"\nmaterial = \"grain\"\npath = \"bed.csv\"",
        "",
    );
    let err = build(&text, dir.path()).err().unwrap().to_string();
    println!("{err}");
    assert!(
        err.contains("dem.particles[0].path")
            && err.contains("bed.csv")
            && err.contains("line 3")
            && err.contains("`oops`"),
        "{err}"
    );
    let err = build(&text.replace("bed.csv", "missing.csv"), dir.path())
        .err()
        .unwrap()
        .to_string();
    println!("{err}");
    assert!(
        err.contains("missing.csv: cannot read") && !err.contains("line"),
        "{err}"
    );
    let err = parse_scene_section(
        &text.replace("material = \"grain\"\npath", "material = \"rye\"\npath"),
    )
    .unwrap_err();
    println!("{err}");
    assert!(err.message.contains("dem.particles[0].material"), "{err}");
}

#[test]
fn keep_cuts_a_bed_file_at_a_height_like_the_seeds_bed_levelling() {
    let dir = tempfile::tempdir().unwrap();
    let mut csv = String::from("x,y,z,radius\n");
    for k in 0..10 {
        csv += &format!("0.025,0.025,{},0.002\n", 0.005 + 0.01 * k as f64);
    }
    std::fs::write(dir.path().join("bed.csv"), csv).unwrap();
    let src = |keep: &str| {
        scene(
            &format!(
                "[[dem.particles]]\nkind = \"file\"\nmaterial = \"grain\"\npath = \"bed.csv\"\n{keep}"
            ),
            "",
        )
    };
    let all = build(&src(""), dir.path()).unwrap();
    assert_eq!(all.num_particles(), 10);
    // centres at 0.005 … 0.095: those at or below 0.05 are 0.005 … 0.045 (5 spheres)
    let cut = build(&src("keep = { max = [1.0, 1.0, 0.05] }"), dir.path()).unwrap();
    assert_eq!(cut.num_particles(), 5);
    assert!(cut.particles().position.iter().all(|x| x.z <= 0.05));
    let band = build(
        &src("keep = { min = [0.0, 0.0, 0.02], max = [1.0, 1.0, 0.06] }"),
        dir.path(),
    )
    .unwrap();
    assert_eq!(band.num_particles(), 4);
    // a box that keeps nothing is an error naming the source, not an empty run
    let err = build(&src("keep = { min = [0.0, 0.0, 0.5] }"), dir.path())
        .err()
        .unwrap()
        .to_string();
    println!("{err}");
    assert!(
        err.contains("removed all 10 spheres") && err.contains("bed.csv"),
        "{err}"
    );
    // an inverted box is refused when the scene is read, naming the field
    let err = parse_scene_section(&src(
        "keep = { min = [0.0, 0.0, 0.5], max = [1.0, 1.0, 0.1] }",
    ))
    .unwrap_err();
    println!("{err}");
    assert!(err.message.contains("dem.particles[0].keep"), "{err}");
}

fn lattice(extra: &str) -> String {
    scene(
        &format!(
            "[[dem.particles]]\nkind = \"lattice\"\nmaterial = \"grain\"\nradius = 0.002\n\
             first = [0.005, 0.005, 0.005]\nspacing = 0.005\ncount = [8, 8, 4]\n{extra}"
        ),
        "",
    )
}

#[test]
fn lattice_jitter_moves_centres_sideways_within_the_bound_and_is_seeded() {
    let dir = tempfile::tempdir().unwrap();
    let exact = by_id(&build(&lattice(""), dir.path()).unwrap());
    let a = by_id(&build(&lattice("jitter = 4e-4"), dir.path()).unwrap());
    let b = by_id(&build(&lattice("jitter = 4e-4"), dir.path()).unwrap());
    let c = by_id(&build(&lattice("jitter = 4e-4\nseed = 7"), dir.path()).unwrap());
    assert_eq!(exact.len(), 256);
    assert!(a == b, "same seed, same lattice");
    assert!(a != c, "another seed, another lattice");
    let mut max_d: f64 = 0.0;
    for (e, j) in exact.iter().zip(&a) {
        assert_eq!(e.0[2], j.0[2], "z is not jittered");
        for ax in 0..2 {
            let d = (e.0[ax] - j.0[ax]).abs();
            assert!(d <= 4e-4, "displacement {d} beyond the jitter");
            max_d = max_d.max(d);
        }
    }
    assert!(max_d > 3e-4, "jitter used most of its range ({max_d})");
    // no two jittered spheres overlap
    for (i, p) in a.iter().enumerate() {
        for q in &a[i + 1..] {
            let d2: f64 = (0..3).map(|k| (p.0[k] - q.0[k]).powi(2)).sum();
            assert!(d2.sqrt() >= 0.004 - 1e-12);
        }
    }
    // a jitter that could make neighbours overlap is refused, naming the field and the bound
    let err = parse_scene_section(&lattice("jitter = 6e-4")).unwrap_err();
    println!("{err}");
    assert!(
        err.message.contains("dem.particles[0].jitter") && err.message.contains("0.0005"),
        "{err}"
    );
}
