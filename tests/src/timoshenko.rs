//! Timoshenko's (1913) semi-analytical solution for a sphere striking a simply
//! supported beam at midspan with Hertzian local contact.
//!
//! References: S. Timoshenko, "Zur Frage nach der Wirkung eines Stoßes auf
//! einen Balken", Z. Math. Phys. 62 (1913) 198–209; W. Goldsmith, *Impact*
//! (1960), §4; Timoshenko & Goodier, *Theory of Elasticity* (impact of a
//! sphere on a beam).
//!
//! # Model and assumptions
//!
//! * **Beam**: Euler–Bernoulli, simply supported at `x = 0` and `x = L`, small
//!   deflections, no damping, no rotary inertia or shear deformation.  The
//!   cross-section is a `width × height` rectangle bent about the axis parallel
//!   to the width, i.e. the sphere strikes the `width` face and moves along the
//!   `height` direction: `A = width·height`, `I = width·height³/12`.  Modes are
//!   `sin(iπx/L)` with `ω_i = (iπ/L)² √(EI/(ρA))`; a midspan point force only
//!   excites the odd (symmetric) modes.  With the midspan modal coordinate
//!   `u_i` (`w(L/2, t) = Σ u_i`), each mode obeys
//!   `ü_i + ω_i² u_i = (2/(ρAL)) P(t)`, i.e.
//!   `w(t) = Σ_{i odd} (2/(ρAL ω_i)) ∫₀ᵗ P(τ) sin ω_i(t−τ) dτ`.
//!   The beam is at rest and undeformed at `t = 0`.
//! * **Sphere**: a rigid body (mass `m = 4/3 π R³ ρ_s`) apart from the Hertz
//!   zone; position `z` (positive into the beam), `z(0) = 0` at first touch,
//!   `ż(0) = v0`; `m z̈ = −P`.  No gravity.
//! * **Contact**: Hertz sphere on a (locally flat) half-space:
//!   approach `α = z − w`, `P = k α^{3/2}` for `α > 0`, else `P = 0`, with
//!   `k = (4/3) E* √R` and `1/E* = (1−ν²)/E + (1−ν_s²)/E_s`.  The Hertz law is
//!   quasi-static: no wave effects in the contact zone, no local indentation
//!   of the beam cross-section beyond the Hertz approach, no friction.
//!
//! # Time integration
//!
//! The contact force is taken piecewise linear in time (linear over each step
//! `h`).  For such a force every modal oscillator and the sphere's free-body
//! motion are integrated *exactly* (closed-form discrete convolution, one
//! recursion per mode).  The end-of-step force `P₁` is implicit: the approach
//! at the end of the step is `α₁ = a − D P₁` with `a` the "free" approach (no
//! new force) and `D = h²/(6m) + (2/(ρAL)) Σ_i a1_i(h)` the step compliance;
//! `α₁ + D k α₁^{3/2} = a` is solved by a monotone Newton iteration.  The only
//! discretisation error is thus the linear interpolation of `P(t)`, which is
//! second order in `h`; the sphere's momentum balance `m(v0 − v) = ∫P dt`
//! holds to round-off by construction.
//!
//! Contact start/end times are located by linear interpolation of `α` across
//! the step in which it changes sign (second-order accurate); peak forces are
//! refined by a parabola through the three step values around the largest.
//! The energy error is the O(h²) force-interpolation error (≈5e-7 relative
//! at `h = 1e-7 s` for the classical case, ≈1.2e-7 at `5e-8 s`).
//!
//! [`solve_with_theory`] optionally replaces the Euler–Bernoulli modes by
//! Timoshenko-beam modes (shear + rotary inertia, two branches per
//! wavenumber); everything else is unchanged.
//!
//! # The classical case
//!
//! [`timoshenko_1913`] returns the data (steel, `E = 2.1e11 Pa`, `ν = 0.3`,
//! `ρ = 7800 kg/m³`).  With this model the ball makes **one** contact
//! (0 – 0.15684 ms, peak 4.8635 N) and leaves with −0.30225 cm/s; the beam's
//! return swing misses it by ≈0.29 µm at ≈0.73 ms, and it is never hit
//! again.  A second impact at ≈1.5 ms with a final 0.35 cm/s (as quoted from
//! Wellmann's thesis) is *not* reproduced, neither with the
//! Timoshenko-beam variant nor with `E = 2.06e11 Pa`, `ν = 0.25`,
//! `ρ = 7850 kg/m³`, or with 0.5 / 2 cm/s.

use std::f64::consts::PI;

/// Simply supported rectangular beam (SI units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Beam {
    /// Span `L` between the supports \[m\].
    pub length: f64,
    /// Width of the struck face \[m\].
    pub width: f64,
    /// Depth in the impact direction \[m\].
    pub height: f64,
    /// Density `ρ` \[kg/m³\].
    pub density: f64,
    /// Young's modulus `E` \[Pa\].
    pub youngs_modulus: f64,
    /// Poisson's ratio (only enters the Hertz constant).
    pub poisson_ratio: f64,
}

/// Impacting sphere (SI units); `velocity` is the initial velocity towards
/// the beam (positive = into the beam).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sphere {
    /// Radius `R` \[m\].
    pub radius: f64,
    /// Density `ρ_s` \[kg/m³\].
    pub density: f64,
    /// Young's modulus `E_s` \[Pa\].
    pub youngs_modulus: f64,
    /// Poisson's ratio `ν_s`.
    pub poisson_ratio: f64,
    /// Initial velocity `v0` \[m/s\], positive towards the beam.
    pub velocity: f64,
}

