//! `cosim study`: the speed–accuracy trade of a scene, measured. A sweep over scene values
//! (coupling window, DEM time step, schedule, force averaging, mesh size, …); every run's wall
//! time, cost split, error against a reference run and whether it stayed stable, in a CSV and
//! two plots (error vs wall time, one colour per schedule; stability map). A half-done sweep
//! resumes: runs that ended are not run again, a run that was stopped half-way continues
//! from its newest checkpoint (scenes with `[output] checkpoint_every` or `checkpoint_wall`)
//! or starts again. Runs that differ only in a seed are an ensemble: `ensembles.csv` has the
//! metric's mean and standard deviation per case.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context};

use crate::run::{run_scene, RunOptions};
use crate::scene::Scene;

/// One `--vary key=v1,v2,…`, or keys that vary together: `a+b=a1:b1,a2:b2` (the cell
/// pressure and the platen's force of a triaxial cell, say).
#[derive(Debug, Clone, PartialEq)]
pub struct Variation {
    /// Dotted path in the scene file, e.g. `coupling.window`, `dem.time_step` or
    /// `dem.walls.2.load.force` (a number picks an entry of a list of tables such as
    /// `[[dem.walls]]`, counting from 0).
    pub key: String,
    pub values: Vec<toml::Value>,
    /// Keys set together with `key`: each with one value per value of `key`.
    pub linked: Vec<(String, Vec<toml::Value>)>,
}

impl Variation {
    /// Every key this variation sets, `key` first (the order of a variant's settings).
    pub fn keys(&self) -> impl Iterator<Item = &str> {
        std::iter::once(self.key.as_str()).chain(self.linked.iter().map(|(k, _)| k.as_str()))
    }
}

fn parse_value(v: &str) -> toml::Value {
    let v = v.trim();
    toml::from_str::<toml::Table>(&format!("x = {v}"))
        .ok()
        .and_then(|t| t.get("x").cloned())
        .unwrap_or_else(|| toml::Value::String(v.to_string()))
}

/// Parses `key=v1,v2,…` or `key1+key2=v1:w1,v2:w2,…`; values are TOML values (numbers,
/// booleans, strings) or bare words.
pub fn parse_variation(text: &str) -> anyhow::Result<Variation> {
    let (keys, values) = text.split_once('=').ok_or_else(|| {
        anyhow!("--vary `{text}`: expected key=value1,value2,… (e.g. coupling.window=1e-4,5e-5)")
    })?;
    let keys: Vec<String> = keys.split('+').map(|k| k.trim().to_string()).collect();
    for key in &keys {
        if key.is_empty() || key.split('.').any(str::is_empty) {
            bail!("--vary `{text}`: `{key}` is not a dotted key such as coupling.window");
        }
    }
    if values.trim().is_empty() {
        bail!("--vary `{text}`: no values");
    }
    let mut columns: Vec<Vec<toml::Value>> = vec![Vec::new(); keys.len()];
    for tuple in values.split(',') {
        let parts: Vec<&str> = if keys.len() == 1 {
            vec![tuple]
        } else {
            tuple.split(':').collect()
        };
        if parts.len() != keys.len() {
            bail!(
                "--vary `{text}`: `{}` gives {} value(s) for the {} keys {} (join one value per \
                 key with `:`)",
                tuple.trim(),
                parts.len(),
                keys.len(),
                keys.join("+")
            );
        }
        for (c, v) in columns.iter_mut().zip(parts) {
            c.push(parse_value(v));
        }
    }
    let mut columns = columns.into_iter();
    let mut keys = keys.into_iter();
    let (key, values) = (
        keys.next().unwrap_or_default(),
        columns.next().unwrap_or_default(),
    );
    Ok(Variation {
        key,
        values,
        linked: keys.zip(columns).collect(),
    })
}

/// Sets `key` (dotted) in a TOML table, creating tables on the way; a number picks an entry
/// of a list (`dem.walls.2.load.force`: the third `[[dem.walls]]`).
fn set_path(table: &mut toml::Table, key: &str, value: toml::Value) -> anyhow::Result<()> {
    let parts: Vec<&str> = key.split('.').collect();
    let Some((last, path)) = parts.split_last() else {
        bail!("an empty key");
    };
    let Some((first, rest)) = path.split_first() else {
        table.insert(last.to_string(), value);
        return Ok(());
    };
    let mut cur = table
        .entry(first.to_string())
        .or_insert_with(|| toml::Value::Table(Default::default()));
    for (i, p) in rest.iter().enumerate() {
        let next_is_index = rest.get(i + 1).unwrap_or(last).parse::<usize>().is_ok();
        cur = match cur {
            toml::Value::Table(t) if next_is_index && !t.contains_key(*p) => bail!(
                "`{key}`: `{}` is not in the scene (a number picks an entry of an existing list)",
                parts[..=i + 1].join(".")
            ),
            toml::Value::Table(t) => t
                .entry(p.to_string())
                .or_insert_with(|| toml::Value::Table(Default::default())),
            toml::Value::Array(a) => list_entry(a, p, &parts[..=i].join("."), key)?,
            _ => bail!(
                "`{key}`: `{}` is not a table in the scene",
                parts[..=i].join(".")
            ),
        };
    }
    let here = path.join(".");
    match cur {
        toml::Value::Table(t) => {
            t.insert(last.to_string(), value);
        }
        toml::Value::Array(a) => *list_entry(a, last, &here, key)? = value,
        _ => bail!("`{key}`: `{here}` is not a table in the scene"),
    }
    Ok(())
}

/// Entry `index` of the list `here` (part of `key`), or why there is none.
fn list_entry<'a>(
    list: &'a mut [toml::Value],
    index: &str,
    here: &str,
    key: &str,
) -> anyhow::Result<&'a mut toml::Value> {
    let n = list.len();
    let last = n.saturating_sub(1);
    let k: usize = index.parse().map_err(|_| {
        anyhow!(
            "`{key}`: `{here}` is a list of {n} entries; pick one by its index (`{here}.0` to \
             `{here}.{last}`)"
        )
    })?;
    list.get_mut(k)
        .ok_or_else(|| anyhow!("`{key}`: `{here}` has {n} entries (indices 0 to {last})"))
}

pub(crate) fn value_text(v: &toml::Value) -> String {
    match v {
        toml::Value::String(s) => s.clone(),
        // 1e-5, not 0.00001
        toml::Value::Float(x) if *x != 0.0 && (x.abs() < 1e-3 || x.abs() >= 1e6) => {
            format!("{x:e}")
        }
        other => other.to_string(),
    }
}

