//! PNG plots of a study (plotters, bitmap backend). Text needs a TrueType font: the first of
//! `COSIM_FONT`, DejaVu Sans, Liberation Sans or any `.ttf` under /usr/share/fonts is used;
//! without one no PNG is written (the SVG plots are, and need no font).

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use anyhow::{anyhow, Context};
use plotters::prelude::*;

use crate::study::{schedule_of, value_text, Outcome, Variation};

const PALETTE: [RGBColor; 6] = [
    RGBColor(0x1f, 0x77, 0xb4),
    RGBColor(0xd6, 0x27, 0x28),
    RGBColor(0x2c, 0xa0, 0x2c),
    RGBColor(0xff, 0x7f, 0x0e),
    RGBColor(0x94, 0x67, 0xbd),
    RGBColor(0x8c, 0x56, 0x4b),
];

fn find_font() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("COSIM_FONT") {
        return Some(PathBuf::from(p));
    }
    for p in [
        "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
        "/usr/share/fonts/truetype/liberation/LiberationSans-Regular.ttf",
        "/usr/share/fonts/TTF/DejaVuSans.ttf",
    ] {
        if Path::new(p).exists() {
            return Some(PathBuf::from(p));
        }
    }
    fn walk(dir: &Path, depth: usize) -> Option<PathBuf> {
        for e in std::fs::read_dir(dir).ok()?.flatten() {
            let p = e.path();
            if p.is_dir() && depth < 4 {
                if let Some(f) = walk(&p, depth + 1) {
                    return Some(f);
                }
            } else if p.extension().is_some_and(|x| x == "ttf") {
                return Some(p);
            }
        }
        None
    }
    walk(Path::new("/usr/share/fonts"), 0)
}

/// Registers a font as "sans-serif" once per process.
fn ensure_font() -> anyhow::Result<()> {
    static FONT: OnceLock<Result<(), String>> = OnceLock::new();
    FONT.get_or_init(|| {
        let path = find_font().ok_or("no TrueType font found (set COSIM_FONT to a .ttf file)")?;
        let bytes = std::fs::read(&path).map_err(|e| format!("{}: {e}", path.display()))?;
        let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
        plotters::style::register_font("sans-serif", FontStyle::Normal, bytes)
            .map_err(|_| format!("{}: not a usable font", path.display()))
    })
    .clone()
    .map_err(|e| anyhow!(e))
}

fn err<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow!("{e:?}")
}

/// The series legend, the same on every plot.
fn legend<'a, DB: DrawingBackend + 'a, CT: plotters::coord::CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
) -> anyhow::Result<()> {
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", 16))
        .draw()
        .map_err(err)
}

/// `error_vs_wall.png` (log–log, one colour per schedule, each schedule's Pareto front drawn)
/// and `stability.png` (a grid over the first two varied keys, or one row per run).
pub fn study_pngs(
    out_dir: &Path,
    outcomes: &[Outcome],
    vars: &[Variation],
    metric: &str,
) -> anyhow::Result<()> {
    ensure_font()?;
    pareto_png(&out_dir.join("error_vs_wall.png"), outcomes, metric)
        .context("error_vs_wall.png")?;
    stability_png(&out_dir.join("stability.png"), outcomes, vars).context("stability.png")
}

/// A named series of (x, y) points.
pub type Series = (String, Vec<(f64, f64)>);

