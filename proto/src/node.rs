//! The node loop shared by every Rust node: a solver implements [`Solver`] and calls
//! [`serve`]; commands, status, errors, snapshots, window checkpoints and shutdown are handled
//! here.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::cli::NodeArgs;
use crate::messages::*;
use crate::participant::Participant;
use crate::ProtoError;

/// An error a node reports to the coordinator before it leaves.
#[derive(Debug, Clone)]
pub struct NodeError {
    pub code: ErrorCode,
    pub message: String,
    /// The coordinator said `stop` while the node waited: not an error to report back.
    pub stopped: bool,
    /// The node arrived in a run already under way: it leaves without a word on the run's
    /// status key (that belongs to the node already in the run).
    pub late: bool,
}

impl NodeError {
    pub fn new(code: ErrorCode, message: impl Into<String>) -> Self {
        NodeError {
            code,
            message: message.into(),
            stopped: false,
            late: false,
        }
    }
}

impl std::fmt::Display for NodeError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{:?}: {}", self.code, self.message)
    }
}

impl From<ProtoError> for NodeError {
    fn from(e: ProtoError) -> Self {
        let code = match &e {
            ProtoError::Timeout { .. } => ErrorCode::Timeout,
            ProtoError::Diverged { .. } => ErrorCode::Unstable,
            _ => ErrorCode::Protocol,
        };
        let stopped = matches!(e, ProtoError::Stopped { .. });
        let late = matches!(e, ProtoError::LateJoin { .. });
        NodeError {
            stopped,
            late,
            ..NodeError::new(code, e.to_string())
        }
    }
}

/// What a window cost.
#[derive(Debug, Clone, Default)]
pub struct WindowReport {
    /// Time spent waiting for the other solver's data (s).
    pub wait_s: f64,
    /// Simulation time at the end of the window.
    pub t_end: f64,
    /// Values the coordinator's monitor looks at (e.g. `kinetic_energy`).
    pub monitor: BTreeMap<String, f64>,
}

/// A solver as the coupling sees it.
#[allow(async_fn_in_trait)]
pub trait Solver {
    /// Reads the node's table of the scene, builds the model, opens the interfaces.
    /// Returns the physics limits (`time_step`, ...) and warnings for `ready`.
    async fn init(
        &mut self,
        p: &mut Participant,
        init: &Init,
    ) -> Result<(BTreeMap<String, f64>, Vec<String>), NodeError>;
    /// One coupling window (reads its input, computes, publishes its output).
    async fn advance(
        &mut self,
        p: &mut Participant,
        w: &AdvanceWindow,
    ) -> Result<WindowReport, NodeError>;
    /// Publishes the current interface output labelled `label`, without stepping (providers:
    /// their state; users: their forces of the last window, averaged where the interface says
    /// so).
    async fn publish(&mut self, p: &mut Participant, label: Label) -> Result<(), NodeError>;
    /// The full state, for checkpoint files (the coupling memory of the participant is added
    /// by the loop).
    fn snapshot(&self) -> Result<Vec<u8>, NodeError>;
    /// Puts the state of a snapshot back. The loop then cuts the node's CSV time series back
    /// to the restored time ([`Solver::time_series`]).
    fn restore(&mut self, bytes: &[u8]) -> Result<(), NodeError>;
    /// Keeps the state in memory as the start of a window an implicit scheme may repeat
    /// (`checkpoint` command). The default keeps a [`Solver::snapshot`]; a solver with a
    /// cheaper copy overrides this and [`Solver::rollback`] together.
    fn checkpoint(&mut self) -> Result<Vec<u8>, NodeError> {
        self.snapshot()
    }
    /// Puts back the state [`Solver::checkpoint`] kept (`rollback` command).
    fn rollback(&mut self, kept: &[u8]) -> Result<(), NodeError> {
        self.restore(kept)
    }
    /// The folder of the node's CSV time series and the simulation time they have reached
    /// (`None`: the node writes none).
    fn time_series(&self) -> Option<(&Path, f64)> {
        None
    }
    /// Final outputs; the scene's result quantities for `summary.json`.
    fn finish(&mut self) -> Result<BTreeMap<String, f64>, NodeError>;
}

