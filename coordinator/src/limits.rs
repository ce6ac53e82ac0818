//! Up-front stability checks: before the first window, the scene is compared with the known
//! limits, from the numbers the nodes report in `ready` (the coordinator links no engine).
//!
//! | limit | from | rule |
//! |---|---|---|
//! | DEM Rayleigh step (Ullrich 2.27) | `dem.time_step`, `dem.rayleigh_time_step` | the DEM node refuses Δt^D above its `rayleigh_fraction` itself; here only reported |
//! | impact resolution (Ullrich fig. 2.5) | `dem.contact_duration_min` | a 1 m/s impact of the smallest, stiffest particle must last ≥ [`MIN_STEPS_PER_CONTACT`] steps (warn below [`GOOD_STEPS_PER_CONTACT`]) |
//! | DEM damped contact step | `dem.damped_step_limit`, `_mode`, `_zeta` | the dashpots of the contacts of spheres and dilated polyhedra (Z = 6 packing, reference overlap) keep velocity Verlet stable only below h = −τ + √(τ² + 4/ω²): warn above [`DAMPED_STEP_WARN_FACTOR`] times it, naming the mode, its ζ and the remedies |
//! | dilated polyhedra (Ullrich §6.1) | `dem.dilation_impact_velocity_max`, `dem.dilation_force_max` | the cores must not meet: warn when an impact slower than [`DILATION_IMPACT_VELOCITY_MIN`] can drive them together (the run stops naming the pair if they do) |
//! | 2-D discs: critical step (Madan 2.14–2.16) | `dem.critical_time_step`, `dem.discs` | refused above Δt_cr = 2/ν_max (Lanczos on the initial contacts) |
//! | DDEM convergence (Madan 3.13–3.14) | `dem.ddem_spectral_radius`, `dem.ddem_kn_over_ep`, `dem.ddem_poisson_ratio` | refused at ρ(B) ≥ 1 of the initial packing, naming k_n/E_p, ν_p and the limit |
//! | FEM explicit critical step | `fem.critical_time_step`, `fem.explicit` | reported: the node sub-steps each window below it |
//! | coupling window (two-way) | `dem.interface_contact_stiffness_typical` (else `contact_stiffness_typical`, else `_max`), `fem.interface_node_mass_min` | Δt^C ≤ C_schedule · T_c, T_c = 2π √(M_node / k_c) |
//!
//! The coupling window limit: the interface forces reach the structure one window late (JIT:
//! computed with extrapolated mesh motion; predictive: the forces of the previous window), so
//! the contact spring k_c acting on an interface node of mass M is integrated explicitly with
//! step Δt^C. Its period T_c = 2π √(M/k_c) sets the scale, with k_c the Hertz stiffness of a
//! particle of the mean radius (the DEM's `interface_contact_stiffness_typical`, else its
//! `contact_stiffness_typical`; a DEM node that reports
//! only `contact_stiffness_max` gets the stiffest contact instead, more conservative). The
//! mean radius makes the JIT limit carry over from the sleeper's one-size CI bed to the
//! polydisperse full-size bed (stable at 0.034 T_c, diverging at 0.068 T_c on both), the
//! largest stone (one of thousands) does not. The constants per schedule were
//! measured with `cosim study` on the sleeper scene's CI variant (docs/speed-accuracy.md):
//! the largest stable window was [`JIT_WINDOW_FRACTION`] · T_c for JIT and
//! [`PREDICTIVE_WINDOW_FRACTION`] · T_c for predictive, [`CONCURRENT_WINDOW_FRACTION`] · T_c for
//! concurrent; on dilated polyhedra the tighter predictive fraction measured on the polyhedral
//! sleeper ([`window_fraction`]) and a warning for JIT ([`JIT_ON_STONES`]). Above the limit
//! the run starts
//! with a warning (the stability monitor stops it if it diverges), and refused beyond
//! [`REFUSE_BEYOND`] times the limit; `coupling.allow_beyond_limits = true` turns refusals into
//! warnings.

use std::collections::BTreeMap;

use crate::scene::{Scene, ScheduleKind};

/// A 1 m/s impact resolved by fewer steps than this is refused (the contact can be missed).
pub const MIN_STEPS_PER_CONTACT: f64 = 3.0;
/// ... and by fewer than this gives a rebound error above ~2e-3 (A2 sweep): warn.
pub const GOOD_STEPS_PER_CONTACT: f64 = 10.0;