/// Columns of a CSV time series: the x column's name and, per selected column, its
/// (x, y · scale) points (empty and non-finite cells skipped). `x` defaults to the first
/// column, `columns` to every other one. Errors name the file, line and column.
pub fn read_series(
    csv: &Path,
    x: Option<&str>,
    columns: &[String],
    scale: f64,
) -> anyhow::Result<(String, Vec<Series>)> {
    let text =
        std::fs::read_to_string(csv).with_context(|| format!("cannot read {}", csv.display()))?;
    let mut lines = text.lines().enumerate();
    let header: Vec<&str> = lines
        .next()
        .map(|(_, h)| h.split(',').map(str::trim).collect())
        .filter(|h: &Vec<&str>| h.len() >= 2)
        .ok_or_else(|| {
            anyhow!(
                "{}: needs a header line with at least two columns",
                csv.display()
            )
        })?;
    let find = |name: &str| {
        header.iter().position(|h| *h == name).ok_or_else(|| {
            anyhow!(
                "{}: no column `{name}`; the columns are: {}",
                csv.display(),
                header.join(", ")
            )
        })
    };
    let xi = match x {
        Some(name) => find(name)?,
        None => 0,
    };
    let ys: Vec<usize> = if columns.is_empty() {
        (0..header.len()).filter(|&i| i != xi).collect()
    } else {
        columns
            .iter()
            .map(|c| find(c))
            .collect::<anyhow::Result<_>>()?
    };
    let mut out: Vec<Series> = ys
        .iter()
        .map(|&i| (header[i].to_string(), Vec::new()))
        .collect();
    for (ln, line) in lines {
        if line.trim().is_empty() {
            continue;
        }
        let cells: Vec<&str> = line.split(',').map(str::trim).collect();
        let num = |i: usize| -> anyhow::Result<Option<f64>> {
            match cells.get(i) {
                None | Some(&"") => Ok(None),
                Some(c) => c.parse::<f64>().map(Some).map_err(|_| {
                    anyhow!(
                        "{} line {}, column `{}`: `{c}` is not a number",
                        csv.display(),
                        ln + 1,
                        header[i]
                    )
                }),
            }
        };
        let Some(xv) = num(xi)?.filter(|v| v.is_finite()) else {
            continue;
        };
        for (k, &i) in ys.iter().enumerate() {
            if let Some(y) = num(i)?.map(|y| y * scale).filter(|y| y.is_finite()) {
                out[k].1.push((xv, y));
            }
        }
    }
    if out.iter().all(|(_, pts)| pts.is_empty()) {
        return Err(anyhow!("{}: no numeric rows to plot", csv.display()));
    }
    Ok((header[xi].to_string(), out))
}

/// An axis label: plain decimals between 1e-3 and 1e5, else scientific notation.
fn tick(y: f64) -> String {
    let a = y.abs();
    if a == 0.0 {
        "0".into()
    } else if (1e-3..1e5).contains(&a) {
        let digits = (3 - a.log10().floor() as i32).clamp(0, 6) as usize;
        format!("{y:.digits$}")
    } else {
        format!("{y:.2e}")
    }
}

/// A line plot of time series (one colour per series, legend) as a PNG.
pub fn series_png(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
) -> anyhow::Result<()> {
    ensure_font()?;
    let root = BitMapBackend::new(path, (1000, 600)).into_drawing_area();
    series_chart(&root, title, x_label, y_label, series)?;
    root.present().map_err(err)?;
    Ok(())
}

/// Draws [`series_png`]'s chart on any backend.
fn series_chart<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
) -> anyhow::Result<()> {
    // positive values spanning more than three decades (a kinetic energy settling) are drawn
    // on a log axis: log10 of the values on a linear axis, labelled with the values
    let log_y = uses_log_axis(series);
    let series: Vec<Series> = if log_y {
        series
            .iter()
            .map(|(n, p)| (n.clone(), p.iter().map(|&(x, y)| (x, y.log10())).collect()))
            .collect()
    } else {
        series.to_vec()
    };
    let y_label = if log_y {
        format!("{y_label} (log scale)")
    } else {
        y_label.to_string()
    };
    let (mut xlo, mut xhi, mut ylo, mut yhi) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for &(x, y) in series.iter().flat_map(|(_, p)| p.iter()) {
        xlo = xlo.min(x);
        xhi = xhi.max(x);
        ylo = ylo.min(y);
        yhi = yhi.max(y);
    }
    if xhi.partial_cmp(&xlo) != Some(std::cmp::Ordering::Greater) {
        // one point (or all at one x): centre it (a static solve at t = 0: ±1)
        let half = if xlo == 0.0 { 1.0 } else { 0.5 * xlo.abs() };
        (xlo, xhi) = (xlo - half, xlo + half);
    }
    let pad = if yhi > ylo {
        0.05 * (yhi - ylo)
    } else {
        0.5 * yhi.abs().max(1e-12)
    };
    let (ylo, yhi) = (ylo - pad, yhi + pad);
    root.fill(&WHITE).map_err(err)?;
    let mut chart = ChartBuilder::on(root)
        .caption(title, ("sans-serif", 20))
        .margin(16)
        .x_label_area_size(48)
        .y_label_area_size(80)
        .build_cartesian_2d(xlo..xhi, ylo..yhi)
        .map_err(err)?;
    let y_tick = |y: &f64| {
        if log_y {
            format!("{:.0e}", 10f64.powf(*y))
        } else {
            tick(*y)
        }
    };
    chart
        .configure_mesh()
        .x_desc(x_label)
        .y_desc(y_label)
        .y_label_formatter(&y_tick)
        .x_label_formatter(&|x| tick(*x))
        .draw()
        .map_err(err)?;
    for (i, (name, pts)) in series.iter().enumerate() {
        let c = PALETTE[i % PALETTE.len()];
        chart
            .draw_series(LineSeries::new(pts.iter().cloned(), c.stroke_width(2)))
            .map_err(err)?
            .label(name.as_str())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], c.stroke_width(2)));
        // few points: each is marked (a single one draws no line)
        if pts.len() <= MARKED_POINTS {
            chart
                .draw_series(pts.iter().map(|&p| Circle::new(p, 4, c.filled())))
                .map_err(err)?;
        }
    }
    legend(&mut chart)?;
    Ok(())
}