/// One run of the sweep.
#[derive(Debug, Clone)]
pub struct Variant {
    pub name: String,
    pub settings: Vec<(String, toml::Value)>,
    pub text: String,
}

/// Every combination of the variations (the Cartesian product), as scene texts.
pub fn variants(base_text: &str, vars: &[Variation]) -> anyhow::Result<Vec<Variant>> {
    let base: toml::Table = toml::from_str(base_text).context("the scene is not valid TOML")?;
    let mut seen = std::collections::BTreeSet::new();
    for v in vars {
        if let Some(k) = v.keys().find(|k| !seen.insert(*k)) {
            bail!("--vary: `{k}` is varied twice; give each key once");
        }
        if let Some((k, _)) = v
            .linked
            .iter()
            .find(|(_, vals)| vals.len() != v.values.len())
        {
            bail!("--vary: `{k}` has not one value per value of `{}`", v.key);
        }
    }
    let mut combos: Vec<Vec<(String, toml::Value)>> = vec![Vec::new()];
    for v in vars {
        combos = combos
            .into_iter()
            .flat_map(|c| {
                v.values.iter().enumerate().map(move |(i, val)| {
                    let mut c = c.clone();
                    c.push((v.key.clone(), val.clone()));
                    for (k, vals) in &v.linked {
                        c.push((k.clone(), vals[i].clone()));
                    }
                    c
                })
            })
            .collect();
    }
    combos
        .into_iter()
        .enumerate()
        .map(|(i, settings)| {
            let mut t = base.clone();
            for (k, v) in &settings {
                set_path(&mut t, k, v.clone())?;
            }
            Ok(Variant {
                name: format!("run{i:03}"),
                settings,
                text: toml::to_string(&t)?,
            })
        })
        .collect()
}

impl Variant {
    /// `key=value key=value …` of the variant's settings.
    pub fn label(&self) -> String {
        self.settings
            .iter()
            .map(|(k, x)| format!("{k}={}", value_text(x)))
            .collect::<Vec<_>>()
            .join(" ")
    }
}

/// What one run gave.
#[derive(Debug, Clone)]
pub struct Outcome {
    pub variant: Variant,
    pub status: String,
    pub error_message: Option<String>,
    pub wall_s: f64,
    pub dem_s: f64,
    pub fem_s: f64,
    pub overhead_s: f64,
    pub metric: Option<f64>,
    /// Relative error of the metric against the reference run.
    pub error: Option<f64>,
}

/// How often a study or run without a terminal logs where it stands.
pub const PROGRESS_LOG_EVERY: std::time::Duration = std::time::Duration::from_secs(600);

/// The study bar's message: each running run's label and its progress note.
fn running_notes(notes: &[(String, crate::run::ProgressNote)]) -> String {
    notes
        .iter()
        .map(|(label, note)| {
            let n = note.lock().unwrap_or_else(|e| e.into_inner());
            if n.is_empty() {
                label.clone()
            } else {
                format!("{label}: {n}")
            }
        })
        .collect::<Vec<_>>()
        .join(" | ")
}

fn number(v: &serde_json::Value, path: &[&str]) -> f64 {
    path.iter()
        .fold(v, |v, p| &v[*p])
        .as_f64()
        .unwrap_or(f64::NAN)
}

/// How a study runs and what it compares.
#[derive(Debug, Clone, Default)]
pub struct StudyOptions {
    /// Summary result compared between runs (e.g. `fem.probe.centre.uz`).
    pub metric: Option<String>,
    /// A time series compared between runs instead: `(file in the run folder, column)`, e.g.
    /// `("fem/fem_probes.csv", "probe.centre.uz")`; the error is the relative L2 norm over
    /// the reference run's times (Ullrich's time histories, not one final value).
    pub series: Option<(String, String)>,
    /// Index of the reference run (default: the finest completed run).
    pub reference: Option<usize>,
    /// Runs at the same time (default 1).
    pub jobs: usize,
    /// A completed run whose error exceeds this is marked `inaccurate` (default 1.0 = 100 %):
    /// its history has little to do with the reference's (a slow divergence the monitor did not
    /// stop, or a window far too long for the physics).
    pub inaccurate_above: Option<f64>,
}

/// A run folder whose summary says the run ended (`completed`, `unstable` or `failed`): a
/// resumed study does not run it again. `running` (a run that died with the study) and
/// `interrupted` runs are run again.
fn run_is_done(dir: &Path) -> bool {
    std::fs::read_to_string(dir.join("summary.json"))
        .ok()
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
        .is_some_and(|s| {
            matches!(
                s["status"].as_str(),
                Some("completed" | "unstable" | "failed")
            )
        })
}

/// The message of an error found in a variant's scene text, in the user's terms: the
/// variant's temporary file (and its line, which is of the rewritten text) becomes the user's
/// scene and the variant's settings.
fn in_user_terms(message: &str, tmp: &Path, scene: &Path, label: &str) -> String {
    let tmp = tmp.display().to_string();
    let user = format!("{} with --vary {label}", scene.display());
    let mut out = String::new();
    let mut rest = message;
    while let Some(i) = rest.find(&tmp) {
        out.push_str(&rest[..i]);
        out.push_str(&user);
        rest = &rest[i + tmp.len()..];
        // drop `:line:column` of the rewritten text
        let mut chars = rest.char_indices().peekable();
        let mut end = 0;
        for _ in 0..2 {
            match chars.next() {
                Some((_, ':')) => {}
                _ => break,
            }
            let mut digits = false;
            while let Some(&(j, c)) = chars.peek() {
                if !c.is_ascii_digit() {
                    break;
                }
                digits = true;
                end = j + 1;
                chars.next();
            }
            if !digits {
                break;
            }
        }
        rest = &rest[end..];
        // the nodes' form: `: line 8, column 1`
        if let Some(after) = strip_line_column(rest) {
            rest = after;
        }
    }
    out.push_str(rest);
    out
}

/// `rest` without a leading `: line <n>, column <m>` (keeping what follows the place).
fn strip_line_column(rest: &str) -> Option<&str> {
    let digits = |t: &str| t.len() - t.trim_start_matches(|c: char| c.is_ascii_digit()).len();
    let t = rest.strip_prefix(": line ")?;
    let n = digits(t);
    let t = t[n..].strip_prefix(", column ").filter(|_| n > 0)?;
    let m = digits(t);
    (m > 0).then(|| &rest[rest.len() - t.len() + m..])
}

