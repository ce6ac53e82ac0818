//! The DEM side of the Arlequin volume coupling (Wellmann ch. 6, SEED-SPEC §4): weighted
//! equations of motion (6.10)–(6.11) with contact-point weights (6.29), the penalty forces
//! (6.25)–(6.26) against prescribed FE node motions, the explicit step limit of the penalty,
//! the reference-configuration check, bitwise continuation and thread independence.
mod common;
use common::*;
use dem::hertz_mindlin::V3;
use dem::volume_coupling::{OverlapMesh, Projection, VolumeSettings};
use dem::{Engine, MotionRule};
use numeric::iso::IsoShape;

const MM: f64 = 1e-3;

/// 6 × 6 × 6 spheres of radius 0.45 mm at `spacing` from (0.5, 0.5, 0.5) mm, no gravity.
fn bed(spacing_mm: f64, jitter_mm: f64, threads: usize) -> Engine {
    bed_r(0.45, spacing_mm, jitter_mm, threads, 1e-6)
}

fn bed_r(radius_mm: f64, spacing_mm: f64, jitter_mm: f64, threads: usize, dt: f64) -> Engine {
    engine(&format!(
        r#"
[dem]
time_step = {dt}
gravity = [0.0, 0.0, 0.0]
threads = {threads}
{GRAIN}
[[dem.particles]]
kind = "lattice"
material = "grain"
radius = {radius}
first = [0.5e-3, 0.5e-3, 0.5e-3]
spacing = {spacing}
count = [6, 6, 6]
jitter = {jitter}
seed = 3
"#,
        radius = radius_mm * MM,
        spacing = spacing_mm * MM,
        jitter = jitter_mm * MM,
    ))
}

/// The overlap: 3 × 3 × 1 hex8 elements of 2 mm over z ∈ [0, 2] mm, w = 0 at z = 0 (the FE
/// side) and 1 at z = 2 mm (the DE side). Returns (ids, flat positions, elements, weights).
fn overlap() -> (Vec<u64>, Vec<f64>, Vec<u32>, Vec<f64>) {
    let (nx, ny, h) = (3usize, 3usize, 2.0 * MM);
    let id = |i: usize, j: usize, k: usize| (k * (ny + 1) + j) * (nx + 1) + i;
    let (mut ids, mut x, mut w) = (Vec::new(), Vec::new(), Vec::new());
    for k in 0..=1 {
        for j in 0..=ny {
            for i in 0..=nx {
                ids.push(100 + id(i, j, k) as u64);
                x.extend([i as f64 * h, j as f64 * h, k as f64 * h]);
                w.push(k as f64);
            }
        }
    }
    let mut e = Vec::new();
    for j in 0..ny {
        for i in 0..nx {
            // the corners in hex8 order: reference ±1 → lattice offsets 0/1
            for r in IsoShape::Hex8.reference_nodes() {
                let [a, b, c] = r.map(|x| usize::from(x > 0.0));
                e.push(id(i + a, j + b, c) as u32);
            }
        }
    }
    (ids, x, e, w)
}

fn mesh(ids: Vec<u64>, x: &[f64], elements: Vec<u32>, weights: Vec<f64>) -> OverlapMesh {
    OverlapMesh {
        shape: IsoShape::Hex8,
        node_ids: ids,
        nodes: x.chunks(3).map(|c| V3::new(c[0], c[1], c[2])).collect(),
        elements,
        weights,
    }
}

fn attach(e: &mut Engine, settings: VolumeSettings) -> Result<usize, dem::DemError> {
    let (ids, x, el, w) = overlap();
    e.add_volume_interface("soil", mesh(ids, &x, el, w), settings)
}

/// Prescribes the FE nodes at their reference positions plus `d(x)`, at rest.
fn move_fe(e: &mut Engine, iface: usize, d: impl Fn(V3) -> V3) {
    let (_, x, _, _) = overlap();
    let p: Vec<f64> = x
        .chunks(3)
        .flat_map(|c| {
            let x = V3::new(c[0], c[1], c[2]);
            let y = x + d(x);
            [y.x, y.y, y.z]
        })
        .collect();
    let zero = vec![0.0; p.len()];
    e.set_volume_kinematics(iface, &p, &zero, &zero, MotionRule::Quadratic)
        .unwrap();
}

/// The weight of the mass of a particle now at height `z`: w = z₀ / 2 mm at its lattice
/// height z₀ (the reference configuration) in the overlap, floored.
fn mass_weight(z: f64, floor: f64) -> f64 {
    let z0 = ((z / MM - 0.5).round() + 0.5) * MM;
    (z0 / (2.0 * MM)).clamp(0.0, 1.0).max(floor)
}

