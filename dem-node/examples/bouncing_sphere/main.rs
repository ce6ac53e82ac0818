//! Ullrich fig. 2.5 (REFERENCE A2): relative rebound-velocity error of a bouncing sphere
//! against the time step for 0.1, 1 and 10 m/s, plain velocity Verlet and with impact
//! refinement (`[dem] impact_substeps`).
//!
//! ```text
//! cargo run --release -p dem-node --example bouncing_sphere -- [OUT_DIR] [--phases K] [--substeps N]
//! ```
//! Writes `fig2_5_bouncing_sphere.csv` (speed, dt, dt / Δt_R, error without and with
//! refinement: the worst over K onset phases, default 4) and `fig2_5_bouncing_sphere.svg`
//! into OUT_DIR (default `out/fig2_5`), prints the table, then the errors at the seed's
//! stated time steps, worst over 16 onset phases. N defaults to 16.

mod sweep;

use std::fmt::Write as _;
use std::path::PathBuf;

struct Row {
    speed: f64,
    dt: f64,
    plain: f64,
    refined: f64,
}

fn main() -> Result<(), String> {
    let mut out = PathBuf::from("out/fig2_5");
    let (mut n_phases, mut substeps) = (4usize, 16usize);
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut num = |what: &str| -> Result<usize, String> {
            args.next()
                .and_then(|v| v.parse().ok())
                .ok_or(format!("{what} needs a positive integer"))
        };
        match a.as_str() {
            "--phases" => n_phases = num("--phases")?,
            "--substeps" => substeps = num("--substeps")?,
            _ if a.starts_with("--") => return Err(format!("unknown option {a}")),
            _ => out = PathBuf::from(a),
        }
    }
    let dt_r = sweep::rayleigh_time_step();
    let mut dts: Vec<f64> = (0..=12)
        .map(|k| 10f64.powf(-8.0 + k as f64 / 3.0))
        .collect();
    dts.push(dt_r);
    dts.sort_by(f64::total_cmp);
    let phases = sweep::phases(n_phases);
    println!("Ullrich fig. 2.5: relative rebound error, worst over {n_phases} onset phases; Δt_R = {dt_r:.4e} s; refined: impact_substeps = {substeps}");
    println!(
        "{:>6} {:>11} {:>9} {:>11} {:>11}",
        "v m/s", "dt s", "dt/dt_R", "plain", "refined"
    );
    let mut rows = Vec::new();
    for &v in &sweep::SPEEDS {
        for &dt in &dts {
            let plain = sweep::worst_over_phases(v, dt, 1, &phases)?.0;
            let refined = sweep::worst_over_phases(v, dt, substeps, &phases)?.0;
            println!(
                "{v:>6} {dt:>11.3e} {:>9.4} {plain:>11.3e} {refined:>11.3e}",
                dt / dt_r
            );
            rows.push(Row {
                speed: v,
                dt,
                plain,
                refined,
            });
        }
    }
    std::fs::create_dir_all(&out).map_err(|e| format!("{}: {e}", out.display()))?;
    let mut csv = String::from("speed,dt,dt_over_rayleigh,error_plain,error_refined\n");
    for r in &rows {
        let _ = writeln!(
            csv,
            "{},{:e},{:e},{:e},{:e}",
            r.speed,
            r.dt,
            r.dt / dt_r,
            r.plain,
            r.refined
        );
    }
    let csv_path = out.join("fig2_5_bouncing_sphere.csv");
    std::fs::write(&csv_path, csv).map_err(|e| format!("{}: {e}", csv_path.display()))?;
    let svg_path = out.join("fig2_5_bouncing_sphere.svg");
    std::fs::write(&svg_path, svg(&rows, dt_r, substeps))
        .map_err(|e| format!("{}: {e}", svg_path.display()))?;
    println!("wrote {} and {}", csv_path.display(), svg_path.display());

    let stated = sweep::phases(16);
    println!("\nAt the stated time steps, worst over 16 onset phases (REFERENCE A2 asks ≤ 1e-5):");
    for &v in &sweep::SPEEDS {
        let dt = sweep::stated_time_step(v);
        let (p, _) = sweep::worst_over_phases(v, dt, 1, &stated)?;
        let (r, _) = sweep::worst_over_phases(v, dt, substeps, &stated)?;
        println!("  v = {v:>4} m/s, dt = {dt:.3e} s: plain {p:.3e}, impact_substeps = {substeps}: {r:.3e}");
    }
    Ok(())
}

