//! Dilated convex polyhedra in the engine (Ullrich's ballast, SEED-SPEC §6.1–6.2): impacts
//! conserve energy on stones and on triangle walls, a stone at rest on a coupled plate loads
//! it with its weight, results do not depend on the thread count or on snapshots, and the
//! model's validity limit (the cores must not meet) stops a run with the pair named.
mod common;

use dem::generate::SplitMix64;
use dem::hertz_mindlin::V3;
use dem::particles::Orientation;
use dem::shape::Stone;
use dem::Engine;

const ELASTIC: &str = r#"
[dem]
time_step = 1e-6
gravity = [0.0, 0.0, 0.0]
[dem.materials.grain]
youngs_modulus = 1e7
poisson_ratio = 0.3
density = 1000.0
restitution = 1.0
friction = 0.0
"#;

fn rot(axis: [f64; 3], angle: f64) -> Orientation {
    Orientation::from_axis_angle(&nalgebra::Unit::new_normalize(V3::from(axis)), angle)
}

/// Stones of 10, 30 and 40 triangles (seeded).
fn stones() -> Vec<Stone> {
    let mut rng = SplitMix64::new(21);
    [10, 30, 40]
        .iter()
        .map(|&t| Stone::random(t, 1.6, 0.1, &mut rng).unwrap())
        .collect()
}

/// An engine of `scene` with the stone bodies (x, v, ω, q, stone, size).
fn engine_with(scene: &str, bodies: &[(V3, V3, V3, Orientation, &Stone, f64)]) -> Engine {
    let mut e = common::engine(scene);
    let p = e.particles_mut();
    for (x, v, w, q, s, size) in bodies {
        let id = p.add_stone((*s).clone());
        p.push_polyhedron(*x, *v, *w, *q, id, *size, 1000.0, 0);
    }
    e.refresh_forces();
    e
}

/// Steps until the contacts have opened again (after at least one); asserts that the kinetic
/// energy then equals the energy before to 1e-5 (case `k`).
fn conserves_energy_until_apart(e: &mut Engine, walls: bool, k: usize) {
    let e0 = e.kinetic_energy();
    let count = |e: &Engine| {
        if walls {
            e.num_wall_contacts()
        } else {
            e.num_contacts()
        }
    };
    let mut touched = false;
    for _ in 0..400_000 {
        e.step().unwrap();
        touched |= count(e) > 0;
        if touched && count(e) == 0 {
            break;
        }
    }
    assert!(touched, "never touched");
    assert_eq!(count(e), 0, "still in contact");
    let rel = (e.kinetic_energy() - e0) / e0;
    println!("case {k}: energy change {rel:e}");
    assert!(rel.abs() < 1e-5, "case {k}: {rel:e}");
}

/// Frictionless elastic (e = 1) impacts of spinning stones, off-centre, so the closest
/// features move over faces, edges and vertices: the normal force is −∇W(δ_d) of the core
/// distance, so the energy after the impact equals the energy before (1e-5).
#[test]
fn frictionless_elastic_polyhedron_impacts_conserve_energy() {
    let s = stones();
    let cases = [(0, 1), (1, 1), (2, 0), (1, 2)];
    for (k, (a, b)) in cases.into_iter().enumerate() {
        let mut e = engine_with(
            ELASTIC,
            &[
                (
                    V3::zeros(),
                    V3::new(0.1, 0.0, 0.0),
                    V3::new(0.0, 30.0, 10.0),
                    rot([0.3, 1.0, 0.2], 0.4 + k as f64),
                    &s[a],
                    4e-3,
                ),
                (
                    V3::new(6e-3, 0.8e-3, 0.5e-3),
                    V3::new(-0.1, 0.0, 0.0),
                    V3::new(20.0, 0.0, -15.0),
                    rot([1.0, -0.2, 0.5], 1.1 + k as f64),
                    &s[b],
                    3.5e-3,
                ),
            ],
        );
        conserves_energy_until_apart(&mut e, false, k);
    }
}

/// A spinning stone bouncing off a box's edge, corner and face (frictionless, e = 1): the
/// closest triangle of the patch changes across the box's edges without a force jump and the
/// energy is conserved (1e-5).
#[test]
fn polyhedron_impacts_on_box_edges_conserve_energy() {
    let scene = format!(
        "{ELASTIC}[[dem.walls]]\nkind = \"box\"\nmaterial = \"grain\"\nmin = [0.0, 0.0, 0.0]\nmax = [0.02, 0.02, 0.02]\n"
    );
    let s = stones();
    let cases = [
        (V3::new(0.024, 0.01, 0.024), V3::new(-0.1, 0.0, -0.1)),
        (V3::new(0.024, 0.024, 0.024), V3::new(-0.08, -0.08, -0.08)),
        (V3::new(0.023, 0.003, 0.01), V3::new(-0.15, 0.05, 0.0)),
    ];
    for (k, (x, v)) in cases.into_iter().enumerate() {
        let mut e = engine_with(
            &scene,
            &[(
                x,
                v,
                V3::new(20.0, -30.0, 10.0),
                rot([0.2, 1.0, 0.4], 0.8),
                &s[1],
                4e-3,
            )],
        );
        conserves_energy_until_apart(&mut e, true, k);
    }
}