/// Series of at most this many points get a marker on each point.
const MARKED_POINTS: usize = 30;

/// Whether [`series_png`] draws `series` on a log y axis (for tests and captions).
pub fn uses_log_axis(series: &[Series]) -> bool {
    let mut pts = series.iter().flat_map(|(_, p)| p.iter());
    let (lo, hi) = pts.clone().fold((f64::INFINITY, 0.0f64), |(l, h), p| {
        (l.min(p.1), h.max(p.1))
    });
    pts.all(|p| p.1 > 0.0) && hi / lo > 1e3
}

/// How the columns of one output CSV become plots.
#[derive(Clone, Copy, PartialEq)]
enum Layout {
    /// One plot per group `probe.seat.*` / `strain.g.*` (fem_probes.csv).
    Grouped,
    /// One plot per column (dem_sensors.csv: the sensors' units differ).
    EachColumn,
    /// dem_timeseries.csv: the kinetic energy and each loaded wall's columns
    /// (`<wall>.displacement`, `.velocity`, `.contact_force`), one plot per column.
    DemTimeSeries,
}

/// The columns dem_timeseries.csv has for each loaded wall (`<wall><suffix>`) and their units.
const LOADED_WALL_COLUMNS: [(&str, &str); 3] = [
    (".displacement", "m"),
    (".velocity", "m/s"),
    (".contact_force", "N"),
];

/// The unit of a loaded wall's column, `None` for any other column.
fn loaded_wall_unit(column: &str) -> Option<&'static str> {
    LOADED_WALL_COLUMNS
        .iter()
        .find(|(suffix, _)| column.ends_with(suffix))
        .map(|&(_, unit)| unit)
}

/// The y-axis label of a plotted column or group.
fn ylabel_of(key: &str) -> String {
    if key.starts_with("probe.") {
        "displacement (m)".into()
    } else if key.starts_with("strain.") {
        "strain".into()
    } else if key == "kinetic_energy" {
        "kinetic energy (J)".into()
    } else if let Some(unit) = loaded_wall_unit(key) {
        format!("{key} ({unit})")
    } else {
        key.to_string()
    }
}

