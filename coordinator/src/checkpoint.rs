//! Checkpoints: every N windows the coordinator asks every node to write its full state, then
//! records its own (schedule, stability monitor, summary so far). All files are written
//! atomically (temporary file, fsync, rename), and `latest.json` moves only once a checkpoint
//! is complete, so a crash at any moment leaves the previous checkpoint usable.
//! `cosim resume <out-dir>` continues from `latest.json`.

use std::path::{Path, PathBuf};

use anyhow::Context;
use serde::{Deserialize, Serialize};

use crate::run::Summary;
use crate::schedule::Scheduler;
use crate::stability::StabilityMonitor;

/// What a run needs to be resumed (`<out>/run.json`); the scene text is `<out>/scene.toml`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RunRecord {
    /// The scene file as given (its folder resolves the scene's relative paths).
    pub scene_file: PathBuf,
    pub run_id: String,
    pub zenoh_config: Option<PathBuf>,
}

/// The coordinator's state at a checkpoint (`<out>/checkpoints/w<k>/state.json`).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CheckpointState {
    /// Last completed window.
    pub window: u64,
    pub scheduler: Scheduler,
    pub stability: StabilityMonitor,
    pub summary: Summary,
    /// Fingerprint of the scene text the run was started with ([`scene_fingerprint`]);
    /// `cosim resume` refuses a folder whose scene.toml no longer matches.
    #[serde(default)]
    pub scene_fingerprint: Option<String>,
}

/// FNV-1a (64 bit) of the scene text, as 16 hex digits: a stable fingerprint to tell whether
/// a checkpoint belongs to a scene (not a security measure).
pub fn scene_fingerprint(text: &str) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in text.as_bytes() {
        h ^= u64::from(*b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    format!("{h:016x}")
}

/// Refuses to resume from a checkpoint that another scene wrote: its scene name and, when
/// recorded, its scene text must be those of the folder's `scene.toml`. Touches nothing.
pub fn check_belongs(
    dir: &Path,
    state: &CheckpointState,
    scene_name: &str,
    scene_text: &str,
) -> anyhow::Result<()> {
    let other = state.summary.scene != scene_name
        || state
            .scene_fingerprint
            .as_deref()
            .is_some_and(|f| f != scene_fingerprint(scene_text));
    if other {
        anyhow::bail!(
            "{}: this checkpoint was written by a run of scene `{}` ({}), not by the scene in the folder's scene.toml (`{scene_name}`): refusing to resume a different scene; start it anew with `cosim run <scene> --out <folder> --overwrite`",
            dir.display(),
            state.summary.scene,
            state.summary.scene_file
        );
    }
    Ok(())
}

#[derive(Debug, Clone, Serialize, Deserialize)]
struct Latest {
    window: u64,
    dir: String,
}

pub fn checkpoints_dir(out_dir: &Path) -> PathBuf {
    out_dir.join("checkpoints")
}

/// Folder of the checkpoint after window `window`.
pub fn checkpoint_dir(out_dir: &Path, window: u64) -> PathBuf {
    checkpoints_dir(out_dir).join(format!("w{window:09}"))
}

/// Where a node writes its state in a checkpoint.
pub fn node_state_path(dir: &Path, node: &str) -> PathBuf {
    dir.join(format!("{node}.state"))
}

pub fn write_json<T: Serialize>(path: &Path, value: &T) -> anyhow::Result<()> {
    let text = serde_json::to_string_pretty(value)?;
    proto::node::write_atomically(path, text.as_bytes())
        .with_context(|| format!("writing {}", path.display()))
}

fn read_json<T: for<'de> Deserialize<'de>>(path: &Path) -> anyhow::Result<T> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    serde_json::from_str(&text)
        .with_context(|| format!("{} is not a valid checkpoint file", path.display()))
}

/// Records a completed checkpoint: its state, then the `latest.json` pointer; prunes all but
/// the two newest checkpoints.
pub fn commit(out_dir: &Path, state: &CheckpointState) -> anyhow::Result<()> {
    let dir = checkpoint_dir(out_dir, state.window);
    write_json(&dir.join("state.json"), state)?;
    let name = dir
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or_default()
        .to_string();
    write_json(
        &checkpoints_dir(out_dir).join("latest.json"),
        &Latest {
            window: state.window,
            dir: name.clone(),
        },
    )?;
    let mut all: Vec<PathBuf> = std::fs::read_dir(checkpoints_dir(out_dir))?
        .flatten()
        .map(|e| e.path())
        .filter(|p| {
            p.is_dir()
                && p.file_name()
                    .and_then(|n| n.to_str())
                    .is_some_and(|n| n.starts_with('w'))
        })
        .collect();
    all.sort();
    let keep = all.len().saturating_sub(2);
    for old in &all[..keep] {
        if old.file_name().and_then(|n| n.to_str()) != Some(name.as_str()) {
            let _ = std::fs::remove_dir_all(old);
        }
    }
    Ok(())
}

/// The newest complete checkpoint of a run folder: its folder and state.
pub fn latest(out_dir: &Path) -> anyhow::Result<(PathBuf, CheckpointState)> {
    let pointer = checkpoints_dir(out_dir).join("latest.json");
    if !pointer.exists() {
        anyhow::bail!(
            "{} has no checkpoint ({} is missing): set `[output] checkpoint_every` in the scene to make runs resumable",
            out_dir.display(),
            pointer.display()
        );
    }
    let latest: Latest = read_json(&pointer)?;
    let dir = checkpoints_dir(out_dir).join(&latest.dir);
    let state: CheckpointState = read_json(&dir.join("state.json"))?;
    if state.window != latest.window {
        anyhow::bail!(
            "{}: the checkpoint is for window {}, latest.json says {}",
            dir.display(),
            state.window,
            latest.window
        );
    }
    Ok((dir, state))
}

pub fn read_record(out_dir: &Path) -> anyhow::Result<RunRecord> {
    read_json(&out_dir.join("run.json"))
}
