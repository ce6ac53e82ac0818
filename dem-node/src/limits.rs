//! Physics limits of the DEM part of a scene, reported to the coordinator in the node's
//! `ready` message for its up-front stability checks (DESIGN: "Physics limits are computed by
//! each node for its own part of the scene").
//!
//! - `contact_stiffness_max`: the largest Hertz normal stiffness k_n = 2E*√(R*δ) (Ullrich
//!   eq. 2.12) over the material pairs present — particle–particle pairs of the materials
//!   that particles use, and particle–interface-material pairs (flat wall, R* = r) when
//!   `interface_material` is set — with the largest radii of each material and the reference
//!   overlap δ = 1 % of the smaller of the two radii. Hertz stiffness grows with the overlap,
//!   so this is a representative, not an upper bound: at 4 % overlap it doubles.
//! - `contact_stiffness_typical`: the same with the mean radius of each material instead of
//!   the largest. The coordinator's coupling-window limit uses it: the window limits measured
//!   on the sleeper's CI variant (one stone size) carry over to the polydisperse full-size
//!   bed with the mean radius (JIT stable at 0.034 T_c, diverging at 0.068 T_c on both), not
//!   with the largest stone, which is one of thousands (docs/speed-accuracy.md).
//! - `interface_contact_stiffness_typical` (with an `interface_material`): the same over the
//!   particle–interface pairs only: what the coupling window's limit needs (the interface
//!   nodes touch particles, not particles touching particles; a soft membrane's contacts
//!   are thousands of times softer than the glass beads' among themselves).
//! - `contact_duration_min`: the shortest Hertz contact duration at a 1 m/s impact,
//!   t_c = 2.87 (m*²/(R* E*² v))^{1/5}, over the same pairs with the smallest radii (and
//!   masses) of each material; m* = m for a wall.
//!
//! - `damped_step_limit` (with spheres or dilated polyhedra, whose contacts have the sphere
//!   law's dashpots): the largest explicit step at which those dashpots keep the update
//!   stable, over the pairs of their materials (the smallest body of each against the
//!   smallest and the largest of the other, reference overlap; with `rotation = false` only
//!   the normal mode) — see [`damped_step`] and [`pair_damped_step`]; a stone counts with its
//!   bounding radius as the lever arm and its smallest principal moment, a bound of the
//!   rotational compliance of its contacts, in the counter-rotation mode and (its normals can
//!   miss its centre) in the normal mode;
//!   `damped_step_mode` says which mode sets it (0 normal, 1 tangential–rotational) and
//!   `damped_step_zeta` its damping ratio. A strong restitution-calibrated dashpot (e ≲ 0.1)
//!   damps the tangential–rotational mode of a sphere contact beyond critical (its mass is
//!   2/7 of m*), and a damping force taken at the half-step velocity then diverges at steps
//!   far below the Rayleigh step: rigid glass beads at e = 0.05 and Δt = 0.28 Δt_R turned
//!   into a gas at 100 kPa (docs/full-size.md, "Glass beads").
//!
//! With the linear contact law (materials' `normal_stiffness`) the stiffnesses are the pairs'
//! springs k_n and the duration is half the undamped period, π√(m*/k_n).
//!
//! Radii are the radii that enter Hertz: a sphere's radius, a superquadric's bounding
//! radius, a dilated polyhedron's dilation radius r_ds (its contact law is Hertz between the
//! dilation spheres, U (2.20)). With dilated polyhedra also the validity limit of that model
//! (U §6.1: the cores must not meet, δ_d < r_ds,1 + r_ds,2), for the stone of each material
//! with the smallest r_ds³/m (the worst; the limits do not depend on the size for a fixed
//! dilation ratio) against itself and the interface material:
//! - `dilation_impact_velocity_max`: the relative normal speed of an elastic impact whose
//!   largest overlap (15 m* v²/(16 E* √R))^{2/5} reaches r_ds,1 + r_ds,2;
//! - `dilation_force_max`: the static contact force 4/3 E* √R (r_ds,1 + r_ds,2)^{3/2} at which
//!   the cores touch.