/// After a restore to simulation time `t`: every CSV time series in `dir` (a `.csv` file
/// whose header starts with `time`) loses the rows after `t`, which the interrupted run wrote
/// after the checkpoint and the resumed run writes again. Rows at `t` stay (within 1e-8
/// relative: the files print 10 significant digits; windows are far longer), as does a file
/// that is not such a time series. Returns the files shortened.
pub fn truncate_time_series_after(dir: &Path, t: f64) -> std::io::Result<Vec<PathBuf>> {
    let mut shortened = Vec::new();
    let entries = match std::fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(shortened),
        Err(e) => return Err(e),
    };
    let limit = t + 1e-8 * t.abs();
    let mut paths: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "csv"))
        .collect();
    paths.sort();
    for path in paths {
        let text = std::fs::read_to_string(&path)?;
        let mut lines = text.split_inclusive('\n');
        let Some(header) = lines.next() else { continue };
        if header.split(',').next().map(str::trim) != Some("time") {
            continue;
        }
        let mut kept = String::with_capacity(text.len());
        kept.push_str(header);
        for line in lines {
            // a row cut short by the kill (no newline) or after t goes
            let time = line
                .split(',')
                .next()
                .and_then(|v| v.trim().parse::<f64>().ok());
            if !line.ends_with('\n') || time.is_none_or(|x| x > limit) {
                break;
            }
            kept.push_str(line);
        }
        if kept.len() < text.len() {
            write_atomically(&path, kept.as_bytes())?;
            shortened.push(path);
        }
    }
    Ok(shortened)
}

/// First bytes of a Rust node's snapshot file: the participant's coupling memory, then the
/// solver's own state.
const SNAPSHOT_MAGIC: &[u8] = b"cosim-node-state v2\n";

/// A node's snapshot file: [`SNAPSHOT_MAGIC`], the coupling memory's length (u64 LE), the
/// coupling memory, the solver's bytes.
pub fn pack_snapshot(coupling: &[u8], solver: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(SNAPSHOT_MAGIC.len() + 8 + coupling.len() + solver.len());
    out.extend_from_slice(SNAPSHOT_MAGIC);
    out.extend_from_slice(&(coupling.len() as u64).to_le_bytes());
    out.extend_from_slice(coupling);
    out.extend_from_slice(solver);
    out
}

/// The two parts of a [`pack_snapshot`] file, or an error naming what is wrong with it.
pub fn unpack_snapshot(bytes: &[u8]) -> Result<(&[u8], &[u8]), String> {
    let rest = bytes.strip_prefix(SNAPSHOT_MAGIC).ok_or_else(|| {
        "not a node snapshot of protocol version 2 (an older cosim wrote it, or it is not a snapshot)"
            .to_string()
    })?;
    if rest.len() < 8 {
        return Err("the snapshot is cut short".into());
    }
    let (len, rest) = rest.split_at(8);
    let len = u64::from_le_bytes(len.try_into().expect("8 bytes")) as usize;
    if rest.len() < len {
        return Err(format!(
            "the snapshot is cut short: its coupling part says {len} bytes, {} remain",
            rest.len()
        ));
    }
    Ok(rest.split_at(len))
}

/// Writes `bytes` to `path` atomically (temporary file, fsync, rename).
pub fn write_atomically(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    use std::io::Write;
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)?;
    }
    let tmp = path.with_extension("tmp");
    let mut f = std::fs::File::create(&tmp)?;
    f.write_all(bytes)?;
    f.sync_all()?;
    std::fs::rename(&tmp, path)
}