/// Without contacts, the coupled particles and the penalty form a conservative system with
/// masses w m: pulled by a translated FE field, the particles swing about it, and
/// Σ ½ w m v² + C (6.23) stays constant under velocity Verlet up to its O(Δt²) error
/// (halving the step divides it by four).
#[test]
fn particles_pulled_by_the_penalty_conserve_the_weighted_energy() {
    for projection in [Projection::Lumped, Projection::Consistent] {
        let mut errors = Vec::new();
        for dt in [2e-7, 1e-7] {
            let mut e = bed_r(0.45, 1.0, 0.0, 1, dt);
            let settings = VolumeSettings {
                projection,
                ..Default::default()
            };
            let iface = attach(&mut e, settings).unwrap();
            let d = V3::new(2e-5, -1e-5, 0.5e-5);
            move_fe(&mut e, iface, |_| d);
            e.refresh_forces();
            let energy = |e: &Engine| {
                let p = e.particles();
                let kinetic: f64 = (0..p.len())
                    .map(|k| {
                        0.5 * p.mass[k]
                            * mass_weight(p.position[k].z, settings.min_weight)
                            * p.velocity[k].norm_squared()
                    })
                    .sum();
                kinetic + e.volume_energy(iface)
            };
            let e0 = energy(&e);
            assert!(e0 > 0.0, "{projection:?}: no penalty energy");
            let (mut max_err, mut max_ux) = (0.0f64, 0.0f64);
            // every step (the fast modes alias at coarser sampling), over 50 µs
            for _ in 0..(50e-6 / dt).round() as usize {
                e.advance(1).unwrap();
                max_err = max_err.max((energy(&e) - e0).abs() / e0);
                let p = e.particles();
                let coupled: Vec<usize> = (0..p.len())
                    .filter(|&k| p.position[k].z < 2.0 * MM)
                    .collect();
                let ux = coupled
                    .iter()
                    .map(|&k| {
                        let x = p.position[k].x / MM - 0.5;
                        (x - x.round()) * MM
                    })
                    .sum::<f64>()
                    / coupled.len() as f64;
                max_ux = max_ux.max(ux);
                // particles outside the overlap feel nothing
                for k in 0..p.len() {
                    if p.position[k].z > 2.0 * MM {
                        assert_eq!(p.velocity[k], V3::zeros());
                    }
                }
            }
            assert!(
                max_ux > 0.9 * d.x,
                "{projection:?}: the particles did not follow the FE field (max mean u_x \
                 {max_ux:e})"
            );
            errors.push(max_err);
        }
        eprintln!("{projection:?}: energy errors {errors:?} at Δt 2e-7, 1e-7");
        assert!(
            errors[1] < 5e-3,
            "{projection:?}: energy error {:e}",
            errors[1]
        );
        let order = errors[0] / errors[1];
        assert!(
            (3.0..5.0).contains(&order),
            "{projection:?}: halving the step divided the energy error by {order}"
        );
    }
}

/// Each contact force carries one weight for both bodies (6.29), so Σ w m a = Σ w F over the
/// bodies equals the penalty's reaction on the FE nodes: the coupled system's momentum
/// balance holds to round-off, in a jittered, compressed packing whose contacts cross the
/// overlap.
#[test]
fn weighted_forces_balance_with_the_penalty_reaction() {
    let mut e = bed_r(0.5, 1.0, 0.0, 1, 2e-7);
    let iface = attach(&mut e, VolumeSettings::default()).unwrap();
    // compresses the overlap layer (strain −0.5 % in z) and shears it
    move_fe(&mut e, iface, |x| {
        V3::new(1e-3 * x.z, 0.0, 5e-3 * (2.0 * MM - x.z))
    });
    for round in 0..3 {
        e.advance(100).unwrap();
        let p = e.particles();
        let mut sum = V3::zeros();
        let mut scale = 0.0;
        for k in 0..p.len() {
            let f = p.force[k] * mass_weight(p.position[k].z, 0.05);
            sum += f;
            scale += f.norm();
        }
        let on_nodes = e.volume_penalty_forces(iface);
        let nodes: V3 = on_nodes.chunks(3).map(|c| V3::new(c[0], c[1], c[2])).sum();
        eprintln!("round {round}: {} contacts", e.num_contacts());
        assert!(
            e.num_contacts() > 50,
            "too few contacts ({})",
            e.num_contacts()
        );
        assert!(nodes.norm() > 0.0);
        let residual = (sum + nodes).norm();
        assert!(
            residual < 1e-9 * scale,
            "round {round}: Σ w F + Σ f_I = {:?} ({residual:e} of {scale:e})",
            sum + nodes
        );
    }
}