use crate::materials::{MaterialTable, PairParams};
use crate::particles::Particles;

/// Overlap at which `contact_stiffness_max` is evaluated, as a fraction of the smaller radius.
pub const REFERENCE_OVERLAP_FRACTION: f64 = 0.01;
/// Impact velocity of `contact_duration_min`, m/s.
pub const REFERENCE_IMPACT_VELOCITY: f64 = 1.0;

/// Hertz normal stiffness k_n = 2E*√(R*δ) (Ullrich eq. 2.12).
pub fn hertz_stiffness(e_star: f64, r_eff: f64, overlap: f64) -> f64 {
    2.0 * e_star * (r_eff * overlap).sqrt()
}

/// Hertz contact duration of an elastic impact at relative normal velocity `v`:
/// t_c = 2.87 (m*²/(R* E*² v))^{1/5} (2.87 ≈ 2 (15/16)^{2/5} ∫₀¹ dx/√(1 − x^{5/2})).
pub fn hertz_contact_duration(m_eff: f64, r_eff: f64, e_star: f64, v: f64) -> f64 {
    2.87 * (m_eff * m_eff / (r_eff * e_star * e_star * v)).powf(0.2)
}

/// Coordination of the reference packing of [`pair_damped_step`] (a dense packing's).
pub const REFERENCE_COORDINATION: f64 = 6.0;

/// Largest stable step of velocity Verlet for ẍ = −ω² x − τω² ẋ, the damping force taken at
/// the half-step velocity as in the DEM's drift → forces → kick: with ζ = ωτ/2 the update is
/// stable for ωh ≤ 2(√(1 + ζ²) − ζ), i.e. h ≤ −τ + √(τ² + 4/ω²) (a dashpot proportional to its
/// spring, c = τk, damps every mode of a network of such contacts with the same τ).
pub fn damped_step(omega: f64, tau: f64) -> f64 {
    -tau + (tau * tau + 4.0 / (omega * omega)).sqrt()
}

/// [`damped_step`] of the two stiffest modes of a packing of bodies a, b — (lever arm r to
/// the contact point, mass m, moment of inertia I) — of coordination
/// [`REFERENCE_COORDINATION`] Z with isotropic fabric, contact springs `k_n`, `k_t` and
/// dashpots `c_n`, `c_t`, in a packing where every a touches Z b and every b Z a (the
/// staggered modes of such a two-body lattice, its fabric isotropic): neighbours moving
/// apart along their normals, ω² = (Z/3) k_n (1/m_a + 1/m_b), and neighbours rotating in
/// opposite senses, ω² = (2Z/3) k_t (r_a²/I_a + r_b²/I_b) — the tangential mode, whose mass
/// (1/m_a + 1/m_b + r_a²/I_a + r_b²/I_b)⁻¹ is 2/7 of m* for solid spheres, is the stiffer and
/// the more damped one. (A small sphere among large ones turns almost alone: its r²/I
/// dominates.) `normal_rotation` adds the rotational compliance of a normal that misses the
/// centres, |l × n|²/I summed over both bodies, to the normal mode's 1/m_a + 1/m_b (0 for
/// spheres). Returns (step, mode 0 normal / 1 tangential, ζ of that mode).
pub fn pair_damped_step(
    (ra, ma, ia): (f64, f64, f64),
    (rb, mb, ib): (f64, f64, f64),
    (k_n, c_n): (f64, f64),
    (k_t, c_t): (f64, f64),
    normal_rotation: f64,
) -> (f64, u8, f64) {
    let z = REFERENCE_COORDINATION;
    let w_n = (z / 3.0 * k_n * (1.0 / ma + 1.0 / mb + normal_rotation)).sqrt();
    let w_t = (2.0 * z / 3.0 * k_t * (ra * ra / ia + rb * rb / ib)).sqrt();
    let (tau_n, tau_t) = (c_n / k_n, if k_t > 0.0 { c_t / k_t } else { 0.0 });
    let (h_n, h_t) = (damped_step(w_n, tau_n), damped_step(w_t, tau_t));
    if h_t < h_n {
        (h_t, 1, 0.5 * w_t * tau_t)
    } else {
        (h_n, 0, 0.5 * w_n * tau_n)
    }
}