/// Steps up to this multiple of the DEM's `damped_step_limit` pass. The estimate assumes six
/// neighbours counter-rotating at 1 % overlap, which a random packing (its loops of three
/// frustrate counter-rotation) and smaller overlaps do not reach. Measured with
/// scenes/glass-beads-rve.toml at e = 0.05 (overlaps ≤ 0.2 % at 100 kPa; limit 1.05e-7 s): 1.9×
/// sheared stably (stress noise ±9 % early), 2.4× began to heat at the end of consolidation,
/// 3.8× and 4.75× turned the packing into a gas (coordination 4 instead of 5, ±50 % stress).
/// The same on 300 dilated polyhedra under a loaded plate (dem-node/DEM.md, "Limits" of the
/// polyhedra): stable at 1.9×, diverging at 2.4–2.5× (e = 0.2 and 0.05).
pub const DAMPED_STEP_WARN_FACTOR: f64 = 1.5;

/// Dilated polyhedra whose cores meet in an elastic impact slower than this (m/s) are warned
/// about: the dilation (or the stiffness) is too small for ordinary impacts (Ullrich needed
/// E ≥ 10 GPa with r_ds = 10 %).
pub const DILATION_IMPACT_VELOCITY_MIN: f64 = 1.0;

/// Relative rebound-velocity error of a Hertz impact resolved by `steps` DEM steps per contact
/// duration, fitted to the bouncing-sphere sweep (REFERENCE A2; the problem is self-similar in
/// Δt / t_c): 5.3e-3 at 7.6 steps, 5.8e-6 at 61 steps.
pub fn impact_error(steps: f64) -> f64 {
    5.3e-3 * (7.6 / steps).powf(3.3)
}

/// Steps per contact duration for a rebound error `err` (inverse of [`impact_error`]).
pub fn steps_for_impact_error(err: f64) -> f64 {
    7.6 * (5.3e-3 / err).powf(1.0 / 3.3)
}
/// Largest stable JIT window as a fraction of the interface contact period T_c, measured on
/// scenes/sleeper-ci.toml (T_c = 1.467e-4 s): stable at 5 µs = 0.034 T_c, diverging at 10 µs.
pub const JIT_WINDOW_FRACTION: f64 = 0.04;
/// Largest stable predictive window as a fraction of T_c, measured on the same scene: stable
/// at 100 µs = 0.68 T_c, an oscillation growing 2× per ms at 200 µs.
pub const PREDICTIVE_WINDOW_FRACTION: f64 = 0.7;
/// Largest stable concurrent window as a fraction of T_c, measured on the same scene: stable
/// at 4 µs = 0.027 T_c (but 35 % off the reference; 0.4 % at 2 µs), diverging at 5 µs. Both
/// solvers lag a window, so the limit lies below JIT's.
pub const CONCURRENT_WINDOW_FRACTION: f64 = 0.025;
// the concurrent schedule lags on both sides: its limit is the tightest
const _: () = assert!(CONCURRENT_WINDOW_FRACTION < JIT_WINDOW_FRACTION);
/// On dilated polyhedra (the DEM reports `dilation_force_max`) the predictive schedule's limit
/// is tighter than on spheres: the bottom face's corner and edge nodes of a structure resting
/// on stones ring under single stones (docs/full-size.md, "Sleeper on polyhedral ballast").
/// Measured with `cosim study` on the polyhedral sleeper, its CI piece (T_c = 3.2e-4 s) and
/// the full-size scene (T_c = 3.26e-4 s): stable at 100 µs = 0.31 T_c (both) and 200 µs =
/// 0.61 T_c (full size), diverging at 200 µs = 0.62 T_c (CI) and 500 µs (both).
pub const PREDICTIVE_WINDOW_FRACTION_STONES: f64 = 0.32;

/// What `cosim check` says about the JIT schedule on dilated polyhedra: on the full-size
/// polyhedral sleeper JIT diverged at every window tried (5, 10 and 20 µs = 0.015–0.06 T_c),
/// the 5 and 10 µs runs at the same bottom corner node at the same moment (28 and 27 ms): a
/// shorter window did not help (on the CI piece 10 µs was stable, 20 µs not).
pub const JIT_ON_STONES: &str = "on dilated polyhedra the just-in-time schedule diverged at every window tried on the full-size sleeper (5, 10 and 20 µs = 0.015–0.06 T_c; the structure's bottom corner nodes under single stones, a shorter window did not help): prefer the predictive schedule";

/// Whether the DEM's bed holds dilated polyhedra (their validity limit is reported).
fn has_stones(dem: &BTreeMap<String, f64>) -> bool {
    dem.contains_key("dilation_force_max")
}