/// The normal force of a pair is Ullrich's (2.20) as printed — 2√2 G/(3(1 − ν)) √r_ds δ^{3/2}
/// for two bodies of the same material and dilation — evaluated at the overlap the narrow
/// phase reports (checked against a brute force in its own tests).
#[test]
fn pair_force_is_ullrich_2_20() {
    let s = stones();
    let (size, e_mod, nu) = (4e-3, 1e7, 0.3);
    let g = e_mod / (2.0 * (1.0 + nu));
    let r = s[1].dilation * size;
    for gap in [0.2e-3, 0.05e-3, 0.005e-3] {
        // two copies facing each other along x, the second pushed in until they touch
        let mut e = engine_with(
            ELASTIC,
            &[
                (
                    V3::zeros(),
                    V3::zeros(),
                    V3::zeros(),
                    Orientation::identity(),
                    &s[1],
                    size,
                ),
                (
                    V3::new(size, 0.0, 0.0),
                    V3::zeros(),
                    V3::zeros(),
                    rot([0.0, 0.0, 1.0], std::f64::consts::PI),
                    &s[1],
                    size,
                ),
            ],
        );
        // move body 1 along −x until the dilated bodies overlap by at least `gap`
        let overlap = |e: &Engine| {
            e.shaped_pair_contacts()
                .map(|c| c.1.overlap)
                .fold(-1.0, f64::max)
        };
        for _ in 0..10_000 {
            if overlap(&e) >= gap {
                break;
            }
            e.particles_mut().position[1].x -= 2e-6;
            e.refresh_forces();
        }
        let p = e.particles();
        let (f0, f1) = (p.force[0], p.force[1]);
        assert!(
            (f0 + f1).norm() < 1e-12 * f0.norm(),
            "action = reaction: {f0} {f1}"
        );
        let delta = e
            .shaped_pair_contacts()
            .find(|c| c.1.touching())
            .unwrap()
            .1
            .overlap;
        let expected = 2.0 * 2f64.sqrt() * g / (3.0 * (1.0 - nu)) * r.sqrt() * delta.powf(1.5);
        println!(
            "gap {gap:e}: δ = {delta:e}, |F| = {:e}, (2.20) {expected:e}",
            f0.norm()
        );
        assert!(delta >= gap && delta < gap + 1e-5);
        assert!((f0.norm() - expected).abs() < 1e-9 * expected);
    }
}

/// A stone landed on a coupled (FEM interface) plate of 8 triangles loads the plate nodes
/// with its weight: the mean nodal force over a window balances the weight and the stone's
/// momentum change (1e-7: the window mean and the leapfrog sum differ by half a step), and
/// the weight to 1e-6 once it has settled.
#[test]
fn polyhedron_at_rest_on_a_coupled_plate_loads_it_with_its_weight() {
    let scene = format!(
        "[dem]\ntime_step = 2e-6\ninterface_material = \"grain\"\n{}",
        common::GRAIN.replace("restitution = 0.5", "restitution = 0.2")
    );
    let s = stones();
    let mut e = engine_with(
        &scene,
        &[(
            V3::new(0.025, 0.025, 0.004),
            V3::zeros(),
            V3::zeros(),
            rot([1.0, 0.5, 0.0], 0.3),
            &s[1],
            4e-3,
        )],
    );
    let mut pos = Vec::new();
    for j in 0..3 {
        for i in 0..3 {
            pos.extend([0.025 * i as f64, 0.025 * j as f64, 0.001]);
        }
    }
    let mut tris = Vec::new();
    for j in 0..2u32 {
        for i in 0..2u32 {
            let a = j * 3 + i;
            tris.extend([a, a + 1, a + 4, a, a + 4, a + 3]);
        }
    }
    let m = e.add_coupled_mesh("plate", &pos, &tris).unwrap();
    let zeros = vec![0.0; pos.len()];
    e.set_mesh_kinematics(m, &pos, &zeros, &zeros, dem::MotionRule::Quadratic)
        .unwrap();
    e.refresh_forces();
    let mass = e.particles().mass[0];
    e.advance(400_000).unwrap(); // 0.8 s: landed, rocking by nanometres
                                 // the mean nodal force of the next 0.2 s (a new window) against the weight: a stone on
                                 // one contact point keeps rocking among the vertices of the face it lies on (ω ~ 0.01
                                 // rad/s, kinetic energy ~1e-14 J here), so the force of one step is not the weight
    e.set_mesh_kinematics(m, &pos, &zeros, &zeros, dem::MotionRule::Quadratic)
        .unwrap();
    let v0 = e.particles().velocity[0].z;
    e.advance(100_000).unwrap();
    let f = e.interface_forces(m, true);
    let fz: f64 = f.chunks(3).map(|c| c[2]).sum();
    let fx: f64 = f.chunks(3).map(|c| c[0]).sum();
    // momentum balance over the window: mean force = weight + m Δv/T
    let dv = e.particles().velocity[0].z - v0;
    let weight = mass * 9.81;
    let ke = e.kinetic_energy();
    println!(
        "weight {weight:e} N, mean nodal force z {fz:e}, x {fx:e}, m Δv/T {:e}, KE {ke:e}",
        mass * dv / 0.2
    );
    assert!(
        (fz + weight + mass * dv / 0.2).abs() < 1e-7 * weight,
        "{fz} vs {weight}"
    );
    assert!((fz + weight).abs() < 1e-6 * weight, "{fz} vs {weight}");
    assert!(fx.abs() < 1e-6 * weight, "{fx}");
}