/// Discretisation options.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Options {
    /// Number of symmetric (odd) beam modes retained: mode indices
    /// `i = 1, 3, …, 2·modes − 1`.  `0` gives a rigid, immovable beam.
    pub modes: usize,
    /// Time step `h` \[s\].
    pub time_step: f64,
    /// Simulated time \[s\]; the run takes `ceil(duration / h)` steps.
    pub duration: f64,
    /// Record a [`Sample`] every `sample_every` steps (plus `t = 0` and the
    /// final state); `0` is treated as `1`.
    pub sample_every: usize,
}

/// State at one output instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Time \[s\].
    pub t: f64,
    /// Contact force `P` \[N\].
    pub force: f64,
    /// Sphere displacement `z` \[m\] (positive into the beam).
    pub sphere: f64,
    /// Beam midspan deflection `w` \[m\] (same sign convention).
    pub beam: f64,
    /// Sphere velocity `ż` \[m/s\].
    pub sphere_velocity: f64,
    /// Beam midspan velocity `ẇ` \[m/s\].
    pub beam_velocity: f64,
}

/// One contact interval.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Contact {
    /// Time the approach becomes positive \[s\].
    pub start: f64,
    /// Time the approach returns to zero \[s\] (or the end of the run if the
    /// contact is still open then).
    pub end: f64,
    /// Largest contact force during the interval \[N\].
    pub peak_force: f64,
    /// `∫ P dt` over the interval \[N·s\].
    pub impulse: f64,
}

/// Result of [`solve`].
#[derive(Debug, Clone, PartialEq)]
pub struct Solution {
    /// Sampled time series.
    pub samples: Vec<Sample>,
    /// Contact intervals in chronological order.
    pub contacts: Vec<Contact>,
    /// Sphere velocity at the end of the run \[m/s\] (negative = rebounding).
    pub final_sphere_velocity: f64,
    /// Sum of the contact impulses \[N·s\].
    pub total_impulse: f64,
}

impl Beam {
    /// Cross-section area `A = width·height`.
    pub fn area(&self) -> f64 {
        self.width * self.height
    }

    /// Second moment of area `I = width·height³/12`.
    pub fn second_moment(&self) -> f64 {
        self.width * self.height.powi(3) / 12.0
    }

    /// Total beam mass `ρAL`.
    pub fn mass(&self) -> f64 {
        self.density * self.area() * self.length
    }

    /// Circular frequency of mode `i` (1-based): `(iπ/L)² √(EI/(ρA))`.
    pub fn natural_frequency(&self, i: usize) -> f64 {
        let kappa = i as f64 * PI / self.length;
        kappa
            * kappa
            * (self.youngs_modulus * self.second_moment() / (self.density * self.area())).sqrt()
    }

    /// Static midspan compliance `L³/(48EI)` \[m/N\].
    pub fn static_compliance(&self) -> f64 {
        self.length.powi(3) / (48.0 * self.youngs_modulus * self.second_moment())
    }
}

impl Sphere {
    /// Mass `4/3 π R³ ρ_s`.
    pub fn mass(&self) -> f64 {
        4.0 / 3.0 * PI * self.radius.powi(3) * self.density
    }
}

/// Hertz constant `k = (4/3) E* √R` of the sphere on the flat beam face
/// \[N/m^{3/2}\].
pub fn hertz_constant(beam: &Beam, sphere: &Sphere) -> f64 {
    let inv_e = (1.0 - beam.poisson_ratio * beam.poisson_ratio) / beam.youngs_modulus
        + (1.0 - sphere.poisson_ratio * sphere.poisson_ratio) / sphere.youngs_modulus;
    4.0 / 3.0 / inv_e * sphere.radius.sqrt()
}

/// `2 ∫₀¹ (1 − x^{5/2})^{−1/2} dx = (4/5) B(2/5, 1/2)`.
pub const HERTZ_DURATION_FACTOR: f64 = 2.943_275_184_324_705;

/// Hertz impact of a mass `m` on a rigid wall: maximum approach
/// `α_max = (5 m v0² / (4k))^{2/5}`.
pub fn rigid_wall_max_approach(m: f64, k: f64, v0: f64) -> f64 {
    (5.0 * m * v0 * v0 / (4.0 * k)).powf(0.4)
}

/// Hertz impact on a rigid wall: contact duration
/// `t_c = 2.9433 α_max / v0 = 3.2181 (m/k)^{2/5} v0^{−1/5}`.
pub fn rigid_wall_contact_time(m: f64, k: f64, v0: f64) -> f64 {
    HERTZ_DURATION_FACTOR * rigid_wall_max_approach(m, k, v0) / v0
}

/// Hertz impact on a rigid wall: peak force `k α_max^{3/2}`.
pub fn rigid_wall_peak_force(m: f64, k: f64, v0: f64) -> f64 {
    k * rigid_wall_max_approach(m, k, v0).powf(1.5)
}

/// Timoshenko's classical example: steel ball, `R = 1 cm`, `v0 = 1 cm/s`,
/// on a steel beam `1 cm × 1 cm`, span `15.35 cm`.  Material constants used
/// here: `E = 2.1e11 Pa`, `ν = 0.3`, `ρ = 7800 kg/m³` for both bodies
/// (Timoshenko worked in technical units, probably `E = 2.1·10⁶ kg/cm²`
/// ≈ 2.06e11 Pa — unverified).
pub fn timoshenko_1913() -> (Beam, Sphere) {
    let (e, nu, rho) = (2.1e11, 0.3, 7800.0);
    (
        Beam {
            length: 0.1535,
            width: 0.01,
            height: 0.01,
            density: rho,
            youngs_modulus: e,
            poisson_ratio: nu,
        },
        Sphere {
            radius: 0.01,
            density: rho,
            youngs_modulus: e,
            poisson_ratio: nu,
            velocity: 0.01,
        },
    )
}