/// The scene file of a variant: a scene of its own next to the user's (its relative paths
/// hold), named after the study's folder too, so that two studies of one scene at once (other
/// `--out`s) do not write the same file.
fn variant_scene_path(scene: &Scene, out_dir: &Path, v: &Variant) -> PathBuf {
    let folder = std::fs::canonicalize(out_dir).unwrap_or_else(|_| out_dir.to_path_buf());
    let tag = crate::checkpoint::scene_fingerprint(&folder.display().to_string());
    scene.path.with_file_name(format!(
        ".study-{}-{}-{}.toml",
        scene.name,
        &tag[..8],
        v.name
    ))
}

/// Every variant is checked before any runs (`cosim check` of each: the coordinator's tables
/// here, the nodes' tables and limits by the nodes); one invalid variant refuses the study,
/// naming the user's scene and the settings. Variants whose node tables are the same are
/// checked by the nodes once.
async fn validate_variants(
    scene: &Scene,
    variants: &[Variant],
    jobs: usize,
    out_dir: &Path,
) -> anyhow::Result<()> {
    let mut errors = Vec::new();
    let mut node_checks: Vec<(Variant, Scene)> = Vec::new();
    let mut seen = std::collections::BTreeSet::new();
    for v in variants {
        let tmp = variant_scene_path(scene, out_dir, v);
        match Scene::parse(&tmp, v.text.clone()) {
            Err(e) => errors.push(in_user_terms(&e.to_string(), &tmp, &scene.path, &v.label())),
            Ok(s) => {
                let t: toml::Table = toml::from_str(&v.text)?;
                let key = format!("{:?}{:?}{}", t.get("dem"), t.get("fem"), s.window.to_bits());
                if seen.insert(key) {
                    node_checks.push((v.clone(), s));
                }
            }
        }
    }
    let mut pending = node_checks
        .into_iter()
        .collect::<std::collections::VecDeque<_>>();
    let mut running = tokio::task::JoinSet::new();
    while !pending.is_empty() || !running.is_empty() {
        while running.len() < jobs {
            let Some((v, s)) = pending.pop_front() else {
                break;
            };
            let dir = out_dir.join(format!(".check-{}", v.name));
            let _ = std::fs::remove_dir_all(&dir);
            let user_scene = scene.path.clone();
            running.spawn(async move {
                std::fs::write(&s.path, &s.text)
                    .with_context(|| format!("writing {}", s.path.display()))?;
                let opts = RunOptions {
                    check_only: true,
                    out_dir: Some(dir.clone()),
                    progress: false,
                    ..Default::default()
                };
                let r = run_scene(&s, &opts).await;
                let _ = std::fs::remove_file(&s.path);
                let _ = std::fs::remove_dir_all(&dir);
                anyhow::Ok(
                    r.err().map(|e| {
                        in_user_terms(&format!("{e:#}"), &s.path, &user_scene, &v.label())
                    }),
                )
            });
        }
        if let Some(done) = running.join_next().await {
            if let Some(e) = done.map_err(|e| anyhow!("a study check panicked: {e}"))?? {
                errors.push(e);
            }
        }
    }
    if !errors.is_empty() {
        errors.sort();
        errors.dedup();
        bail!(
            "the study of {} has {} invalid variant{} (nothing was run):\n  {}",
            scene.path.display(),
            errors.len(),
            if errors.len() == 1 { "" } else { "s" },
            errors.join("\n  ")
        );
    }
    Ok(())
}

/// Parses `--series file:column`.
pub fn parse_series(text: &str) -> anyhow::Result<(String, String)> {
    match text.rsplit_once(':') {
        Some((f, c)) if !f.is_empty() && !c.is_empty() => Ok((f.to_string(), c.to_string())),
        _ => bail!(
            "--series `{text}`: expected `file:column`, e.g. `fem/fem_probes.csv:probe.centre.uz`"
        ),
    }
}

/// Reads `(time, column)` pairs from a CSV with a header row whose first column is time.
pub fn read_series(path: &Path, column: &str) -> anyhow::Result<Vec<(f64, f64)>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut lines = text.lines();
    let header: Vec<&str> = lines
        .next()
        .ok_or_else(|| anyhow!("{}: empty file", path.display()))?
        .split(',')
        .collect();
    let col = header
        .iter()
        .position(|h| h.trim() == column)
        .ok_or_else(|| {
            anyhow!(
                "{}: no column `{column}` (columns: {})",
                path.display(),
                header.join(", ")
            )
        })?;
    let mut out = Vec::new();
    for (i, l) in lines.enumerate() {
        let f: Vec<&str> = l.split(',').collect();
        let num = |k: usize| -> anyhow::Result<f64> {
            f.get(k)
                .and_then(|x| x.trim().parse::<f64>().ok())
                .ok_or_else(|| {
                    anyhow!(
                        "{}:{}: not a number in column {}",
                        path.display(),
                        i + 2,
                        k + 1
                    )
                })
        };
        out.push((num(0)?, num(col)?));
    }
    Ok(out)
}

/// Relative L2 distance of `y` from the reference `r` over the reference's times inside both
/// ranges (`y` interpolated linearly): √(Σ (y − r)²) / √(Σ r²).
pub fn series_error(y: &[(f64, f64)], r: &[(f64, f64)]) -> Option<f64> {
    let (t0, t1) = (y.first()?.0, y.last()?.0);
    let at = |t: f64| -> f64 {
        let k = y.partition_point(|p| p.0 < t);
        if k == 0 {
            return y[0].1;
        }
        if k >= y.len() {
            return y[y.len() - 1].1;
        }
        let (a, b) = (y[k - 1], y[k]);
        if b.0 == a.0 {
            b.1
        } else {
            a.1 + (b.1 - a.1) * (t - a.0) / (b.0 - a.0)
        }
    };
    let (mut num, mut den, mut n) = (0.0, 0.0, 0);
    for &(t, v) in r.iter().filter(|p| p.0 >= t0 - 1e-12 && p.0 <= t1 + 1e-12) {
        num += (at(t) - v).powi(2);
        den += v * v;
        n += 1;
    }
    (n > 0 && den > 0.0).then(|| (num / den).sqrt())
}