/// The result does not depend on the thread count, and a snapshot taken mid-run continues
/// bitwise (the coupling operators are rebuilt from the stored overlap, particles and ε — the
/// restoring engine attached its interface with another ε — and the last step's pull is
/// there again for a replayed publish).
#[test]
fn coupled_runs_are_bitwise_for_threads_and_resume() {
    let run = |threads: usize, split: Option<usize>| {
        let mut e = bed_r(0.5, 1.0, 0.0, threads, 2e-7);
        let iface = attach(
            &mut e,
            VolumeSettings {
                projection: Projection::Consistent,
                penalty: 5e13,
                ..Default::default()
            },
        )
        .unwrap();
        move_fe(&mut e, iface, |x| {
            V3::new(2e-3 * x.z, 0.0, 5e-3 * (2.0 * MM - x.z))
        });
        if let Some(n) = split {
            e.advance(n).unwrap();
            let snap = e.snapshot();
            let mut f = bed_r(0.5, 1.0, 0.0, threads, 2e-7);
            attach(&mut f, VolumeSettings::default()).unwrap();
            f.restore(&snap).unwrap();
            let last = e.volume_forces(0, false);
            assert!(last.iter().any(|&v| v != 0.0));
            assert_eq!(
                f.volume_forces(0, false),
                last,
                "the last pull after a restore"
            );
            f.advance(300 - n).unwrap();
            e = f;
        } else {
            e.advance(300).unwrap();
        }
        let p = e.particles();
        let mut state: Vec<(u32, [u64; 6])> = (0..p.len())
            .map(|k| {
                let (x, v) = (p.position[k], p.velocity[k]);
                (p.id[k], [x.x, x.y, x.z, v.x, v.y, v.z].map(f64::to_bits))
            })
            .collect();
        state.sort();
        (state, e.volume_forces(0, true), e.volume_energy(0))
    };
    let one = run(1, None);
    assert!(one.2 > 0.0);
    assert_eq!(one, run(2, None), "1 vs 2 threads");
    assert_eq!(one, run(1, Some(137)), "resumed at step 137");
}

#[test]
fn a_particle_leaving_its_element_stops_the_run_naming_it() {
    let mut e = bed(1.0, 0.0, 1);
    let iface = attach(&mut e, VolumeSettings::default()).unwrap();
    let p = e.particles_mut();
    let k = (0..p.len()).find(|&k| p.position[k].z < 1.0 * MM).unwrap();
    let id = p.id[k];
    p.position[k].z -= 1.5 * MM;
    let (_, x, _, _) = overlap();
    let zero = vec![0.0; x.len()];
    let err = e
        .set_volume_kinematics(iface, &x, &zero, &zero, MotionRule::Quadratic)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains(&format!("particle {id} at ("))
            && err.contains("left its overlap element by 0.500 element sizes")
            && err.contains("relative to the continuum"),
        "{err}"
    );
    // the same grain with the continuum moved down alongside it has not left its element
    let moved: Vec<f64> = x
        .iter()
        .enumerate()
        .map(|(i, v)| if i % 3 == 2 { v - 1.5 * MM } else { *v })
        .collect();
    let mut e = bed(1.0, 0.0, 1);
    let iface = attach(&mut e, VolumeSettings::default()).unwrap();
    let p = e.particles_mut();
    for k in 0..p.len() {
        p.position[k].z -= 1.5 * MM;
    }
    e.set_volume_kinematics(iface, &moved, &zero, &zero, MotionRule::Quadratic)
        .unwrap();
}

#[test]
fn bad_volume_interfaces_are_refused_with_the_reason() {
    let mut e = bed(1.0, 0.0, 1);
    let err = attach(
        &mut e,
        VolumeSettings {
            penalty: 1e22,
            ..Default::default()
        },
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("explicit step limit"), "{err}");
    // an overlap beside the particles: no centre in it
    let (ids, x, el, w) = overlap();
    let far: Vec<f64> = x
        .iter()
        .enumerate()
        .map(|(i, v)| if i % 3 == 0 { v + 0.1 } else { *v })
        .collect();
    let err = e
        .add_volume_interface(
            "soil",
            mesh(ids.clone(), &far, el.clone(), w.clone()),
            VolumeSettings::default(),
        )
        .unwrap_err()
        .to_string();
    assert!(err.contains("volume interface `soil`"), "{err}");
    assert!(
        err.contains("overlap node 100") || err.contains("no particle centre"),
        "{err}"
    );
    let mut bad_w = w.clone();
    bad_w[3] = -0.5;
    let err = e
        .add_volume_interface("soil", mesh(ids, &x, el, bad_w), VolumeSettings::default())
        .unwrap_err()
        .to_string();
    assert!(err.contains("overlap node 103: weight -0.5"), "{err}");
}
