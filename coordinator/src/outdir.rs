//! The run's output folder, kept honest: a run holds an exclusive lock on its folder for its
//! whole life (a second run into it is refused, naming the first one's process), and a new run
//! does not mix its files with those of an earlier one: a folder that holds another run's files
//! is refused unless the user asks to replace them (`--overwrite`, which clears the folder
//! first) or to continue them (`cosim resume`).

use std::io::{Read, Seek, Write};
use std::os::fd::AsRawFd;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context};

/// The lock file inside a run folder (kept after the run: the lock is the open file's, not
/// the file's existence, so a killed run never leaves a stale lock).
pub const LOCK_FILE: &str = ".cosim.lock";

/// Held while a run (or check) uses its folder; released when dropped or when the process
/// ends, however it ends.
#[derive(Debug)]
pub struct FolderLock {
    _file: std::fs::File,
    pub dir: PathBuf,
    /// The folder had a lock file before: an earlier run (or check) used it.
    pub was_used: bool,
}

/// Takes the exclusive lock on `dir` (created if missing). `what` (e.g. `run of scene beam`)
/// is written into the lock file so that a refused second run can say who holds it.
pub fn lock(dir: &Path, what: &str) -> anyhow::Result<FolderLock> {
    std::fs::create_dir_all(dir)
        .with_context(|| format!("creating the output folder {}", dir.display()))?;
    let path = dir.join(LOCK_FILE);
    let was_used = path.exists();
    let mut file = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .open(&path)
        .with_context(|| format!("opening the lock file {}", path.display()))?;
    // SAFETY: flock on a file descriptor this function owns.
    let rc = unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) };
    if rc != 0 {
        let err = std::io::Error::last_os_error();
        if err.raw_os_error() == Some(libc::EWOULDBLOCK) {
            let mut holder = String::new();
            let _ = file.read_to_string(&mut holder);
            let holder = holder.trim();
            bail!(
                "the output folder {} is in use by another cosim {}: wait for it to end, stop it, or choose another folder with --out",
                dir.display(),
                if holder.is_empty() {
                    "process".to_string()
                } else {
                    holder.to_string()
                }
            );
        }
        return Err(err).with_context(|| format!("locking {}", path.display()));
    }
    file.set_len(0)?;
    file.rewind()?;
    writeln!(file, "process {} ({what})", std::process::id())
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(FolderLock {
        _file: file,
        dir: dir.to_path_buf(),
        was_used,
    })
}

/// The entries of `dir` other than the lock file, sorted.
fn entries(dir: &Path) -> anyhow::Result<Vec<PathBuf>> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("reading the output folder {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.file_name().is_none_or(|n| n != LOCK_FILE))
        .collect();
    v.sort();
    Ok(v)
}

/// What an earlier run left in `dir`, in a few words (scene and status from its summary).
fn describe_earlier(dir: &Path) -> String {
    let summary = std::fs::read_to_string(dir.join("summary.json"))
        .ok()
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok());
    match summary {
        Some(s) => format!(
            "a run of scene `{}` (status `{}`)",
            s["scene"].as_str().unwrap_or("?"),
            s["status"].as_str().unwrap_or("?")
        ),
        None => "another run's files".to_string(),
    }
}

/// Makes the locked folder ready for a new run: empty is fine; a folder with an
/// earlier run's files is refused, or with `overwrite` cleared. A folder whose files are not
/// a run's (no `run.json`, `summary.json` or lock file) is never cleared: `--out .` must not
/// wipe the user's work.
pub fn prepare_new(lock: &FolderLock, overwrite: bool) -> anyhow::Result<()> {
    let dir = lock.dir.as_path();
    let found = entries(dir)?;
    if found.is_empty() {
        return Ok(());
    }
    let is_run_folder =
        dir.join("run.json").exists() || dir.join("summary.json").exists() || lock.was_used;
    if !is_run_folder {
        bail!(
            "the output folder {} holds files that are not a cosim run's (e.g. {}): choose an empty or new folder with --out",
            dir.display(),
            found[0].display()
        );
    }
    if !overwrite {
        bail!(
            "the output folder {} holds {}: pass --overwrite to replace it, run `cosim resume {}` to continue it, or choose another folder with --out",
            dir.display(),
            describe_earlier(dir),
            dir.display()
        );
    }
    for p in found {
        let r = if p.is_dir() && !p.is_symlink() {
            std::fs::remove_dir_all(&p)
        } else {
            std::fs::remove_file(&p)
        };
        r.with_context(|| format!("clearing {} (--overwrite)", p.display()))?;
    }
    tracing::info!("cleared {} (--overwrite)", dir.display());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_second_lock_is_refused_naming_the_holder_and_freed_on_drop() {
        let d = tempfile::tempdir().unwrap();
        let first = lock(d.path(), "run of scene a").unwrap();
        // flock locks belong to the open file description: a second open in this process
        // conflicts like another process would
        let e = lock(d.path(), "run of scene b").unwrap_err().to_string();
        assert!(e.contains("in use by another cosim process"), "{e}");
        assert!(
            e.contains(&format!("{} (run of scene a)", std::process::id())),
            "{e}"
        );
        drop(first);
        lock(d.path(), "run of scene b").unwrap();
    }

    #[test]
    fn a_folder_with_an_earlier_run_is_refused_then_cleared_on_overwrite() {
        let d = tempfile::tempdir().unwrap();
        let l = lock(d.path(), "test").unwrap();
        prepare_new(&l, false).unwrap();
        std::fs::write(
            d.path().join("summary.json"),
            r#"{"scene":"beam","status":"completed"}"#,
        )
        .unwrap();
        std::fs::create_dir_all(d.path().join("fem")).unwrap();
        std::fs::write(d.path().join("fem/x.csv"), "time\n").unwrap();
        let e = prepare_new(&l, false).unwrap_err().to_string();
        assert!(
            e.contains("a run of scene `beam` (status `completed`)") && e.contains("--overwrite"),
            "{e}"
        );
        prepare_new(&l, true).unwrap();
        assert!(entries(d.path()).unwrap().is_empty());
        assert!(d.path().join(LOCK_FILE).exists());
    }

    #[test]
    fn a_folder_of_other_files_is_never_cleared() {
        let d = tempfile::tempdir().unwrap();
        std::fs::write(d.path().join("thesis.tex"), "precious").unwrap();
        // locking it for the first time does not make it a run's
        let l = lock(d.path(), "test").unwrap();
        let e = prepare_new(&l, true).unwrap_err().to_string();
        assert!(e.contains("not a cosim run's"), "{e}");
        assert!(d.path().join("thesis.tex").exists());
    }
}
