//! Bitwise reproducibility: any thread count, and snapshot/restore continuation.
mod common;
use common::*;
use dem::MotionRule;

fn scene(threads: Option<usize>) -> String {
    scene_with(threads, 1)
}

fn scene_with(threads: Option<usize>, impact_substeps: usize) -> String {
    let t = threads
        .map(|n| format!("threads = {n}\n"))
        .unwrap_or_default();
    format!(
        r#"
[dem]
time_step = 5e-5
gravity = [0.0, 0.0, -9.81]
interface_material = "steel"
impact_substeps = {impact_substeps}
{t}
[dem.materials.grain]
youngs_modulus = 5e6
poisson_ratio = 0.3
density = 1500.0
restitution = 0.5
friction = 0.5
rolling_friction = 0.05
[dem.materials.steel]
youngs_modulus = 2e11
poisson_ratio = 0.3
density = 7800.0
restitution = 0.6
friction = 0.3
[[dem.walls]]
kind = "box"
material = "steel"
min = [0.0, 0.0, 0.0]
max = [0.1, 0.1, 0.3]
open = ["+z"]
[[dem.particles]]
kind = "fill"
material = "grain"
min = [0.0, 0.0, 0.05]
max = [0.1, 0.1, 0.3]
count = 3000
seed = 7
distribution = {{ kind = "uniform", min = 0.002, max = 0.003 }}
velocity = [0.1, -0.05, 0.0]
"#
    )
}

/// A coupled plate inside the box moving by the JIT rule.
fn add_plate(e: &mut dem::Engine) -> usize {
    let pos = [
        0.0, 0.0, 0.045, 0.1, 0.0, 0.045, 0.1, 0.1, 0.045, 0.0, 0.1, 0.045,
    ];
    let m = e
        .add_coupled_mesh("plate", &pos, &[0, 1, 2, 0, 2, 3])
        .unwrap();
    let v = [0.0, 0.0, 0.05].repeat(4);
    let a = [0.0, 0.0, -1.0].repeat(4);
    e.set_mesh_kinematics(m, &pos, &v, &a, MotionRule::Quadratic)
        .unwrap();
    m
}

fn run_in_pool(threads: usize, steps: usize) -> (Vec<u8>, Vec<f64>) {
    run_in_pool_with(threads, steps, 1).0
}

/// (snapshot, averaged interface forces), refined steps.
fn run_in_pool_with(
    threads: usize,
    steps: usize,
    impact_substeps: usize,
) -> ((Vec<u8>, Vec<f64>), u64) {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        let mut e = engine(&scene_with(None, impact_substeps));
        let m = add_plate(&mut e);
        e.advance(steps).unwrap();
        (
            (e.snapshot(), e.interface_forces(m, true)),
            e.refined_steps(),
        )
    })
}

#[test]
fn one_and_two_threads_give_bitwise_equal_state() {
    let (a, fa) = run_in_pool(1, 1500);
    let (b, fb) = run_in_pool(2, 1500);
    let ea = engine(&scene(None));
    println!(
        "snapshot {} bytes, {} particles",
        a.len(),
        ea.num_particles()
    );
    assert!(fa.iter().any(|f| *f != 0.0), "particles reached the plate");
    assert_eq!(fa, fb, "interface forces differ");
    assert!(a == b, "engine state differs between 1 and 2 threads");
    // the engine's own pool (dem.threads) gives the same bits
    let mut e = engine(&scene(Some(2)));
    add_plate(&mut e);
    e.advance(1500).unwrap();
    assert!(e.snapshot() == a);
}

#[test]
fn snapshot_restore_continues_bitwise_identically() {
    let mut e = engine(&scene(None));
    let m = add_plate(&mut e);
    e.advance(600).unwrap();
    let snap = e.snapshot();
    let t_snap = e.time();
    e.advance(600).unwrap();
    let end_a = e.snapshot();
    let forces_a = e.interface_forces(m, false);

    let mut f = engine(&scene(None));
    add_plate(&mut f);
    f.restore(&snap).unwrap();
    assert_eq!(f.time(), t_snap);
    f.advance(600).unwrap();
    assert!(f.snapshot() == end_a, "continuation after restore differs");
    assert_eq!(f.interface_forces(m, false), forces_a);
    assert!(f.restore(&snap[..snap.len() / 2]).is_err());
}

/// Impact refinement sub-steps the whole system, and its decision is a boolean over all
/// contacts: 1 and 2 threads (and the engine's own pool) give the same bits, and the same
/// refined steps.
#[test]
fn impact_refinement_gives_bitwise_equal_state_for_one_and_two_threads() {
    let steps = 800;
    let ((a, fa), ra) = run_in_pool_with(1, steps, 4);
    let ((b, fb), rb) = run_in_pool_with(2, steps, 4);
    println!("refined {ra} of {steps} steps");
    assert!(ra > 0 && ra == rb);
    assert!(fa.iter().any(|f| *f != 0.0), "particles reached the plate");
    assert_eq!(fa, fb, "interface forces differ");
    assert!(a == b, "engine state differs between 1 and 2 threads");
    let mut e = engine(&scene_with(Some(2), 4));
    add_plate(&mut e);
    e.advance(steps).unwrap();
    assert!(e.snapshot() == a);
    let (plain, _) = run_in_pool(1, steps);
    assert!(plain != a, "refinement changed the run");
}