/// After a run: PNGs of the nodes' time series in `<out>/plots/`. A FEM node's
/// `fem_probes.csv` gives one plot per probe (ux, uy, uz) and per strain gauge (its three strain
/// measures), the DEM's `dem_sensors.csv` one plot per sensor (their units differ),
/// `dem_timeseries.csv` the particles' kinetic energy and each loaded wall's displacement,
/// velocity and contact force. Every node folder `<out>/<node>/` is looked at; the plots of a
/// node other than `dem` and `fem` (one of several structures) are named after it. Returns the
/// files written.
pub fn run_plots(out_dir: &Path) -> anyhow::Result<Vec<PathBuf>> {
    let mut written = Vec::new();
    let dir = out_dir.join("plots");
    let mut nodes: Vec<String> = std::fs::read_dir(out_dir)
        .map(|d| {
            d.flatten()
                .filter(|e| e.path().is_dir())
                .filter_map(|e| e.file_name().to_str().map(String::from))
                .collect()
        })
        .unwrap_or_default();
    nodes.sort();
    let mut sources = Vec::new();
    for node in &nodes {
        let prefix = if node == "dem" || node == "fem" {
            String::new()
        } else {
            format!("{node}.")
        };
        for (file, layout) in [
            ("fem_probes.csv", Layout::Grouped),
            ("dem_sensors.csv", Layout::EachColumn),
            ("dem_timeseries.csv", Layout::DemTimeSeries),
        ] {
            sources.push((out_dir.join(node).join(file), layout, prefix.clone()));
        }
    }
    for node in &nodes {
        let csv = out_dir.join(node).join("discs.csv");
        if csv.exists() {
            let prefix = if node == "dem" {
                String::new()
            } else {
                format!("{node}.")
            };
            written.extend(disc_plots(out_dir, &csv, &dir, &prefix)?);
        }
    }
    for (csv, layout, prefix) in sources {
        if !csv.exists() {
            continue;
        }
        let (xname, series) = read_series(&csv, None, &[], 1.0)?;
        // groups of columns: `probe.seat.uz` → `probe.seat`; otherwise each column alone
        let mut groups: Vec<(String, Vec<Series>)> = Vec::new();
        for (name, pts) in series {
            let key = match (layout, name.rsplit_once('.')) {
                (Layout::Grouped, Some((g, _))) => g.to_string(),
                (Layout::DemTimeSeries, _)
                    if name != "kinetic_energy" && loaded_wall_unit(&name).is_none() =>
                {
                    continue
                }
                _ => name.clone(),
            };
            match groups.iter_mut().find(|(g, _)| *g == key) {
                Some((_, v)) => v.push((name, pts)),
                None => groups.push((key, vec![(name, pts)])),
            }
        }
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        let xlabel = if xname == "time" {
            "time (s)".to_string()
        } else {
            xname.clone()
        };
        for (key, series) in groups {
            if series.iter().all(|(_, p)| p.is_empty()) {
                continue;
            }
            let file = dir.join(format!("{prefix}{key}.png"));
            let source = csv
                .strip_prefix(out_dir)
                .unwrap_or(&csv)
                .display()
                .to_string();
            series_png(
                &file,
                &format!("{key} ({source})"),
                &xlabel,
                &ylabel_of(&key),
                &series,
            )
            .with_context(|| format!("writing {}", file.display()))?;
            written.push(file);
        }
    }
    Ok(written)
}

/// The plots of a 2-D disc run's `discs.csv` (Madan's energies (2.55)–(2.61) and the uniaxial
/// measurement): `energies.png` (W_ext, E_k, E_el,c, E_el,p and the dissipated rest over
/// time), `strains.png` (the sample's ε_yy, ε_xx and the largest particle strain) and, with a
/// measurement, `stress_strain.png` (σ_yy against ε_yy) and `shear_stress_strain.png` (σ_xy
/// against ε_xy).
fn disc_plots(
    out_dir: &Path,
    csv: &Path,
    dir: &Path,
    prefix: &str,
) -> anyhow::Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let source = csv
        .strip_prefix(out_dir)
        .unwrap_or(csv)
        .display()
        .to_string();
    let cols = |names: &[&str]| names.iter().map(|n| n.to_string()).collect::<Vec<_>>();
    let mut written = Vec::new();
    // (file, x column or time, y columns, x label, y label)
    type Plot<'a> = (&'a str, Option<&'a str>, Vec<String>, &'a str, &'a str);
    let plots: [Plot; 4] = [
        (
            "energies",
            None,
            cols(&[
                "external_work",
                "kinetic_energy",
                "contact_energy",
                "particle_energy",
                "dissipated",
            ]),
            "time (s)",
            "energy (J)",
        ),
        (
            "strains",
            None,
            cols(&["strain_yy", "strain_xx", "strain_xy", "strain_max"]),
            "time (s)",
            "strain",
        ),
        (
            "stress_strain",
            Some("strain_yy"),
            cols(&["stress_yy"]),
            "sample strain ε_yy",
            "σ_yy (Pa)",
        ),
        (
            "shear_stress_strain",
            Some("strain_xy"),
            cols(&["stress_xy"]),
            "sample strain ε_xy",
            "σ_xy (Pa)",
        ),
    ];
    for (name, x, columns, xlabel, ylabel) in plots {
        let (_, series) = match read_series(csv, x, &columns, 1.0) {
            Ok(s) => s,
            // no measurement in this scene: its columns are empty
            Err(_) if name != "energies" => continue,
            Err(e) => return Err(e),
        };
        let series: Vec<Series> = series.into_iter().filter(|(_, p)| !p.is_empty()).collect();
        if series.is_empty() {
            continue;
        }
        let file = dir.join(format!("{prefix}{name}.png"));
        series_png(
            &file,
            &format!("{name} ({source})"),
            xlabel,
            ylabel,
            &series,
        )
        .with_context(|| format!("writing {}", file.display()))?;
        written.push(file);
    }
    Ok(written)
}

