//! `cosim fit`: the non-associated Mohr–Coulomb parameters of a granular material from the
//! triaxial curves of its periodic RVE (Wellmann §5.4, SEED-SPEC §3.6), written as the
//! `[fem.materials]` table the FEM reads, with a plot of the fitted model over the curves.
//!
//! Per curve (the shear stage of a `periodic.csv`: the last stage that strains an axis;
//! compression positive, strains from the stage's start):
//! - E and ν from the initial slopes: Δq = E Δε_a and Δε_V = (1 − 2ν) Δε_a over the rows up
//!   to a quarter of the peak deviator q = σ_a − σ_l (drained triaxial, σ_l constant);
//! - φ from the Mohr circle at the maximum axial stress: t = s sin φ + c cos φ with
//!   t = (σ_a − σ_l)/2, s = (σ_a + σ_l)/2 — one curve: c given (the thesis's 15 Pa keeps the
//!   unloaded state off the apex); several curves at different pressures: c and φ from the
//!   straight line through their circles' tops (the thesis's tangent to the circles);
//! - ψ from the constant dilation rate: −Δε_V/Δε_a = 2 sin ψ/(1 − sin ψ) over an axial-strain
//!   window (default 10–15 %, W Table 5.2's interval; the last third of a shorter curve).
//!
//! E, ν and ψ are averaged over the curves (mean and standard deviation reported).

use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context};

/// One triaxial curve, compression positive.
#[derive(Debug, Clone, Default)]
pub struct Curve {
    pub name: String,
    /// Axial strain from the stage start.
    pub axial: Vec<f64>,
    /// Volumetric strain from the stage start (positive: compaction).
    pub volumetric: Vec<f64>,
    pub sigma_axial: Vec<f64>,
    pub sigma_lateral: Vec<f64>,
    /// Solid fraction at the start of the shear (for the continuum density).
    pub solid_fraction: Option<f64>,
    /// The grains' density, from the run's scene.
    pub grain_density: Option<f64>,
}

/// What the fit found for one curve.
#[derive(Debug, Clone, PartialEq)]
pub struct CurveFit {
    /// E and ν of the initial slopes (NaN when fewer than 3 rows precede a quarter of the
    /// peak deviator: the rows are too far apart to see them).
    pub youngs_modulus: f64,
    pub poisson_ratio: f64,
    /// Rows (the stage's starting state included) up to a quarter of the peak deviator.
    pub initial_rows: usize,
    /// E50, the secant from the stage's start to half the peak deviator (interpolated
    /// between rows; NaN when the first row after the start is already past it).
    pub secant_modulus: f64,
    /// (s, t) at the maximum axial stress.
    pub peak: (f64, f64),
    pub peak_ratio: f64,
    /// The lateral stress at the peak (the curve's confining pressure).
    pub lateral: f64,
    pub dilation_rate: f64,
    pub dilation_angle: f64,
    /// The axial-strain window of the dilation rate.
    pub window: (f64, f64),
}

/// The fitted Mohr–Coulomb parameters (angles in degrees).
#[derive(Debug, Clone, PartialEq)]
pub struct Fit {
    pub youngs_modulus: f64,
    pub poisson_ratio: f64,
    pub friction_angle: f64,
    pub dilation_angle: f64,
    pub cohesion: f64,
    pub density: Option<f64>,
    pub curves: Vec<CurveFit>,
    /// Standard deviations over the curves of E, ν, ψ (0 for one curve).
    pub spread: [f64; 3],
    /// How φ and c were found (a line through the circles, or the given c).
    pub envelope: String,
    /// Which slope E is (when not given).
    pub modulus: Modulus,
}