/// Beam theory used for the modal model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BeamTheory {
    /// Euler–Bernoulli (Timoshenko 1913, the default of [`solve`]).
    EulerBernoulli,
    /// Timoshenko beam (shear deformation + rotary inertia) with shear
    /// coefficient `κ` (5/6 or Cowper's `10(1+ν)/(12+11ν)` for a rectangle);
    /// `G = E/(2(1+ν))`.  Each symmetric wavenumber contributes two branches
    /// (bending and thickness-shear).
    Timoshenko {
        /// Shear correction factor `κ`.
        shear_coefficient: f64,
    },
}

/// Midspan oscillators `(ω_j, g_j)`: `w(L/2) = Σ u_j`, `ü_j + ω_j² u_j = g_j P`.
fn oscillators(beam: &Beam, modes: usize, theory: BeamTheory) -> Vec<(f64, f64)> {
    let l = beam.length;
    match theory {
        BeamTheory::EulerBernoulli => {
            let g = 2.0 / beam.mass();
            (0..modes)
                .map(|j| (beam.natural_frequency(2 * j + 1), g))
                .collect()
        }
        BeamTheory::Timoshenko { shear_coefficient } => {
            // Per wavenumber κ_i = iπ/L, w = W sin, ψ = Ψ cos:
            // M = diag(ρA, ρI), K = [[kGA κ², −kGA κ], [−kGA κ, EI κ² + kGA]],
            // generalized force (2/L)(±P, 0).  With φᵀMφ = 1 the midspan
            // share of a branch obeys ü + ω² u = (2 φ_W²/L) P.
            let (rho, e) = (beam.density, beam.youngs_modulus);
            let (a, i2) = (beam.area(), beam.second_moment());
            let kga = shear_coefficient * e / (2.0 * (1.0 + beam.poisson_ratio)) * a;
            let (m11, m22) = (rho * a, rho * i2);
            let mut out = Vec::with_capacity(2 * modes);
            for j in 0..modes {
                let kap = (2 * j + 1) as f64 * PI / l;
                let (k11, k12, k22) = (kga * kap * kap, -kga * kap, e * i2 * kap * kap + kga);
                // m11 m22 λ² − (k11 m22 + k22 m11) λ + (k11 k22 − k12²) = 0
                let b = k11 * m22 + k22 * m11;
                let c = k11 * k22 - k12 * k12;
                let disc = (b * b - 4.0 * m11 * m22 * c).max(0.0).sqrt();
                let lam_hi = (b + disc) / (2.0 * m11 * m22);
                let lam_lo = c / (m11 * m22 * lam_hi);
                for lam in [lam_lo, lam_hi] {
                    // Two candidate (unnormalised) eigenvectors; use the
                    // better-conditioned one.
                    let v1 = (-k12, k11 - lam * m11);
                    let v2 = (k22 - lam * m22, -k12);
                    let n1 = v1.0.hypot(v1.1);
                    let n2 = v2.0.hypot(v2.1);
                    let (pw, ppsi) = if n1 >= n2 { v1 } else { v2 };
                    let phi_w2 = pw * pw / (m11 * pw * pw + m22 * ppsi * ppsi);
                    out.push((lam.sqrt(), 2.0 * phi_w2 / l));
                }
            }
            out
        }
    }
}

/// Exact one-step propagator of `ü + ω² u = g P(t)` with `P` linear over the
/// step: `u₁ = c u₀ + (s/ω) v₀ + a0 P₀ + a1 P₁`,
/// `v₁ = −ω s u₀ + c v₀ + b0 P₀ + b1 P₁` (force coefficients include `g`).
#[derive(Debug, Clone, Copy)]
struct ModeStep {
    omega: f64,
    /// Force gain: `ü + ω² u = g P` for this oscillator's midspan share `u`.
    #[cfg_attr(not(test), allow(dead_code))]
    g: f64,
    c: f64,
    s_over_omega: f64,
    omega_s: f64,
    a0: f64,
    a1: f64,
    b0: f64,
    b1: f64,
}

impl ModeStep {
    fn new(omega: f64, g: f64, h: f64) -> Self {
        let x = omega * h;
        let (s, c) = x.sin_cos();
        // u0 = (sin x/x − cos x)/x², u1 = (1 − sin x/x)/x²,
        // v0 = sin x/x − (1 − cos x)/x², v1 = (1 − cos x)/x²;
        // Taylor series for small x to avoid cancellation.
        let (u0, u1, v0, v1, sinc) = if x < 0.1 {
            let x2 = x * x;
            let x4 = x2 * x2;
            let x6 = x4 * x2;
            (
                1.0 / 3.0 - x2 / 30.0 + x4 / 840.0 - x6 / 45_360.0,
                1.0 / 6.0 - x2 / 120.0 + x4 / 5040.0 - x6 / 362_880.0,
                0.5 - x2 / 8.0 + x4 / 144.0 - x6 / 5760.0,
                0.5 - x2 / 24.0 + x4 / 720.0 - x6 / 40_320.0,
                1.0 - x2 / 6.0 + x4 / 120.0 - x6 / 5040.0,
            )
        } else {
            let x2 = x * x;
            let sinc = s / x;
            let one_minus_c = 2.0 * (0.5 * x).sin().powi(2);
            (
                (sinc - c) / x2,
                (1.0 - sinc) / x2,
                sinc - one_minus_c / x2,
                one_minus_c / x2,
                sinc,
            )
        };
        ModeStep {
            omega,
            g,
            c,
            s_over_omega: h * sinc,
            omega_s: omega * s,
            a0: g * h * h * u0,
            a1: g * h * h * u1,
            b0: g * h * v0,
            b1: g * h * v1,
        }
    }
}