/// A body as the limits see it: the radius that enters Hertz, its mass, and for the
/// counter-rotation mode a lever arm to its contact points and a moment of inertia — a
/// sphere's radius and 2/5 m r²; for a dilated polyhedron its bounding radius and its smallest
/// principal moment, the largest rotational compliance |l × t|²/I a contact on it can see.
/// `normal_lever` bounds how far a contact normal passes from the centre: 0 for a sphere, the
/// bounding radius for a stone.
#[derive(Debug, Clone, Copy)]
struct Body {
    r: f64,
    m: f64,
    lever: f64,
    normal_lever: f64,
    inertia: f64,
}

/// The particles of one material: the bodies of the smallest and the largest contact radius,
/// and the summed radius and count.
#[derive(Debug, Clone, Copy)]
struct Extent {
    small: Body,
    large: Body,
    r_sum: f64,
    count: usize,
}

impl Extent {
    /// Counts body `b` into a material's extent.
    fn add(slot: &mut Option<Extent>, b: Body) {
        let e = slot.get_or_insert(Extent {
            small: b,
            large: b,
            r_sum: 0.0,
            count: 0,
        });
        e.r_sum += b.r;
        e.count += 1;
        if b.r < e.small.r {
            e.small = b;
        }
        if b.r > e.large.r {
            e.large = b;
        }
    }

    fn r_mean(&self) -> f64 {
        self.r_sum / self.count as f64
    }
}