/// A box of plane walls with `count` stones (and as many spheres with `mixed`) poured in.
fn poured_scene(threads: usize, count: usize, mixed: bool) -> String {
    let spheres = if mixed {
        format!(
            r#"
[[dem.particles]]
kind = "fill"
material = "grain"
min = [0.0, 0.0, 0.002]
max = [0.05, 0.05, 0.08]
count = {count}
seed = 4
distribution = {{ kind = "uniform", min = 0.0015, max = 0.0025 }}
"#
        )
    } else {
        String::new()
    };
    format!(
        r#"
[dem]
time_step = 1e-5
threads = {threads}
[dem.materials.grain]
youngs_modulus = 5e7
poisson_ratio = 0.3
density = 1500.0
restitution = 0.3
friction = 0.5
[[dem.walls]]
kind = "box"
material = "grain"
min = [0.0, 0.0, 0.0]
max = [0.05, 0.05, 0.12]
open = ["+z"]
[[dem.walls]]
kind = "plane"
material = "grain"
point = [0.0, 0.0, 0.0]
normal = [1.0, 0.0, 0.0]
[[dem.particles]]
kind = "fill"
material = "grain"
min = [0.0, 0.0, 0.002]
max = [0.05, 0.05, 0.08]
count = {count}
seed = 3
distribution = {{ kind = "uniform", min = 0.002, max = 0.003 }}
velocity = [0.05, -0.02, 0.0]
shape = {{ kind = "polyhedron", triangles = 30, stones = 8 }}
{spheres}"#
    )
}

fn run_pour(threads: usize, steps: usize, split: bool) -> Vec<u8> {
    let mut e = common::engine(&poured_scene(threads, 80, true));
    if split {
        for _ in 0..steps {
            e.step().unwrap();
        }
    } else {
        e.advance(steps).unwrap();
    }
    assert!(
        e.num_contacts() >= 8 && e.num_wall_contacts() > 10,
        "the pour should be in contact by now: {} pairs, {} wall contacts",
        e.num_contacts(),
        e.num_wall_contacts()
    );
    // stones touch spheres (the mixed pairs go through the polyhedral narrow phase)
    let p = e.particles();
    let ids: Vec<u32> = (0..p.len())
        .filter(|&k| p.template(k).is_none())
        .map(|k| p.id[k])
        .collect();
    let mixed = e
        .shaped_pair_contacts()
        .filter(|(pair, c)| c.touching() && pair.iter().any(|id| ids.contains(id)))
        .count();
    assert!(mixed > 2, "{mixed} sphere–stone contacts");
    e.snapshot()
}

/// Bitwise: 1 vs 2 threads, `step` × n vs `advance(n)`, and a restored snapshot continues
/// as the uninterrupted run — a mixed bed of stones and spheres in a box of triangles and
/// planes.
#[test]
fn polyhedron_pour_is_bitwise_reproducible() {
    let steps = 10_000;
    let a = run_pour(1, steps, false);
    let b = run_pour(2, steps, false);
    assert!(a == b, "1 and 2 threads differ");
    let c = run_pour(2, steps, true);
    assert!(a == c, "step × n differs from advance(n)");
    let mut full = common::engine(&poured_scene(2, 80, true));
    full.advance(steps).unwrap();
    let mut half = common::engine(&poured_scene(2, 80, true));
    half.advance(steps / 2).unwrap();
    let snap = half.snapshot();
    let mut resumed = common::engine(&poured_scene(2, 80, true));
    resumed.restore(&snap).unwrap();
    resumed.advance(steps - steps / 2).unwrap();
    assert!(
        full.snapshot() == resumed.snapshot(),
        "restore does not continue bitwise"
    );
}