/// Joins the run and serves commands until `stop`. Errors are reported to the coordinator
/// (when it can still be reached) and returned.
pub async fn serve<S: Solver>(
    args: &NodeArgs,
    hello: Hello,
    mut solver: S,
) -> Result<(), NodeError> {
    let mut p = Participant::connect(&args.link()?, &args.run_id, &args.node, hello).await?;
    let mut window: Option<u64> = None;
    // the state at the start of the window an implicit scheme may repeat
    let mut kept: Option<Kept> = None;
    let mut compute_s = 0.0;
    let mut wait_s = 0.0;
    let result: Result<(), NodeError> = async {
        loop {
            let cmd = match p.next_command(None).await {
                Ok(c) => c,
                Err(e) => return Err(e.into()),
            };
            match cmd {
                CommandBody::Init(init) => {
                    let (limits, warnings) = solver.init(&mut p, &init).await?;
                    p.report(StatusBody::Ready { limits, warnings }).await?;
                }
                CommandBody::AdvanceWindow(w) => {
                    window = Some(w.window);
                    let t = Instant::now();
                    let r = solver.advance(&mut p, &w).await?;
                    let end = Instant::now();
                    let total = (end - t).as_secs_f64();
                    let compute = (total - r.wait_s).max(0.0);
                    // the bookkeeping after this window's data left (its partner computes
                    // meanwhile)
                    let after_output = p
                        .last_data_sent()
                        .filter(|&s| s >= t)
                        .map_or(0.0, |s| (end - s).as_secs_f64())
                        .min(compute);
                    compute_s += compute;
                    wait_s += r.wait_s;
                    p.report(StatusBody::WindowDone {
                        window: w.window,
                        t_end: r.t_end,
                        compute_s: compute,
                        wait_s: r.wait_s,
                        monitor: r.monitor,
                        after_output_s: after_output,
                    })
                    .await?;
                }
                CommandBody::Publish { label } => solver.publish(&mut p, label).await?,
                CommandBody::Checkpoint { window: k } => {
                    kept = Some(Kept {
                        window: k,
                        coupling: p.coupling_state(),
                        state: solver.checkpoint()?,
                        series: time_series_lengths(&solver)?,
                    });
                }
                CommandBody::Rollback { window: k } => {
                    let kept = match &kept {
                        Some(c) if c.window == k => c,
                        Some(Kept { window: w, .. }) => {
                            return Err(NodeError::new(
                                ErrorCode::Protocol,
                                format!("`rollback` to window {k}, but the checkpoint kept is of window {w}"),
                            ))
                        }
                        None => {
                            return Err(NodeError::new(
                                ErrorCode::Protocol,
                                format!("`rollback` to window {k} without a `checkpoint` before it"),
                            ))
                        }
                    };
                    p.set_coupling_state(&kept.coupling)?;
                    solver.rollback(&kept.state)?;
                    // the rows written since the checkpoint go: cut to the lengths then (no
                    // re-reading of the growing files on every repeat); a time series begun
                    // since goes entirely
                    for (path, _) in time_series_lengths(&solver)? {
                        if !kept.series.iter().any(|(p, _)| *p == path) {
                            std::fs::remove_file(&path).map_err(|e| {
                                NodeError::new(
                                    ErrorCode::Io,
                                    format!("removing {}: {e}", path.display()),
                                )
                            })?;
                        }
                    }
                    for (path, len) in &kept.series {
                        let cut = std::fs::OpenOptions::new()
                            .write(true)
                            .open(path)
                            .and_then(|f| f.set_len(*len));
                        cut.map_err(|e| {
                            NodeError::new(
                                ErrorCode::Io,
                                format!("cutting {} back to the checkpoint: {e}", path.display()),
                            )
                        })?;
                    }
                }
                CommandBody::Snapshot { window: k, path } => {
                    let bytes = pack_snapshot(&p.coupling_state(), &solver.snapshot()?);
                    write_atomically(Path::new(&path), &bytes).map_err(|e| {
                        NodeError::new(ErrorCode::Io, format!("writing snapshot {path}: {e}"))
                    })?;
                    p.report(StatusBody::SnapshotDone { window: k, path })
                        .await?;
                }
                CommandBody::Restore { window: k, path } => {
                    let bytes = std::fs::read(&path).map_err(|e| {
                        NodeError::new(ErrorCode::Io, format!("reading snapshot {path}: {e}"))
                    })?;
                    let (coupling, state) = unpack_snapshot(&bytes).map_err(|e| {
                        NodeError::new(ErrorCode::Io, format!("snapshot {path}: {e}"))
                    })?;
                    p.set_coupling_state(coupling)?;
                    solver.restore(state)?;
                    // rows the interrupted run wrote after the checkpoint would appear twice
                    truncate_outputs(&solver)?;
                    p.report(StatusBody::Restored { window: k }).await?;
                }
                CommandBody::Stop { reason } => {
                    tracing::info!("stop: {reason}");
                    let results = solver.finish()?;
                    p.report(StatusBody::Stopped {
                        results,
                        compute_s,
                        wait_s,
                    })
                    .await?;
                    return Ok(());
                }
            }
        }
    }
    .await;
    match result {
        Ok(()) => {
            p.finish().await?;
            Ok(())
        }
        Err(e) => {
            if e.late {
                let _ = p.finish().await;
                return Err(e);
            }
            if e.stopped {
                tracing::info!("{}", e.message);
                let _ = p.finish().await;
                return Ok(());
            }
            {
                let _ = p
                    .report(StatusBody::Error {
                        code: e.code,
                        message: e.message.clone(),
                        window,
                    })
                    .await;
                // let the error reach the coordinator before the liveliness token goes
                tokio::time::sleep(std::time::Duration::from_millis(100)).await;
            }
            let _ = p.finish().await;
            Err(e)
        }
    }
}