/// The limits as (key, value) pairs; nothing without particles.
pub fn contact_limits(
    p: &Particles,
    materials: &MaterialTable,
    interface_material: Option<u16>,
    rotation: bool,
) -> Vec<(String, f64)> {
    if p.is_empty() {
        return Vec::new();
    }
    let mut ext: Vec<Option<Extent>> = vec![None; materials.materials.len()];
    // per material, the stone with the smallest r_ds³/m: (r_ds, m)
    let mut stones: Vec<Option<(f64, f64)>> = vec![None; materials.materials.len()];
    // the same as `ext` over the bodies with the sphere law's dashpots: spheres and polyhedra
    let mut damped_bodies: Vec<Option<Extent>> = vec![None; materials.materials.len()];
    // the smallest and largest contact radius
    let (mut r_min, mut r_max) = (f64::INFINITY, f64::NEG_INFINITY);
    for k in 0..p.len() {
        let (r, slot) = (p.radius[k], p.material[k] as usize);
        let stone = p.polyhedron(k);
        let b = Body {
            r: stone.map_or(r, |(s, scale)| s.dilation * scale),
            m: p.mass[k],
            lever: r,
            normal_lever: if stone.is_some() { r } else { 0.0 },
            inertia: p.inertia[k],
        };
        (r_min, r_max) = (r_min.min(b.r), r_max.max(b.r));
        if stone.is_some() {
            let worst = stones[slot].get_or_insert((b.r, b.m));
            if b.r.powi(3) / b.m < worst.0.powi(3) / worst.1 {
                *worst = (b.r, b.m);
            }
        }
        Extent::add(&mut ext[slot], b);
        if stone.is_some() || p.template(k).is_none() {
            Extent::add(&mut damped_bodies[slot], b);
        }
    }
    let masses = &p.mass;
    let min = |v: &[f64]| v.iter().cloned().fold(f64::INFINITY, f64::min);
    let max = |v: &[f64]| v.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    let mut k_max = 0.0f64;
    let mut k_typical = 0.0f64;
    let mut t_min = f64::INFINITY;
    let mut k_interface = 0.0f64;
    // k_n of a particle pair with radii ra, rb at the reference overlap (a linear spring's k_n
    // whatever the radii)
    let pair_k = |pp: &PairParams, ra: f64, rb: f64| {
        if pp.linear_normal > 0.0 {
            return pp.linear_normal;
        }
        hertz_stiffness(
            pp.e_star,
            ra * rb / (ra + rb),
            REFERENCE_OVERLAP_FRACTION * ra.min(rb),
        )
    };
    // ... and of a particle of radius r on a flat wall
    let wall_k = |pp: &PairParams, r: f64| {
        if pp.linear_normal > 0.0 {
            return pp.linear_normal;
        }
        hertz_stiffness(pp.e_star, r, REFERENCE_OVERLAP_FRACTION * r)
    };
    // the contact duration at 1 m/s: Hertz's, or half the undamped period π√(m*/k) of a
    // linear spring
    let duration = |pp: &PairParams, m_eff: f64, r_eff: f64| {
        if pp.linear_normal > 0.0 {
            return std::f64::consts::PI * (m_eff / pp.linear_normal).sqrt();
        }
        hertz_contact_duration(m_eff, r_eff, pp.e_star, REFERENCE_IMPACT_VELOCITY)
    };
    let present: Vec<(u16, Extent)> = ext
        .iter()
        .enumerate()
        .filter_map(|(m, e)| e.map(|e| (m as u16, e)))
        .collect();
    for (x, &(a, ea)) in present.iter().enumerate() {
        for &(b, eb) in &present[x..] {
            let pp = materials.pair(a, b);
            k_max = k_max.max(pair_k(pp, ea.large.r, eb.large.r));
            k_typical = k_typical.max(pair_k(pp, ea.r_mean(), eb.r_mean()));
            let (ra, rb, ma, mb) = (ea.small.r, eb.small.r, ea.small.m, eb.small.m);
            t_min = t_min.min(duration(pp, ma * mb / (ma + mb), ra * rb / (ra + rb)));
        }
        if let Some(w) = interface_material {
            let pp = materials.pair(a, w);
            k_max = k_max.max(wall_k(pp, ea.large.r));
            k_typical = k_typical.max(wall_k(pp, ea.r_mean()));
            k_interface = k_interface.max(wall_k(pp, ea.r_mean()));
            t_min = t_min.min(duration(pp, ea.small.m, ea.small.r));
        }
    }
    let mut out: Vec<(String, f64)> = vec![
        ("particle_mass_min".into(), min(masses)),
        ("particle_mass_max".into(), max(masses)),
        ("particle_radius_min".into(), r_min),
        ("particle_radius_max".into(), r_max),
        ("contact_stiffness_max".into(), k_max),
        ("contact_stiffness_typical".into(), k_typical),
        ("contact_duration_min".into(), t_min),
    ];
    if interface_material.is_some() {
        out.push(("interface_contact_stiffness_typical".into(), k_interface));
    }
    // the dashpots' stability limit of the contacts of spheres and dilated polyhedra
    let present: Vec<(u16, Extent)> = damped_bodies
        .iter()
        .enumerate()
        .filter_map(|(m, e)| e.map(|e| (m as u16, e)))
        .collect();
    let mut damped = (f64::INFINITY, 0u8, 0.0);
    for (x, &(a, ea)) in present.iter().enumerate() {
        for &(b, eb) in &present[x..] {
            let pp = materials.pair(a, b);
            // the smallest body of one material against the smallest and the largest of the
            // other (a larger partner stiffens the contact)
            for (sa, sb) in [
                (ea.small, eb.small),
                (ea.small, eb.large),
                (ea.large, eb.small),
            ] {
                let k_n = pair_k(pp, sa.r, sb.r);
                // with rotation locked there is no counter-rotation mode
                let k_t = if rotation {
                    k_n * pp.sqrt_stiffness_ratio.powi(2)
                } else {
                    0.0
                };
                let m_eff = sa.m * sb.m / (sa.m + sb.m);
                // the dashpots of `hertz_mindlin::contact_force` at that stiffness
                let (c_n, c_t) = pp.dashpots(k_n, m_eff);
                // a stone's normal can miss its centre and turn it (not with rotation locked)
                let normal_rotation = if rotation {
                    sa.normal_lever.powi(2) / sa.inertia + sb.normal_lever.powi(2) / sb.inertia
                } else {
                    0.0
                };
                let h = pair_damped_step(
                    (sa.lever, sa.m, sa.inertia),
                    (sb.lever, sb.m, sb.inertia),
                    (k_n, c_n),
                    (k_t, c_t),
                    normal_rotation,
                );
                if h.0 < damped.0 {
                    damped = h;
                }
            }
        }
    }
    if damped.0.is_finite() {
        out.push(("damped_step_limit".into(), damped.0));
        out.push(("damped_step_mode".into(), damped.1 as f64));
        out.push(("damped_step_zeta".into(), damped.2));
    }
    // the dilated-polyhedron validity limit
    let (mut v_max, mut f_max) = (f64::INFINITY, f64::INFINITY);
    let mut limit = |e_star: f64, r_eff: f64, reach: f64, m_eff: f64| {
        v_max = v_max.min(dilation_impact_velocity(e_star, r_eff, reach, m_eff));
        f_max = f_max.min(4.0 / 3.0 * e_star * r_eff.sqrt() * reach.powf(1.5));
    };
    let present: Vec<(u16, (f64, f64))> = stones
        .iter()
        .enumerate()
        .filter_map(|(m, s)| s.map(|s| (m as u16, s)))
        .collect();
    for (x, &(a, (ra, ma))) in present.iter().enumerate() {
        for &(b, (rb, mb)) in &present[x..] {
            let e_star = materials.pair(a, b).e_star;
            limit(e_star, ra * rb / (ra + rb), ra + rb, ma * mb / (ma + mb));
        }
        if let Some(w) = interface_material {
            limit(materials.pair(a, w).e_star, ra, ra, ma);
        }
    }
    if !present.is_empty() {
        out.push(("dilation_impact_velocity_max".into(), v_max));
        out.push(("dilation_force_max".into(), f_max));
    }
    out
}

