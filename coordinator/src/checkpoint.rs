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
    /// Fingerprint of the scene's settings ([`settings_fingerprint`]: comments, layout and
    /// key order do not count), so that a scene whose comments were edited since still
    /// resumes. Checkpoints from before it have none.
    #[serde(default)]
    pub settings_fingerprint: Option<String>,
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

/// Fingerprint of a scene's settings: its TOML parsed and written out canonically (keys
/// sorted, numbers exact), so that comments, blank lines, quoting, key order and the
/// checkpoint period do not change it; `None` if the text is not TOML.
pub fn settings_fingerprint(text: &str) -> Option<String> {
    let mut table: toml::Table = toml::from_str(text).ok()?;
    // how often checkpoints are written does not change the run (resumes are bitwise)
    if let Some(toml::Value::Table(output)) = table.get_mut("output") {
        output.remove("checkpoint_every");
        output.remove("checkpoint_wall");
        if output.is_empty() {
            table.remove("output");
        }
    }
    // serde_json's maps are sorted by key; integers and floats stay apart (1 vs 1.0)
    let canonical = serde_json::to_value(&table).ok()?.to_string();
    Some(scene_fingerprint(&canonical))
}

/// Whether `scene_text` is the scene a checkpoint recorded by its text fingerprint `text` and
/// settings fingerprint `settings` (either may be missing in older checkpoints: no text
/// fingerprint accepts any scene; without the settings one, those of `started()`, the text
/// the run began with, count if that is the recorded text).
fn same_scene(
    text: Option<&str>,
    settings: Option<&str>,
    started: impl FnOnce() -> Option<String>,
    scene_text: &str,
) -> bool {
    let Some(text) = text else { return true };
    if text == scene_fingerprint(scene_text) {
        return true;
    }
    let recorded = settings.map(str::to_string).or_else(|| {
        let t = started()?;
        (scene_fingerprint(&t) == text)
            .then(|| settings_fingerprint(&t))
            .flatten()
    });
    let now = settings_fingerprint(scene_text);
    now.is_some() && now == recorded
}

/// Refuses to resume from a checkpoint that another scene wrote: its scene name and, when
/// recorded, its scene text must be those of the folder's `scene.toml` — or its settings,
/// when only comments, layout or the checkpoint period were edited since (recorded in the
/// checkpoint; for older checkpoints, those of the run folder's `scene.toml` the run was
/// started with, which helps a study, whose variant text is not that file). Touches nothing.
pub fn check_belongs(
    dir: &Path,
    state: &CheckpointState,
    scene_name: &str,
    scene_text: &str,
) -> anyhow::Result<()> {
    // the text of the run folder's scene.toml (the run's start), for older checkpoints
    let started = || {
        let path = dir.parent()?.parent()?.join("scene.toml");
        std::fs::read_to_string(path).ok()
    };
    let other = state.summary.scene != scene_name
        || !same_scene(
            state.scene_fingerprint.as_deref(),
            state.settings_fingerprint.as_deref(),
            started,
            scene_text,
        );
    if other {
        anyhow::bail!(
            "{}: this checkpoint was written by a run of scene `{}` ({}), not by the scene in the folder's scene.toml (`{scene_name}`{}): refusing to resume a different scene; start it anew with `cosim run <scene> --out <folder> --overwrite`",
            dir.display(),
            state.summary.scene,
            state.summary.scene_file,
            if state.summary.scene == scene_name {
                ", with other settings"
            } else {
                ""
            }
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
            "{} has no checkpoint ({} is missing): set `[output] checkpoint_every` (windows) or `checkpoint_wall` (wall time) in the scene to make runs resumable",
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

#[cfg(test)]
mod tests {
    use super::*;

    const SCENE: &str = "[scene]\nname = \"a\"\nend_time = \"1 s\" # comment\n\n[dem]\ntime_step = 1e-5\ngravity = [0.0, 0.0, -9.81]\n";

    #[test]
    fn settings_ignore_comments_layout_and_key_order_but_not_values() {
        let edited = "# a new first line\n[dem]\ngravity = [ 0.0,0.0, -9.81 ]   # g\ntime_step = 1e-5\n\n[scene]\nend_time = '1 s'\nname = \"a\"\n";
        assert_ne!(scene_fingerprint(SCENE), scene_fingerprint(edited));
        assert_eq!(settings_fingerprint(SCENE), settings_fingerprint(edited));
        assert!(settings_fingerprint(SCENE).is_some());
        // nor does a checkpoint period added or changed
        for period in [
            "[output]\ncheckpoint_wall = \"20 min\"\n",
            "[output]\ncheckpoint_every = 500\ncheckpoint_wall = 60\n",
        ] {
            let text = format!("{SCENE}{period}");
            assert_eq!(settings_fingerprint(SCENE), settings_fingerprint(&text));
        }
        for changed in [
            SCENE.replace("1e-5", "2e-5"),
            SCENE.replace("\"1 s\"", "\"2 s\""),
            SCENE.replace("-9.81]", "-9.81, 1.0]"),
            // an integer is not the float of the same value: the scene reader may tell them apart
            SCENE.replace("0.0, 0.0,", "0, 0.0,"),
            SCENE.replace("[dem]", "[dem]\nthreads = 1"),
            format!("{SCENE}[output]\nfinal_state = true\n"),
        ] {
            assert_ne!(
                settings_fingerprint(SCENE),
                settings_fingerprint(&changed),
                "{changed}"
            );
        }
        assert_eq!(settings_fingerprint("[scene"), None);
    }

    #[test]
    fn a_checkpoint_belongs_to_its_text_or_its_settings() {
        let text = scene_fingerprint(SCENE);
        let settings = settings_fingerprint(SCENE).unwrap();
        let commented = format!("{SCENE}# edited later\n");
        let changed = SCENE.replace("1e-5", "2e-5");
        let none = || None;
        // the same text; any text for checkpoints without a fingerprint
        assert!(same_scene(Some(&text), None, none, SCENE));
        assert!(same_scene(None, None, none, &changed));
        // comments edited: by the recorded settings ...
        assert!(same_scene(Some(&text), Some(&settings), none, &commented));
        assert!(!same_scene(Some(&text), Some(&settings), none, &changed));
        // ... or, for older checkpoints, by the text the run began with ...
        let started = || Some(SCENE.to_string());
        assert!(same_scene(Some(&text), None, started, &commented));
        assert!(!same_scene(Some(&text), None, started, &changed));
        // ... if that is the recorded text; without it, only the recorded text counts
        let other_start = || Some(commented.clone());
        assert!(!same_scene(Some(&text), None, other_start, &commented));
        assert!(!same_scene(Some(&text), None, none, &commented));
    }
}