/// Two soft stones shot at each other far too fast: the overlap outgrows the dilation, the
/// cores meet, and the run stops with an error naming both particles and the limit.
#[test]
fn cores_meeting_stop_the_run_naming_the_pair() {
    let s = stones();
    let scene = ELASTIC.replace("youngs_modulus = 1e7", "youngs_modulus = 1e4");
    let mut e = engine_with(
        &scene,
        &[
            (
                V3::zeros(),
                V3::new(5.0, 0.0, 0.0),
                V3::zeros(),
                Orientation::identity(),
                &s[1],
                4e-3,
            ),
            (
                V3::new(5e-3, 0.0, 0.0),
                V3::new(-5.0, 0.0, 0.0),
                V3::zeros(),
                Orientation::identity(),
                &s[0],
                4e-3,
            ),
        ],
    );
    let err = (0..10_000)
        .find_map(|_| e.step().err())
        .expect("the cores must meet");
    let msg = err.to_string();
    println!("{msg}");
    assert!(
        msg.contains("cores of particle 0 and particle 1")
            || msg.contains("cores of particle 1 and particle 0"),
        "{msg}"
    );
    assert!(msg.contains("dilation"), "{msg}");
}

/// Shape keys out of range are refused at validation with the field and the limit named; a
/// non-convex stone in the library is refused naming the file and the vertex.
#[test]
fn polyhedron_keys_and_stone_files_are_validated() {
    let base = poured_scene(1, 5, false);
    for (bad, field) in [
        ("triangles = 30", "triangles = 31"),
        ("stones = 8", "stones = 8, dilation = 0.6"),
        ("stones = 8", "stones = 8, elongation = 0.5"),
    ] {
        let scene = base.replace(bad, field);
        let err = match dem::parse_scene_section(&scene) {
            Err(e) => e.to_string(),
            Ok(Some(cfg)) => match Engine::from_config(&cfg, std::path::Path::new(".")) {
                Err(e) => e.to_string(),
                Ok(_) => panic!("accepted: {field}"),
            },
            Ok(None) => panic!("no [dem]"),
        };
        let key = field
            .rsplit(", ")
            .next()
            .unwrap()
            .split(' ')
            .next()
            .unwrap();
        println!("{field}: {err}");
        assert!(err.contains(&format!("shape.{key}")), "{err}");
    }
    // a stone file with a dent
    let dir = tempfile::tempdir().unwrap();
    let mut stl = String::from("solid dent\n");
    let v = |x: f64, y: f64, z: f64| V3::new(x, y, z);
    let tris = [
        [v(0., 0., 0.), v(1., 1., 0.), v(1., 0., 0.)],
        [v(0., 0., 0.), v(0., 1., 0.), v(1., 1., 0.)],
        [v(0., 0., 0.), v(1., 0., 0.), v(0.5, 0.5, 0.2)],
        [v(1., 0., 0.), v(1., 1., 0.), v(0.5, 0.5, 0.2)],
        [v(1., 1., 0.), v(0., 1., 0.), v(0.5, 0.5, 0.2)],
        [v(0., 1., 0.), v(0., 0., 0.), v(0.5, 0.5, 0.2)],
        [v(0., 0., 0.), v(1., 0., 0.), v(0.5, 0.5, 1.0)],
        [v(1., 0., 0.), v(1., 1., 0.), v(0.5, 0.5, 1.0)],
    ];
    for t in tris {
        stl.push_str("facet normal 0 0 0\nouter loop\n");
        for p in t {
            stl.push_str(&format!("vertex {} {} {}\n", p.x, p.y, p.z));
        }
        stl.push_str("endloop\nendfacet\n");
    }
    stl.push_str("endsolid dent\n");
    std::fs::write(dir.path().join("dent.stl"), stl).unwrap();
    let scene = base.replace("stones = 8", "library = [\"dent.stl\"]");
    let cfg = dem::parse_scene_section(&scene).unwrap().unwrap();
    let err = Engine::from_config(&cfg, dir.path())
        .err()
        .unwrap()
        .to_string();
    println!("{err}");
    assert!(
        err.contains("dent.stl") && err.contains("not convex"),
        "{err}"
    );
}