/// Root of `α + dk·α^{3/2} = a` (`a > 0`, `dk ≥ 0`), `0 < α ≤ a`.
/// Newton from `α = a`: the function is increasing and convex, so the
/// iterates decrease monotonically onto the root.
fn solve_approach(a: f64, dk: f64) -> f64 {
    let mut x = a;
    for _ in 0..200 {
        let sq = x.sqrt();
        let f = x + dk * x * sq - a;
        let df = 1.0 + 1.5 * dk * sq;
        let xn = x - f / df;
        if xn.is_nan() || xn <= 0.0 {
            // Round-off guard; cannot happen in exact arithmetic.
            x *= 0.5;
            continue;
        }
        if xn >= x || x - xn <= 4.0 * f64::EPSILON * x {
            return xn.min(x);
        }
        x = xn;
    }
    x
}

/// Coupled sphere–beam state advanced by the exact piecewise-linear-force
/// propagator.
#[derive(Debug, Clone)]
struct Simulator {
    h: f64,
    m: f64,
    k: f64,
    /// `(h²/(6m) + Σ a1) · k`.
    dk: f64,
    modes: Vec<ModeStep>,
    u: Vec<f64>,
    v: Vec<f64>,
    z: f64,
    vz: f64,
    p: f64,
    n: u64,
}

impl Simulator {
    fn new(beam: &Beam, sphere: &Sphere, oscillators: &[(f64, f64)], h: f64) -> Self {
        let m = sphere.mass();
        let k = hertz_constant(beam, sphere);
        let modes: Vec<ModeStep> = oscillators
            .iter()
            .map(|&(omega, g)| ModeStep::new(omega, g, h))
            .collect();
        let beam_step_compliance: f64 = modes.iter().map(|md| md.a1).sum::<f64>();
        let d = h * h / (6.0 * m) + beam_step_compliance;
        Simulator {
            h,
            m,
            k,
            dk: d * k,
            u: vec![0.0; modes.len()],
            v: vec![0.0; modes.len()],
            modes,
            z: 0.0,
            vz: sphere.velocity,
            p: 0.0,
            n: 0,
        }
    }

    fn time(&self) -> f64 {
        self.n as f64 * self.h
    }

    fn beam_deflection(&self) -> f64 {
        self.u.iter().sum()
    }

    fn beam_velocity(&self) -> f64 {
        self.v.iter().sum()
    }

    /// Hertz approach `α = z − w` (negative = gap).
    fn approach(&self) -> f64 {
        self.z - self.beam_deflection()
    }

    fn sample(&self) -> Sample {
        Sample {
            t: self.time(),
            force: self.p,
            sphere: self.z,
            beam: self.beam_deflection(),
            sphere_velocity: self.vz,
            beam_velocity: self.beam_velocity(),
        }
    }

    /// Sphere kinetic + beam modal (kinetic + strain) + Hertz potential.
    #[cfg_attr(not(test), allow(dead_code))]
    fn energy(&self) -> f64 {
        let beam: f64 = self
            .modes
            .iter()
            .zip(self.u.iter().zip(&self.v))
            .map(|(md, (u, v))| (v * v + md.omega * md.omega * u * u) / (2.0 * md.g))
            .sum::<f64>();
        let alpha = self.approach();
        let hertz = if alpha > 0.0 {
            0.4 * self.k * alpha.powf(2.5)
        } else {
            0.0
        };
        0.5 * self.m * self.vz * self.vz + beam + hertz
    }

    /// Upper bound of the midspan deflection for all future free vibration.
    fn free_amplitude_bound(&self) -> f64 {
        self.modes
            .iter()
            .zip(self.u.iter().zip(&self.v))
            .map(|(md, (u, v))| u.hypot(v / md.omega))
            .sum()
    }

    fn step(&mut self) {
        let h = self.h;
        let p0 = self.p;
        let mut w_free = 0.0;
        for (md, (u, v)) in self.modes.iter().zip(self.u.iter().zip(&self.v)) {
            w_free += md.c * u + md.s_over_omega * v + md.a0 * p0;
        }
        let z_free = self.z + self.vz * h - h * h * p0 / (3.0 * self.m);
        let a = z_free - w_free;
        let p1 = if a > 0.0 {
            let alpha = solve_approach(a, self.dk);
            self.k * alpha * alpha.sqrt()
        } else {
            0.0
        };
        for (md, (u, v)) in self
            .modes
            .iter()
            .zip(self.u.iter_mut().zip(self.v.iter_mut()))
        {
            let un = md.c * *u + md.s_over_omega * *v + md.a0 * p0 + md.a1 * p1;
            let vn = -md.omega_s * *u + md.c * *v + md.b0 * p0 + md.b1 * p1;
            *u = un;
            *v = vn;
        }
        self.z = z_free - h * h * p1 / (6.0 * self.m);
        self.vz -= 0.5 * h * (p0 + p1) / self.m;
        self.p = p1;
        self.n += 1;
    }
}

/// Contact interval under construction.
#[derive(Debug, Clone, Copy)]
struct OpenContact {
    start: f64,
    impulse: f64,
    peak: f64,
    before_peak: f64,
    after_peak: Option<f64>,
}