/// The points of `pts` (x, y) not dominated by another (smaller x and smaller y), by x.
pub fn pareto_front(pts: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let mut p: Vec<(f64, f64)> = pts.to_vec();
    p.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
    let mut front: Vec<(f64, f64)> = Vec::new();
    for q in p {
        if front.last().is_none_or(|l| q.1 < l.1) {
            front.push(q);
        }
    }
    front
}

fn pareto_png(path: &Path, outcomes: &[Outcome], metric: &str) -> anyhow::Result<()> {
    // the reference run (error 0) and round-off-level errors are drawn at the bottom of the axis
    let pts: Vec<(f64, f64, String)> = outcomes
        .iter()
        .filter_map(|o| {
            o.error
                .filter(|_| o.wall_s > 0.0)
                .map(|e| (o.wall_s, e, schedule_of(o)))
        })
        .collect();
    let positive = pts.iter().map(|p| p.1).filter(|&e| e > 1e-14);
    let ymin = positive.clone().fold(f64::INFINITY, f64::min);
    let ymax = positive.fold(0.0, f64::max);
    let (ylo, yhi) = if ymin.is_finite() {
        (
            10f64.powf(ymin.log10().floor() - 1.0),
            10f64.powf(ymax.log10().ceil()),
        )
    } else {
        (1e-6, 1.0)
    };
    let xmin = pts.iter().map(|p| p.0).fold(f64::INFINITY, f64::min);
    let xmax = pts.iter().map(|p| p.0).fold(0.0, f64::max);
    let (xlo, xhi) = if xmin.is_finite() {
        (xmin / 1.5, xmax * 1.5)
    } else {
        (0.1, 10.0)
    };
    let root = BitMapBackend::new(path, (900, 620)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!("Speed–accuracy trade: error of {metric}"),
            ("sans-serif", 20),
        )
        .margin(16)
        .x_label_area_size(48)
        .y_label_area_size(72)
        .build_cartesian_2d((xlo..xhi).log_scale(), (ylo..yhi).log_scale())
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("wall time (s)")
        .y_desc("relative error vs reference")
        .y_label_formatter(&|y| format!("{y:.0e}"))
        .x_label_formatter(&|x| format!("{x:.2}"))
        .draw()
        .map_err(err)?;
    let mut schedules: Vec<String> = pts.iter().map(|p| p.2.clone()).collect();
    schedules.sort();
    schedules.dedup();
    for (i, sch) in schedules.iter().enumerate() {
        let c = PALETTE[i % PALETTE.len()];
        let mine: Vec<(f64, f64)> = pts
            .iter()
            .filter(|p| &p.2 == sch)
            .map(|p| (p.0, p.1.max(ylo)))
            .collect();
        chart
            .draw_series(mine.iter().map(|&p| Circle::new(p, 5, c.filled())))
            .map_err(err)?
            .label(sch.as_str())
            .legend(move |(x, y)| Circle::new((x + 8, y), 5, c.filled()));
        chart
            .draw_series(LineSeries::new(pareto_front(&mine), c.stroke_width(2)))
            .map_err(err)?;
    }
    legend(&mut chart)?;
    root.present().map_err(err)?;
    Ok(())
}

fn status_colour(status: &str) -> RGBColor {
    match status {
        "completed" => RGBColor(0x2c, 0xa0, 0x2c),
        "unstable" => RGBColor(0xd6, 0x27, 0x28),
        "refused" => RGBColor(0x99, 0x99, 0x99),
        "inaccurate" => RGBColor(0xff, 0x7f, 0x0e),
        _ => RGBColor(0x8c, 0x56, 0x4b),
    }
}