/// A window checkpoint in memory: the participant's coupling memory, the solver's state and the
/// length of each CSV time series then.
struct Kept {
    window: u64,
    coupling: Vec<u8>,
    state: Vec<u8>,
    series: Vec<(PathBuf, u64)>,
}

/// The length of each CSV time series of the node (the files
/// [`truncate_time_series_after`] cuts), for a rollback to cut them back to. The files are
/// appended to by reopening, so cutting their length is all a rollback needs.
fn time_series_lengths<S: Solver>(solver: &S) -> Result<Vec<(PathBuf, u64)>, NodeError> {
    let Some((dir, _)) = solver.time_series() else {
        return Ok(Vec::new());
    };
    let io = |e: std::io::Error| {
        NodeError::new(
            ErrorCode::Io,
            format!("reading the time series in {}: {e}", dir.display()),
        )
    };
    let mut out = Vec::new();
    let entries = match std::fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(out),
        Err(e) => return Err(io(e)),
    };
    for path in entries.filter_map(|e| e.ok().map(|e| e.path())) {
        if path.extension().is_none_or(|x| x != "csv") {
            continue;
        }
        let mut header = String::new();
        std::io::BufRead::read_line(
            &mut std::io::BufReader::new(std::fs::File::open(&path).map_err(io)?),
            &mut header,
        )
        .map_err(io)?;
        if header.split(',').next().map(str::trim) == Some("time") {
            out.push((path.clone(), std::fs::metadata(&path).map_err(io)?.len()));
        }
    }
    Ok(out)
}

/// After a restore: the node's CSV time series lose the rows after its time.
fn truncate_outputs<S: Solver>(solver: &S) -> Result<(), NodeError> {
    if let Some((dir, t)) = solver.time_series() {
        truncate_time_series_after(dir, t).map_err(|e| {
            NodeError::new(
                ErrorCode::Io,
                format!("shortening the time series in {}: {e}", dir.display()),
            )
        })?;
    }
    Ok(())
}

/// Makes a panic print one line on stderr instead of the default message and backtrace hint:
/// `<program>: internal error: <message> at <file:line:column>; please report` (`program`
/// names the binary: `dem-node`, `fem-node`, `cosim`). A panic is a bug, not a scene error (those are values), and the node's
/// log, which the coordinator shows, then says why the node died. The exit status stays that
/// of a panic (non-zero). With `RUST_BACKTRACE` set (and not `0`) the default report follows
/// the line, for whoever debugs it.
pub fn install_panic_hook(program: &'static str) {
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        eprintln!("{}", panic_line(program, info));
        if std::env::var("RUST_BACKTRACE").is_ok_and(|v| v != "0") {
            default(info);
        }
    }));
}

/// The one line [`install_panic_hook`] prints.
pub fn panic_line(program: &str, info: &std::panic::PanicHookInfo<'_>) -> String {
    let payload = info.payload();
    let message = payload
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "(no message)".into());
    let location = info.location().map_or_else(
        || "an unknown location".to_string(),
        |l| format!("{}:{}:{}", l.file(), l.line(), l.column()),
    );
    // one line: a multi-line message would be split by the log reader
    let message = message.replace('\n', " ");
    format!("{program}: internal error: {message} at {location}; please report")
}

/// The coordinator that starts a node puts its process id here; the node ends when that
/// process is gone (killed, crashed), whatever the network says. Nodes started by hand (other
/// machines) do not have it and rely on zenoh liveliness.
pub const COORDINATOR_PID_ENV: &str = "COSIM_COORDINATOR_PID";