/// A log–log plot of the rows (SVG, no font or plotting dependency needed).
fn svg(rows: &[Row], dt_r: f64, substeps: usize) -> String {
    let (w, h, l, r, t, b) = (720.0, 480.0, 80.0, 170.0, 30.0, 60.0);
    let (x0, x1, y0, y1) = (-8.0, -4.0, -16.0, 1.0);
    let px = |dt: f64| l + (dt.log10() - x0) / (x1 - x0) * (w - l - r);
    let py = |e: f64| t + (y1 - e.max(1e-16).log10().clamp(y0, y1)) / (y1 - y0) * (h - t - b);
    let mut s = format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" font-family="sans-serif" font-size="12">
<rect width="100%" height="100%" fill="white"/>
<rect x="{l}" y="{t}" width="{}" height="{}" fill="none" stroke="black"/>
"#,
        w - l - r,
        h - t - b
    );
    for k in -8..=-4 {
        let x = px(10f64.powi(k));
        let _ = writeln!(
            s,
            r#"<text x="{x}" y="{}" text-anchor="middle">1e{k}</text>"#,
            h - b + 16.0
        );
    }
    for k in (-16..=0).step_by(2) {
        let y = py(10f64.powi(k));
        let _ = writeln!(
            s,
            r#"<text x="{}" y="{}" text-anchor="end">1e{k}</text>"#,
            l - 6.0,
            y + 4.0
        );
        let _ = writeln!(
            s,
            r##"<line x1="{l}" x2="{}" y1="{y}" y2="{y}" stroke="#ddd"/>"##,
            w - r
        );
    }
    let xr = px(dt_r);
    let _ = writeln!(
        s,
        r#"<line x1="{xr}" x2="{xr}" y1="{t}" y2="{}" stroke="gray" stroke-dasharray="4 3"/><text x="{}" y="{}">Δt_R</text>"#,
        h - b,
        xr + 4.0,
        t + 14.0
    );
    let _ = writeln!(
        s,
        r#"<text x="{}" y="{}" text-anchor="middle">time step Δt / s</text>"#,
        l + 0.5 * (w - l - r),
        h - 16.0
    );
    let _ = writeln!(
        s,
        r#"<text transform="translate(18 {}) rotate(-90)" text-anchor="middle">relative rebound-velocity error</text>"#,
        t + 0.5 * (h - t - b)
    );
    let colours = ["#1f77b4", "#d62728", "#2ca02c"];
    for (c, &v) in sweep::SPEEDS.iter().enumerate() {
        for (dash, refined) in [("", false), (r#" stroke-dasharray="6 4""#, true)] {
            let pts: Vec<String> = rows
                .iter()
                .filter(|r| r.speed == v)
                .map(|r| {
                    format!(
                        "{:.1},{:.1}",
                        px(r.dt),
                        py(if refined { r.refined } else { r.plain })
                    )
                })
                .collect();
            let _ = writeln!(
                s,
                r#"<polyline points="{}" fill="none" stroke="{}" stroke-width="1.5"{dash}/>"#,
                pts.join(" "),
                colours[c]
            );
            let y = t + 20.0 + (2 * c + refined as usize) as f64 * 18.0;
            let label = if refined {
                format!("{v} m/s, N = {substeps}")
            } else {
                format!("{v} m/s")
            };
            let _ = writeln!(
                s,
                r#"<line x1="{}" x2="{}" y1="{y}" y2="{y}" stroke="{}" stroke-width="1.5"{dash}/><text x="{}" y="{}">{label}</text>"#,
                w - r + 10.0,
                w - r + 40.0,
                colours[c],
                w - r + 46.0,
                y + 4.0
            );
        }
    }
    s.push_str("</svg>\n");
    s
}