/// Runs (or reuses) every variant and compares them (see [`StudyOptions`]). Every variant
/// runs with `coupling.allow_beyond_limits = true` unless the sweep varies it: a study is how
/// the limits are measured.
pub async fn run_study(
    scene: &Scene,
    vars: &[Variation],
    opts: &StudyOptions,
    out_dir: &Path,
) -> anyhow::Result<(String, Vec<Outcome>)> {
    let mut variants = variants(&scene.text, vars)?;
    if !vars
        .iter()
        .flat_map(Variation::keys)
        .any(|k| k == "coupling.allow_beyond_limits")
    {
        for v in &mut variants {
            let mut t: toml::Table = toml::from_str(&v.text)?;
            set_path(
                &mut t,
                "coupling.allow_beyond_limits",
                toml::Value::Boolean(true),
            )?;
            v.text = toml::to_string(&t)?;
        }
    }
    // one study at a time in a folder (each of its runs also locks its own)
    let _lock = crate::outdir::lock(out_dir, &format!("study of scene `{}`", scene.name))?;
    validate_variants(scene, &variants, opts.jobs.max(1), out_dir).await?;
    let mut signals = crate::interrupt::Watch::new();
    let bar = indicatif::ProgressBar::new(variants.len() as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{elapsed_precise} [{bar:30}] run {pos}/{len} {msg}",
        )
        .expect("valid template")
        .progress_chars("=> "),
    );
    // run what is missing (or was interrupted), `jobs` at a time
    let jobs = opts.jobs.max(1);
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mut pending = variants
        .iter()
        .filter(|v| !run_is_done(&out_dir.join(&v.name)))
        .cloned()
        .collect::<std::collections::VecDeque<_>>();
    bar.inc((variants.len() - pending.len()) as u64);
    let mut running = tokio::task::JoinSet::new();
    // the running runs' progress notes (label → note), shown on the study's bar
    let mut notes: Vec<(String, crate::run::ProgressNote)> = Vec::new();
    let mut last_note = std::time::Instant::now();
    let mut interrupted = None;
    while !pending.is_empty() || !running.is_empty() {
        if let Some(sig) = signals.poll() {
            // the runs under way stop too (each watches the signals); start no more
            pending.clear();
            interrupted = Some(crate::interrupt::Interrupted { signal: sig });
        }
        while running.len() < jobs {
            // the cores shared by the runs that will run together (the last ones get more)
            let together = jobs.min(running.len() + pending.len());
            let node_threads = (jobs > 1).then(|| (cores / together.max(1)).max(1));
            let Some(v) = pending.pop_front() else { break };
            let dir = out_dir.join(&v.name);
            let label = v.label();
            let note = crate::run::ProgressNote::default();
            notes.push((label.clone(), note.clone()));
            let path = variant_scene_path(scene, out_dir, &v);
            running.spawn(async move {
                // validated above: every variant parses
                let s = Scene::parse(&path, v.text.clone())?;
                std::fs::write(&path, &v.text)
                    .with_context(|| format!("writing {}", path.display()))?;
                // a run that was interrupted or died half-way continues from its newest
                // checkpoint when the scene writes them (the same variant's, checked), else
                // it starts again
                let resume = crate::checkpoint::latest(&dir).ok().filter(|(d, st)| {
                    let belongs = crate::checkpoint::check_belongs(d, st, &s.name, &s.text);
                    if belongs.is_err() {
                        tracing::warn!(
                            "{label}: its checkpoint after window {} was written from other settings of the scene: the run starts again",
                            st.window
                        );
                    }
                    belongs.is_ok()
                });
                if let Some((_, st)) = &resume {
                    tracing::info!("{label}: resuming after window {}", st.window);
                }
                let opts = RunOptions {
                    out_dir: Some(dir.clone()),
                    progress: false,
                    progress_note: Some(note),
                    overwrite: resume.is_none(),
                    resume,
                    node_threads,
                    ..Default::default()
                };
                let r = run_scene(&s, &opts).await;
                let _ = std::fs::remove_file(&path);
                if let Err(e) = &r {
                    tracing::info!("{label}: {e:#}");
                }
                anyhow::Ok((
                    label,
                    r.err()
                        .and_then(|e| e.downcast_ref::<crate::interrupt::Interrupted>().copied()),
                ))
            });
        }
        tokio::select! {
            done = running.join_next(), if !running.is_empty() => {
                if let Some(done) = done {
                    let (label, stop) = done.map_err(|e| anyhow!("a study run panicked: {e}"))??;
                    notes.retain(|(l, _)| *l != label);
                    if let Some(i) = stop {
                        pending.clear();
                        interrupted = Some(i);
                    }
                    bar.inc(1);
                }
            }
            _ = tokio::time::sleep(std::time::Duration::from_millis(200)) => {}
        }
        bar.set_message(running_notes(&notes));
        // without a terminal (a log file, nohup) the bar is not drawn: say where the study
        // stands every few minutes instead
        if bar.is_hidden() && last_note.elapsed() >= PROGRESS_LOG_EVERY && !notes.is_empty() {
            tracing::info!(
                "study: {} of {} runs done; {}",
                bar.position(),
                variants.len(),
                running_notes(&notes)
            );
            last_note = std::time::Instant::now();
        }
    }
    if let Some(i) = interrupted {
        bar.finish_and_clear();
        return Err(anyhow::Error::new(i).context(format!(
            "the study in {} stopped; `cosim study` with the same arguments continues it",
            out_dir.display()
        )));
    }
    let mut outcomes = Vec::new();
    let mut summaries = Vec::new();
    for v in &variants {
        let summary_path = out_dir.join(&v.name).join("summary.json");
        let s: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&summary_path).unwrap_or_default())
                .unwrap_or(serde_json::json!({ "status": "failed" }));
        summaries.push(s.clone());
        outcomes.push(Outcome {
            variant: v.clone(),
            status: s["status"].as_str().unwrap_or("failed").to_string(),
            error_message: s["error"].as_str().map(String::from),
            wall_s: number(&s, &["timing", "total_wall_s"]),
            dem_s: number(&s, &["timing", "dem_compute_s"]),
            fem_s: number(&s, &["timing", "fem_compute_s"]),
            overhead_s: number(&s, &["timing", "coupling_overhead_s"]),
            metric: None,
            error: None,
        });
    }
    bar.finish_and_clear();
    let (metric, reference) = (opts.metric.as_deref(), opts.reference);
    // default metric: the first probe's vertical displacement, else the DEM's kinetic energy
    let metric = match metric {
        Some(m) => m.to_string(),
        None => summaries
            .iter()
            .filter(|s| s["status"] == "completed")
            .flat_map(|s| {
                s["results"]
                    .as_object()
                    .map(|r| r.keys().cloned().collect::<Vec<_>>())
                    .unwrap_or_default()
            })
            .find(|k| k.starts_with("fem.probe.") && k.ends_with(".uz"))
            .unwrap_or_else(|| "dem.kinetic_energy".into()),
    };
    for (o, s) in outcomes.iter_mut().zip(&summaries) {
        o.metric = s["results"][metric.as_str()].as_f64();
    }
    let metric = match &opts.series {
        Some((file, column)) => format!("{file}:{column}"),
        None => metric,
    };
    let metric = metric.as_str();
    let finest = |o: &Outcome| {
        let get = |k: &str| {
            o.variant
                .settings
                .iter()
                .find(|(key, _)| key == k)
                .and_then(|(_, v)| v.as_float().or(v.as_integer().map(|i| i as f64)))
        };
        (
            get("coupling.window").unwrap_or(scene.window),
            get("dem.time_step").unwrap_or(f64::INFINITY),
        )
    };
    // the reference: as given, else the finest completed run; with none completed (every run
    // diverged) the table and the stability map are still written, without errors
    let reference = reference.or_else(|| {
        (0..outcomes.len())
            .filter(|&i| outcomes[i].status == "completed")
            .min_by(|&a, &b| {
                finest(&outcomes[a])
                    .partial_cmp(&finest(&outcomes[b]))
                    .unwrap_or(std::cmp::Ordering::Equal)
            })
    });
    if let Some(reference) = reference {
        set_errors(out_dir, opts, metric, reference, &mut outcomes)?;
    } else {
        tracing::warn!("no run of the study completed: no errors to compare, only stability");
    }
    let threshold = opts.inaccurate_above.unwrap_or(1.0);
    for o in &mut outcomes {
        if o.status == "completed" && o.error.is_some_and(|e| e > threshold) {
            o.status = "inaccurate".into();
        }
    }
    write_csv(
        &out_dir.join("study.csv"),
        vars,
        metric,
        &outcomes,
        reference,
    )?;
    std::fs::write(
        out_dir.join("error_vs_wall.svg"),
        pareto_svg(&outcomes, metric),
    )?;
    std::fs::write(
        out_dir.join("stability.svg"),
        stability_svg(&outcomes, vars),
    )?;
    if let Err(e) = crate::plot::study_pngs(out_dir, &outcomes, vars, metric) {
        tracing::warn!("PNG plots not written ({e:#}); the SVG plots are");
    }
    let ensembles_csv = out_dir.join("ensembles.csv");
    let _ = std::fs::remove_file(&ensembles_csv); // an earlier study's, over other settings
    write_ensembles(&ensembles_csv, metric, &ensembles(&outcomes))?;
    Ok((metric.to_string(), outcomes))
}

