//! Sinks (`[[dem.sinks]] min, max`): particles whose centre enters the box are removed at the
//! next neighbour-list build, counted in `removed_particles` / `removed_mass`.
mod common;
use common::*;

/// 128 spheres over a table that covers half of them: 64 land on it, 64 fall past it into the
/// sink 0.1 m below.
fn table_scene(extra: &str, sink: &str) -> String {
    format!(
        r#"
[dem]
time_step = 5e-5
gravity = [0.0, 0.0, -9.81]
{extra}
{GRAIN}
[[dem.walls]]
kind = "box"
material = "grain"
min = [0.0, 0.0, -0.01]
max = [0.05, 0.1, 0.0]
[[dem.particles]]
kind = "lattice"
material = "grain"
radius = 0.0045
first = [0.006, 0.006, 0.01]
spacing = 0.0125
count = [8, 8, 2]
{sink}
"#
    )
}

const SINK: &str = r#"
[[dem.sinks]]
min = [-1.0, -1.0, -1.0]
max = [1.0, 1.0, -0.1]
"#;

#[test]
fn particles_falling_into_a_sink_are_removed_and_counted() {
    let mut e = engine(&table_scene("", SINK));
    let m = e.particles().mass[0];
    assert_eq!(e.num_particles(), 128);
    e.advance(2000).unwrap(); // 0.1 s: the falling half has dropped 5 cm, not yet 10
    assert_eq!(e.num_particles(), 128);
    assert_eq!(result(&e, "removed_particles"), 0.0);
    e.advance(4000).unwrap(); // 0.3 s: fell 0.44 m
    assert_eq!(e.num_particles(), 64, "the half off the table is gone");
    assert_eq!(result(&e, "removed_particles"), 64.0);
    assert!((result(&e, "removed_mass") - 64.0 * m).abs() < 1e-12 * m);
    // the ones left are those resting on the table, with their identities
    let p = e.particles();
    assert!(p.position.iter().all(|x| x.x < 0.05 && x.z > 0.0));
    let mut ids: Vec<u32> = p.id.clone();
    ids.sort();
    let expected: Vec<u32> = (0..128u32).filter(|&k| (k % 8) < 4).collect();
    assert_eq!(ids, expected, "lattice order: x fastest");
    e.advance(2000).unwrap();
    assert!(result(&e, "kinetic_energy") < 1e-6, "the rest lie still");
}

#[test]
fn a_sink_is_bitwise_deterministic_across_threads_step_advance_and_restore() {
    let run = |threads: usize, fused: bool| {
        let mut e = engine(&table_scene(&format!("threads = {threads}"), SINK));
        if fused {
            e.advance(5000).unwrap();
        } else {
            for _ in 0..5000 {
                e.step().unwrap();
            }
        }
        assert!(e.num_particles() < 128, "particles were removed");
        e.snapshot()
    };
    let a = run(1, true);
    assert!(a == run(2, true), "1 vs 2 threads");
    assert!(a == run(1, false), "advance vs step");
    let mut e = engine(&table_scene("", SINK));
    e.advance(3000).unwrap();
    let snap = e.snapshot();
    let mut f = engine(&table_scene("", SINK));
    f.restore(&snap).unwrap();
    f.advance(2000).unwrap();
    assert!(f.snapshot() == a, "continuation after restore");
}

#[test]
fn without_a_sink_nothing_is_removed_and_there_is_no_count() {
    let mut e = engine(&table_scene("", ""));
    e.advance(6000).unwrap();
    assert_eq!(e.num_particles(), 128);
    assert!(e.results().iter().all(|(k, _)| k != "removed_particles"));
}

#[test]
fn an_empty_sink_box_is_refused_with_its_field() {
    let text = table_scene("", &SINK.replace("-0.1]", "-1.0]"));
    let err = dem::parse_scene_section(&text).unwrap_err();
    println!("{err}");
    assert!(err.message.contains("dem.sinks[0].max"), "{err}");
    let text = table_scene("", &SINK.replace("min =", "low ="));
    let err = dem::parse_scene_section(&text).unwrap_err();
    assert!(err.message.contains("low"), "{err}");
}

#[test]
fn a_flow_sensor_keeps_counting_while_a_sink_removes_particles() {
    // the lower layer reaches the sink (z < −0.1) while the upper one, 12.5 mm higher, has yet
    // to cross the sensor plane at z = −0.095: every crossing must count, removals or not
    let sensor = r#"
[[dem.sensors]]
name = "down"
kind = "flow"
axis = "z"
value = -0.095
"#;
    let mut e = engine(&table_scene("", &format!("{SINK}{sensor}")));
    let m = e.particles().mass[0];
    let dir = tempfile::tempdir().unwrap();
    let mut removed_before_last_crossing = false;
    for _ in 0..60 {
        e.advance(100).unwrap(); // 5 ms
        e.write_outputs(dir.path()).unwrap();
        let crossed = result(&e, "sensor.down.mass");
        if result(&e, "removed_particles") > 0.0 && crossed < 64.0 * m * (1.0 - 1e-9) {
            removed_before_last_crossing = true;
        }
    }
    assert!(
        removed_before_last_crossing,
        "the test needs removals before the last crossing"
    );
    assert_eq!(result(&e, "removed_particles"), 64.0);
    let crossed = result(&e, "sensor.down.mass");
    assert!(
        (crossed - 64.0 * m).abs() < 1e-9 * m,
        "{crossed} kg vs {} kg",
        64.0 * m
    );
}