/// The relative normal speed of an elastic Hertz impact whose largest overlap
/// (15 m* v²/(16 E* √R))^{2/5} is `overlap`.
pub fn dilation_impact_velocity(e_star: f64, r_eff: f64, overlap: f64, m_eff: f64) -> f64 {
    (16.0 * e_star * r_eff.sqrt() * overlap.powf(2.5) / (15.0 * m_eff)).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::parse_scene_section;

    #[test]
    fn hertz_stiffness_is_two_e_star_root_r_delta() {
        // 2 · 1e8 · √(1e-3 · 1e-5) = 2e4 N/m
        assert!((hertz_stiffness(1e8, 1e-3, 1e-5) - 2e4).abs() < 1e-9);
        // grows as √δ: four times the overlap, twice the stiffness
        let ratio = hertz_stiffness(3e9, 0.02, 4e-4) / hertz_stiffness(3e9, 0.02, 1e-4);
        assert!((ratio - 2.0).abs() < 1e-12);
    }

    #[test]
    fn hertz_contact_duration_matches_an_integrated_elastic_impact() {
        // m* ẍ = −4/3 E* √R* x^{3/2}, entering at 1 m/s: time until the overlap is zero again
        let (m, r, e, v0) = (1e-3, 1e-3, 1e8, 1.0);
        let want = hertz_contact_duration(m, r, e, v0);
        let dt = want * 1e-6;
        let (mut x, mut v, mut t) = (0.0f64, v0, 0.0);
        let acc = |x: f64| -4.0 / 3.0 * e * r.sqrt() * x.max(0.0).powf(1.5) / m;
        let mut a = acc(x);
        loop {
            v += 0.5 * dt * a;
            x += dt * v;
            a = acc(x);
            v += 0.5 * dt * a;
            t += dt;
            if x <= 0.0 {
                break;
            }
        }
        println!("t_c formula {want:e} s, integrated {t:e} s");
        assert!((t - want).abs() < 2e-3 * want, "{t} vs {want}");
        assert!((v + v0).abs() < 1e-6, "elastic rebound {v}");
    }

    const SCENE: &str = r#"
[dem]
time_step = 1e-6
allow_large_time_step = true
interface_material = "steel"
[dem.materials.grain]
youngs_modulus = 1e8
poisson_ratio = 0.3
density = 1000.0
restitution = 0.5
friction = 0.5
[dem.materials.steel]
youngs_modulus = 2e11
poisson_ratio = 0.3
density = 7800.0
restitution = 0.5
friction = 0.3
[[dem.particles]]
kind = "list"
material = "grain"
spheres = [
  { position = [0.0, 0.0, 0.0], radius = 0.001 },
  { position = [1.0, 0.0, 0.0], radius = 0.003 },
]
"#;

    #[test]
    fn limits_of_a_two_size_grain_against_steel_by_hand() {
        let cfg = parse_scene_section(SCENE).unwrap().unwrap();
        let e = crate::Engine::from_config(&cfg, std::path::Path::new(".")).unwrap();
        let l: std::collections::BTreeMap<String, f64> = e.limits().into_iter().collect();
        let pi = std::f64::consts::PI;
        let (m1, m3) = (
            1000.0 * 4.0 / 3.0 * pi * 1e-9,
            1000.0 * 4.0 / 3.0 * pi * 27e-9,
        );
        let close = |l: &std::collections::BTreeMap<String, f64>, k: &str, want: f64| {
            let got = l[k];
            assert!(
                (got - want).abs() <= 1e-12 * want.abs(),
                "{k}: {got} vs {want}"
            );
        };
        close(&l, "particle_radius_min", 0.001);
        close(&l, "particle_radius_max", 0.003);
        close(&l, "particle_mass_min", m1);
        close(&l, "particle_mass_max", m3);
        // grain–steel: E* = 1/((1−0.09)/1e8 + (1−0.09)/2e11); the flat wall is stiffer than
        // a grain pair (R* = r instead of r/2, larger E*), at r = 3 mm, δ = 30 µm
        let e_gs = 1.0 / (0.91 / 1e8 + 0.91 / 2e11);
        close(
            &l,
            "contact_stiffness_max",
            2.0 * e_gs * (0.003f64 * 3e-5).sqrt(),
        );
        // typical: the mean radius 2 mm on the wall, δ = 20 µm (half-way in k between the two
        // sizes, since k ∝ r at a fixed relative overlap)
        close(
            &l,
            "contact_stiffness_typical",
            2.0 * e_gs * (0.002f64 * 2e-5).sqrt(),
        );
        // shortest: the 1 mm grain on the steel wall (m* = m, R* = r) vs the grain pair
        // (m* = m/2, R* = r/2, E* = E/(2(1−ν²))): wall 2.87 (m²/(r E*²))^{1/5}
        let e_gg = 1.0 / (2.0 * 0.91 / 1e8);
        let wall = 2.87 * (m1 * m1 / (1e-3 * e_gs * e_gs)).powf(0.2);
        let pair = 2.87 * (m1 * m1 / 4.0 / (0.5e-3 * e_gg * e_gg)).powf(0.2);
        assert!(wall < pair);
        close(&l, "contact_duration_min", wall);
        assert_eq!(l["particles"], 2.0);
        assert_eq!(l["time_step"], 1e-6);
        // without an interface material only the grain pair counts
        let mut cfg = cfg;
        cfg.interface_material = None;
        let e = crate::Engine::from_config(&cfg, std::path::Path::new(".")).unwrap();
        let l: std::collections::BTreeMap<String, f64> = e.limits().into_iter().collect();
        close(&l, "contact_duration_min", pair);
        // grain pair at the largest radius: R* = 1.5 mm, δ = 30 µm
        close(
            &l,
            "contact_stiffness_max",
            2.0 * e_gg * (0.0015f64 * 3e-5).sqrt(),
        );
        // ... and at the mean radius: R* = 1 mm, δ = 20 µm
        close(
            &l,
            "contact_stiffness_typical",
            2.0 * e_gg * (0.001f64 * 2e-5).sqrt(),
        );
    }

    /// Amplitude after `n` steps of ẍ = −ω² x − τω² ẋ from x = 1 by the DEM's scheme: half
    /// kick, drift, force at the half-step velocity, half kick.
    fn damped_run(omega: f64, tau: f64, h: f64, n: usize) -> f64 {
        let (mut x, mut v) = (1.0f64, 0.0f64);
        let force = |x: f64, v: f64| -omega * omega * (x + tau * v);
        let mut a = force(x, v);
        for _ in 0..n {
            v += 0.5 * h * a;
            x += h * v;
            a = force(x, v);
            v += 0.5 * h * a;
        }
        x.abs().max((v / omega).abs())
    }

    #[test]
    fn damped_step_is_where_velocity_verlet_with_a_dashpot_diverges() {
        for (omega, zeta) in [(1.0, 0.0), (1.0, 0.3), (2e6, 1.0), (2e6, 5.6)] {
            let tau = 2.0 * zeta / omega;
            let h = damped_step(omega, tau);
            if zeta == 0.0 {
                assert!((h - 2.0 / omega).abs() < 1e-12 / omega);
            }
            let (below, above) = (
                damped_run(omega, tau, 0.99 * h, 20_000),
                damped_run(omega, tau, 1.01 * h, 20_000),
            );
            println!(
                "ω = {omega:e}, ζ = {zeta}: h = {h:e}, amplitude {below:e} below, {above:e} above"
            );
            // near the limit leapfrog's velocity amplitude exceeds ω x₀ (by 1/√(1 − (ωh/2)²)
            // undamped), but it stays bounded; above it grows without bound
            assert!(below < 50.0, "stable below: {below}");
            assert!(above.is_nan() || above > 1e6, "diverges above: {above}");
        }
    }

    #[test]
    fn damped_step_of_equal_spheres_by_hand() {
        // equal solid spheres: the opposite rotation of Z = 6 neighbours, ω² = (2Z/3) k_t 2r²/I
        // = 20 k_t/m; the normal mode ω² = (Z/3) k_n/m* = 4 k_n/m
        let (r, m) = (1e-3, 4e-6);
        let i = 0.4 * m * r * r;
        let (k_n, k_t) = (1e6, 0.85e6);
        let (c_n, c_t) = (0.5, 0.4);
        let (h, mode, zeta) = pair_damped_step((r, m, i), (r, m, i), (k_n, c_n), (k_t, c_t), 0.0);
        let w_t = (20.0 * k_t / m).sqrt();
        let w_n = (4.0 * k_n / m).sqrt();
        let h_t = damped_step(w_t, c_t / k_t);
        assert!(h_t < damped_step(w_n, c_n / k_n));
        assert_eq!(mode, 1);
        assert!((h - h_t).abs() < 1e-15, "{h} vs {h_t}");
        assert!((zeta - 0.5 * w_t * c_t / k_t).abs() < 1e-12);
        // without a tangential dashpot a weakly damped normal mode can set it
        let (h0, mode0, _) = pair_damped_step((r, m, i), (r, m, i), (k_n, 5.0), (k_t, 0.0), 0.0);
        assert_eq!(mode0, 0);
        assert!((h0 - damped_step(w_n, 5.0 / k_n)).abs() < 1e-15);
    }

    #[test]
    fn glass_beads_report_the_damped_step_of_their_restitution_dashpot() {
        // 1 mm glass beads: e = 0.05 (an overdamped dashpot) against e = 0.5 and Wellmann's
        // normal-only ζ = 0.9
        let scene = |extra: &str, e: f64| {
            format!(
                "[dem]\ntime_step = 1e-7\n[dem.materials.glass]\nyoungs_modulus = 63e9\npoisson_ratio = 0.23\ndensity = 2550.0\nrestitution = {e}\nfriction = 0.16\n{extra}[[dem.particles]]\nkind = \"list\"\nmaterial = \"glass\"\nspheres = [{{ position = [0.0, 0.0, 0.0], radius = 0.001 }}, {{ position = [1.0, 0.0, 0.0], radius = 0.0012 }}]\n"
            )
        };
        let limit = |s: String| {
            let cfg = parse_scene_section(&s).unwrap().unwrap();
            let engine = crate::Engine::from_config(&cfg, std::path::Path::new(".")).unwrap();
            let l: std::collections::BTreeMap<String, f64> = engine.limits().into_iter().collect();
            (
                l["damped_step_limit"],
                l["damped_step_mode"],
                l["damped_step_zeta"],
            )
        };
        let strong = limit(scene("", 0.05));
        let weak = limit(scene("", 0.5));
        let zeta = limit(scene(
            "[[dem.interactions]]\nmaterials = [\"glass\", \"glass\"]\ndamping_ratio = 0.9\n",
            0.05,
        ));
        println!("e = 0.05 {strong:?}, e = 0.5 {weak:?}, ζ = 0.9 {zeta:?}");
        assert_eq!(strong.1, 1.0);
        assert!(strong.2 > 1.0, "overdamped tangential mode {strong:?}");
        assert!(weak.0 > 4.0 * strong.0, "{weak:?} {strong:?}");
        // normal only: ζ of the normal mode is ζ √(Z/3)
        assert_eq!(zeta.1, 0.0);
        assert!((zeta.2 - 0.9 * 2f64.sqrt()).abs() < 1e-9, "{zeta:?}");
        // by hand: two 1 mm beads at 1 % overlap (the 1 mm bead against the 1.2 mm one is
        // stiffer, but the larger bead turns less: (2Z/3) k_t (r_a²/I_a + r_b²/I_b) is lower)
        let pairs = crate::materials::MaterialTable::from_config(
            &parse_scene_section(&scene("", 0.05)).unwrap().unwrap(),
        );
        let pp = pairs.pair(0, 0);
        let rho = 2550.0;
        let mass = |r: f64| rho * 4.0 / 3.0 * std::f64::consts::PI * r * r * r;
        let by_hand = |ra: f64, rb: f64| {
            let (ma, mb) = (mass(ra), mass(rb));
            let r_eff = ra * rb / (ra + rb);
            let k_n = hertz_stiffness(pp.e_star, r_eff, 0.01 * ra.min(rb));
            let k_t = 8.0 * pp.g_star * (r_eff * 0.01 * ra.min(rb)).sqrt();
            let m_eff = ma * mb / (ma + mb);
            let tau_t = pp.damping_factor * (k_n * m_eff).sqrt() * pp.sqrt_stiffness_ratio / k_t;
            // I = 2/5 m r²: r²/I = 2.5/m
            damped_step((4.0 * k_t * (2.5 / ma + 2.5 / mb)).sqrt(), tau_t)
        };
        let want = by_hand(1e-3, 1e-3);
        assert!(by_hand(1e-3, 1.2e-3) > want);
        assert!(
            (strong.0 - want).abs() < 1e-9 * want,
            "{} vs {want}",
            strong.0
        );
        // with rotation locked only the normal mode is left
        let locked = limit(scene("", 0.05).replace("[dem]\n", "[dem]\nrotation = false\n"));
        assert_eq!(locked.1, 0.0, "{locked:?}");
        assert!(locked.0 > strong.0, "{locked:?}");
    }
}