/// The stones' VTK surfaces: every point of `polyhedra_*.vtk` lies on its stone's dilated
/// surface (distance r_ds from the core, to 1e-7 of the size: the file has 10 digits).
#[test]
fn polyhedra_show_their_real_surfaces_in_paraview() {
    let dir = tempfile::tempdir().unwrap();
    let scene = poured_scene(1, 5, false).replace(
        "[dem.materials.grain]",
        "[dem.output]\nvtk_every = 100\n[dem.materials.grain]",
    );
    let mut e = common::engine(&scene);
    e.advance(100).unwrap();
    e.write_outputs(dir.path()).unwrap();
    let name = std::fs::read_dir(dir.path())
        .unwrap()
        .filter_map(|f| f.ok().map(|f| f.file_name().to_string_lossy().to_string()))
        .find(|n| n.starts_with("polyhedra_") && n.ends_with(".vtk"))
        .expect("a polyhedra VTK file");
    assert!(dir.path().join("polyhedra.pvd").exists());
    let text = std::fs::read_to_string(dir.path().join(&name)).unwrap();
    let mut lines = text.lines().skip_while(|l| !l.starts_with("POINTS"));
    let n: usize = lines
        .next()
        .unwrap()
        .split_whitespace()
        .nth(1)
        .unwrap()
        .parse()
        .unwrap();
    let points: Vec<V3> = lines
        .take(n)
        .map(|l| {
            let c: Vec<f64> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            V3::new(c[0], c[1], c[2])
        })
        .collect();
    let ids: Vec<u32> = text
        .lines()
        .skip_while(|l| !l.starts_with("SCALARS id"))
        .skip(2)
        .take(n)
        .map(|l| l.parse().unwrap())
        .collect();
    let p = e.particles();
    let mut checked = 0;
    for (x, id) in points.iter().zip(&ids) {
        let k = p.id.iter().position(|i| i == id).unwrap();
        let (stone, scale) = p.polyhedron(k).unwrap();
        let local = p.orientation[k].inverse_transform_vector(&(x - p.position[k])) / scale;
        // distance of `local` (outside the core) to the core
        let mut d = f64::INFINITY;
        for t in &stone.triangles {
            let [a, b, c] = t.map(|i| stone.vertices[i as usize]);
            d = d.min(dem::triangle_contact::distance_squared(&local, &a, &b, &c).sqrt());
        }
        assert!(
            (d - stone.dilation).abs() < 1e-7,
            "{d} vs {}",
            stone.dilation
        );
        checked += 1;
    }
    assert!(
        checked == points.len() && points.len() > 5 * 100,
        "{checked} of {} points, {} ids",
        points.len(),
        ids.len()
    );
}

/// The validity limit `cosim check` reports (`dilation_impact_velocity_max`) is the speed at
/// which the cores meet: a stone falling onto a plane on its outermost vertex (straight
/// below its centre, so it does not turn) at 0.97 of it rebounds, at 1.03 of it stops the
/// run naming the plane.
#[test]
fn the_dilation_limit_is_the_speed_at_which_the_cores_meet() {
    let scene = format!(
        "{}interface_material = \"grain\"\n{}[[dem.walls]]\nkind = \"plane\"\nmaterial = \"grain\"\npoint = [0.0, 0.0, 0.0]\nnormal = [0.0, 0.0, 1.0]\n",
        "[dem]\ntime_step = 1e-7\ngravity = [0.0, 0.0, 0.0]\nallow_large_time_step = true\n",
        &ELASTIC[ELASTIC.find("[dem.materials").unwrap()..]
    );
    let stone = stones()[1].clone();
    let tip = *stone
        .vertices
        .iter()
        .max_by(|a, b| a.norm().total_cmp(&b.norm()))
        .unwrap();
    let down = Orientation::rotation_between(&tip, &-V3::z()).unwrap();
    let size = 4e-3;
    let height = tip.norm() * size + stone.dilation * size;
    let limit = {
        let e = engine_with(
            &scene,
            &[(
                V3::new(0.0, 0.0, 0.01),
                V3::zeros(),
                V3::zeros(),
                down,
                &stone,
                size,
            )],
        );
        e.limits()
            .into_iter()
            .find(|(k, _)| k == "dilation_impact_velocity_max")
            .expect("the limit is reported")
            .1
    };
    println!("dilation impact velocity limit {limit} m/s");
    for (factor, fails) in [(0.97, false), (1.03, true)] {
        let mut e = engine_with(
            &scene,
            &[(
                V3::new(0.0, 0.0, height + 1e-6),
                V3::new(0.0, 0.0, -factor * limit),
                V3::zeros(),
                down,
                &stone,
                size,
            )],
        );
        let mut outcome = Ok(());
        for _ in 0..200_000 {
            outcome = e.step();
            if outcome.is_err() || e.particles().velocity[0].z > 0.0 {
                break;
            }
        }
        match outcome {
            Ok(()) => {
                assert!(!fails, "{factor}: no core contact");
                assert!(e.particles().velocity[0].z > 0.0, "{factor}: no rebound");
            }
            Err(err) => {
                println!("{factor}: {err}");
                assert!(fails, "{factor}: {err}");
                assert!(
                    err.to_string().contains("particle 0 and plane wall 0"),
                    "{err}"
                );
            }
        }
    }
}

