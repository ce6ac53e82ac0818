//! Ullrich fig. 2.5 (REFERENCE A2): an elastic sphere (R = 0.01 m, ν = 0.25, E = 1 GPa,
//! ρ = 1000 kg/m³) hits a plane wall head-on; the relative error of the rebound speed against
//! the time step, with and without impact refinement. Shared by the example
//! `bouncing_sphere` and the test `tests/bouncing_sphere_sweep.rs`.
#![allow(dead_code)]

pub const RADIUS: f64 = 0.01;
pub const YOUNGS_MODULUS: f64 = 1e9;
pub const POISSON_RATIO: f64 = 0.25;
pub const DENSITY: f64 = 1000.0;
/// The seed's impact speeds, m/s.
pub const SPEEDS: [f64; 3] = [0.1, 1.0, 10.0];

/// Rayleigh step of the sphere, Ullrich eq. (2.27) (≈ 5.4e-5 s).
pub fn rayleigh_time_step() -> f64 {
    let g = YOUNGS_MODULUS / (2.0 * (1.0 + POISSON_RATIO));
    dem::rayleigh_time_step_of(RADIUS, POISSON_RATIO, DENSITY, g)
}

/// The seed's stated time step for each speed: Δt_R for 0.1 m/s, 1e-6 s for 1 m/s, 1e-7 s
/// for 10 m/s.
pub fn stated_time_step(speed: f64) -> f64 {
    if speed < 0.5 {
        rayleigh_time_step()
    } else if speed < 5.0 {
        1e-6
    } else {
        1e-7
    }
}

/// The scene: no gravity, e = 1, the sphere's surface `phase`·v·Δt above the wall, so the
/// contact begins at that fraction of the first step.
pub fn scene(dt: f64, speed: f64, phase: f64, impact_substeps: usize) -> String {
    format!(
        r#"[dem]
time_step = {dt:e}
gravity = [0.0, 0.0, 0.0]
allow_large_time_step = true
impact_substeps = {impact_substeps}
[dem.materials.ball]
youngs_modulus = {YOUNGS_MODULUS:e}
poisson_ratio = {POISSON_RATIO}
density = {DENSITY}
restitution = 1.0
friction = 0.0
[[dem.walls]]
kind = "plane"
material = "ball"
point = [0.0, 0.0, 0.0]
normal = [0.0, 0.0, 1.0]
[[dem.particles]]
kind = "list"
material = "ball"
spheres = [ {{ position = [0.0, 0.0, {z:e}], radius = {RADIUS}, velocity = [0.0, 0.0, {vz:e}] }} ]
"#,
        z = RADIUS + phase * speed * dt,
        vz = -speed
    )
}

/// One bounce.
#[derive(Debug, Clone, Copy)]
pub struct Bounce {
    /// |v_out − v_in| / v_in.
    pub relative_error: f64,
    /// Steps from the start to the end of the contact.
    pub steps: u64,
    /// Of those, steps run as impact sub-steps.
    pub refined_steps: u64,
}

/// Runs one bounce; `Err` names what went wrong (scene, instability, no rebound).
pub fn bounce(speed: f64, dt: f64, phase: f64, impact_substeps: usize) -> Result<Bounce, String> {
    let cfg = dem::parse_scene_section(&scene(dt, speed, phase, impact_substeps))
        .map_err(|e| e.to_string())?
        .ok_or("no [dem] table")?;
    let mut e =
        dem::Engine::from_config(&cfg, std::path::Path::new(".")).map_err(|e| e.to_string())?;
    let z = |e: &dem::Engine| e.particles().position[0].z;
    // contact lasts < 1e-3 s for these speeds; allow 100 contact times
    let max_steps = (0.1 / dt) as u64 + 100;
    let mut touched = false;
    for _ in 0..max_steps {
        e.advance(1).map_err(|e| e.to_string())?;
        if z(&e) < RADIUS {
            touched = true;
        } else if touched {
            let v_out = e.particles().velocity[0].z;
            return Ok(Bounce {
                relative_error: (v_out - speed).abs() / speed,
                steps: e.steps(),
                refined_steps: e.refined_steps(),
            });
        }
    }
    Err(format!(
        "v = {speed} m/s, dt = {dt:e} s: no rebound within {max_steps} steps"
    ))
}

/// Onset phases within a step (fractions of the first step at which the contact begins):
/// the golden-ratio sequence, so they do not line up with any sub-step grid either.
pub fn phases(count: usize) -> Vec<f64> {
    let golden = 0.5 * (5f64.sqrt() - 1.0);
    (0..count)
        .map(|k| (0.5 + k as f64 * golden).fract())
        .collect()
}

/// The largest error over the onset phases, and the phase giving it.
pub fn worst_over_phases(
    speed: f64,
    dt: f64,
    impact_substeps: usize,
    phases: &[f64],
) -> Result<(f64, f64), String> {
    let mut worst = (0.0, f64::NAN);
    for &ph in phases {
        let b = bounce(speed, dt, ph, impact_substeps)?;
        // a NaN error counts as the worst
        if b.relative_error.is_nan() || b.relative_error > worst.0 {
            worst = (b.relative_error, ph);
        }
    }
    Ok(worst)
}