impl OpenContact {
    fn close(self, end: f64) -> Contact {
        let mut peak = self.peak;
        if let Some(after) = self.after_peak {
            let (ym, y0, yp) = (self.before_peak, self.peak, after);
            let den = ym - 2.0 * y0 + yp;
            if ym > 0.0 && yp > 0.0 && den < 0.0 {
                peak = y0 - 0.125 * (ym - yp) * (ym - yp) / den;
            }
        }
        Contact {
            start: self.start,
            end,
            peak_force: peak,
            impulse: self.impulse,
        }
    }
}

/// Detects contact starts/ends and accumulates impulses and peaks.
#[derive(Debug, Default)]
struct Tracker {
    open: Option<OpenContact>,
    closed: Vec<Contact>,
}

impl Tracker {
    /// Feed one step `t0 → t0 + h`; returns the start time if a contact
    /// began in this step.
    fn update(
        &mut self,
        t0: f64,
        h: f64,
        alpha0: f64,
        p0: f64,
        alpha1: f64,
        p1: f64,
    ) -> Option<f64> {
        let mut started = None;
        if p0 <= 0.0 && p1 > 0.0 {
            let frac = if alpha1 > alpha0 {
                (-alpha0 / (alpha1 - alpha0)).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let start = t0 + frac * h;
            started = Some(start);
            self.open = Some(OpenContact {
                start,
                impulse: 0.0,
                peak: 0.0,
                before_peak: 0.0,
                after_peak: None,
            });
        }
        if let Some(c) = self.open.as_mut() {
            c.impulse += 0.5 * h * (p0 + p1);
            if p1 > c.peak {
                c.peak = p1;
                c.before_peak = p0;
                c.after_peak = None;
            } else if c.after_peak.is_none() {
                c.after_peak = Some(p1);
            }
            if p1 <= 0.0 {
                let frac = if alpha0 > alpha1 {
                    (alpha0 / (alpha0 - alpha1)).clamp(0.0, 1.0)
                } else {
                    1.0
                };
                let closed = c.close(t0 + frac * h);
                self.closed.push(closed);
                self.open = None;
            }
        }
        started
    }
}

fn valid(beam: &Beam, sphere: &Sphere, opt: &Options) -> bool {
    let pos = |x: f64| x.is_finite() && x > 0.0;
    let nu = |x: f64| x.is_finite() && x > -1.0 && x < 1.0;
    pos(beam.length)
        && pos(beam.width)
        && pos(beam.height)
        && pos(beam.density)
        && pos(beam.youngs_modulus)
        && nu(beam.poisson_ratio)
        && pos(sphere.radius)
        && pos(sphere.density)
        && pos(sphere.youngs_modulus)
        && nu(sphere.poisson_ratio)
        && sphere.velocity.is_finite()
        && pos(opt.time_step)
        && opt.duration.is_finite()
        && opt.duration >= 0.0
        && (opt.duration / opt.time_step) < 1e12
}

/// Core driver: runs `opt.duration`, then (if `horizon > 0`) continues the
/// free/contact evolution up to `horizon` further seconds looking for the
/// next contact start.  `observer` sees the state after every step of the
/// main run.
fn run<F: FnMut(&Simulator)>(
    beam: &Beam,
    sphere: &Sphere,
    opt: &Options,
    theory: BeamTheory,
    horizon: f64,
    mut observer: F,
) -> (Solution, Option<f64>) {
    let theory_ok = match theory {
        BeamTheory::EulerBernoulli => true,
        BeamTheory::Timoshenko { shear_coefficient } => {
            shear_coefficient.is_finite() && shear_coefficient > 0.0
        }
    };
    if !theory_ok || !valid(beam, sphere, opt) {
        return (
            Solution {
                samples: Vec::new(),
                contacts: Vec::new(),
                final_sphere_velocity: sphere.velocity,
                total_impulse: 0.0,
            },
            None,
        );
    }
    let h = opt.time_step;
    let every = opt.sample_every.max(1) as u64;
    let n_steps = ((opt.duration / h) * (1.0 - 1e-12)).ceil() as u64;
    let mut sim = Simulator::new(beam, sphere, &oscillators(beam, opt.modes, theory), h);
    let mut tracker = Tracker::default();
    let mut samples = vec![sim.sample()];
    observer(&sim);
    let mut alpha = sim.approach();
    for _ in 0..n_steps {
        let (t0, p0, alpha0) = (sim.time(), sim.p, alpha);
        sim.step();
        alpha = sim.approach();
        tracker.update(t0, h, alpha0, p0, alpha, sim.p);
        observer(&sim);
        if sim.n % every == 0 {
            samples.push(sim.sample());
        }
    }
    if !sim.n % every == 0 {
        samples.push(sim.sample());
    }
    let mut contacts = tracker.closed.clone();
    if let Some(open) = tracker.open {
        contacts.push(open.close(sim.time()));
    }
    let total_impulse = contacts.iter().map(|c| c.impulse).sum();
    let solution = Solution {
        samples,
        contacts,
        final_sphere_velocity: sim.vz,
        total_impulse,
    };

    // Optional look-ahead for a further contact.
    let mut next = None;
    if horizon.is_finite() && horizon > 0.0 {
        let t_stop = sim.time() + horizon;
        let mut i = 0u64;
        while sim.time() < t_stop {
            if sim.p <= 0.0
                && sim.vz <= 0.0
                && i % 64 == 0
                && sim.z + sim.free_amplitude_bound() < 0.0
            {
                // The sphere moves away and is already beyond the largest
                // deflection the freely vibrating beam can ever reach.
                break;
            }
            let (t0, p0, alpha0) = (sim.time(), sim.p, alpha);
            sim.step();
            alpha = sim.approach();
            if let Some(start) = tracker.update(t0, h, alpha0, p0, alpha, sim.p) {
                next = Some(start);
                break;
            }
            i += 1;
        }
    }
    (solution, next)
}

/// Solves the sphere–beam impact (see the module documentation).
///
/// Invalid input (non-positive or non-finite dimensions, moduli, densities,
/// time step; `|ν| ≥ 1`; negative duration) yields an empty solution with
/// `final_sphere_velocity = sphere.velocity`.  A contact still open at the
/// end of the run is reported with `end` = final time.
pub fn solve(beam: &Beam, sphere: &Sphere, opt: &Options) -> Solution {
    run(beam, sphere, opt, BeamTheory::EulerBernoulli, 0.0, |_| {}).0
}

/// As [`solve`], and additionally continues the motion for up to `horizon`
/// seconds past the end of the run and returns the start time of the next
/// contact (the beam hitting the sphere again), or `None` if there is none
/// within the horizon.  The look-ahead stops early, with `None`, as soon as
/// the receding sphere is provably out of reach of the freely vibrating beam
/// (`z < −Σ_i |amplitude_i|`).
pub fn solve_with_horizon(
    beam: &Beam,
    sphere: &Sphere,
    opt: &Options,
    horizon: f64,
) -> (Solution, Option<f64>) {
    run(
        beam,
        sphere,
        opt,
        BeamTheory::EulerBernoulli,
        horizon,
        |_| {},
    )
}

/// General entry point: [`solve_with_horizon`] with a choice of beam theory
/// (`horizon = 0` disables the look-ahead).  For
/// [`BeamTheory::Timoshenko`], `opt.modes` counts symmetric wavenumbers,
/// each contributing two oscillators.
pub fn solve_with_theory(
    beam: &Beam,
    sphere: &Sphere,
    opt: &Options,
    theory: BeamTheory,
    horizon: f64,
) -> (Solution, Option<f64>) {
    run(beam, sphere, opt, theory, horizon, |_| {})
}

#[cfg(test)]
mod tests {
    use super::*;