/// A poured bed of stones and spheres written as `particles_final.csv` (with its stone
/// library `particles_final.stones.json`) starts the next run where it stopped: positions,
/// velocities, orientations, angular velocities, masses, moments and stones read back
/// bitwise, and both runs continue alike.
#[test]
fn polyhedron_bed_round_trips_through_a_particle_file() {
    let dir = tempfile::tempdir().unwrap();
    let scene = poured_scene(1, 40, true).replace(
        "[dem.materials.grain]",
        "[dem.output]\nfinal_particles = true\n[dem.materials.grain]",
    );
    let mut a = common::engine(&scene);
    a.advance(3000).unwrap();
    let file = a.write_final_particles(dir.path()).unwrap().unwrap();
    assert!(dir.path().join("particles_final.stones.json").exists());
    let start = scene.find("[[dem.particles]]").unwrap();
    let next = format!(
        "{}[[dem.particles]]\nkind = \"file\"\nmaterial = \"grain\"\npath = \"{}\"\n",
        &scene[..start],
        file.display()
    );
    let mut b = common::engine(&next);
    let (pa, pb) = (a.particles(), b.particles());
    assert_eq!(pa.len(), pb.len());
    let mut stones = 0;
    for ka in 0..pa.len() {
        let kb = pb.id.iter().position(|&i| i == pa.id[ka]).unwrap();
        assert_eq!(pa.position[ka], pb.position[kb]);
        assert_eq!(pa.velocity[ka], pb.velocity[kb]);
        assert_eq!(pa.angular_velocity[ka], pb.angular_velocity[kb]);
        assert_eq!(pa.orientation[ka], pb.orientation[kb]);
        assert_eq!(pa.mass[ka].to_bits(), pb.mass[kb].to_bits());
        assert_eq!(pa.radius[ka].to_bits(), pb.radius[kb].to_bits());
        match (pa.polyhedron(ka), pb.polyhedron(kb)) {
            (None, None) => assert!(pa.template(ka).is_none() && pb.template(kb).is_none()),
            (Some((sa, ka_scale)), Some((sb, kb_scale))) => {
                assert_eq!(sa, sb);
                assert_eq!(ka_scale.to_bits(), kb_scale.to_bits());
                stones += 1;
            }
            other => panic!("{other:?}"),
        }
    }
    assert_eq!(stones, 40);
    // a wrong stone index names the line and the library
    let text = std::fs::read_to_string(&file).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let col = header.iter().position(|c| *c == "stone").unwrap();
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let line = (1..lines.len())
        .find(|&l| !lines[l].split(',').nth(col).unwrap().is_empty())
        .unwrap();
    let mut fields: Vec<String> = lines[line].split(',').map(String::from).collect();
    fields[col] = "99".into();
    lines[line] = fields.join(",");
    std::fs::write(&file, lines.join("\n")).unwrap();
    let cfg = dem::parse_scene_section(&next).unwrap().unwrap();
    let err = Engine::from_config(&cfg, std::path::Path::new("."))
        .err()
        .unwrap()
        .to_string();
    println!("{err}");
    assert!(
        err.contains(&format!("line {}", line + 1)) && err.contains("stones.json"),
        "{err}"
    );
    // both continue alike
    a.advance(500).unwrap();
    b.advance(500).unwrap();
    let (pa, pb) = (a.particles(), b.particles());
    for ka in 0..pa.len() {
        let kb = pb.id.iter().position(|&i| i == pa.id[ka]).unwrap();
        assert!((pa.position[ka] - pb.position[kb]).norm() < 1e-9);
    }
}