/// The stable window of an explicit schedule as a fraction of T_c, for the DEM's particles.
pub fn window_fraction(schedule: ScheduleKind, dem: &BTreeMap<String, f64>) -> Option<f64> {
    let stones = has_stones(dem);
    // JIT on stones: see JIT_ON_STONES (no window was stable at full size)
    Some(match (schedule, stones) {
        (ScheduleKind::Jit, _) => JIT_WINDOW_FRACTION,
        (ScheduleKind::Predictive, false) => PREDICTIVE_WINDOW_FRACTION,
        (ScheduleKind::Predictive, true) => PREDICTIVE_WINDOW_FRACTION_STONES,
        (ScheduleKind::Concurrent, _) => CONCURRENT_WINDOW_FRACTION,
        // implicit: iterated to a fixed point, no window limit of the explicit kind is known
        // (measured in docs/speed-accuracy.md)
        (ScheduleKind::None | ScheduleKind::OneWay | ScheduleKind::Implicit, _) => return None,
    })
}

/// The longest implicit window measured stable, as a fraction of T_c (sleeper-ci: 1 ms =
/// 6.8 T_c, serial and concurrent; no limit found).
pub const IMPLICIT_STABLE_TESTED: f64 = 6.8;
/// The window of a volume interface beyond which the run is warned about, as a fraction of
/// the penalty's explicit step limit 2√(w m / k̂), measured on scenes/arlequin-patch.toml (a
/// regular lattice with only contact damping, JIT): at ε = 1e14 N/m⁴ windows of 0.28 × stable
/// (both projections), 0.55 × diverging with the consistent projection (stable lumped), 1.1–1.4
/// × diverging with both, and 5.5 × diverging or oscillating; at ε = 1e13 stable to 1.75 ×.
/// Dissipative packings are more forgiving (the triaxial cube: 4 × at 1e13 and 12 × at 1e14),
/// but not always: the pile under gravity (scenes/pile-ci.toml) threw its overlap's bottom
/// grains 2 mm sideways within 4 ms at 4 × (ε = 1e13, 20 µs) and ran at 0.37 × (1e12, 6 µs).
pub const VOLUME_WINDOW_FRACTION: f64 = 0.5;
/// Beyond the limit the run is warned about; beyond this many times the limit it is refused
/// (the limit is an estimate: T_c uses the stiffness at a 1 % overlap and the lightest node).
/// Measured: 2× the limit diverged on the sleeper (JIT and predictive), 6.5× on the plate
/// under a 1 m sphere.
pub const REFUSE_BEYOND: f64 = 4.0;

#[derive(
    Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum Level {
    Info,
    Warn,
    Refuse,
}

/// One comparison of the scene with a limit.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Finding {
    pub level: Level,
    /// Short name of the limit, e.g. `coupling window`.
    pub limit: String,
    /// What was compared, the limit's value and the number to use.
    pub message: String,
}

impl std::fmt::Display for Finding {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.limit, self.message)
    }
}

/// What the checks need from the scene (kept small so tests can build it directly).
#[derive(Debug, Clone)]
pub struct SceneFacts {
    pub schedule: ScheduleKind,
    pub window: f64,
    pub has_dem: bool,
    pub has_fem: bool,
    /// Adaptive windows: (min_window, max_window).
    pub adaptive: Option<(f64, f64)>,
}

impl From<&Scene> for SceneFacts {
    fn from(s: &Scene) -> Self {
        SceneFacts {
            schedule: s.schedule,
            window: s.window,
            has_dem: s.has_dem,
            has_fem: s.has_fem,
            adaptive: s.adaptive.as_ref().map(|a| (a.min_window, a.max_window)),
        }
    }
}

/// The contact stiffness k_c of the window limit (N/m) and which DEM number it is: the
/// particle–interface stiffness at the mean particle radius when the DEM reports it, else
/// the typical stiffness of any contact, else the stiffest contact.
pub fn contact_stiffness(dem: &BTreeMap<String, f64>) -> Option<(f64, &'static str)> {
    dem.get("interface_contact_stiffness_typical")
        .map(|&k| (k, "typical particle–interface contact (mean radius)"))
        .or_else(|| {
            dem.get("contact_stiffness_typical")
                .map(|&k| (k, "typical contact (mean radius)"))
        })
        .or_else(|| {
            dem.get("contact_stiffness_max")
                .map(|&k| (k, "stiffest contact"))
        })
}

/// The interface contact period T_c = 2π √(M_node / k_c) (s), when both numbers are known.
pub fn contact_period(dem: &BTreeMap<String, f64>, fem: &BTreeMap<String, f64>) -> Option<f64> {
    let (k, _) = contact_stiffness(dem)?;
    let m = *fem.get("interface_node_mass_min")?;
    (k > 0.0 && m > 0.0 && k.is_finite() && m.is_finite())
        .then(|| 2.0 * std::f64::consts::PI * (m / k).sqrt())
}

/// The largest coupling window the schedule is known to keep stable (s), if it has one.
pub fn window_limit(
    schedule: ScheduleKind,
    dem: &BTreeMap<String, f64>,
    fem: &BTreeMap<String, f64>,
) -> Option<f64> {
    let fraction = window_fraction(schedule, dem)?;
    contact_period(dem, fem).map(|t| fraction * t)
}

