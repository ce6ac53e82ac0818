//! Starting the nodes a scene needs as local processes (the embedded default).

use std::path::{Path, PathBuf};
use std::process::Stdio;

use anyhow::{bail, Context};
use proto::NodeKind;

use crate::scene::NodeLaunch;

/// A node the coordinator started (or waits for, when it is external).
pub struct NodeProcess {
    pub name: String,
    pub kind: NodeKind,
    pub child: Option<tokio::process::Child>,
    pub log: Option<PathBuf>,
    pub listen: Vec<String>,
    pub connect: Vec<String>,
}

/// Where the node binaries are: `$COSIM_BIN_DIR`, else next to the running `cosim`.
pub fn bin_dir() -> anyhow::Result<PathBuf> {
    if let Some(d) = std::env::var_os("COSIM_BIN_DIR") {
        return Ok(PathBuf::from(d));
    }
    let exe = std::env::current_exe().context("locating the cosim executable")?;
    Ok(exe.parent().map(Path::to_path_buf).unwrap_or_default())
}

/// The thread-pool size a launched node reads (rayon's, used by the DEM and FEM nodes).
pub const THREADS_ENV: &str = "RAYON_NUM_THREADS";

impl NodeProcess {
    /// Starts node `name` of `kind`: the scene's command if it gives one, else the built-in
    /// binary of its kind. Output goes to `<log_dir>/<name>.log`.
    #[allow(clippy::too_many_arguments)]
    pub fn spawn(
        kind: NodeKind,
        name: &str,
        launch: Option<&NodeLaunch>,
        run_id: &str,
        listen: Vec<String>,
        connect: Vec<String>,
        log_dir: &Path,
        scene_dir: &Path,
        lease: Option<std::time::Duration>,
        threads: Option<usize>,
    ) -> anyhow::Result<NodeProcess> {
        let name = name.to_string();
        let mut node = NodeProcess {
            name: name.clone(),
            kind,
            child: None,
            log: None,
            listen,
            connect,
        };
        if launch.is_some_and(|l| l.external) {
            return Ok(node);
        }
        let (program, mut args): (PathBuf, Vec<String>) = match launch
            .and_then(|l| l.command.clone())
        {
            Some(cmd) if !cmd.is_empty() => (PathBuf::from(&cmd[0]), cmd[1..].to_vec()),
            Some(_) => bail!("nodes.{name}.command is empty"),
            None => {
                let exe = bin_dir()?.join(format!("{kind}-node{}", std::env::consts::EXE_SUFFIX));
                if !exe.exists() {
                    bail!(
                        "the {kind} node binary {} does not exist: build it with `cargo build --release` or set COSIM_BIN_DIR",
                        exe.display()
                    );
                }
                (exe, Vec::new())
            }
        };
        args.extend([
            "--run-id".to_string(),
            run_id.to_string(),
            "--node".to_string(),
            name.clone(),
        ]);
        for l in &node.listen {
            args.extend(["--listen".to_string(), l.clone()]);
        }
        for c in &node.connect {
            args.extend(["--connect".to_string(), c.clone()]);
        }
        std::fs::create_dir_all(log_dir)
            .with_context(|| format!("creating {}", log_dir.display()))?;
        let log = log_dir.join(format!("{name}.log"));
        let out =
            std::fs::File::create(&log).with_context(|| format!("creating {}", log.display()))?;
        let err = out.try_clone()?;
        // Relative program paths in a scene's command are relative to the scene file.
        let program = if program.components().count() > 1 && program.is_relative() {
            scene_dir.join(program)
        } else {
            program
        };
        let mut command = tokio::process::Command::new(&program);
        match lease {
            // its links' lease (proto::link::LOCAL_LEASE): an environment variable, so that
            // the node programs (the Python one, the users' own) need no new flag
            Some(lease) => command.env(proto::link::LEASE_ENV, lease.as_millis().to_string()),
            // not one from the user's shell either: the node keeps the default
            None => command.env_remove(proto::link::LEASE_ENV),
        };
        // a user's own setting wins (an empty one is rayon's "unset")
        let users = std::env::var_os(THREADS_ENV).is_some_and(|v| !v.is_empty());
        if let Some(n) = threads.filter(|_| !users) {
            command.env(THREADS_ENV, n.to_string());
        }
        let child = command
            .args(&args)
            // the node ends when this process is gone, whatever the network says
            .env(
                proto::node::COORDINATOR_PID_ENV,
                std::process::id().to_string(),
            )
            // its own process group: a Ctrl-C in the terminal reaches the coordinator only,
            // which then stops the node cleanly (crate::interrupt)
            .process_group(0)
            .stdin(Stdio::null())
            .stdout(out)
            .stderr(err)
            .kill_on_drop(true)
            .spawn()
            .with_context(|| format!("starting the {name} node: {}", program.display()))?;
        tracing::info!(node = %name, pid = child.id(), "started {} {}", program.display(), args.join(" "));
        node.child = Some(child);
        node.log = Some(log);
        Ok(node)
    }

    /// If the process has exited: its status and the end of its log.
    pub fn exited(&mut self) -> Option<String> {
        let child = self.child.as_mut()?;
        match child.try_wait() {
            Ok(Some(status)) => Some(format!(
                "the {} node exited ({status}){}",
                self.name,
                self.log_tail()
            )),
            _ => None,
        }
    }

    /// The last lines of the node's log, for error messages.
    pub fn log_tail(&self) -> String {
        let Some(log) = &self.log else {
            return String::new();
        };
        let text = std::fs::read_to_string(log).unwrap_or_default();
        let lines: Vec<&str> = text.lines().rev().take(8).collect();
        if lines.is_empty() {
            return String::new();
        }
        let tail: Vec<&str> = lines.into_iter().rev().collect();
        format!(
            "; last lines of {}:\n  {}",
            log.display(),
            tail.join("\n  ")
        )
    }

    /// Waits up to `grace` for the process to exit, then kills it. Returns whether it exited
    /// by itself with success.
    pub async fn reap(&mut self, grace: std::time::Duration) -> bool {
        let Some(child) = self.child.as_mut() else {
            return true;
        };
        match tokio::time::timeout(grace, child.wait()).await {
            Ok(Ok(status)) => status.success(),
            _ => {
                let _ = child.kill().await;
                false
            }
        }
    }
}