/// Whether process `pid` exists (a zombie counts as gone only once reaped).
fn process_alive(pid: i32) -> bool {
    // SAFETY: signal 0 only checks that the process exists and may be signalled.
    let rc = unsafe { libc::kill(pid, 0) };
    rc == 0 || std::io::Error::last_os_error().raw_os_error() == Some(libc::EPERM)
}

/// When `COSIM_COORDINATOR_PID` names a process: a thread that ends this process (exit code
/// 3, after one line in the log) soon after that process is gone. The check looks at the
/// parent first (a node whose coordinator died is adopted by another process at once), then
/// at the process itself (a node started through a wrapper).
pub fn exit_with_coordinator() {
    let Some(pid) = std::env::var(COORDINATOR_PID_ENV)
        .ok()
        .and_then(|v| v.trim().parse::<i32>().ok())
        .filter(|&p| p > 1)
    else {
        return;
    };
    // SAFETY: getppid has no preconditions.
    let direct_child = unsafe { libc::getppid() } == pid;
    let spawned = std::thread::Builder::new()
        .name("coordinator-watch".into())
        .spawn(move || loop {
            std::thread::sleep(std::time::Duration::from_millis(250));
            // SAFETY: as above.
            let gone = if direct_child {
                (unsafe { libc::getppid() }) != pid
            } else {
                !process_alive(pid)
            };
            if gone {
                eprintln!(
                    "error: the coordinator (process {pid}) is gone: this node stops (its state since the last checkpoint is lost)"
                );
                std::process::exit(3);
            }
        });
    if let Err(e) = spawned {
        tracing::warn!("cannot watch the coordinator's process: {e}");
    }
}

/// Runs `serve` on a fresh runtime and turns the outcome into an exit code; for `main`.
pub fn main_with<S: Solver>(args: NodeArgs, hello: Hello, solver: S) -> std::process::ExitCode {
    exit_with_coordinator();
    let rt = match tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
    {
        Ok(rt) => rt,
        Err(e) => {
            eprintln!("error: cannot start the async runtime: {e}");
            return std::process::ExitCode::FAILURE;
        }
    };
    match rt.block_on(serve(&args, hello, solver)) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: node `{}` in run `{}`: {e}", args.node, args.run_id);
            std::process::ExitCode::FAILURE
        }
    }
}

/// Logging for node binaries: to stderr, filter from `COSIM_LOG` (default `info,zenoh=warn`).
pub fn init_logging() {
    let filter = std::env::var("COSIM_LOG").unwrap_or_else(|_| "info,zenoh=warn".into());
    let _ = tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_new(filter).unwrap_or_else(|_| "info".into()),
        )
        .with_writer(std::io::stderr)
        .with_target(false)
        .with_ansi(false)
        .try_init();
}

/// Per-window interface traces (`Init::trace`): CSV files of full-precision numbers, one row
/// per record, flushed at once so a reader sees every completed row.
#[derive(Debug, Default)]
pub struct Trace {
    files: std::collections::HashMap<PathBuf, std::io::BufWriter<std::fs::File>>,
}

impl Trace {
    /// Appends `prefix` then `values` as one row of `path` (created with `header` if new).
    pub fn row(
        &mut self,
        path: &Path,
        header: &str,
        prefix: &[String],
        values: &[f64],
    ) -> Result<(), NodeError> {
        use std::io::Write;
        let io = |e: std::io::Error| {
            NodeError::new(
                ErrorCode::Io,
                format!("writing trace {}: {e}", path.display()),
            )
        };
        if !self.files.contains_key(path) {
            let mut f = std::io::BufWriter::new(std::fs::File::create(path).map_err(io)?);
            writeln!(f, "{header}").map_err(io)?;
            self.files.insert(path.to_path_buf(), f);
        }
        let f = self.files.get_mut(path).expect("inserted above");
        let mut line = prefix.join(",");
        for v in values {
            if !line.is_empty() {
                line.push(',');
            }
            // Display of f64 is the shortest text that reads back to the same bits
            line.push_str(&v.to_string());
        }
        writeln!(f, "{line}").map_err(io)?;
        f.flush().map_err(io)
    }
}

/// Sum of a flat xyz array.
pub fn total(xyz: &[f64]) -> [f64; 3] {
    let mut t = [0.0; 3];
    for v in xyz.chunks_exact(3) {
        for i in 0..3 {
            t[i] += v[i];
        }
    }
    t
}