    fn classical_opts(modes: usize, h: f64) -> Options {
        Options {
            modes,
            time_step: h,
            duration: 4.0e-3,
            sample_every: 100,
        }
    }

    fn rel(a: f64, b: f64) -> f64 {
        (a - b).abs() / b.abs().max(f64::MIN_POSITIVE)
    }

    /// Largest relative change in peak force and in contact start/end times
    /// (times measured relative to the contact's duration).
    fn contact_change(a: &Solution, b: &Solution) -> (f64, f64) {
        assert_eq!(a.contacts.len(), b.contacts.len(), "contact count changed");
        let mut dp: f64 = 0.0;
        let mut dt: f64 = 0.0;
        for (x, y) in a.contacts.iter().zip(&b.contacts) {
            let dur = y.end - y.start;
            dp = dp.max(rel(x.peak_force, y.peak_force));
            dt = dt.max((x.start - y.start).abs() / dur);
            dt = dt.max((x.end - y.end).abs() / dur);
        }
        (dp, dt)
    }

    #[test]
    fn modal_normalisation_matches_static_compliance() {
        let (beam, _) = timoshenko_1913();
        let g = 2.0 / beam.mass();
        let sum: f64 = (0..20_000)
            .map(|j| {
                let w = beam.natural_frequency(2 * j + 1);
                g / (w * w)
            })
            .sum();
        assert!(rel(sum, beam.static_compliance()) < 1e-12, "{sum}");
    }

    #[test]
    fn mode_step_series_matches_closed_form() {
        // Compare the step coefficients at the series/closed-form switch and
        // against a brute-force fine-step integration of a ramp force.
        let h = 1.0;
        let lo = ModeStep::new(0.1 * (1.0 - 1e-12), 1.0, h);
        let hi = ModeStep::new(0.1, 1.0, h);
        for (a, b) in [
            (lo.a0, hi.a0),
            (lo.a1, hi.a1),
            (lo.b0, hi.b0),
            (lo.b1, hi.b1),
        ] {
            assert!(rel(a, b) < 1e-11, "{a} {b}");
        }
        for omega in [1e-3, 0.05, 0.3, 2.0, 40.0] {
            let md = ModeStep::new(omega, 1.0, h);
            let (f0, f1, u0, v0) = (0.7, -1.3, 0.2, -0.4);
            // Closed form of u(t) for the ramp, evaluated directly.
            let (s, c) = omega.sin_cos();
            let slope = f1 - f0;
            let w2 = omega * omega;
            let u_ex =
                u0 * c + v0 * s / omega + f0 * (1.0 - c) / w2 + slope / w2 * (1.0 - s / omega);
            let v_ex = -u0 * omega * s + v0 * c + f0 * s / omega + slope / w2 * (1.0 - c);
            let u_st = md.c * u0 + md.s_over_omega * v0 + md.a0 * f0 + md.a1 * f1;
            let v_st = -md.omega_s * u0 + md.c * v0 + md.b0 * f0 + md.b1 * f1;
            let tol = if omega < 0.01 { 1e-6 } else { 1e-12 };
            assert!(
                (u_st - u_ex).abs() < tol * (1.0 + u_ex.abs()),
                "{omega}: {u_st} {u_ex}"
            );
            assert!(
                (v_st - v_ex).abs() < tol * (1.0 + v_ex.abs()),
                "{omega}: {v_st} {v_ex}"
            );
        }
    }

