//! `cosim`: the user's command line.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use clap::{Parser, Subcommand};
use coordinator::run::{run_scene, schedule_name, RunOptions};
use coordinator::scene::Scene;
use coordinator::units::format_seconds;

#[derive(Parser)]
#[command(
    name = "cosim",
    version,
    about = "DEM–FEM co-simulation over zenoh: run, check and study scenes"
)]
struct Cli {
    /// Log level (error, warn, info, debug, trace) or a tracing filter.
    #[arg(
        long,
        global = true,
        default_value = "info,zenoh=warn",
        env = "COSIM_LOG"
    )]
    log: String,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run a scene: start the nodes it needs, couple them, write out/<scene>/summary.json.
    Run {
        scene: PathBuf,
        /// Output folder (default: the scene's `output.dir`, else out/<scene name>).
        #[arg(long)]
        out: Option<PathBuf>,
        /// zenoh configuration of the coordinator (e.g. deploy/coordinator.json5): client of
        /// a router; the nodes are then started on their machines (see deploy/README.md).
        #[arg(long)]
        config: Option<PathBuf>,
        /// Run id (default: scene name and a random suffix).
        #[arg(long)]
        run_id: Option<String>,
        /// Local runs: the coordinator's endpoint (default tcp/127.0.0.1:<free port>).
        #[arg(long)]
        listen: Option<String>,
        /// A node (by id: `dem`, `fem`, or a structure's id) that is started elsewhere; the
        /// coordinator waits for it (repeatable).
        #[arg(long)]
        external: Vec<String>,
        /// No progress bar.
        #[arg(long)]
        no_progress: bool,
        /// Replace an earlier run in the output folder (its files are deleted first).
        #[arg(long)]
        overwrite: bool,
    },
    /// Plot columns of a CSV time series (e.g. out/sleeper/dem/dem_sensors.csv) against its
    /// first column as a PNG.
    Plot {
        csv: PathBuf,
        /// Columns to plot, comma-separated (default: all but the x column).
        #[arg(long, value_delimiter = ',')]
        columns: Vec<String>,
        /// The x column (default: the first).
        #[arg(long)]
        x: Option<String>,
        /// Factor applied to every y value (e.g. -1e3: a downward displacement in mm).
        #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
        scale: f64,
        /// y-axis label (default: the column names).
        #[arg(long)]
        ylabel: Option<String>,
        /// Title (default: the file name).
        #[arg(long)]
        title: Option<String>,
        /// Output PNG (default: the CSV's path with the extension .png).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Measure the speed–accuracy trade: run the scene for every combination of values,
    /// e.g. `--vary coupling.window=1e-4,5e-5 --vary coupling.schedule=jit,predictive`;
    /// writes study.csv and error_vs_wall / stability plots (PNG and SVG); a half-done sweep resumes.
    Study {
        scene: PathBuf,
        /// `key=value1,value2,…` (dotted scene key, a number picks an entry of a list such as
        /// `dem.walls.1.load.force`; repeatable: every combination runs). Keys that move
        /// together: `key1+key2=a1:b1,a2:b2` (e.g. a cell pressure and the platen force it
        /// needs).
        #[arg(long, required = true)]
        vary: Vec<String>,
        /// Result compared between runs (default: the first FEM probe's uz).
        #[arg(long)]
        metric: Option<String>,
        /// Compare a time series instead of one value: `file:column` in each run's folder,
        /// e.g. `fem/fem_probes.csv:probe.centre.uz` (relative L2 error over time).
        #[arg(long)]
        series: Option<String>,
        /// Index of the reference run (default: the finest completed run).
        #[arg(long)]
        reference: Option<usize>,
        /// Mark a completed run `inaccurate` when its error exceeds this (default 1.0 = 100 %).
        #[arg(long)]
        inaccurate_above: Option<f64>,
        /// Runs at the same time (default: one per two cores; each run is two processes, whose
        /// thread pools then share the cores: RAYON_NUM_THREADS = cores / runs at once, one
        /// core each for serial schedules, where a run's two nodes take turns).
        #[arg(long)]
        jobs: Option<usize>,
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Serve as the zenoh router of runs over several machines (a zenohd with this
    /// project's defaults): `cosim router --config deploy/router.json5`.
    Router {
        #[arg(long)]
        config: PathBuf,
    },
    /// Continue a run from its newest checkpoint (after a node or the coordinator died).
    Resume {
        /// The run's output folder (holds run.json, scene.toml and checkpoints/).
        out_dir: PathBuf,
        #[arg(long)]
        no_progress: bool,
    },
    /// Validate a scene without running it: the file, then each node's own table and limits.
    Check {
        scene: PathBuf,
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Fit a non-associated Mohr–Coulomb material (E, ν, φ, ψ, c; Wellmann §5.4) to the
    /// triaxial curves of periodic-cell runs (their folders or dem/periodic.csv files); writes
    /// the `[fem.materials]` table and plots of the fit over the curves.
    Fit {
        #[arg(required = true)]
        runs: Vec<PathBuf>,
        /// Material name of the table.
        #[arg(long, default_value = "sand")]
        name: String,
        /// Cohesion c (Pa) with one curve (several at different pressures fit it; this is
        /// then its floor). Default 15 Pa, the thesis's.
        #[arg(long, default_value_t = 15.0)]
        cohesion: f64,
        /// Axial-strain window of the dilation rate, `from,to` (default 0.10,0.15).
        #[arg(long, value_delimiter = ',', num_args = 2, default_values_t = [0.10, 0.15])]
        window: Vec<f64>,
        /// The stage to fit (default: the last that strains an axis).
        #[arg(long)]
        stage: Option<usize>,
        /// Continuum density (kg/m³); default Φ × the grains' density from the run's scene.
        #[arg(long)]
        density: Option<f64>,
        /// E (Pa) instead of the initial slope (needed when the rows are too far apart to
        /// show it).
        #[arg(long)]
        youngs_modulus: Option<f64>,
        /// ν instead of the initial slope.
        #[arg(long)]
        poisson_ratio: Option<f64>,
        /// Which slope is E: the initial tangent (up to a quarter of the peak deviator) or
        /// E50, the secant to half the peak deviator (both are in the table's comments).
        #[arg(long, value_enum, default_value_t)]
        modulus: coordinator::fit::Modulus,
        /// Output TOML (default: mohr_coulomb.toml in the first run's folder); the plots go
        /// beside it.
        #[arg(long)]
        out: Option<PathBuf>,
    },
}

fn report(scene: &Scene, s: &coordinator::run::Summary, out_dir: &std::path::Path) {
    println!(
        "{}: {} windows of {} ({}), {} simulated in {:.2} s wall (DEM {:.2} s, FEM {:.2} s, coupling {:.2} s = {:.1} %)",
        s.scene,
        s.windows_done,
        format_seconds(s.coupling_window_s),
        schedule_name(scene.schedule),
        format_seconds(s.simulated_time_s),
        s.timing.total_wall_s,
        s.timing.dem_compute_s,
        s.timing.fem_compute_s,
        s.timing.coupling_overhead_s,
        100.0 * s.timing.coupling_overhead_fraction
    );
    for (k, v) in &s.results {
        println!("  {k} = {v:.6e}");
    }
    println!("summary: {}", out_dir.join("summary.json").display());
    match coordinator::plot::run_plots(out_dir) {
        Ok(files) if !files.is_empty() => {
            println!(
                "plots: {} ({} PNG)",
                out_dir.join("plots").display(),
                files.len()
            )
        }
        Ok(_) => {}
        Err(e) => tracing::warn!("no plots: {e:#}"),
    }
    // the last line says where to look
    let pvd: Vec<String> = std::fs::read_dir(out_dir)
        .into_iter()
        .flatten()
        .flatten()
        .filter(|e| e.path().is_dir() && e.file_name() != "checkpoints")
        .filter_map(|e| std::fs::read_dir(e.path()).ok())
        .flat_map(|d| d.flatten().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "pvd"))
        .map(|p| p.display().to_string())
        .collect::<std::collections::BTreeSet<_>>()
        .into_iter()
        .collect();
    let mut look = vec![format!("{}/", out_dir.join("plots").display())];
    if !pvd.is_empty() {
        look.push(format!("in ParaView: {}", pvd.join(" ")));
    }
    println!("look at: {}", look.join("; "));
}

fn main() -> ExitCode {
    proto::node::install_panic_hook("cosim");
    proto::alloc::keep_message_buffers();
    let cli = Cli::parse();
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_new(&cli.log).unwrap_or_else(|_| "info".into()),
        )
        .with_writer(std::io::stderr)
        .with_target(false)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .init();
    let rt = match tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
    {
        Ok(rt) => rt,
        Err(e) => {
            eprintln!("error: cannot start the async runtime: {e}");
            return ExitCode::FAILURE;
        }
    };
    let result = rt.block_on(async {
        match cli.command {
            Command::Run {
                scene,
                out,
                config,
                run_id,
                listen,
                external,
                no_progress,
                overwrite,
            } => {
                let scene = Scene::load(&scene)?;
                coordinator::interrupt::install()?;
                let opts = RunOptions {
                    overwrite,
                    out_dir: out,
                    zenoh_config: config,
                    run_id,
                    listen,
                    external,
                    progress: !no_progress,
                    ..Default::default()
                };
                let s = run_scene(&scene, &opts).await?;
                report(
                    &scene,
                    &s,
                    &opts.out_dir.clone().unwrap_or(scene.out_dir.clone()),
                );
                anyhow::Ok(())
            }
            Command::Study {
                scene,
                vary,
                metric,
                series,
                reference,
                jobs,
                inaccurate_above,
                out,
            } => {
                let scene = Scene::load(&scene)?;
                let vars = vary
                    .iter()
                    .map(|v| coordinator::study::parse_variation(v))
                    .collect::<anyhow::Result<Vec<_>>>()?;
                let out = out.unwrap_or_else(|| coordinator::study::default_out(&scene));
                coordinator::interrupt::install()?;
                let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
                let study = coordinator::study::StudyOptions {
                    metric,
                    series: series
                        .as_deref()
                        .map(coordinator::study::parse_series)
                        .transpose()?,
                    reference,
                    jobs: jobs.unwrap_or((cores / 2).max(1)),
                    inaccurate_above,
                };
                let (metric, outcomes) =
                    coordinator::study::run_study(&scene, &vars, &study, &out).await?;
                println!(
                    "{}: {} runs, error of {metric} against the finest run",
                    scene.name,
                    outcomes.len()
                );
                for (name, line) in coordinator::study::table(&outcomes) {
                    println!("  {name} {line}");
                }
                let ensembles = coordinator::study::ensembles(&outcomes);
                if !ensembles.is_empty() {
                    println!("ensembles (runs that differ only in a seed):");
                    for e in &ensembles {
                        println!("  {}", e.line(&metric));
                    }
                    println!("ensembles: {}", out.join("ensembles.csv").display());
                }
                println!("study: {}", out.join("study.csv").display());
                Ok(())
            }
            Command::Router { config } => {
                let link = proto::LinkConfig {
                    zenoh_config: Some(config.clone()),
                    ..Default::default()
                };
                let session = link
                    .open()
                    .await
                    .with_context(|| format!("starting the router from {}", config.display()))?;
                eprintln!(
                    "router {} running from {} (Ctrl-C to stop)",
                    session.zid(),
                    config.display()
                );
                tokio::signal::ctrl_c().await?;
                session.close().await.map_err(|e| anyhow::anyhow!("{e}"))?;
                Ok(())
            }
            Command::Resume {
                out_dir,
                no_progress,
            } => {
                let record = coordinator::checkpoint::read_record(&out_dir)?;
                let text_path = out_dir.join("scene.toml");
                let text = std::fs::read_to_string(&text_path)
                    .with_context(|| format!("reading {}", text_path.display()))?;
                // the scene as it was (its own path resolves the files it names)
                let scene = Scene::parse(&record.scene_file, text)?;
                let (dir, state) = coordinator::checkpoint::latest(&out_dir)?;
                coordinator::checkpoint::check_belongs(&dir, &state, &scene.name, &scene.text)?;
                if let Some(done) = std::fs::read_to_string(out_dir.join("summary.json"))
                    .ok()
                    .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
                    .filter(|s| s["status"] == "completed")
                {
                    anyhow::bail!(
                        "{}: the run of scene `{}` completed; there is nothing to resume (run it again with `cosim run <scene> --out {} --overwrite`)",
                        out_dir.display(),
                        done["scene"].as_str().unwrap_or("?"),
                        out_dir.display()
                    );
                }
                coordinator::interrupt::install()?;
                eprintln!(
                    "resuming {} after window {} from {}",
                    scene.name,
                    state.window,
                    dir.display()
                );
                let opts = RunOptions {
                    out_dir: Some(out_dir.clone()),
                    zenoh_config: record.zenoh_config,
                    progress: !no_progress,
                    resume: Some((dir, state)),
                    ..Default::default()
                };
                let s = run_scene(&scene, &opts).await?;
                report(&scene, &s, &out_dir);
                Ok(())
            }
            Command::Plot {
                csv,
                columns,
                x,
                scale,
                ylabel,
                title,
                out,
            } => {
                let (xname, series) =
                    coordinator::plot::read_series(&csv, x.as_deref(), &columns, scale)?;
                let out = out.unwrap_or_else(|| csv.with_extension("png"));
                let names: Vec<&str> = series.iter().map(|(n, _)| n.as_str()).collect();
                let ylabel = ylabel.unwrap_or_else(|| names.join(", "));
                let title = title.unwrap_or_else(|| csv.display().to_string());
                let xlabel = if xname == "time" {
                    "time (s)".to_string()
                } else {
                    xname
                };
                coordinator::plot::series_png(&out, &title, &xlabel, &ylabel, &series)?;
                println!("wrote {}", out.display());
                Ok(())
            }
            Command::Fit {
                runs,
                name,
                cohesion,
                window,
                stage,
                density,
                youngs_modulus,
                poisson_ratio,
                modulus,
                out,
            } => {
                let curves = runs
                    .iter()
                    .map(|r| coordinator::fit::read_curve(r, stage))
                    .collect::<anyhow::Result<Vec<_>>>()?;
                let given = coordinator::fit::Given {
                    youngs_modulus,
                    poisson_ratio,
                    density,
                    modulus,
                };
                let f = coordinator::fit::fit(&curves, (window[0], window[1]), cohesion, given)?;
                let out = out.unwrap_or_else(|| {
                    let first = &runs[0];
                    let dir = if first.is_dir() {
                        first.clone()
                    } else {
                        first.parent().map(PathBuf::from).unwrap_or_default()
                    };
                    dir.join("mohr_coulomb.toml")
                });
                let toml = coordinator::fit::material_toml(&f, &name, &runs);
                // `--out fits/sand.toml`: the folder is made, as `--out` of run and study does
                if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
                    std::fs::create_dir_all(dir)
                        .with_context(|| format!("creating {}", dir.display()))?;
                }
                std::fs::write(&out, &toml)
                    .with_context(|| format!("writing {}", out.display()))?;
                print!("{toml}");
                println!("wrote {}", out.display());
                match coordinator::fit::plots(&f, &curves, &out) {
                    Ok(paths) => {
                        for p in paths {
                            println!("wrote {}", p.display());
                        }
                    }
                    Err(e) => eprintln!("no plots: {e:#}"),
                }
                Ok(())
            }
            Command::Check { scene, out } => {
                let scene = Scene::load(&scene)?;
                // the nodes' outputs of a check go to a scratch folder, removed afterwards
                // only if the check made it (an existing --out must be empty)
                let dir = out.unwrap_or_else(|| {
                    std::env::temp_dir().join(format!("cosim-check-{}", std::process::id()))
                });
                let made = !dir.exists();
                let opts = RunOptions {
                    check_only: true,
                    out_dir: Some(dir.clone()),
                    progress: false,
                    ..Default::default()
                };
                let s = run_scene(&scene, &opts).await;
                if made {
                    let _ = std::fs::remove_dir_all(&dir);
                }
                let s = s?;
                println!(
                    "{}: ok ({}, {} windows of {})",
                    scene.path.display(),
                    schedule_name(scene.schedule),
                    scene.windows,
                    format_seconds(scene.window)
                );
                if s.dem_substeps > 0 {
                    println!(
                        "  DEM substeps per coupling window n^D = {}",
                        s.dem_substeps
                    );
                }
                for c in &s.checks {
                    let tag = match c.level {
                        coordinator::limits::Level::Info => "ok",
                        coordinator::limits::Level::Warn => "warning",
                        coordinator::limits::Level::Refuse => "beyond (allowed)",
                    };
                    println!("  [{tag}] {c}");
                }
                for (node, n) in &s.nodes {
                    for (k, v) in &n.limits {
                        println!("  {node}.{k} = {v:.6e}");
                    }
                    for w in &n.warnings {
                        println!("  warning ({node}): {w}");
                    }
                }
                Ok(())
            }
        }
    });
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            if let Some(i) = e.downcast_ref::<coordinator::interrupt::Interrupted>() {
                eprintln!("{e:#}: the nodes were stopped, summary.json says `interrupted`");
                return ExitCode::from(i.exit_code());
            }
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