/// The force has no jump while the closest features change: a stone slid across a box edge
/// (face → edge → off), and a stone turned against another (its closest face, edge and
/// vertex take turns). Sampled along the path at n and 2n points, the largest change of the
/// force between neighbouring samples halves with the spacing (a jump would stay).
#[test]
fn the_force_has_no_jump_between_face_edge_and_vertex() {
    let s = stones();
    let path_max_step = |n: usize, f: &mut dyn FnMut(f64) -> V3| -> (f64, f64) {
        let forces: Vec<V3> = (0..=n).map(|k| f(k as f64 / n as f64)).collect();
        let scale = forces.iter().map(|f| f.norm()).fold(0.0, f64::max);
        let step = forces
            .windows(2)
            .map(|w| (w[1] - w[0]).norm())
            .fold(0.0, f64::max);
        (step, scale)
    };
    // across the edge x = 0.02 of a box's top face (z = 0.02)
    let scene = format!(
        "{ELASTIC}[[dem.walls]]\nkind = \"box\"\nmaterial = \"grain\"\nmin = [0.0, 0.0, 0.0]\nmax = [0.02, 0.02, 0.02]\n"
    );
    let q = rot([0.3, 1.0, 0.2], 0.7);
    let mut e = engine_with(
        &scene,
        &[(
            V3::new(0.017, 0.01, 0.022),
            V3::zeros(),
            V3::zeros(),
            q,
            &s[1],
            4e-3,
        )],
    );
    // the stone's lowest point just below the top face: overlap ~ 20 µm while over the face
    let lowest = {
        let local = q.inverse_transform_vector(&-V3::z());
        (q * (s[1].support(&local) * 4e-3)).z - s[1].dilation * 4e-3
    };
    let z0 = 0.02 - lowest - 2e-5;
    let mut slide = |t: f64| -> V3 {
        // from over the face, across the edge, down the side
        let x = 0.016 + 0.008 * t;
        let z = z0 - 0.004 * (t - 0.5).max(0.0);
        e.particles_mut().position[0] = V3::new(x, 0.01, z);
        e.refresh_forces();
        e.particles().force[0]
    };
    let (a, scale) = path_max_step(1000, &mut slide);
    let (b, _) = path_max_step(2000, &mut slide);
    println!(
        "edge: largest force change {a:e} N (n = 1000), {b:e} N (n = 2000), |F| ≤ {scale:e} N"
    );
    assert!(
        scale > 0.0 && b < 0.6 * a && b < 0.05 * scale,
        "{a} {b} {scale}"
    );
    // a stone turned against another about an axis through its centre, in contact all along
    // (placed at an overlap of half a dilation radius first, by bisection on the distance)
    let mut e = engine_with(
        ELASTIC,
        &[
            (
                V3::zeros(),
                V3::zeros(),
                V3::zeros(),
                Orientation::identity(),
                &s[2],
                4e-3,
            ),
            (
                V3::new(8e-3, 0.0, 0.0),
                V3::zeros(),
                V3::zeros(),
                Orientation::identity(),
                &s[1],
                4e-3,
            ),
        ],
    );
    let target = 0.5 * s[1].dilation * 4e-3;
    let overlap = |e: &Engine| {
        e.shaped_pair_contacts()
            .map(|c| c.1.overlap)
            .fold(-1.0, f64::max)
    };
    let (mut near, mut far) = (2e-3, 8e-3);
    for _ in 0..60 {
        let d = 0.5 * (near + far);
        e.particles_mut().position[1].x = d;
        e.refresh_forces();
        if overlap(&e) > target {
            near = d;
        } else {
            far = d;
        }
    }
    let mut touching = true;
    let mut turn = |t: f64| -> V3 {
        e.particles_mut().orientation[1] = rot([0.2, 0.4, 1.0], 0.5 * t);
        e.refresh_forces();
        touching &= overlap(&e) > 0.0;
        e.particles().force[0]
    };
    let (a, scale) = path_max_step(1000, &mut turn);
    let (b, _) = path_max_step(2000, &mut turn);
    println!(
        "turning: largest force change {a:e} N (n = 1000), {b:e} N (n = 2000), |F| ≤ {scale:e} N"
    );
    assert!(touching, "the stones must stay in contact while turning");
    assert!(
        scale > 0.0 && b < 0.6 * a && b < 0.05 * scale,
        "{a} {b} {scale}"
    );
}