/// Reads the shear stage of a run folder's `dem/periodic.csv` (or of that file given
/// directly); `stage` picks another stage. Errors name the file and line.
pub fn read_curve(path: &Path, stage: Option<usize>) -> anyhow::Result<Curve> {
    let (csv, run_dir) = if path.is_dir() {
        (
            path.join("dem").join("periodic.csv"),
            Some(path.to_path_buf()),
        )
    } else {
        let dir = path
            .parent()
            .and_then(|d| d.parent())
            .filter(|d| d.join("scene.toml").exists())
            .map(Path::to_path_buf);
        (path.to_path_buf(), dir)
    };
    let text = std::fs::read_to_string(&csv)
        .with_context(|| format!("cannot read {} (a periodic cell's curves)", csv.display()))?;
    let mut lines = text.lines();
    let header: Vec<&str> = lines
        .next()
        .ok_or_else(|| anyhow!("{}: empty", csv.display()))?
        .split(',')
        .collect();
    let col = |name: &str| {
        header.iter().position(|h| *h == name).ok_or_else(|| {
            anyhow!(
                "{}: no column `{name}` (is it a periodic cell's periodic.csv?)",
                csv.display()
            )
        })
    };
    let stage_col = col("stage")?;
    let axes = ["x", "y", "z"];
    let strain: Vec<usize> = axes
        .iter()
        .map(|a| col(&format!("stage_strain_{a}")))
        .collect::<anyhow::Result<_>>()?;
    let stress: Vec<usize> = ["xx", "yy", "zz"]
        .iter()
        .map(|a| col(&format!("stress_{a}")))
        .collect::<anyhow::Result<_>>()?;
    let vol = col("stage_volumetric_strain")?;
    let phi = col("solid_fraction")?;
    let mut rows: Vec<Vec<f64>> = Vec::new();
    for (k, line) in lines.enumerate() {
        let row: Vec<f64> = line
            .split(',')
            .map(|v| v.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|e| anyhow!("{}, line {}: {e}", csv.display(), k + 2))?;
        if row.len() != header.len() {
            bail!(
                "{}, line {}: {} values for {} columns",
                csv.display(),
                k + 2,
                row.len(),
                header.len()
            );
        }
        rows.push(row);
    }
    // the shear: the last stage whose rows strain an axis
    let spans = |s: usize| {
        let of: Vec<&Vec<f64>> = rows.iter().filter(|r| r[stage_col] == s as f64).collect();
        let last = of
            .last()
            .map(|r| strain.iter().map(|&c| r[c].abs()).fold(0.0, f64::max));
        (of.len(), last.unwrap_or(0.0))
    };
    let chosen = match stage {
        Some(s) => s,
        None => {
            let max = rows
                .iter()
                .map(|r| r[stage_col] as usize)
                .max()
                .unwrap_or(0);
            (0..=max)
                .rev()
                .find(|&s| {
                    let (n, e) = spans(s);
                    n >= 3 && e > 1e-3
                })
                .ok_or_else(|| {
                    anyhow!(
                        "{}: no stage strains an axis by more than 0.1 % over 3 rows or more \
                         (no triaxial shear to fit)",
                        csv.display()
                    )
                })?
        }
    };
    let shear: Vec<&Vec<f64>> = rows
        .iter()
        .filter(|r| r[stage_col] == chosen as f64)
        .collect();
    // the state the stage starts from: the last row before it (its strains are zero then)
    let before = rows.iter().rev().find(|r| r[stage_col] < chosen as f64);
    if shear.len() < 3 {
        bail!(
            "{}: stage {chosen} has {} rows; a fit needs 3 or more",
            csv.display(),
            shear.len()
        );
    }
    let last = shear[shear.len() - 1];
    let axis = (0..3)
        .max_by(|&a, &b| last[strain[a]].abs().total_cmp(&last[strain[b]].abs()))
        .unwrap_or(2);
    let (l1, l2) = ((axis + 1) % 3, (axis + 2) % 3);
    let mut c = Curve {
        name: run_dir
            .as_ref()
            .and_then(|d| d.file_name())
            .map_or_else(|| csv.display().to_string(), |n| n.to_string_lossy().into()),
        solid_fraction: Some(shear[0][phi]),
        grain_density: run_dir.as_deref().and_then(grain_density),
        ..Default::default()
    };
    if let Some(r) = before {
        c.axial.push(0.0);
        c.volumetric.push(0.0);
        c.sigma_axial.push(-r[stress[axis]]);
        c.sigma_lateral.push(-0.5 * (r[stress[l1]] + r[stress[l2]]));
    }
    for r in shear {
        c.axial.push(-r[strain[axis]]);
        c.volumetric.push(-r[vol]);
        c.sigma_axial.push(-r[stress[axis]]);
        c.sigma_lateral.push(-0.5 * (r[stress[l1]] + r[stress[l2]]));
    }
    Ok(c)
}