    /// Runs the classical case and returns (max, final) relative energy
    /// error, sampled after every step.
    fn energy_drift(theory: BeamTheory, modes: usize, h: f64) -> (f64, f64, usize) {
        let (beam, sphere) = timoshenko_1913();
        let opt = classical_opts(modes, h);
        let mut e0 = None;
        let mut worst: f64 = 0.0;
        let mut last: f64 = 0.0;
        let sol = run(&beam, &sphere, &opt, theory, 0.0, |sim| {
            let e = sim.energy();
            let e0 = *e0.get_or_insert(e);
            last = (e - e0).abs() / e0;
            worst = worst.max(last);
        })
        .0;
        (worst, last, sol.contacts.len())
    }

    #[test]
    fn energy_is_conserved() {
        let eb = BeamTheory::EulerBernoulli;
        let (w1, f1, n) = energy_drift(eb, 200, 1.0e-7);
        let (w2, f2, _) = energy_drift(eb, 200, 0.5e-7);
        println!(
            "energy (E-B, 200 modes, {n} contact(s)): max |ΔE|/E0 = {w1:.3e} (h = 1e-7), \
             {w2:.3e} (h = 5e-8); at the end {f1:.3e}, {f2:.3e}"
        );
        assert!(w1 < 1e-6 && w2 < 1e-6, "energy drift {w1:e} {w2:e}");
        // The residual is the O(h²) force-interpolation error, not a leak.
        assert!(
            w1 / w2 > 3.0 && w1 / w2 < 5.0,
            "not second order: {}",
            w1 / w2
        );
        let tb = BeamTheory::Timoshenko {
            shear_coefficient: 5.0 / 6.0,
        };
        let (w3, f3, _) = energy_drift(tb, 200, 1.0e-7);
        println!("energy (Timoshenko beam): max {w3:.3e}, end {f3:.3e}");
        assert!(w3 < 1e-6, "energy drift {w3:e}");
    }

    #[test]
    fn timoshenko_beam_static_compliance_and_slender_limit() {
        let (beam, _) = timoshenko_1913();
        let kappa = 5.0 / 6.0;
        let th = BeamTheory::Timoshenko {
            shear_coefficient: kappa,
        };
        let kga = kappa * beam.youngs_modulus / (2.0 * (1.0 + beam.poisson_ratio)) * beam.area();
        let exact = beam.static_compliance() + beam.length / (4.0 * kga);
        let sum: f64 = oscillators(&beam, 100_000, th)
            .iter()
            .map(|&(w, g)| g / (w * w))
            .sum();
        assert!(rel(sum, exact) < 1e-5, "{sum} vs {exact}");
        // Slender beam: lowest branch ≈ Euler–Bernoulli.
        let slender = Beam {
            length: 100.0 * beam.length,
            ..beam
        };
        let osc = oscillators(&slender, 1, th);
        assert!(rel(osc[0].0, slender.natural_frequency(1)) < 1e-5);
        assert!(rel(osc[0].1, 2.0 / slender.mass()) < 1e-5);
        assert!(osc[1].1 < 1e-6 * osc[0].1);
    }

    #[test]
    fn momentum_equals_impulse() {
        let (beam, sphere) = timoshenko_1913();
        let sol = solve(&beam, &sphere, &classical_opts(200, 1.0e-7));
        let m = sphere.mass();
        let dp = m * (sphere.velocity - sol.final_sphere_velocity);
        let sum: f64 = sol.contacts.iter().map(|c| c.impulse).sum();
        let r = rel(dp, sol.total_impulse);
        println!(
            "momentum: m(v0 - v) = {dp:.12e}, ∫P dt = {:.12e}, rel {r:.2e}",
            sol.total_impulse
        );
        assert!(r < 1e-9);
        assert!(rel(sum, sol.total_impulse) < 1e-15);
    }

    #[test]
    fn converges_in_time_step_and_modes() {
        let (beam, sphere) = timoshenko_1913();
        let base = solve(&beam, &sphere, &classical_opts(200, 1.0e-7));
        let half = solve(&beam, &sphere, &classical_opts(200, 0.5e-7));
        let (dp, dt) = contact_change(&base, &half);
        println!("h 1e-7 -> 5e-8: peak {dp:.2e}, times {dt:.2e}");
        assert!(dp < 1e-4 && dt < 1e-4);
        let more = solve(&beam, &sphere, &classical_opts(400, 1.0e-7));
        let (dp, dt) = contact_change(&base, &more);
        println!("modes 200 -> 400: peak {dp:.2e}, times {dt:.2e}");
        assert!(dp < 1e-3 && dt < 1e-3);
    }

    #[test]
    fn rigid_heavy_beam_gives_hertz_wall_impact() {
        let (mut beam, sphere) = timoshenko_1913();
        beam.youngs_modulus *= 1e6;
        beam.density *= 1e6;
        let m = sphere.mass();
        let k = hertz_constant(&beam, &sphere);
        let v0 = sphere.velocity;
        let tc = rigid_wall_contact_time(m, k, v0);
        let pmax = rigid_wall_peak_force(m, k, v0);
        let opt = Options {
            modes: 200,
            time_step: tc / 2000.0,
            duration: 1.5 * tc,
            sample_every: 0,
        };
        let sol = solve(&beam, &sphere, &opt);
        assert_eq!(sol.contacts.len(), 1);
        let c = sol.contacts[0];
        println!(
            "rigid wall: t_c {:.6e} vs {tc:.6e}, P {:.6e} vs {pmax:.6e}, v {:.6e}",
            c.end - c.start,
            c.peak_force,
            sol.final_sphere_velocity
        );
        assert!(rel(c.end - c.start, tc) < 1e-3);
        assert!(rel(c.peak_force, pmax) < 1e-3);
        assert!(rel(sol.final_sphere_velocity, -v0) < 1e-3);
    }