/// The relative error of every completed run against run `reference`: of the time series
/// `opts.series`, else of the result `metric`.
fn set_errors(
    out_dir: &Path,
    opts: &StudyOptions,
    metric: &str,
    reference: usize,
    outcomes: &mut [Outcome],
) -> anyhow::Result<()> {
    if let Some((file, column)) = &opts.series {
        let name = &outcomes
            .get(reference)
            .ok_or_else(|| {
                anyhow!(
                    "--reference {reference}: the study has {} runs",
                    outcomes.len()
                )
            })?
            .variant
            .name;
        let r = read_series(&out_dir.join(name).join(file), column)?;
        for (i, o) in outcomes.iter_mut().enumerate() {
            if o.status == "completed" {
                let y = read_series(&out_dir.join(&o.variant.name).join(file), column)?;
                o.error = if i == reference {
                    Some(0.0)
                } else {
                    series_error(&y, &r)
                };
                o.metric = y.last().map(|p| p.1);
            }
        }
    } else {
        let ref_value = outcomes
            .get(reference)
            .and_then(|o| o.metric)
            .ok_or_else(|| anyhow!("the reference run has no result `{metric}`"))?;
        for o in outcomes.iter_mut() {
            o.error = o
                .metric
                .filter(|_| o.status == "completed")
                .map(|m| (m - ref_value).abs() / ref_value.abs().max(f64::MIN_POSITIVE));
        }
    }
    Ok(())
}

fn write_csv(
    path: &Path,
    vars: &[Variation],
    metric: &str,
    outcomes: &[Outcome],
    reference: Option<usize>,
) -> anyhow::Result<()> {
    let mut s = String::from("run");
    for k in vars.iter().flat_map(Variation::keys) {
        write!(s, ",{k}")?;
    }
    writeln!(s, ",status,wall_s,dem_compute_s,fem_compute_s,coupling_overhead_s,{metric},relative_error,reference")?;
    for (i, o) in outcomes.iter().enumerate() {
        write!(s, "{}", o.variant.name)?;
        for (_, v) in &o.variant.settings {
            write!(s, ",{}", value_text(v).replace(',', ";"))?;
        }
        let opt = |x: Option<f64>| x.map(|x| format!("{x:e}")).unwrap_or_default();
        writeln!(
            s,
            ",{},{:.4},{:.4},{:.4},{:.4},{},{},{}",
            o.status,
            o.wall_s,
            o.dem_s,
            o.fem_s,
            o.overhead_s,
            opt(o.metric),
            opt(o.error),
            Some(i) == reference
        )?;
    }
    std::fs::write(path, s).with_context(|| format!("writing {}", path.display()))
}

const COLOURS: [&str; 6] = [
    "#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b",
];

pub(crate) fn schedule_of(o: &Outcome) -> String {
    o.variant
        .settings
        .iter()
        .find(|(k, _)| k == "coupling.schedule")
        .map(|(_, v)| value_text(v))
        .unwrap_or_else(|| "scene".into())
}