/// Stones have the sphere law's restitution dashpots (U Table 6.1's e = 0.2), and with them
/// its damped step (`damped_step_limit`, dem-node/src/limits.rs): by hand for a small and a
/// large stone of one material — Hertz between the dilation spheres at 1 % of the smaller
/// r_ds, Mindlin's k_t, the dashpots γ_n = 2√(5/6)|β|√(k_n m*) (β calibrated to e), γ_t = γ_n √(k_t/k_n), and the
/// counter-rotation of six neighbours with each stone's bounding radius as the lever arm and
/// its smallest principal moment. A stone turns more easily than its volume-equal sphere
/// (r²/I above 2.5/m), so that mode sets the limit; without rotation the normal mode does.
#[test]
fn stones_report_the_damped_step_of_their_restitution_dashpot() {
    let scene = ELASTIC.replace("restitution = 1.0", "restitution = 0.2");
    let stone = stones()[1].clone();
    let (small, large) = (3e-3, 5e-3);
    let bodies = [small, large].map(|size| {
        (
            V3::new(size * 100.0, 0.0, 0.0),
            V3::zeros(),
            V3::zeros(),
            Orientation::identity(),
            &stone,
            size,
        )
    });
    let limits = |scene: &str| -> std::collections::BTreeMap<String, f64> {
        engine_with(scene, &bodies).limits().into_iter().collect()
    };
    let l = limits(&scene);
    // by hand
    let (e, nu, rho) = (1e7, 0.3, 1000.0);
    let e_star = e / (2.0 * (1.0 - nu * nu));
    // k_t / k_n, Mindlin over Hertz
    let stiffness_ratio = 2.0 * (1.0 - nu) / (2.0 - nu);
    // (r_ds, m, lever, I) of the stone at `size`
    let body = |size: f64| {
        (
            stone.dilation * size,
            rho * stone.volume * size.powi(3),
            stone.circumradius * size,
            rho * stone.inertia.min() * size.powi(5),
        )
    };
    // (step, mode, ζ) with the dashpot of |β|; with rotation, the normal mode's compliance
    // also has the turn of an off-centre normal, l²/I per stone
    let by_hand = |beta: f64, rotation: bool| {
        let mut want = (f64::INFINITY, 0.0, 0.0);
        for (a, b) in [(small, small), (small, large), (large, small)] {
            let ((ra, ma, la, ia), (rb, mb, lb, ib)) = (body(a), body(b));
            let k_n = 2.0 * e_star * (ra * rb / (ra + rb) * 0.01 * ra.min(rb)).sqrt();
            let k_t = stiffness_ratio * k_n;
            let m_eff = ma * mb / (ma + mb);
            let gamma_n = 2.0 * (5.0f64 / 6.0).sqrt() * beta * (k_n * m_eff).sqrt();
            let gamma_t = gamma_n * stiffness_ratio.sqrt();
            let turn = la * la / ia + lb * lb / ib;
            let w_n = (2.0 * k_n * (1.0 / m_eff + if rotation { turn } else { 0.0 })).sqrt();
            let w_t = (4.0 * k_t * turn).sqrt();
            let mut modes = vec![(
                dem::limits::damped_step(w_n, gamma_n / k_n),
                0.0,
                0.5 * w_n * gamma_n / k_n,
            )];
            if rotation {
                modes.push((
                    dem::limits::damped_step(w_t, gamma_t / k_t),
                    1.0,
                    0.5 * w_t * gamma_t / k_t,
                ));
            }
            for (h, mode, zeta) in modes {
                if h < want.0 {
                    want = (h, mode, zeta);
                }
            }
        }
        want
    };
    let matches = |l: &std::collections::BTreeMap<String, f64>, want: (f64, f64, f64)| {
        for (key, value) in [
            ("damped_step_limit", want.0),
            ("damped_step_mode", want.1),
            ("damped_step_zeta", want.2),
        ] {
            assert!(
                (l[key] - value).abs() <= 1e-9 * value.abs(),
                "{key}: {} vs {value}",
                l[key]
            );
        }
    };
    // |β| of the Tsuji dashpot calibrated to e = 0.2 on the Hertz impact
    let beta = -dem::hertz_mindlin::damping_beta(0.2);
    let want = by_hand(beta, true);
    let (_, m, l_arm, i) = body(small);
    println!(
        "stone r²/I = {:.3} / m (a sphere's 2.5 / m); damped step {:?}, by hand {want:?}",
        l_arm * l_arm / i * m,
        (
            l["damped_step_limit"],
            l["damped_step_mode"],
            l["damped_step_zeta"]
        )
    );
    assert!(l_arm * l_arm / i > 2.5 / m);
    assert_eq!(want.1, 1.0, "the counter-rotation mode sets it");
    matches(&l, want);
    // rotation locked: the normal mode alone, of the masses alone, a longer step
    let locked = limits(&scene.replace("[dem]\n", "[dem]\nrotation = false\n"));
    matches(&locked, by_hand(beta, false));
    assert!(locked["damped_step_limit"] > l["damped_step_limit"]);
    // no dashpot (e = 1): the undamped limit 2/ω of the stiffest mode
    let elastic = limits(ELASTIC);
    let undamped = by_hand(0.0, true);
    assert_eq!(undamped.2, 0.0);
    matches(&elastic, undamped);
}