impl Init {
    /// The folder the scene's relative file names are relative to.
    pub fn scene_dir(&self) -> &Path {
        Path::new(&self.scene_path)
            .parent()
            .unwrap_or(Path::new("."))
    }

    /// Reads this node's table of the scene ([`Init::table`]: `[dem]`, `[fem]`, …) with the
    /// engine's parser; errors name the scene file (the parser gives line, column and field).
    pub fn scene_table<T, E: std::fmt::Display>(
        &self,
        parse: impl FnOnce(&str, &str) -> Result<Option<T>, E>,
    ) -> Result<T, NodeError> {
        parse(&self.scene_toml, &self.table)
            .map_err(|e| NodeError::new(ErrorCode::Scene, format!("{}: {e}", self.scene_path)))?
            .ok_or_else(|| {
                NodeError::new(
                    ErrorCode::Scene,
                    format!(
                        "{}: the scene has no [{}] table",
                        self.scene_path, self.table
                    ),
                )
            })
    }

    /// This node's output folder `<out_dir>/<node>`, created.
    pub fn node_out_dir(&self, node: &str) -> Result<PathBuf, NodeError> {
        let dir = PathBuf::from(&self.out_dir).join(node);
        std::fs::create_dir_all(&dir).map_err(|e| {
            NodeError::new(ErrorCode::Io, format!("creating {}: {e}", dir.display()))
        })?;
        Ok(dir)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn snapshots_pack_and_unpack_and_foreign_files_are_named() {
        let packed = pack_snapshot(b"abc", b"state bytes");
        assert_eq!(
            unpack_snapshot(&packed).unwrap(),
            (&b"abc"[..], &b"state bytes"[..])
        );
        let e = unpack_snapshot(b"DEM1 old snapshot").unwrap_err();
        assert!(e.contains("protocol version 2"), "{e}");
        let e = unpack_snapshot(&packed[..SNAPSHOT_MAGIC.len() + 9]).unwrap_err();
        assert!(e.contains("cut short"), "{e}");
    }

    #[test]
    fn time_series_lose_the_rows_after_the_restored_time_and_nothing_else() {
        let dir = tempfile::tempdir().unwrap();
        let p = |name: &str| dir.path().join(name);
        // the FEM prints 10 significant digits: 3e-4 may read back a little above t
        std::fs::write(
            p("probes.csv"),
            "time,u\n1.000000000e-4,1\n2.000000000e-4,2\n3.000000000e-4,3\n4.000000000e-4,4\n5.0e-4,5",
        )
        .unwrap();
        std::fs::write(p("other.csv"), "x,y\n9,9\n").unwrap();
        std::fs::write(p("notes.txt"), "time,u\n9,9\n").unwrap();
        std::fs::write(p("short.csv"), "time,u\n1e-4,1\n").unwrap();
        let t = 3.0e-4 * (1.0 - 1e-12);
        let changed = truncate_time_series_after(dir.path(), t).unwrap();
        assert_eq!(changed, vec![p("probes.csv")]);
        assert_eq!(
            std::fs::read_to_string(p("probes.csv")).unwrap(),
            "time,u\n1.000000000e-4,1\n2.000000000e-4,2\n3.000000000e-4,3\n"
        );
        assert_eq!(
            std::fs::read_to_string(p("other.csv")).unwrap(),
            "x,y\n9,9\n"
        );
        assert_eq!(
            std::fs::read_to_string(p("notes.txt")).unwrap(),
            "time,u\n9,9\n"
        );
        assert_eq!(
            std::fs::read_to_string(p("short.csv")).unwrap(),
            "time,u\n1e-4,1\n"
        );
        // a row cut short by a kill goes even if its time is early
        std::fs::write(p("cut.csv"), "time,u\n1e-4,1\n2e-4,2").unwrap();
        truncate_time_series_after(dir.path(), 1.0).unwrap();
        assert_eq!(
            std::fs::read_to_string(p("cut.csv")).unwrap(),
            "time,u\n1e-4,1\n"
        );
        // no folder: nothing to do
        assert!(truncate_time_series_after(&p("missing"), 1.0)
            .unwrap()
            .is_empty());
    }
}