/// Error vs wall time, log–log, one colour per schedule (the Pareto front of the trade).
fn pareto_svg(outcomes: &[Outcome], metric: &str) -> String {
    let pts: Vec<(f64, f64, String)> = outcomes
        .iter()
        .filter_map(|o| o.error.map(|e| (o.wall_s, e.max(1e-16), schedule_of(o))))
        .collect();
    let (w, h, m) = (640.0, 440.0, 70.0);
    let lx = |v: f64| v.max(1e-300).log10();
    let (x0, x1) = pts
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
            (a.min(lx(p.0)), b.max(lx(p.0)))
        });
    let (y0, y1) = pts
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
            (a.min(lx(p.1)), b.max(lx(p.1)))
        });
    let (x0, x1) = if x0.is_finite() {
        (x0.floor(), x1.ceil().max(x0.floor() + 1.0))
    } else {
        (0.0, 1.0)
    };
    let (y0, y1) = if y0.is_finite() {
        (y0.floor(), y1.ceil().max(y0.floor() + 1.0))
    } else {
        (-6.0, 0.0)
    };
    let sx = |v: f64| m + (lx(v) - x0) / (x1 - x0) * (w - 2.0 * m);
    let sy = |v: f64| h - m - (lx(v) - y0) / (y1 - y0) * (h - 2.0 * m);
    let mut s = format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" font-family="sans-serif" font-size="12"><rect width="100%" height="100%" fill="white"/>"#
    );
    let _ = write!(
        s,
        r#"<rect x="{m}" y="{m}" width="{}" height="{}" fill="none" stroke="black"/>"#,
        w - 2.0 * m,
        h - 2.0 * m
    );
    for d in (x0 as i32)..=(x1 as i32) {
        let x = m + (d as f64 - x0) / (x1 - x0) * (w - 2.0 * m);
        let _ = write!(
            s,
            r#"<text x="{x}" y="{}" text-anchor="middle">1e{d}</text>"#,
            h - m + 16.0
        );
    }
    for d in (y0 as i32)..=(y1 as i32) {
        let y = h - m - (d as f64 - y0) / (y1 - y0) * (h - 2.0 * m);
        let _ = write!(
            s,
            r#"<text x="{}" y="{}" text-anchor="end">1e{d}</text>"#,
            m - 6.0,
            y + 4.0
        );
    }
    let _ = write!(
        s,
        r#"<text x="{}" y="{}" text-anchor="middle">wall time (s)</text>"#,
        w / 2.0,
        h - 20.0
    );
    let _ = write!(
        s,
        r#"<text x="18" y="{}" transform="rotate(-90 18 {})" text-anchor="middle">relative error of {metric}</text>"#,
        h / 2.0,
        h / 2.0
    );
    let mut schedules: Vec<String> = pts.iter().map(|p| p.2.clone()).collect();
    schedules.sort();
    schedules.dedup();
    for (i, sch) in schedules.iter().enumerate() {
        let c = COLOURS[i % COLOURS.len()];
        for p in pts.iter().filter(|p| &p.2 == sch) {
            let _ = write!(
                s,
                r#"<circle cx="{:.1}" cy="{:.1}" r="5" fill="{c}"/>"#,
                sx(p.0),
                sy(p.1)
            );
        }
        let _ = write!(
            s,
            r#"<circle cx="{}" cy="{}" r="5" fill="{c}"/><text x="{}" y="{}">{sch}</text>"#,
            w - m - 110.0,
            m + 16.0 + 18.0 * i as f64,
            w - m - 98.0,
            m + 20.0 + 18.0 * i as f64
        );
    }
    s.push_str("</svg>\n");
    s
}

/// Stability map: one row per run, green completed, red unstable/failed, grey refused.
fn stability_svg(outcomes: &[Outcome], vars: &[Variation]) -> String {
    let row = 22.0;
    let h = 40.0 + row * outcomes.len() as f64;
    let mut s = format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="760" height="{h}" font-family="sans-serif" font-size="12"><rect width="100%" height="100%" fill="white"/>"#
    );
    let header: Vec<&str> = vars.iter().flat_map(Variation::keys).collect();
    let _ = write!(
        s,
        r#"<text x="10" y="20" font-weight="bold">{}  →  status</text>"#,
        header.join(", ")
    );
    for (i, o) in outcomes.iter().enumerate() {
        let y = 30.0 + row * i as f64;
        let c = match o.status.as_str() {
            "completed" => "#2ca02c",
            "inaccurate" => "#ff7f0e",
            "refused" => "#999999",
            _ => "#d62728",
        };
        let label: Vec<String> = o
            .variant
            .settings
            .iter()
            .map(|(_, v)| value_text(v))
            .collect();
        let _ = write!(
            s,
            r#"<rect x="10" y="{y}" width="16" height="16" fill="{c}"/><text x="34" y="{}">{}: {}</text>"#,
            y + 13.0,
            label.join(", "),
            o.status
        );
    }
    s.push_str("</svg>\n");
    s
}

/// Default folder of a study.
pub fn default_out(scene: &Scene) -> PathBuf {
    PathBuf::from("out").join(format!("{}-study", scene.name))
}

/// Columns for a terminal table.
pub fn table(outcomes: &[Outcome]) -> BTreeMap<String, String> {
    outcomes
        .iter()
        .map(|o| {
            (
                o.variant.name.clone(),
                format!(
                    "{:<50} {:>10} {:>9.2} s  error {}",
                    o.variant.label(),
                    o.status,
                    o.wall_s,
                    o.error
                        .map(|e| format!("{e:.3e}"))
                        .unwrap_or_else(|| "-".into())
                ),
            )
        })
        .collect()
}

/// The runs of a study that differ only in a seed (`--vary dem.particles.0.seed=1,2,3`): an
/// ensemble of random samples of one case (Wellmann Table 5.2), summarised by mean and
/// standard deviation.
#[derive(Debug, Clone, PartialEq)]
pub struct Ensemble {
    /// The case: every varied setting but the seeds (`key=value`).
    pub case: Vec<(String, String)>,
    /// Its runs, and how many of them completed with a value of the metric.
    pub runs: usize,
    pub values: Vec<f64>,
    /// Mean wall time of the completed runs (s).
    pub wall_mean_s: f64,
}

impl Ensemble {
    pub fn mean(&self) -> Option<f64> {
        (!self.values.is_empty())
            .then(|| self.values.iter().sum::<f64>() / self.values.len() as f64)
    }