/// The density of the first particle source's material in a run folder's scene.
fn grain_density(run_dir: &Path) -> Option<f64> {
    let text = std::fs::read_to_string(run_dir.join("scene.toml")).ok()?;
    let v: toml::Table = toml::from_str(&text).ok()?;
    let dem = v.get("dem")?;
    let material = dem
        .get("particles")?
        .as_array()?
        .first()?
        .get("material")?
        .as_str()?;
    let d = dem.get("materials")?.get(material)?.get("density")?;
    d.as_float().or_else(|| d.as_integer().map(|i| i as f64))
}

/// Least-squares slope of y over x through their first point.
fn slope_from_first(x: &[f64], y: &[f64]) -> f64 {
    let (x0, y0) = (x[0], y[0]);
    let (mut num, mut den) = (0.0, 0.0);
    for (a, b) in x.iter().zip(y).skip(1) {
        num += (a - x0) * (b - y0);
        den += (a - x0) * (a - x0);
    }
    num / den
}

/// Least-squares slope of y over x.
fn slope(x: &[f64], y: &[f64]) -> f64 {
    let n = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let (mut num, mut den) = (0.0, 0.0);
    for (a, b) in x.iter().zip(y) {
        num += (a - mx) * (b - my);
        den += (a - mx) * (a - mx);
    }
    num / den
}

/// Fits one curve's elastic constants, peak and dilation rate over `window` (axial strain).
pub fn fit_curve(c: &Curve, window: (f64, f64)) -> anyhow::Result<CurveFit> {
    let n = c.axial.len();
    let q: Vec<f64> = (0..n)
        .map(|k| c.sigma_axial[k] - c.sigma_lateral[k])
        .collect();
    let peak = (0..n)
        .max_by(|&a, &b| c.sigma_axial[a].total_cmp(&c.sigma_axial[b]))
        .ok_or_else(|| anyhow!("{}: no rows", c.name))?;
    // the initial part: up to a quarter of the way to the peak deviator
    let limit = q[0] + 0.25 * (q[peak] - q[0]);
    let initial = (0..=peak).take_while(|&k| q[k] <= limit).count().max(1);
    // E50: where the deviator first reaches half its rise to the peak
    let half = q[0] + 0.5 * (q[peak] - q[0]);
    let secant = match (1..=peak).find(|&k| q[k] >= half) {
        Some(k) if k >= 2 && q[k] > q[k - 1] => {
            let t = (half - q[k - 1]) / (q[k] - q[k - 1]);
            let e50 = c.axial[k - 1] + t * (c.axial[k] - c.axial[k - 1]);
            (half - q[0]) / (e50 - c.axial[0])
        }
        _ => f64::NAN,
    };
    let (e, nu) = if initial >= 3 {
        let e = slope_from_first(&c.axial[..initial], &q[..initial]);
        let s = slope_from_first(&c.axial[..initial], &c.volumetric[..initial]);
        (e, 0.5 * (1.0 - s))
    } else {
        (f64::NAN, f64::NAN)
    };
    // dilation rate over the window, or the last third of a shorter curve
    let end = c.axial[n - 1];
    let window = if end >= window.1 {
        window
    } else {
        (end * 2.0 / 3.0, end)
    };
    let ks: Vec<usize> = (0..n)
        .filter(|&k| c.axial[k] >= window.0 && c.axial[k] <= window.1)
        .collect();
    if ks.len() < 2 {
        bail!(
            "{}: fewer than 2 rows between axial strains {:.3} and {:.3} for the dilation rate",
            c.name,
            window.0,
            window.1
        );
    }
    let xs: Vec<f64> = ks.iter().map(|&k| c.axial[k]).collect();
    let ys: Vec<f64> = ks.iter().map(|&k| c.volumetric[k]).collect();
    // −Δε_V/Δε_a with ε_V positive in compaction: the dilation rate r = −slope
    let r = -slope(&xs, &ys);
    let sin_psi = (r / (2.0 + r)).max(0.0);
    let (sa, sl) = (c.sigma_axial[peak], c.sigma_lateral[peak]);
    Ok(CurveFit {
        youngs_modulus: e,
        poisson_ratio: nu,
        initial_rows: initial,
        secant_modulus: secant,
        peak: (0.5 * (sa + sl), 0.5 * (sa - sl)),
        peak_ratio: sa / sl,
        lateral: sl,
        dilation_rate: r,
        dilation_angle: sin_psi.asin().to_degrees(),
        window,
    })
}