/// Compares the scene with every limit the nodes' numbers allow.
pub fn assess(
    scene: &SceneFacts,
    dem: Option<&BTreeMap<String, f64>>,
    fem: Option<&BTreeMap<String, f64>>,
) -> Vec<Finding> {
    let mut out = Vec::new();
    let empty = BTreeMap::new();
    let d = dem.unwrap_or(&empty);
    let f = fem.unwrap_or(&empty);
    let mut push = |level, limit: &str, message: String| {
        out.push(Finding {
            level,
            limit: limit.to_string(),
            message,
        })
    };
    // DEM: Rayleigh step and impact resolution
    if let (Some(&dt), Some(&dt_r)) = (d.get("time_step"), d.get("rayleigh_time_step")) {
        push(
            Level::Info,
            "DEM Rayleigh step",
            format!(
                "Δt^D = {dt:.3e} s = {:.3} Δt_R (Δt_R = {dt_r:.3e} s)",
                dt / dt_r
            ),
        );
        if let Some(&tc) = d.get("contact_duration_min") {
            let steps = tc / dt;
            let good = tc / steps_for_impact_error(1e-4);
            if steps < MIN_STEPS_PER_CONTACT {
                push(Level::Refuse, "DEM impact resolution", format!(
                    "a 1 m/s impact of the smallest, stiffest particle lasts {tc:.3e} s = {steps:.2} DEM steps (< {MIN_STEPS_PER_CONTACT}): contacts can be stepped over; use Δt^D ≤ {good:.3e} s"
                ));
            } else if steps < GOOD_STEPS_PER_CONTACT {
                push(Level::Warn, "DEM impact resolution", format!(
                    "a 1 m/s impact of the smallest, stiffest particle lasts only {steps:.1} DEM steps ({tc:.3e} s): rebound velocities err by ~{:.1e} (faster impacts: more); use Δt^D ≤ {good:.3e} s for 1e-4", impact_error(steps)
                ));
            }
        }
    }
    // the dashpots of sphere and stone contacts: strong damping shortens the stable step
    if let (Some(&dt), Some(&h)) = (d.get("time_step"), d.get("damped_step_limit")) {
        let mode = match d.get("damped_step_mode") {
            Some(1.0) => "tangential–rotational (neighbours turning in opposite senses)",
            _ => "normal",
        };
        let zeta = d.get("damped_step_zeta").copied().unwrap_or(f64::NAN);
        // the DEM reports the dilation limit only with dilated polyhedra
        let bodies = if d.contains_key("dilation_impact_velocity_max") {
            "sphere and stone"
        } else {
            "sphere"
        };
        let what = format!(
            "Δt^D = {dt:.3e} s = {:.3} of the damped limit {h:.3e} s of {bodies} contacts (its {mode} mode, ζ = {zeta:.2}, in a packing of coordination 6 at 1 % overlap)",
            dt / h
        );
        if dt > DAMPED_STEP_WARN_FACTOR * h {
            push(Level::Warn, "DEM damped contact step", format!(
                "{what}, beyond {DAMPED_STEP_WARN_FACTOR}× of which the dashpots make the explicit update diverge in a dense packing — it heats up, contacts flicker and it loses strength, while the Rayleigh check passes. Use dem.time_step ≤ {:.3e} s, a larger restitution, or `damping_ratio` in [[dem.interactions]] (Wellmann's normal-only dashpot, W 3.29)",
                DAMPED_STEP_WARN_FACTOR * h
            ));
        } else {
            push(Level::Info, "DEM damped contact step", what);
        }
    }
    // 2-D discs (Madan): the critical step of central differences and the DDEM's ρ(B) < 1
    if let (Some(&dt), Some(&crit), Some(_)) = (
        d.get("time_step"),
        d.get("critical_time_step"),
        d.get("discs"),
    ) {
        let damped = match d.get("critical_time_step_undamped") {
            Some(&u) if u > crit => format!(
                "; damping shortens it from 2/ν_max = {u:.4e} s (viscous contact damping by √(1 + ζ²) − ζ, non-viscous α by 1/√(1 + α))"
            ),
            _ => String::new(),
        };
        let what = format!(
            "Δt = {dt:.4e} s = {:.4} Δt_cr (Δt_cr = {crit:.4e} s of the initial contacts, Madan (2.14)–(2.16){damped}; the DDEM leaves it unchanged)",
            dt / crit
        );
        if dt > crit {
            push(
                Level::Refuse,
                "disc critical time step",
                format!("{what}: central differences diverge; use dem.time_step ≤ {crit:.4e} s"),
            );
        } else {
            push(Level::Info, "disc critical time step", what);
        }
    }
    if let (Some(&rho), Some(&ratio), Some(&nu)) = (
        d.get("ddem_spectral_radius"),
        d.get("ddem_kn_over_ep"),
        d.get("ddem_poisson_ratio"),
    ) {
        let limit = d.get("ddem_kn_over_ep_limit").copied().unwrap_or(f64::NAN);
        let lattice = d
            .get("ddem_spectral_radius_lattice")
            .map(|a| {
                format!("; the infinite lattice's analytic ρ(B) = {a:.4} (Madan (3.41)/(3.76))")
            })
            .unwrap_or_default();
        let what = format!(
            "k_n/E_p = {ratio:.4}, ν_p = {nu}: the iteration matrix of the initial packing has ρ(B) = {rho:.4}{lattice}; the limit ρ(B) = 1 lies at k_n/E_p = {limit:.4} for this packing and ν_p"
        );
        if rho >= 1.0 {
            push(Level::Refuse, "DDEM convergence", format!(
                "{what}: the lagged scheme diverges (Madan (3.13)–(3.14), §3.5–3.6); lower dem.contact.normal_stiffness or raise dem.ddem.youngs_modulus above {:.4e} Pa",
                ratio / limit * d.get("ddem_youngs_modulus").copied().unwrap_or(f64::NAN)
            ));
        } else {
            push(Level::Info, "DDEM convergence", what);
        }
    }
    // dilated polyhedra: the validity limit of the model
    if let Some(&v) = d.get("dilation_impact_velocity_max") {
        let f_max = d.get("dilation_force_max").copied().unwrap_or(f64::NAN);
        let what = format!(
            "the cores of the dilated polyhedra meet (the model's validity limit) in an elastic impact at {v:.3e} m/s or under a static contact force of {f_max:.3e} N"
        );
        if v < DILATION_IMPACT_VELOCITY_MIN {
            push(Level::Warn, "dilated polyhedra", format!(
                "{what}: slower than {DILATION_IMPACT_VELOCITY_MIN} m/s; raise the Young's modulus or the dilation (the run stops naming the pair if the cores meet)"
            ));
        } else {
            push(Level::Info, "dilated polyhedra", what);
        }
    }
    // a structure without a static solve cannot take the one-way schedule's static step
    if scene.schedule == ScheduleKind::OneWay && f.get("static_solve") == Some(&0.0) {
        push(
            Level::Refuse,
            "one-way schedule",
            "the structure has no static solve (a membrane steps explicitly); use the \
             predictive, JIT or implicit schedule"
                .to_string(),
        );
    }
    // FEM explicit: the node sub-steps each window at a safety fraction of Δt_crit itself
    if let (Some(&crit), Some(&1.0)) = (f.get("critical_time_step"), f.get("explicit")) {
        let w = scene.window;
        push(
            Level::Info,
            "FEM explicit critical step",
            format!(
                "Δt_crit = {crit:.3e} s ({}); the FEM node sub-steps each window of {w:.3e} s ({} substeps or more)",
                if f.contains_key("membrane") {
                    "its membranes' shortest edge over the fastest wave, now"
                } else {
                    "Lanczos"
                },
                (w / crit).ceil()
            ),
        );
    }
    // two-way coupling window
    if scene.has_dem && scene.has_fem && f.get("volume_interface") == Some(&1.0) {
        // an Arlequin overlap: the FE side holds the penalty ε V in its operator, the
        // particles feel it explicitly at every DEM step (refused at set-up beyond the limit)
        let penalty = f.get("volume_penalty").copied().unwrap_or(f64::NAN);
        let step_limit = d.get("volume_penalty_step_limit").copied();
        push(
            Level::Info,
            "coupling window",
            format!(
                "volume interface (ε = {penalty:.3e} N/m⁴): the penalty acts implicitly on the FE \
                 side and explicitly on the particles within the DEM step{}; no window limit \
                 from a contact period",
                step_limit
                    .map(|l| format!(
                        " (its limit 2√(w m / k̂) = {l:.3e} s, Δt^D = {:.3} of it)",
                        d.get("time_step").copied().unwrap_or(f64::NAN) / l
                    ))
                    .unwrap_or_default()
            ),
        );
        // the staggered exchange: the continuum answers the particles a window late, and the
        // light, stiffly tied particles of the overlap oscillate with a period of the order of
        // the penalty's step limit (the window sweep of docs/two-scale.md)
        if let Some(l) = step_limit.filter(|&l| scene.window > VOLUME_WINDOW_FRACTION * l) {
            push(
                Level::Warn,
                "coupling window",
                format!(
                    "volume interface: Δt^C = {:.3e} s is {:.2} × the penalty's step limit \
                     2√(w m / k̂) = {l:.3e} s; in the patch test (a regular, nearly undamped \
                     lattice at ε = 1e14 N/m⁴) windows of 0.55–5.5 × that limit diverged and \
                     0.28 × did not, while dissipative packings ran stable at 4–12 × (the \
                     triaxial cube). Watch the energy audit and `volume.<name>.prediction_defect`, \
                     or use Δt^C ≤ {:.3e} s",
                    scene.window,
                    scene.window / l,
                    VOLUME_WINDOW_FRACTION * l
                ),
            );
        }
    } else if scene.has_dem && scene.has_fem {
        if let (Some(tc), Some((k, which))) = (contact_period(d, f), contact_stiffness(d)) {
            let m = f["interface_node_mass_min"];
            let name = crate::run::schedule_name(scene.schedule);
            match window_limit(scene.schedule, d, f) {
                Some(limit) => {
                    let w = scene.window;
                    if scene.schedule == ScheduleKind::Jit && has_stones(d) {
                        push(Level::Warn, "coupling window", JIT_ON_STONES.to_string());
                    }
                    let basis = format!(
                        "interface contact period T_c = 2π√(M/k) = {tc:.3e} s (lightest interface node M = {m:.3e} kg, {which} k = {k:.3e} N/m){}",
                        if has_stones(d) && scene.schedule == ScheduleKind::Predictive {
                            "; the fraction measured on dilated polyhedra, tighter than on spheres (a structure's corner nodes ring under single stones)"
                        } else {
                            ""
                        }
                    );
                    if w > limit {
                        let level = if w > REFUSE_BEYOND * limit {
                            Level::Refuse
                        } else {
                            Level::Warn
                        };
                        push(level, "coupling window", format!(
                            "Δt^C = {w:.3e} s exceeds the {name} limit {limit:.3e} s = {:.3} T_c; {basis}; use Δt^C ≤ {limit:.3e} s{}",
                            limit / tc,
                            match (scene.schedule, window_limit(ScheduleKind::Predictive, d, f)) {
                                (ScheduleKind::Jit, Some(p)) => format!(" (the predictive schedule allows {p:.3e} s)"),
                                _ => String::new(),
                            }
                        ));
                    } else {
                        push(
                            Level::Info,
                            "coupling window",
                            format!("Δt^C = {w:.3e} s = {:.3} of the {name} limit {limit:.3e} s; {basis}", w / limit),
                        );
                    }
                }
                None => push(
                    Level::Info,
                    "coupling window",
                    format!("{name}: no window limit (T_c = {tc:.3e} s)"),
                ),
            }
            if let (Some((min, max)), Some(limit)) =
                (scene.adaptive, window_limit(scene.schedule, d, f))
            {
                push(
                    Level::Info,
                    "adaptive windows",
                    format!(
                        "Δt^C from {min:.3e} s to {max:.3e} s (min_window × 2^i); while an interface is loaded the controller keeps it ≤ the {name} limit {limit:.3e} s{}",
                        if min > limit {
                            " — but min_window is above it: the loaded windows will exceed the limit"
                        } else {
                            ""
                        }
                    ),
                );
            }
            // every schedule's limit, for choosing one
            let all: Vec<String> = [
                ScheduleKind::Concurrent,
                ScheduleKind::Jit,
                ScheduleKind::Predictive,
            ]
            .iter()
            .filter_map(|&k| {
                window_limit(k, d, f).map(|l| {
                    format!(
                        "{} ≤ {l:.3e} s ({:.3} T_c)",
                        crate::run::schedule_name(k),
                        l / tc
                    )
                })
            })
            .collect();
            push(
                Level::Info,
                "window limits by schedule",
                format!(
                    "{}; implicit: none known (stable to {IMPLICIT_STABLE_TESTED} T_c, measured), each window costs its iterations",
                    all.join(", ")
                ),
            );
            if let Some(&mp) = d.get("particle_mass_max") {
                let ratio = mp / m;
                if !(1e-4..=1e4).contains(&ratio) {
                    push(Level::Info, "mass ratio", format!(
                        "heaviest particle / lightest interface node = {ratio:.3e}; the window limit above accounts for it through T_c"
                    ));
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn m(pairs: &[(&str, f64)]) -> BTreeMap<String, f64> {
        pairs.iter().map(|(k, v)| (k.to_string(), *v)).collect()
    }

    /// A DEM-only scene (no coupling window to check).
    fn dem_only() -> SceneFacts {
        SceneFacts {
            has_fem: false,
            ..facts(ScheduleKind::None, 1e-3)
        }
    }

    fn facts(schedule: ScheduleKind, window: f64) -> SceneFacts {
        SceneFacts {
            schedule,
            window,
            has_dem: true,
            has_fem: true,
            adaptive: None,
        }
    }

    #[test]
    fn contact_period_is_the_spring_mass_period() {
        let t = contact_period(
            &m(&[("contact_stiffness_max", 4e6)]),
            &m(&[("interface_node_mass_min", 1.0)]),
        )
        .unwrap();
        assert!((t - 2.0 * std::f64::consts::PI / 2000.0).abs() < 1e-15);
        assert!(contact_period(&m(&[]), &m(&[("interface_node_mass_min", 1.0)])).is_none());
        // the stiffness at the mean radius is preferred to the stiffest contact
        let both = m(&[
            ("contact_stiffness_max", 16e6),
            ("contact_stiffness_typical", 4e6),
        ]);
        let f = m(&[("interface_node_mass_min", 1.0)]);
        assert_eq!(contact_period(&both, &f), Some(t));
        let facts = facts(ScheduleKind::Predictive, 1e-4);
        let found = assess(&facts, Some(&both), Some(&f));
        let w = found.iter().find(|x| x.limit == "coupling window").unwrap();
        assert!(
            w.message
                .contains("typical contact (mean radius) k = 4.000e6"),
            "{w}"
        );
    }

    #[test]
    fn a_window_beyond_the_schedule_limit_is_refused_with_the_number_to_use() {
        let d = m(&[("contact_stiffness_max", 4e6)]);
        let f = m(&[("interface_node_mass_min", 1.0)]);
        let tc = 2.0 * std::f64::consts::PI / 2000.0;
        let jit_limit = JIT_WINDOW_FRACTION * tc;
        let ok = assess(
            &facts(ScheduleKind::Jit, 0.9 * jit_limit),
            Some(&d),
            Some(&f),
        );
        assert!(ok.iter().all(|x| x.level != Level::Refuse), "{ok:?}");
        let warned = assess(
            &facts(ScheduleKind::Jit, 1.1 * jit_limit),
            Some(&d),
            Some(&f),
        );
        assert!(warned
            .iter()
            .any(|x| x.level == Level::Warn && x.limit == "coupling window"));
        assert!(
            warned.iter().all(|x| x.level != Level::Refuse),
            "{warned:?}"
        );
        let bad = assess(
            &facts(ScheduleKind::Jit, 5.0 * jit_limit),
            Some(&d),
            Some(&f),
        );
        let r = bad
            .iter()
            .find(|x| x.level == Level::Refuse)
            .expect("refused");
        assert_eq!(r.limit, "coupling window");
        assert!(r.message.contains(&format!("{jit_limit:.3e}")), "{r}");
        assert!(r.message.contains("predictive schedule allows"), "{r}");
        // the same window is fine for the predictive schedule
        let p = assess(
            &facts(ScheduleKind::Predictive, 5.0 * jit_limit),
            Some(&d),
            Some(&f),
        );
        assert!(p.iter().all(|x| x.level != Level::Refuse), "{p:?}");
        // one-way coupling has no window limit
        let o = assess(&facts(ScheduleKind::OneWay, 1.0), Some(&d), Some(&f));
        assert!(o.iter().all(|x| x.level != Level::Refuse), "{o:?}");
        // adaptive windows: the range and the limit the controller keeps while loaded
        let mut a = facts(ScheduleKind::Predictive, 1e-6);
        a.adaptive = Some((1e-6, 1.0));
        let all = assess(&a, Some(&d), Some(&f));
        let l = all
            .iter()
            .find(|x| x.limit == "adaptive windows")
            .expect("the adaptive range");
        let p_limit = PREDICTIVE_WINDOW_FRACTION * tc;
        assert!(l.message.contains(&format!("{p_limit:.3e}")), "{l}");
        a.adaptive = Some((1.0, 2.0));
        let all = assess(&a, Some(&d), Some(&f));
        assert!(all
            .iter()
            .any(|x| x.message.contains("min_window is above it")));
        // ... and whatever the schedule, the check lists every schedule's limit
        for k in [
            ScheduleKind::OneWay,
            ScheduleKind::Implicit,
            ScheduleKind::Jit,
        ] {
            let all = assess(&facts(k, 1e-6), Some(&d), Some(&f));
            let l = all
                .iter()
                .find(|x| x.limit == "window limits by schedule")
                .expect("the table of limits");
            for (name, fraction) in [
                ("concurrent", CONCURRENT_WINDOW_FRACTION),
                ("jit", JIT_WINDOW_FRACTION),
                ("predictive", PREDICTIVE_WINDOW_FRACTION),
            ] {
                let expected = format!("{name} ≤ {:.3e} s", fraction * tc);
                assert!(l.message.contains(&expected), "{expected}: {l}");
            }
            assert!(l.message.contains("implicit: none known"), "{l}");
        }
    }

    #[test]
    fn stones_get_the_predictive_fraction_and_the_jit_warning_measured_on_polyhedral_ballast() {
        let spheres = m(&[("contact_stiffness_max", 4e6)]);
        let stones = m(&[("contact_stiffness_max", 4e6), ("dilation_force_max", 1e5)]);
        let f = m(&[("interface_node_mass_min", 1.0)]);
        let tc = 2.0 * std::f64::consts::PI / 2000.0;
        let a = window_limit(ScheduleKind::Predictive, &spheres, &f).unwrap();
        let b = window_limit(ScheduleKind::Predictive, &stones, &f).unwrap();
        assert!((a - PREDICTIVE_WINDOW_FRACTION * tc).abs() < 1e-15);
        assert!((b - PREDICTIVE_WINDOW_FRACTION_STONES * tc).abs() < 1e-15);
        let findings = |d: &BTreeMap<String, f64>, k, w| {
            assess(&facts(k, w), Some(d), Some(&f))
                .into_iter()
                .filter(|x| x.level != Level::Info && x.limit == "coupling window")
                .map(|x| x.message)
                .collect::<Vec<_>>()
        };
        // predictive: the measured stable 0.31 T_c passes on stones, the diverging 0.62 is
        // warned, naming the stones; on spheres 0.62 T_c passes
        assert!(findings(&stones, ScheduleKind::Predictive, 0.31 * tc).is_empty());
        let w = findings(&stones, ScheduleKind::Predictive, 0.62 * tc);
        assert!(w.len() == 1 && w[0].contains("dilated polyhedra"), "{w:?}");
        assert!(findings(&spheres, ScheduleKind::Predictive, 0.62 * tc).is_empty());
        // JIT on stones is warned at any window, on spheres not below its limit
        let w = findings(&stones, ScheduleKind::Jit, 0.015 * tc);
        assert!(w.len() == 1 && w[0] == JIT_ON_STONES, "{w:?}");
        assert!(findings(&spheres, ScheduleKind::Jit, 0.015 * tc).is_empty());
    }

    #[test]
    fn unresolved_impacts_are_refused_and_poorly_resolved_ones_warned() {
        let s = dem_only();
        let d = |tc: f64| {
            m(&[
                ("time_step", 1e-5),
                ("rayleigh_time_step", 1e-4),
                ("contact_duration_min", tc),
            ])
        };
        let level = |tc| {
            assess(&s, Some(&d(tc)), None)
                .iter()
                .map(|x| x.level)
                .max()
                .unwrap()
        };
        assert_eq!(level(2e-5), Level::Refuse);
        assert_eq!(level(5e-5), Level::Warn);
        assert_eq!(level(1e-3), Level::Info);
    }

    #[test]
    fn soft_dilated_polyhedra_are_warned_with_the_speed_and_force_named() {
        let s = dem_only();
        let found = |v: f64| {
            assess(
                &s,
                Some(&m(&[
                    ("dilation_impact_velocity_max", v),
                    ("dilation_force_max", 12.5),
                ])),
                None,
            )
            .into_iter()
            .find(|x| x.limit == "dilated polyhedra")
            .unwrap()
        };
        let soft = found(0.4);
        assert_eq!(soft.level, Level::Warn);
        assert!(
            soft.message.contains("4.000e-1 m/s") && soft.message.contains("1.250e1 N"),
            "{soft}"
        );
        assert_eq!(found(20.0).level, Level::Info);
        // spheres: no such finding
        assert!(assess(&s, Some(&m(&[])), None)
            .iter()
            .all(|x| x.limit != "dilated polyhedra"));
    }

    #[test]
    fn steps_beyond_the_damped_limit_of_sphere_contacts_are_warned_with_the_mode() {
        let s = dem_only();
        let found = |dt: f64, mode: f64| {
            assess(
                &s,
                Some(&m(&[
                    ("time_step", dt),
                    ("rayleigh_time_step", 1.8e-6),
                    ("damped_step_limit", 1.05e-7),
                    ("damped_step_mode", mode),
                    ("damped_step_zeta", 5.6),
                ])),
                None,
            )
            .into_iter()
            .find(|x| x.limit == "DEM damped contact step")
            .unwrap()
        };
        let over = found(5e-7, 1.0);
        assert_eq!(over.level, Level::Warn);
        assert!(
            over.message.contains("tangential–rotational")
                && over.message.contains("ζ = 5.60")
                && over.message.contains("dem.time_step ≤ 1.575e-7 s")
                && over.message.contains("damping_ratio"),
            "{over}"
        );
        assert!(found(5e-7, 0.0).message.contains("its normal mode"));
        assert_eq!(found(1e-7, 1.0).level, Level::Info);
        assert_eq!(found(1.5e-7, 1.0).level, Level::Info);
        assert_eq!(found(1.6e-7, 1.0).level, Level::Warn);
        // no spheres: no such finding
        assert!(assess(&s, Some(&m(&[("time_step", 1e-6)])), None)
            .iter()
            .all(|x| x.limit != "DEM damped contact step"));
    }
}