fn stability_png(path: &Path, outcomes: &[Outcome], vars: &[Variation]) -> anyhow::Result<()> {
    // grid: columns = values of the first key, rows = combinations of the others
    let key0 = vars
        .first()
        .map(|v| v.keys().collect::<Vec<_>>().join(" / "))
        .unwrap_or_default();
    // a column per value of the first variation (with its linked keys' values: `25e3 / -95`)
    let width = vars.first().map_or(1, |v| 1 + v.linked.len());
    let cols: Vec<String> = vars
        .first()
        .map(|v| {
            (0..v.values.len())
                .map(|i| {
                    std::iter::once(&v.values[i])
                        .chain(v.linked.iter().map(|(_, vals)| &vals[i]))
                        .map(value_text)
                        .collect::<Vec<_>>()
                        .join(" / ")
                })
                .collect()
        })
        .unwrap_or_default();
    let col_of = |o: &Outcome| -> String {
        o.variant
            .settings
            .iter()
            .take(width)
            .map(|(_, v)| value_text(v))
            .collect::<Vec<_>>()
            .join(" / ")
    };
    let row_of = |o: &Outcome| -> String {
        o.variant
            .settings
            .iter()
            .skip(width)
            .map(|(k, v)| format!("{k}={}", value_text(v)))
            .collect::<Vec<_>>()
            .join(" ")
    };
    let mut rows: Vec<String> = outcomes.iter().map(row_of).collect();
    rows.dedup();
    let mut seen = std::collections::BTreeSet::new();
    rows.retain(|r| seen.insert(r.clone()));
    let (cw, rh, left, top) = (110i32, 34i32, 330i32, 70i32);
    let w = (left + cw * cols.len().max(1) as i32 + 20) as u32;
    let h = (top + rh * rows.len().max(1) as i32 + 60) as u32;
    let root = BitMapBackend::new(path, (w.max(640), h)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let font = |s| ("sans-serif", s).into_font();
    root.draw(&Text::new(
        format!("Stability map ({key0} across)"),
        (10, 10),
        font(20),
    ))
    .map_err(err)?;
    for (j, c) in cols.iter().enumerate() {
        root.draw(&Text::new(
            c.clone(),
            (left + cw * j as i32 + 6, top - 24),
            font(14),
        ))
        .map_err(err)?;
    }
    for (i, r) in rows.iter().enumerate() {
        let y = top + rh * i as i32;
        root.draw(&Text::new(
            if r.is_empty() {
                "runs".into()
            } else {
                r.clone()
            },
            (10, y + 9),
            font(14),
        ))
        .map_err(err)?;
        for o in outcomes.iter().filter(|o| &row_of(o) == r) {
            let j = cols.iter().position(|c| *c == col_of(o)).unwrap_or(0) as i32;
            let x = left + cw * j;
            root.draw(&Rectangle::new(
                [(x + 2, y + 2), (x + cw - 2, y + rh - 2)],
                status_colour(&o.status).filled(),
            ))
            .map_err(err)?;
            root.draw(&Text::new(
                o.status.clone(),
                (x + 8, y + 9),
                ("sans-serif", 14).into_font().color(&WHITE),
            ))
            .map_err(err)?;
        }
    }
    root.present().map_err(err)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn time_series_columns_are_read_and_plotted_with_clear_errors() {
        let dir = tempfile::tempdir().unwrap();
        let csv = dir.path().join("probes.csv");
        std::fs::write(&csv, "time,a,b\n0.0,1.0,\n0.1,2.0,5.0\n0.2,NaN,6.0\n").unwrap();
        let (x, s) = read_series(&csv, None, &[], -2.0).unwrap();
        assert_eq!(x, "time");
        assert_eq!(s[0], ("a".to_string(), vec![(0.0, -2.0), (0.1, -4.0)]));
        assert_eq!(s[1], ("b".to_string(), vec![(0.1, -10.0), (0.2, -12.0)]));
        let (_, s) = read_series(&csv, Some("a"), &["b".to_string()], 1.0).unwrap();
        assert_eq!(s[0].1, vec![(2.0, 5.0)]);
        let e = read_series(&csv, None, &["c".to_string()], 1.0)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("no column `c`") && e.contains("time, a, b"),
            "{e}"
        );
        std::fs::write(&csv, "time,a\n0.0,1.0\n0.1,oops\n").unwrap();
        let e = read_series(&csv, None, &[], 1.0).unwrap_err().to_string();
        assert!(
            e.contains("line 3") && e.contains("`a`") && e.contains("oops"),
            "{e}"
        );
        // a PNG with the series (fonts: see find_font; this machine has DejaVu)
        let png = dir.path().join("p.png");
        let e = read_series(&csv.with_file_name("none.csv"), None, &[], 1.0).unwrap_err();
        assert!(e.to_string().contains("cannot read"), "{e}");
        let s = vec![("a".to_string(), vec![(0.0, 1.0), (1.0, 2.0)])];
        series_png(&png, "test", "time (s)", "a", &s).unwrap();
        let bytes = std::fs::read(&png).unwrap();
        assert_eq!(&bytes[..4], b"\x89PNG");
    }

    #[test]
    fn a_run_gets_one_plot_per_probe_gauge_sensor_and_wall_quantity() {
        let out = tempfile::tempdir().unwrap();
        std::fs::create_dir_all(out.path().join("fem")).unwrap();
        std::fs::create_dir_all(out.path().join("dem")).unwrap();
        std::fs::write(
            out.path().join("fem/fem_probes.csv"),
            "time,probe.a.ux,probe.a.uy,probe.a.uz,probe.b.ux,probe.b.uy,probe.b.uz,\
             strain.g.max_principal,strain.g.min_principal,strain.g.von_mises\n\
             0.1,0,0,-1e-6,0,0,-2e-6,1e-4,-1e-4,1e-4\n0.2,0,0,-2e-6,0,0,-3e-6,2e-4,-2e-4,2e-4\n",
        )
        .unwrap();
        std::fs::write(
            out.path().join("dem/dem_sensors.csv"),
            "time,p1,flow\n0.1,1e5,0.0\n0.2,2e5,0.01\n",
        )
        .unwrap();
        std::fs::write(
            out.path().join("dem/dem_timeseries.csv"),
            "time,step,particles,kinetic_energy,contacts,plate.displacement,plate.velocity,\
             plate.contact_force\n0.1,10,5,1.0,3,-0.01,-0.1,100\n0.2,20,5,0.5,4,-0.02,0,200\n",
        )
        .unwrap();
        let mut names: Vec<String> = run_plots(out.path())
            .unwrap()
            .iter()
            .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        names.sort();
        assert_eq!(
            names,
            [
                "flow.png",
                "kinetic_energy.png",
                "p1.png",
                "plate.contact_force.png",
                "plate.displacement.png",
                "plate.velocity.png",
                "probe.a.png",
                "probe.b.png",
                "strain.g.png"
            ]
        );
        // nothing to plot: no files, no error
        let empty = tempfile::tempdir().unwrap();
        assert!(run_plots(empty.path()).unwrap().is_empty());
    }

    /// Pixels of the first series' colour in the middle of a 1000×600 rendering of `series`.
    fn drawn_in_the_middle(series: &[Series]) -> usize {
        ensure_font().unwrap();
        let mut buf = vec![0u8; 1000 * 600 * 3];
        {
            let root = BitMapBackend::with_buffer(&mut buf, (1000, 600)).into_drawing_area();
            series_chart(&root, "t", "time (s)", "y", series).unwrap();
            root.present().unwrap();
        }
        let c = PALETTE[0];
        (200..450)
            .flat_map(|y| (300..700).map(move |x| (x, y)))
            .filter(|&(x, y)| {
                let i = 3 * (y * 1000 + x);
                buf[i..i + 3] == [c.0, c.1, c.2]
            })
            .count()
    }

    #[test]
    fn a_single_point_is_drawn_and_decades_go_on_a_log_axis() {
        // one row (a one-way run's single window) used to draw nothing at all
        let one = vec![("uz".to_string(), vec![(0.5, -7.0e-7)])];
        assert!(drawn_in_the_middle(&one) > 20);
        // a settling kinetic energy over eight decades: log axis; a sign change: linear
        let ke = vec![(
            "ke".to_string(),
            (0..50i32)
                .map(|i| (f64::from(i), 10f64.powi(-i / 6)))
                .collect(),
        )];
        assert!(uses_log_axis(&ke));
        assert!(drawn_in_the_middle(&ke) > 20);
        let signed = vec![("u".to_string(), vec![(0.0, -1.0), (1.0, 1e-6)])];
        assert!(!uses_log_axis(&signed));
        let flat = vec![("u".to_string(), vec![(0.0, 1.0), (1.0, 2.0)])];
        assert!(!uses_log_axis(&flat));
    }

    #[test]
    fn the_pareto_front_keeps_only_undominated_points() {
        let f = pareto_front(&[(1.0, 0.1), (2.0, 0.2), (3.0, 0.01), (0.5, 1.0), (4.0, 0.01)]);
        assert_eq!(f, vec![(0.5, 1.0), (1.0, 0.1), (3.0, 0.01)]);
    }
}