/// Given values that replace fitted ones, and which modulus the table takes.
#[derive(Debug, Clone, Copy, Default)]
pub struct Given {
    pub youngs_modulus: Option<f64>,
    pub poisson_ratio: Option<f64>,
    pub density: Option<f64>,
    pub modulus: Modulus,
}

/// Which slope of the σ_a–ε_a curve is the table's E.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum Modulus {
    /// The initial tangent: the least-squares slope up to a quarter of the peak deviator.
    #[default]
    Tangent,
    /// E50: the secant to half the peak deviator, the geotechnical stiffness of a
    /// hardening curve (the thesis's E = 60 MPa is a fit "in the medium pressure regime").
    Secant50,
}

/// Fits the Mohr–Coulomb parameters to `curves`. `cohesion` is used with one curve (and as
/// the floor of a fitted one); `given` values replace the fitted ones (E and ν must be given
/// when a curve's rows are too far apart to show its initial slopes).
pub fn fit(
    curves: &[Curve],
    window: (f64, f64),
    cohesion: f64,
    given: Given,
) -> anyhow::Result<Fit> {
    if curves.is_empty() {
        bail!("no curves to fit");
    }
    let mut fits: Vec<CurveFit> = curves
        .iter()
        .map(|c| fit_curve(c, window))
        .collect::<anyhow::Result<_>>()?;
    let tangent_needed = given.poisson_ratio.is_none()
        || (given.youngs_modulus.is_none() && given.modulus == Modulus::Tangent);
    if let Some(coarse) = fits.iter().position(|f| f.initial_rows < 3) {
        if tangent_needed {
            bail!(
                "{}: only {} row(s) (the stage's start included) before the deviator reaches a \
                 quarter of its peak: the initial slopes (E, ν) need 3 or more; write rows more \
                 often (a smaller coupling.window), shear more slowly, or give \
                 --youngs-modulus and --poisson-ratio",
                curves[coarse].name,
                fits[coarse].initial_rows
            );
        }
    }
    if given.youngs_modulus.is_none() && given.modulus == Modulus::Secant50 {
        if let Some(k) = fits.iter().position(|f| !f.secant_modulus.is_finite()) {
            bail!(
                "{}: the deviator passes half its peak before the second row: E50 needs rows \
                 closer together (a smaller coupling.window, or a slower shear), or give \
                 --youngs-modulus",
                curves[k].name
            );
        }
        for f in &mut fits {
            f.youngs_modulus = f.secant_modulus;
        }
    }
    for f in &mut fits {
        if let Some(e) = given.youngs_modulus {
            f.youngs_modulus = e;
        }
        if let Some(nu) = given.poisson_ratio {
            f.poisson_ratio = nu;
        }
    }
    let density = given.density;
    let (friction_angle, cohesion, envelope) = mohr_envelope(&fits, cohesion);
    let mean_sd = |f: &dyn Fn(&CurveFit) -> f64| {
        let n = fits.len() as f64;
        let m = fits.iter().map(f).sum::<f64>() / n;
        let v = fits.iter().map(|c| (f(c) - m).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
        (m, v.sqrt())
    };
    let (e, e_sd) = mean_sd(&|c| c.youngs_modulus);
    let (nu, nu_sd) = mean_sd(&|c| c.poisson_ratio);
    let (psi, psi_sd) = mean_sd(&|c| c.dilation_angle);
    let density = density.or_else(|| {
        let ds: Vec<f64> = curves
            .iter()
            .filter_map(|c| Some(c.solid_fraction? * c.grain_density?))
            .collect();
        (ds.len() == curves.len()).then(|| ds.iter().sum::<f64>() / ds.len() as f64)
    });
    Ok(Fit {
        youngs_modulus: e,
        poisson_ratio: nu,
        friction_angle,
        dilation_angle: psi.min(friction_angle),
        cohesion,
        density,
        curves: fits,
        spread: [e_sd, nu_sd, psi_sd],
        envelope,
        modulus: given.modulus,
    })
}

/// φ (degrees) and c of the Mohr–Coulomb envelope t = s sin φ + c cos φ: through the mean
/// circle top of curves at one confining pressure (an ensemble) with the given c, or the
/// least-squares line through the circles of curves at confining pressures more than 10 %
/// apart (c not below `floor`; when the line's c is, φ through the mean circle with `floor`).
/// The third value says which, for the fitted table's comments.
fn mohr_envelope(fits: &[CurveFit], floor: f64) -> (f64, f64, String) {
    let pts: Vec<(f64, f64)> = fits.iter().map(|f| f.peak).collect();
    let (lo, hi) = fits.iter().fold((f64::INFINITY, 0.0f64), |(a, b), f| {
        (a.min(f.lateral), b.max(f.lateral))
    });
    let distinct = hi > 1.1 * lo;
    if distinct {
        let xs: Vec<f64> = pts.iter().map(|p| p.0).collect();
        let ys: Vec<f64> = pts.iter().map(|p| p.1).collect();
        let sin_phi = slope(&xs, &ys).clamp(0.0, 0.999);
        let n = xs.len() as f64;
        let intercept = ys.iter().sum::<f64>() / n - sin_phi * xs.iter().sum::<f64>() / n;
        let cos_phi = (1.0 - sin_phi * sin_phi).sqrt();
        let c = intercept / cos_phi;
        let phi = sin_phi.asin().to_degrees();
        if c >= floor {
            return (
                phi,
                c,
                format!(
                    "envelope: the least-squares line through the {} circles' tops (φ {phi:.2}°, c {c:.4e} Pa)",
                    pts.len()
                ),
            );
        }
        let (phi_f, _, _) = mohr_envelope_through_mean(&pts, floor);
        return (
            phi_f,
            floor,
            format!(
                "envelope: the line through the {} circles' tops has φ {phi:.2}° and c {c:.4e} Pa < {floor:.4e} Pa: φ through their mean circle top with c = {floor:.4e} Pa",
                pts.len()
            ),
        );
    }
    mohr_envelope_through_mean(&pts, floor)
}

/// φ of the envelope t = s sin φ + c cos φ through the mean circle top of `pts` with c given.
fn mohr_envelope_through_mean(pts: &[(f64, f64)], floor: f64) -> (f64, f64, String) {
    // t = s sin φ + c cos φ for the mean circle top, solved for φ by bisection
    let n = pts.len() as f64;
    let (s, t) = (
        pts.iter().map(|p| p.0).sum::<f64>() / n,
        pts.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let g = |phi: f64| s * phi.sin() + floor * phi.cos() - t;
    let (mut lo, mut hi) = (0.0f64, std::f64::consts::FRAC_PI_2);
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if g(mid) < 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    (
        0.5 * (lo + hi).to_degrees(),
        floor,
        format!(
            "envelope: through the mean circle top of {} curve(s) at one pressure with c = {floor:.4e} Pa",
            pts.len()
        ),
    )
}

/// The drained triaxial response of the fitted single element at lateral stress `sl` and the
/// curve's initial stresses: axial stress and volumetric strain (compaction positive) at
/// axial strain `e`, elastic until yield then perfectly plastic with the dilation of ψ.
pub fn model_response(f: &Fit, sa0: f64, sl: f64, e: f64) -> (f64, f64) {
    let (sp, spsi) = (
        f.friction_angle.to_radians().sin(),
        f.dilation_angle.to_radians().sin(),
    );
    let n_phi = (1.0 + sp) / (1.0 - sp);
    let yield_sa = sl * n_phi + 2.0 * f.cohesion * n_phi.sqrt();
    let e_yield = ((yield_sa - sa0) / f.youngs_modulus).max(0.0);
    let elastic = 1.0 - 2.0 * f.poisson_ratio;
    if e <= e_yield {
        (sa0 + f.youngs_modulus * e, elastic * e)
    } else {
        let rate = 2.0 * spsi / (1.0 - spsi);
        (yield_sa, elastic * e_yield - rate * (e - e_yield))
    }
}

/// The `[fem.materials.<name>]` table of the fit, with a comment naming its sources.
pub fn material_toml(f: &Fit, name: &str, sources: &[PathBuf]) -> String {
    let mut out = format!(
        "# cosim fit of {}: non-associated Mohr–Coulomb (Wellmann §5.4)\n",
        sources
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    );
    for (k, c) in f.curves.iter().enumerate() {
        if c.initial_rows < 3 {
            out.push_str(&format!(
                "# curve {k}: E and ν given (its rows are too far apart to show the initial \
                 slopes: {} row(s) up to a quarter of the peak deviator)\n",
                c.initial_rows
            ));
        }
        out.push_str(&format!(
            "# curve {k}: E {:.4e} Pa (E50 {}), ν {:.4}, peak σa/σl {:.4} at s = {:.4e} Pa, \
             dilation rate {:.4} over axial strain {:.3}–{:.3} (ψ {:.2}°)\n",
            c.youngs_modulus,
            if c.secant_modulus.is_finite() {
                format!("{:.4e} Pa", c.secant_modulus)
            } else {
                "not resolved".to_string()
            },
            c.poisson_ratio,
            c.peak_ratio,
            c.peak.0,
            c.dilation_rate,
            c.window.0,
            c.window.1,
            c.dilation_angle
        ));
    }
    if f.curves.len() > 1 {
        // an ensemble: mean ± standard deviation over its curves
        let ms = |v: &dyn Fn(&CurveFit) -> f64| {
            let n = f.curves.len() as f64;
            let m = f.curves.iter().map(v).sum::<f64>() / n;
            let sd = (f.curves.iter().map(|c| (v(c) - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
            format!("{m:.4} ± {sd:.4}")
        };
        out.push_str(&format!(
            "# over {} curves (mean ± s.d.): peak σa/σl {}, dilation rate {}, ψ {}°, E {} MPa, ν {}\n",
            f.curves.len(),
            ms(&|c| c.peak_ratio),
            ms(&|c| c.dilation_rate),
            ms(&|c| c.dilation_angle),
            ms(&|c| c.youngs_modulus * 1e-6),
            ms(&|c| c.poisson_ratio),
        ));
    }
    if f.modulus == Modulus::Secant50 {
        out.push_str(
            "# E is E50, the secant to half the peak deviator (--modulus secant50), unless given\n",
        );
    }
    out.push_str(&format!("# {}\n", f.envelope));
    out.push_str(&format!(
        "[fem.materials.{name}]\nmodel = \"mohr_coulomb\"\nyoungs_modulus = {:.6e}\n\
         poisson_ratio = {:.6}\nfriction_angle = {:.4}\ndilation_angle = {:.4}\n\
         cohesion = {:.6e}\n",
        f.youngs_modulus, f.poisson_ratio, f.friction_angle, f.dilation_angle, f.cohesion
    ));
    match f.density {
        Some(d) => out.push_str(&format!("density = {d:.6e}\n")),
        None => out
            .push_str("# density: unknown (no scene beside the curves); give it with --density\n"),
    }
    out
}

/// `<out>_stress_ratio.png` and `<out>_volumetric_strain.png` beside the TOML: each curve
/// and the fitted element's response at its lateral stress.
pub fn plots(f: &Fit, curves: &[Curve], out: &Path) -> anyhow::Result<Vec<PathBuf>> {
    let stem = out.with_extension("");
    let mut ratio = Vec::new();
    let mut volume = Vec::new();
    // one model line per confining pressure (curves within 10 % share it)
    let mut drawn: Vec<f64> = Vec::new();
    for c in curves {
        let n = c.axial.len();
        let sl = c.sigma_lateral.iter().sum::<f64>() / n as f64;
        ratio.push((
            c.name.clone(),
            (0..n)
                .map(|k| (c.axial[k], c.sigma_axial[k] / c.sigma_lateral[k]))
                .collect(),
        ));
        volume.push((
            c.name.clone(),
            (0..n).map(|k| (c.axial[k], -c.volumetric[k])).collect(),
        ));
        if drawn.iter().any(|d| (d - sl).abs() <= 0.1 * d.abs()) {
            continue;
        }
        drawn.push(sl);
        let end = c.axial[n - 1];
        let model: Vec<(f64, f64, f64)> = (0..=400)
            .map(|k| {
                let e = end * k as f64 / 400.0;
                let (sa, v) = model_response(f, c.sigma_axial[0], sl, e);
                (e, sa / sl, -v)
            })
            .collect();
        ratio.push((
            format!("Mohr–Coulomb at σl = {:.3e} Pa", sl),
            model.iter().map(|m| (m.0, m.1)).collect(),
        ));
        volume.push((
            format!("Mohr–Coulomb at σl = {:.3e} Pa", sl),
            model.iter().map(|m| (m.0, m.2)).collect(),
        ));
    }
    let a = PathBuf::from(format!("{}_stress_ratio.png", stem.display()));
    let b = PathBuf::from(format!("{}_volumetric_strain.png", stem.display()));
    crate::plot::series_png(
        &a,
        "Triaxial curves and the fitted Mohr–Coulomb element",
        "axial strain (compression)",
        "σ_axial / σ_lateral",
        &ratio,
    )?;
    crate::plot::series_png(
        &b,
        "Triaxial curves and the fitted Mohr–Coulomb element",
        "axial strain (compression)",
        "volumetric strain (dilation positive)",
        &volume,
    )?;
    Ok(vec![a, b])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A curve of the fitted element itself (elastic, then perfectly plastic with dilation).
    fn synthetic(f: &Fit, sl: f64, n: usize, end: f64) -> Curve {
        let mut c = Curve {
            name: format!("synthetic {sl}"),
            ..Default::default()
        };
        for k in 0..n {
            let e = end * k as f64 / (n - 1) as f64;
            let (sa, v) = model_response(f, sl, sl, e);
            c.axial.push(e);
            c.volumetric.push(v);
            c.sigma_axial.push(sa);
            c.sigma_lateral.push(sl);
        }
        c
    }

    /// One curve fitted over W's 10–15 % window with the thesis's c = 15 Pa.
    fn fit_one(c: &Curve, given: Given) -> anyhow::Result<Fit> {
        fit(std::slice::from_ref(c), (0.10, 0.15), 15.0, given)
    }

    fn thesis() -> Fit {
        Fit {
            youngs_modulus: 60e6,
            poisson_ratio: 0.145,
            friction_angle: 23.15,
            dilation_angle: 5.17,
            cohesion: 15.0,
            density: None,
            curves: vec![],
            spread: [0.0; 3],
            envelope: String::new(),
            modulus: Modulus::Tangent,
        }
    }

    /// The fit of the curves the thesis's fitted element draws gives its parameters back:
    /// from one curve (c given), and from three pressures (c fitted too).
    #[test]
    fn fitting_the_thesis_elements_curves_returns_its_parameters() {
        let truth = thesis();
        let one = synthetic(&truth, 25e3, 20001, 0.2);
        let f = fit_one(&one, Given::default()).unwrap();
        println!("{f:?}");
        assert!((f.youngs_modulus / 60e6 - 1.0).abs() < 1e-9);
        assert!((f.poisson_ratio - 0.145).abs() < 1e-9);
        assert!((f.friction_angle - 23.15).abs() < 1e-6);
        assert!((f.dilation_angle - 5.17).abs() < 1e-9);
        // (1 + sin φ)/(1 − sin φ) = 2.296 (SEED-SPEC §3.6), plus the cohesion's 2c√N/σl
        assert!(
            (f.curves[0].peak_ratio - 2.2963).abs() < 2e-3,
            "{}",
            f.curves[0].peak_ratio
        );
        let curves: Vec<Curve> = [25e3, 50e3, 100e3]
            .iter()
            .map(|&p| synthetic(&truth, p, 20001, 0.2))
            .collect();
        let f = fit(&curves, (0.10, 0.15), 0.0, Given::default()).unwrap();
        assert!(
            (f.friction_angle - 23.15).abs() < 1e-6,
            "{}",
            f.friction_angle
        );
        assert!((f.cohesion - 15.0).abs() < 1e-3, "{}", f.cohesion);
        assert!(f.spread[0] / f.youngs_modulus < 1e-9);
        let table = material_toml(&f, "sand", &[]);
        assert!(
            table.contains("# over 3 curves (mean ± s.d.): peak σa/σl"),
            "{table}"
        );
        assert!(table.contains("E 60.0000 ± 0.0000 MPa"), "{table}");
    }

    /// E50 is the secant to half the peak deviator: E itself on the fitted element's
    /// elastic–plastic curve, and Ei (1 − q_p/(2 q_u)) on a hyperbolic (Duncan–Chang) curve
    /// q = Ei ε/(1 + Ei ε/q_u) whose peak q_p is its last row; `Secant50` puts it in the
    /// table, and refuses a curve that passes half its peak before its second row.
    #[test]
    fn the_secant_modulus_is_the_slope_to_half_the_peak_deviator() {
        let one = synthetic(&thesis(), 25e3, 20001, 0.2);
        let f = fit_one(&one, Given::default()).unwrap();
        assert!((f.curves[0].secant_modulus / 60e6 - 1.0).abs() < 1e-9);
        let (ei, qu, end, sl) = (160e6, 40e3, 0.02, 25e3);
        let mut c = Curve {
            name: "hyperbolic".into(),
            ..Default::default()
        };
        for k in 0..4001 {
            let e = end * k as f64 / 4000.0;
            c.axial.push(e);
            c.volumetric.push(-0.2 * e);
            c.sigma_axial.push(sl + ei * e / (1.0 + ei * e / qu));
            c.sigma_lateral.push(sl);
        }
        let qp = ei * end / (1.0 + ei * end / qu);
        let exact = ei * (1.0 - qp / (2.0 * qu));
        let given = Given {
            modulus: Modulus::Secant50,
            ..Default::default()
        };
        let f = fit_one(&c, given).unwrap();
        println!("E50 {:.6e} (exact {exact:.6e})", f.youngs_modulus);
        assert!((f.youngs_modulus / exact - 1.0).abs() < 1e-4);
        assert!(material_toml(&f, "sand", &[]).contains("# E is E50"));
        // the tangent of the first quarter is the stiffer one
        let t = fit_one(&c, Given::default()).unwrap();
        assert!(t.youngs_modulus > 1.5 * exact, "{}", t.youngs_modulus);
        // rows so far apart that the first is past half the peak
        let coarse = Curve {
            name: "coarse".into(),
            axial: vec![0.0, 0.01, 0.015, 0.02],
            volumetric: vec![0.0, -0.002, -0.003, -0.004],
            sigma_axial: vec![sl, sl + 30e3, sl + 31e3, sl + 32e3],
            sigma_lateral: vec![sl; 4],
            ..Default::default()
        };
        let e = fit_one(
            &coarse,
            Given {
                poisson_ratio: Some(0.2),
                ..given
            },
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("E50 needs rows closer"), "{e}");
    }

    /// A curve too coarse to show its initial slope is refused with what to change, and
    /// fitted with E and ν given.
    #[test]
    fn a_coarse_curve_needs_its_elastic_constants_given() {
        let c = synthetic(&thesis(), 25e3, 21, 0.2);
        let e = fit_one(&c, Given::default()).unwrap_err().to_string();
        assert!(
            e.contains("coupling.window") && e.contains("--youngs-modulus"),
            "{e}"
        );
        let given = Given {
            youngs_modulus: Some(60e6),
            poisson_ratio: Some(0.145),
            density: Some(1600.0),
            ..Default::default()
        };
        let f = fit_one(&c, given).unwrap();
        assert_eq!((f.youngs_modulus, f.poisson_ratio), (60e6, 0.145));
        assert!((f.friction_angle - 23.15).abs() < 1e-6);
        assert!((f.dilation_angle - 5.17).abs() < 1e-9);
        assert!(material_toml(&f, "sand", &[]).contains("E and ν given"));
    }
}