    #[test]
    fn invalid_input_does_not_panic() {
        let (beam, sphere) = timoshenko_1913();
        let mut opt = classical_opts(10, 0.0);
        assert!(solve(&beam, &sphere, &opt).samples.is_empty());
        opt.time_step = 1e-6;
        opt.modes = 0; // rigid, immovable beam
        let sol = solve(&beam, &sphere, &opt);
        assert_eq!(sol.contacts.len(), 1);
        let mut away = sphere;
        away.velocity = -0.01;
        assert!(solve(&beam, &away, &opt).contacts.is_empty());
    }

    #[test]
    fn classical_case() {
        let (beam, sphere) = timoshenko_1913();
        let m = sphere.mass();
        let k = hertz_constant(&beam, &sphere);
        println!(
            "Timoshenko 1913: m = {m:.6e} kg, beam mass = {:.6e} kg, k = {k:.6e} N/m^1.5, \
             f1 = {:.2} Hz, L^3/48EI = {:.4e} m/N",
            beam.mass(),
            beam.natural_frequency(1) / (2.0 * PI),
            beam.static_compliance()
        );
        println!(
            "rigid-wall reference: t_c = {:.4e} s, P = {:.4} N",
            rigid_wall_contact_time(m, k, sphere.velocity),
            rigid_wall_peak_force(m, k, sphere.velocity)
        );
        let opt = Options {
            duration: 5.0e-3,
            ..classical_opts(200, 0.5e-7)
        };
        let (sol, next) = solve_with_horizon(&beam, &sphere, &opt, 1.0);
        for (i, c) in sol.contacts.iter().enumerate() {
            println!(
                "contact {}: {:.5} .. {:.5} ms (duration {:.5} ms), peak {:.5} N, impulse {:.5e} N s",
                i + 1,
                c.start * 1e3,
                c.end * 1e3,
                (c.end - c.start) * 1e3,
                c.peak_force,
                c.impulse
            );
        }
        println!(
            "final sphere velocity {:.5} cm/s, total impulse {:.6e} N s, next contact within 1 s: {next:?}",
            sol.final_sphere_velocity * 100.0,
            sol.total_impulse
        );
        for &(modes, h) in &[
            (25, 1e-7),
            (50, 1e-7),
            (100, 1e-7),
            (200, 4e-7),
            (200, 2e-7),
            (200, 1e-7),
            (200, 0.5e-7),
            (400, 1e-7),
            (800, 1e-7),
        ] {
            let s = solve(
                &beam,
                &sphere,
                &Options {
                    duration: 5.0e-3,
                    ..classical_opts(modes, h)
                },
            );
            let cs: Vec<String> = s
                .contacts
                .iter()
                .map(|c| {
                    format!(
                        "[{:.7}-{:.7} ms {:.7} N]",
                        c.start * 1e3,
                        c.end * 1e3,
                        c.peak_force
                    )
                })
                .collect();
            println!(
                "modes {modes:4} (i<={:4}) h {h:.1e}: v_f {:.8} cm/s {}",
                2 * modes - 1,
                s.final_sphere_velocity * 100.0,
                cs.join(" ")
            );
        }
        // Closest re-approach after the last separation: the smallest gap
        // w − z after the gap has passed its first local maximum.
        let fine = solve(
            &beam,
            &sphere,
            &Options {
                duration: 5.0e-3,
                sample_every: 1,
                ..classical_opts(200, 1e-7)
            },
        );
        let t_sep = fine.contacts.last().map_or(0.0, |c| c.end);
        let gaps: Vec<(f64, f64)> = fine
            .samples
            .iter()
            .filter(|s| s.t > t_sep)
            .map(|s| (s.t, s.beam - s.sphere))
            .collect();
        let first_max = gaps.windows(2).position(|w| w[1].1 < w[0].1).unwrap_or(0);
        let closest = gaps[first_max..]
            .iter()
            .copied()
            .fold((0.0, f64::INFINITY), |a, b| if b.1 < a.1 { b } else { a });
        println!(
            "closest re-approach after separation: gap {:.4e} m at {:.4} ms",
            closest.1,
            closest.0 * 1e3
        );
        let tb = solve_with_theory(
            &beam,
            &sphere,
            &opt,
            BeamTheory::Timoshenko {
                shear_coefficient: 5.0 / 6.0,
            },
            1.0,
        );
        for c in &tb.0.contacts {
            println!(
                "Timoshenko-beam variant (kappa 5/6): contact {:.5} .. {:.5} ms, peak {:.5} N; v_f {:.5} cm/s, next {:?}",
                c.start * 1e3,
                c.end * 1e3,
                c.peak_force,
                tb.0.final_sphere_velocity * 100.0,
                tb.1
            );
        }
        let v = sol.final_sphere_velocity;
        assert!((-0.006..=-0.001).contains(&v), "final velocity {v}");
        // NB: this model gives a single contact for the classical data (the
        // beam's return swing misses the receding sphere by ~0.29 µm), not
        // Wellmann's two impacts (the second at ≈ 1.5 ms): his Fig. 4.7a data are
        // not in the text, and with these data a second contact does not occur.
        assert_eq!(sol.contacts.len(), 1);
        assert!(next.is_none());
        assert!(closest.1 > 0.0);
    }
}