    /// Sample standard deviation (n − 1), with at least two values.
    pub fn std_dev(&self) -> Option<f64> {
        let m = self.mean()?;
        let n = self.values.len();
        (n >= 2).then(|| {
            (self.values.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt()
        })
    }

    /// `case: mean ± s.d. (n of runs)`.
    pub fn line(&self, metric: &str) -> String {
        let case = if self.case.is_empty() {
            "all runs".to_string()
        } else {
            self.case
                .iter()
                .map(|(k, v)| format!("{k}={v}"))
                .collect::<Vec<_>>()
                .join(" ")
        };
        let value = match (self.mean(), self.std_dev()) {
            (Some(m), Some(sd)) => format!("{m:.6e} ± {sd:.2e}"),
            (Some(m), None) => format!("{m:.6e}"),
            _ => "-".into(),
        };
        format!(
            "{case}: {metric} {value} ({} of {} runs)",
            self.values.len(),
            self.runs
        )
    }
}

/// A setting that picks a random sample: its last dotted part is `seed`.
fn is_seed(key: &str) -> bool {
    key.rsplit('.').next() == Some("seed")
}

/// The study's ensembles: its runs grouped by every varied setting except the seeds, in the
/// order of their first run; empty when no seed is varied.
pub fn ensembles(outcomes: &[Outcome]) -> Vec<Ensemble> {
    if !outcomes
        .iter()
        .any(|o| o.variant.settings.iter().any(|(k, _)| is_seed(k)))
    {
        return Vec::new();
    }
    let mut out: Vec<Ensemble> = Vec::new();
    for o in outcomes {
        let case: Vec<(String, String)> = o
            .variant
            .settings
            .iter()
            .filter(|(k, _)| !is_seed(k))
            .map(|(k, v)| (k.clone(), value_text(v)))
            .collect();
        let i = match out.iter().position(|e| e.case == case) {
            Some(i) => i,
            None => {
                out.push(Ensemble {
                    case,
                    runs: 0,
                    values: Vec::new(),
                    wall_mean_s: 0.0,
                });
                out.len() - 1
            }
        };
        let e = &mut out[i];
        e.runs += 1;
        // a completed run (`inaccurate` is one too: its error is against another seed)
        let done = matches!(o.status.as_str(), "completed" | "inaccurate");
        if let Some(m) = o.metric.filter(|m| done && m.is_finite()) {
            let n = e.values.len() as f64;
            e.wall_mean_s = (e.wall_mean_s * n + o.wall_s) / (n + 1.0);
            e.values.push(m);
        }
    }
    // a seed linked to another setting gives one run per case: no ensemble
    if out.iter().all(|e| e.runs < 2) {
        out.clear();
    }
    out
}

/// `ensembles.csv`: one row per case, its runs, and the metric's mean, standard deviation,
/// minimum and maximum over the completed ones.
fn write_ensembles(path: &Path, metric: &str, ensembles: &[Ensemble]) -> anyhow::Result<()> {
    let Some(first) = ensembles.first() else {
        return Ok(());
    };
    let mut s = String::new();
    for (k, _) in &first.case {
        write!(s, "{k},")?;
    }
    writeln!(
        s,
        "runs,completed,{metric}_mean,{metric}_std_dev,{metric}_min,{metric}_max,wall_mean_s"
    )?;
    let opt = |x: Option<f64>| x.map(|x| format!("{x:e}")).unwrap_or_default();
    for e in ensembles {
        for (_, v) in &e.case {
            write!(s, "{},", v.replace(',', ";"))?;
        }
        let min = e.values.iter().copied().reduce(f64::min);
        let max = e.values.iter().copied().reduce(f64::max);
        writeln!(
            s,
            "{},{},{},{},{},{},{}",
            e.runs,
            e.values.len(),
            opt(e.mean()),
            opt(e.std_dev()),
            opt(min),
            opt(max),
            if e.values.is_empty() {
                String::new()
            } else {
                format!("{:.4}", e.wall_mean_s)
            }
        )?;
    }
    std::fs::write(path, s).with_context(|| format!("writing {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn runs_that_differ_only_in_a_seed_form_an_ensemble_with_mean_and_spread() {
        let vars = [
            parse_variation("dem.periodic.size+dem.particles.0.count=0.01:100,0.02:800").unwrap(),
            parse_variation("dem.particles.0.seed=1,2,3").unwrap(),
        ];
        let vs = variants("[dem]\n[[dem.particles]]\nseed = 0\n", &vars).unwrap();
        assert_eq!(vs.len(), 6);
        let outcome = |i: usize, v: &Variant| Outcome {
            variant: v.clone(),
            status: ["completed", "inaccurate", "failed"][i % 3].into(),
            error_message: None,
            wall_s: 10.0 * (i + 1) as f64,
            dem_s: 0.0,
            fem_s: 0.0,
            overhead_s: 0.0,
            metric: Some(2.0 + i as f64),
            error: None,
        };
        let outcomes_of = |vs: &[Variant]| -> Vec<Outcome> {
            vs.iter().enumerate().map(|(i, v)| outcome(i, v)).collect()
        };
        let outcomes = outcomes_of(&vs);
        let e = ensembles(&outcomes);
        assert_eq!(e.len(), 2);
        let case = |size: &str, count: &str| {
            vec![
                ("dem.periodic.size".to_string(), size.to_string()),
                ("dem.particles.0.count".to_string(), count.to_string()),
            ]
        };
        assert_eq!(e[0].case, case("0.01", "100"));
        assert_eq!(e[1].case, case("0.02", "800"));
        // seeds 1, 2 of each case counted (seed 3 failed)
        assert_eq!((e[0].runs, e[0].values.clone()), (3, vec![2.0, 3.0]));
        assert_eq!(e[1].values, vec![5.0, 6.0]);
        assert_eq!(e[0].mean(), Some(2.5));
        assert!((e[0].std_dev().unwrap() - 0.5f64.sqrt()).abs() < 1e-15);
        assert_eq!(e[0].wall_mean_s, 15.0);
        assert_eq!(
            e[1].line("m"),
            "dem.periodic.size=0.02 dem.particles.0.count=800: m 5.500000e0 ± 7.07e-1 (2 of 3 runs)"
        );
        // one value: no spread; no seed varied: no ensembles
        let one = Ensemble {
            values: vec![1.0],
            ..e[0].clone()
        };
        assert_eq!(one.std_dev(), None);
        let plain = variants(
            "[dem]\ntime_step = 1\n",
            &[parse_variation("dem.time_step=1,2").unwrap()],
        )
        .unwrap();
        assert!(ensembles(&outcomes_of(&plain)).is_empty());
        // a seed linked to another setting: one run per case, no ensemble
        let linked = variants(
            "[dem]\ntime_step = 1\nseed = 0\n",
            &[parse_variation("dem.time_step+dem.seed=1:1,2:2").unwrap()],
        )
        .unwrap();
        assert!(ensembles(&outcomes_of(&linked)).is_empty());
    }

    #[test]
    fn the_study_bar_names_each_running_run_with_its_note() {
        let a = crate::run::ProgressNote::default();
        let b = crate::run::ProgressNote::default();
        let notes = vec![
            ("seed=1".to_string(), a.clone()),
            ("seed=2".to_string(), b.clone()),
        ];
        assert_eq!(running_notes(&notes), "seed=1 | seed=2");
        *a.lock().unwrap() = "stage 4/4 `shear`: 36.0 % of its strain".into();
        assert_eq!(
            running_notes(&notes),
            "seed=1: stage 4/4 `shear`: 36.0 % of its strain | seed=2"
        );
    }

    #[test]
    fn errors_in_a_variant_name_the_users_scene_and_settings_not_the_temporary_file() {
        let tmp = Path::new("scenes/.study-m-run001.toml");
        let user = Path::new("scenes/m.toml");
        let label = "dem.time_step=3e-5";
        // the coordinator's form (file:line:column) and the nodes' (file: line n, column m)
        assert_eq!(
            in_user_terms(
                "scenes/.study-m-run001.toml:7:3: coupling.window: bad",
                tmp,
                user,
                label
            ),
            "scenes/m.toml with --vary dem.time_step=3e-5: coupling.window: bad"
        );
        assert_eq!(
            in_user_terms(
                "node `dem` reported a Scene error: scenes/.study-m-run001.toml: line 8, column 1: unknown field `x`",
                tmp,
                user,
                label
            ),
            "node `dem` reported a Scene error: scenes/m.toml with --vary dem.time_step=3e-5: unknown field `x`"
        );
        assert_eq!(
            in_user_terms("no path here", tmp, user, label),
            "no path here"
        );
        assert_eq!(value_text(&toml::Value::Float(3e-5)), "3e-5");
        assert_eq!(value_text(&toml::Value::Float(0.5)), "0.5");
    }

    #[test]
    fn variations_multiply_and_set_dotted_keys() {
        let vars = vec![
            parse_variation("coupling.window=1e-4,5e-5").unwrap(),
            parse_variation("coupling.schedule=jit,predictive").unwrap(),
        ];
        assert_eq!(vars[1].values[0], toml::Value::String("jit".into()));
        let v = variants(
            "[scene]\nend_time = 1.0\n[coupling]\nwindow = 1.0\n[dem]\ntime_step = 1e-6\n",
            &vars,
        )
        .unwrap();
        assert_eq!(v.len(), 4);
        let t: toml::Table = toml::from_str(&v[3].text).unwrap();
        assert_eq!(t["coupling"]["window"].as_float(), Some(5e-5));
        assert_eq!(t["coupling"]["schedule"].as_str(), Some("predictive"));
        assert_eq!(t["dem"]["time_step"].as_float(), Some(1e-6));
    }

    #[test]
    fn linked_keys_vary_together_and_numbers_pick_list_entries() {
        let base = "[scene]\nend_time = 1.0\n[fem]\nx = 1\n[[fem.loads]]\nvalue = 100e3\n\
                    [[dem.walls]]\nkind = \"plane\"\n[[dem.walls]]\nkind = \"plane\"\n\
                    load = { force = -383.87 }\n";
        let vars = vec![
            parse_variation("fem.loads.0.value+dem.walls.1.load.force=25e3:-95.23, 400e3:-1538.4")
                .unwrap(),
            parse_variation("dem.time_step=1e-6,5e-7").unwrap(),
        ];
        assert_eq!(
            vars[0].keys().collect::<Vec<_>>(),
            ["fem.loads.0.value", "dem.walls.1.load.force"]
        );
        let v = variants(base, &vars).unwrap();
        // zipped, then multiplied by the other key: 2 × 2 runs, not 2 × 2 × 2
        assert_eq!(v.len(), 4);
        let t: toml::Table = toml::from_str(&v[2].text).unwrap();
        assert_eq!(t["fem"]["loads"][0]["value"].as_float(), Some(400e3));
        assert_eq!(
            t["dem"]["walls"][1]["load"]["force"].as_float(),
            Some(-1538.4)
        );
        assert_eq!(t["dem"]["walls"][0].get("load"), None);
        assert_eq!(t["dem"]["time_step"].as_float(), Some(1e-6));
        assert_eq!(
            v[2].label(),
            "fem.loads.0.value=400000.0 dem.walls.1.load.force=-1538.4 dem.time_step=1e-6"
        );
        // a whole entry can be replaced, an index past the end or a word in a list is named
        let mut t: toml::Table = toml::from_str(base).unwrap();
        set_path(
            &mut t,
            "fem.loads.0",
            toml::Value::Table(Default::default()),
        )
        .unwrap();
        assert!(t["fem"]["loads"][0].as_table().unwrap().is_empty());
        let e = set_path(&mut t, "dem.walls.2.kind", toml::Value::Integer(1)).unwrap_err();
        assert!(
            e.to_string()
                .contains("`dem.walls` has 2 entries (indices 0 to 1)"),
            "{e}"
        );
        let e = set_path(&mut t, "dem.walls.top.kind", toml::Value::Integer(1)).unwrap_err();
        assert!(e.to_string().contains("pick one by its index"), "{e}");
        let e = set_path(&mut t, "fem.x.y", toml::Value::Integer(1)).unwrap_err();
        assert!(e.to_string().contains("`fem.x` is not a table"), "{e}");
        // a list that is not in the scene, a key varied twice
        let e = set_path(&mut t, "fem.sections.0.x", toml::Value::Integer(1)).unwrap_err();
        assert!(
            e.to_string().contains("`fem.sections` is not in the scene"),
            "{e}"
        );
        let twice = [
            parse_variation("a.b+c.d=1:2").unwrap(),
            parse_variation("c.d=3").unwrap(),
        ];
        let e = variants(base, &twice).unwrap_err().to_string();
        assert!(e.contains("`c.d` is varied twice"), "{e}");
        // a tuple of the wrong length is named
        let e = parse_variation("a.b+c.d=1:2,3").unwrap_err().to_string();
        assert!(
            e.contains("`3` gives 1 value(s) for the 2 keys a.b+c.d"),
            "{e}"
        );
    }

    #[test]
    fn a_malformed_variation_is_named() {
        assert!(parse_variation("coupling.window")
            .unwrap_err()
            .to_string()
            .contains("key=value"));
        assert!(parse_variation("coupling..window=1").is_err());
    }
}
