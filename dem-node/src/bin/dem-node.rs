//! `dem-node`: the DEM engine as a node of a co-simulation run. A thin adapter: it speaks
//! `proto` over zenoh and calls the `dem` engine; all physics is in the library.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use clap::Parser;
use dem::discs::{config::Model, DiscEngine};
use dem::{Engine, MotionRule};
use proto::cli::NodeArgs;
use proto::node::{main_with, total, NodeError, Solver, Trace, WindowReport};
use proto::participant::{Participant, Side};
use proto::{
    AdvanceWindow, ErrorCode, Hello, Init, InterfaceForces, Label, NodeKind, PROTOCOL_VERSION,
};

#[derive(Parser)]
#[command(
    name = "dem-node",
    version,
    about = "DEM solver node of a cosim run (started by `cosim run`)"
)]
struct Args {
    #[command(flatten)]
    node: NodeArgs,
}

/// A coupled interface: the provider's mesh as the DEM sees it (a surface mesh, or the
/// overlap of a volume interface).
struct Coupled {
    name: String,
    /// Index among the engine's coupled meshes, or its volume interfaces when `volume`.
    mesh: usize,
    volume: bool,
    nodes: usize,
    /// Send the mean of the window's substep forces (Ullrich (3.8)) instead of the last.
    force_averaging: bool,
}

struct DemNode {
    engine: Option<Engine>,
    /// A scene with `model = "discs-2d"`: Madan's 2-D disc engine (DEM-only).
    discs: Option<DiscEngine>,
    coupled: Vec<Coupled>,
    out_dir: PathBuf,
    data_timeout: std::time::Duration,
    /// Substeps of the last window (the number of forces an averaged message is the mean of).
    substeps: u32,
    trace: Option<Trace>,
}

impl Coupled {
    /// The forces on the provider's nodes: contact forces on a surface, penalty forces
    /// (6.25) on a volume interface's nodes.
    fn forces(&self, engine: &Engine, averaged: bool) -> Vec<f64> {
        if self.volume {
            engine.volume_forces(self.mesh, averaged)
        } else {
            engine.interface_forces(self.mesh, averaged)
        }
    }

    fn positions(&self, engine: &Engine) -> Vec<f64> {
        if self.volume {
            engine.volume_node_positions(self.mesh)
        } else {
            engine.mesh_positions(self.mesh)
        }
    }
}

fn scene_error(e: impl std::fmt::Display) -> NodeError {
    NodeError::new(ErrorCode::Scene, e.to_string())
}

impl DemNode {
    fn engine(&mut self) -> Result<&mut Engine, NodeError> {
        self.engine.as_mut().ok_or_else(|| {
            NodeError::new(ErrorCode::Protocol, "a window command came before `init`")
        })
    }

    async fn write_forces(&mut self, p: &mut Participant, label: Label) -> Result<(), NodeError> {
        let substeps = self.substeps;
        let engine = self
            .engine
            .as_ref()
            .ok_or_else(|| NodeError::new(ErrorCode::Protocol, "`publish` before `init`"))?;
        let time = engine.time();
        let msgs: Vec<InterfaceForces> = self
            .coupled
            .iter()
            .map(|c| InterfaceForces {
                version: PROTOCOL_VERSION,
                run_id: p.run_id().to_string(),
                interface: c.name.clone(),
                window: label.window,
                iteration: label.iteration,
                time,
                forces: c.forces(engine, c.force_averaging).into(),
                averaged: c.force_averaging,
                samples: if c.force_averaging { substeps } else { 1 },
            })
            .collect();
        for m in &msgs {
            p.write_forces(m).await?;
        }
        Ok(())
    }
}

impl DemNode {
    /// `init` of a disc scene: the engine, its limits (the critical step, the DDEM's ρ(B)); a
    /// disc scene couples no interfaces.
    async fn init_discs(
        &mut self,
        p: &mut Participant,
        init: &Init,
    ) -> Result<(BTreeMap<String, f64>, Vec<String>), NodeError> {
        let cfg = init.scene_table(dem::discs::parse_scene_table)?;
        if let Some(decl) = init.interfaces.first() {
            return Err(scene_error(format!(
                "{}: interface `{}`: a 2-D disc scene (model = \"discs-2d\") runs DEM-only; it couples no interfaces",
                init.scene_path, decl.name
            )));
        }
        let engine = DiscEngine::from_config(&cfg, init.scene_dir())
            .map_err(|e| scene_error(format!("{}: {e}", init.scene_path)))?;
        self.out_dir = init.node_out_dir(p.node())?;
        p.wait_for_peers(self.data_timeout).await?;
        let limits = engine.limits().into_iter().collect();
        self.discs = Some(engine);
        Ok((limits, Vec::new()))
    }

    fn advance_discs(&mut self, w: &AdvanceWindow) -> Result<WindowReport, NodeError> {
        let out_dir = self.out_dir.clone();
        let d = self.discs.as_mut().ok_or_else(|| {
            NodeError::new(ErrorCode::Protocol, "a window command came before `init`")
        })?;
        let step = d.time_step();
        let substeps = proto::motion::whole_substeps(w.dt, step).map_err(|ratio| {
            NodeError::new(
                ErrorCode::Protocol,
                format!(
                    "window {}: Δt^C = {} s is not a whole multiple of the disc time step {step} s (ratio {ratio})",
                    w.window, w.dt
                ),
            )
        })?;
        d.advance(substeps as u64).map_err(|e| {
            NodeError::new(ErrorCode::Unstable, format!("window {}: {e}", w.window))
        })?;
        d.write_outputs(&out_dir)
            .map_err(|e| NodeError::new(ErrorCode::Io, e.to_string()))?;
        let monitor = BTreeMap::from([
            ("kinetic_energy".to_string(), d.kinetic_energy()),
            ("contact_energy".to_string(), d.contact_energy()),
            ("particle_energy".to_string(), d.particle_energy()),
        ]);
        Ok(WindowReport {
            wait_s: 0.0,
            t_end: d.time(),
            monitor,
        })
    }
}

impl Solver for DemNode {
    async fn init(
        &mut self,
        p: &mut Participant,
        init: &Init,
    ) -> Result<(BTreeMap<String, f64>, Vec<String>), NodeError> {
        if dem::discs::scene_model(&init.scene_toml, &init.table) == Model::Discs2d {
            return self.init_discs(p, init).await;
        }
        let cfg = init.scene_table(dem::parse_scene_table)?;
        let base = init.scene_dir();
        let mut engine = Engine::from_config(&cfg, base)
            .map_err(|e| scene_error(format!("{}: {e}", init.scene_path)))?;
        self.out_dir = init.node_out_dir(p.node())?;
        self.trace = init.trace.then(Trace::default);
        for (decl, side) in p.open_interfaces(&init.interfaces).await? {
            let name = &decl.name;
            if side == Side::Provider {
                return Err(scene_error(format!(
                    "{}: interface `{name}` names the DEM node `{}` as its provider; a DEM node uses surface interfaces that a FEM node provides",
                    init.scene_path,
                    p.node()
                )));
            }
            let mesh = p.read_mesh(name, self.data_timeout).await?;
            let volume = decl.kind == proto::InterfaceKind::Volume;
            let id =
                match (&mesh.volume, volume) {
                    (Some(v), true) => {
                        let shape = dem::volume_coupling::shape_of(&v.shape).ok_or_else(|| {
                            scene_error(format!(
                                "interface `{name}`: unknown element shape `{}`",
                                v.shape
                            ))
                        })?;
                        let overlap = dem::volume_coupling::OverlapMesh {
                            shape,
                            node_ids: mesh.node_ids.clone(),
                            nodes: mesh
                                .positions
                                .as_slice()
                                .chunks(3)
                                .map(|c| dem::hertz_mindlin::V3::new(c[0], c[1], c[2]))
                                .collect(),
                            elements: v.elements.clone(),
                            weights: v.weights.as_slice().to_vec(),
                        };
                        // the provider's ε: both sides use the same penalty
                        let settings = dem::volume_coupling::VolumeSettings {
                            penalty: v.penalty,
                            ..cfg.volume_coupling
                        };
                        engine
                            .add_volume_interface(name, overlap, settings)
                            .map_err(|e| scene_error(format!("{}: {e}", init.scene_path)))?
                    }
                    (None, false) => engine
                        .add_coupled_mesh(name, mesh.positions.as_slice(), &mesh.triangles)
                        .map_err(|e| scene_error(format!("interface `{name}`: {e}")))?,
                    (Some(_), false) | (None, true) => {
                        return Err(scene_error(format!(
                        "interface `{name}` is declared a {:?} interface but its provider sent \
                         a {} mesh",
                        decl.kind,
                        if mesh.volume.is_some() { "volume" } else { "surface" }
                    )))
                    }
                };
            self.coupled.push(Coupled {
                name: name.clone(),
                mesh: id,
                volume,
                nodes: mesh.num_nodes(),
                // a volume interface sends the pull ε V u^DE of the window's end: the FE's
                // implicit penalty (K + ε V) u = F + ε V u^DE is an end-of-step balance, and a
                // window mean lags the driven grains by half a window, which ε V (far stiffer
                // than the continuum) turns into a spurious load
                force_averaging: decl.force_averaging && !volume,
            });
        }
        p.wait_for_peers(self.data_timeout).await?;
        let limits = engine.limits().into_iter().collect();
        self.engine = Some(engine);
        Ok((limits, Vec::new()))
    }

    async fn advance(
        &mut self,
        p: &mut Participant,
        w: &AdvanceWindow,
    ) -> Result<WindowReport, NodeError> {
        if self.discs.is_some() {
            return self.advance_discs(w);
        }
        let step = self.engine()?.time_step();
        let substeps = proto::motion::whole_substeps(w.dt, step).map_err(|ratio| {
            NodeError::new(
                ErrorCode::Protocol,
                format!(
                    "window {}: Δt^C = {} s is not a whole multiple of the DEM time step {step} s (ratio {ratio})",
                    w.window, w.dt
                ),
            )
        })?;
        self.substeps = substeps;
        let t_wait = Instant::now();
        let rule = match w.motion {
            proto::MotionRule::Quadratic => MotionRule::Quadratic,
            proto::MotionRule::Linear | proto::MotionRule::Fixed => MotionRule::Linear,
        };
        // Ullrich ch. 3.3: the mesh follows the provider's kinematics of this window by the
        // window's rule (proto::motion); without new kinematics it stays where it is (which
        // also restarts the force average).
        let mut kinematics = Vec::new();
        for c in &self.coupled {
            kinematics.push(match w.input {
                Some(label) => {
                    let m = p
                        .read_motion(&c.name, label, w.motion, w.dt, c.nodes, self.data_timeout)
                        .await?;
                    (m.positions, m.velocities, m.accelerations)
                }
                None => {
                    let pos = self
                        .engine
                        .as_ref()
                        .map(|e| c.positions(e))
                        .unwrap_or_default();
                    let zeros = vec![0.0; pos.len()];
                    (pos, zeros.clone(), zeros)
                }
            });
        }
        let wait_s = t_wait.elapsed().as_secs_f64();
        let meshes: Vec<(usize, bool)> = self.coupled.iter().map(|c| (c.mesh, c.volume)).collect();
        let out_dir = self.out_dir.clone();
        let engine = self.engine.as_mut().ok_or_else(|| {
            NodeError::new(ErrorCode::Protocol, "a window command came before `init`")
        })?;
        for (&(mesh, volume), (pos, vel, acc)) in meshes.iter().zip(&kinematics) {
            if volume {
                // a particle that left its element stops the run (Wellmann §6.3)
                engine
                    .set_volume_kinematics(mesh, pos, vel, acc, rule)
                    .map_err(|e| {
                        NodeError::new(ErrorCode::Unstable, format!("window {}: {e}", w.window))
                    })?;
            } else {
                engine
                    .set_mesh_kinematics(mesh, pos, vel, acc, rule)
                    .map_err(|e| NodeError::new(ErrorCode::Protocol, e.to_string()))?;
            }
        }
        let unstable = |e: dem::DemError| {
            NodeError::new(ErrorCode::Unstable, format!("window {}: {e}", w.window))
        };
        if let Some(trace) = self.trace.as_mut() {
            // Substep by substep, recording the total force on each coupled mesh, so that
            // force averaging (Ullrich (3.8)) can be checked against what the FEM received.
            for s in 0..substeps {
                engine.advance(1).map_err(unstable)?;
                for c in &self.coupled {
                    let f = total(&c.forces(engine, false));
                    let path = out_dir.join(format!("trace_{}_substep_forces.csv", c.name));
                    trace.row(
                        &path,
                        "window,substep,fx,fy,fz",
                        &[w.window.to_string(), s.to_string()],
                        &f,
                    )?;
                }
            }
            for c in &self.coupled {
                let path = out_dir.join(format!("trace_{}_mesh.csv", c.name));
                let mut row = vec![engine.time()];
                row.extend(c.positions(engine));
                trace.row(
                    &path,
                    "window,t_end,positions...",
                    &[w.window.to_string()],
                    &row,
                )?;
            }
        } else {
            engine.advance(substeps as usize).map_err(unstable)?;
        }
        // the interface forces leave first: the partner waits for them, for the outputs and
        // the monitor below nobody waits (they were on every window's critical path)
        if let Some(label) = w.output {
            self.write_forces(p, label).await?;
        }
        let engine = self.engine.as_mut().ok_or_else(|| {
            NodeError::new(ErrorCode::Protocol, "a window command came before `init`")
        })?;
        engine
            .write_outputs(&out_dir)
            .map_err(|e| NodeError::new(ErrorCode::Io, e.to_string()))?;
        let t_end = engine.time();
        let mut monitor = BTreeMap::from([("kinetic_energy".to_string(), engine.kinetic_energy())]);
        if engine.programme_finished() {
            // a periodic cell ran its last stage: the coordinator ends the run here
            monitor.insert("programme_finished".to_string(), 1.0);
        }
        // where the programme stands, for the coordinator's progress display
        if let Some((stage, progress)) = engine.programme_progress() {
            monitor.insert("programme_stage".to_string(), stage as f64);
            match progress {
                Some(dem::periodic::StageProgress::Strain(f)) => {
                    monitor.insert("programme_strain_fraction".to_string(), f);
                }
                Some(dem::periodic::StageProgress::Stress(f)) => {
                    monitor.insert("programme_stress_fraction".to_string(), f);
                }
                None => {}
            }
        }
        // the interface energy audit: the work of this window's contact forces on each
        // coupled mesh as it moved in the DEM, Σ_steps Δt Σ_nodes f·v
        for c in &self.coupled {
            monitor.insert(
                format!("interface_work.{}", c.name),
                if c.volume {
                    engine.volume_work(c.mesh)
                } else {
                    engine.interface_work(c.mesh)
                },
            );
            if c.volume {
                monitor.insert(
                    format!("penalty_energy.{}", c.name),
                    engine.volume_energy(c.mesh),
                );
            }
            // whether the interface carries contacts now (adaptive windows keep the stiffness
            // limit while it does): the largest nodal force of the window
            let largest = c
                .forces(engine, c.force_averaging)
                .chunks_exact(3)
                .map(|f| (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt())
                .fold(0.0f64, f64::max);
            monitor.insert(format!("interface_force_max.{}", c.name), largest);
            if let Some(t) = (!c.volume)
                .then(|| engine.interface_approach_time(c.mesh))
                .flatten()
            {
                monitor.insert(format!("interface_approach_time.{}", c.name), t);
            }
        }
        Ok(WindowReport {
            wait_s,
            t_end,
            monitor,
        })
    }

    async fn publish(&mut self, p: &mut Participant, label: Label) -> Result<(), NodeError> {
        self.write_forces(p, label).await
    }

    fn snapshot(&self) -> Result<Vec<u8>, NodeError> {
        if let Some(d) = &self.discs {
            return Ok(d.snapshot());
        }
        self.engine
            .as_ref()
            .map(|e| e.snapshot())
            .ok_or_else(|| NodeError::new(ErrorCode::Protocol, "snapshot before `init`"))
    }

    fn restore(&mut self, bytes: &[u8]) -> Result<(), NodeError> {
        if let Some(d) = self.discs.as_mut() {
            return d.restore(bytes).map_err(|e| {
                NodeError::new(ErrorCode::Io, format!("restoring the disc state: {e}"))
            });
        }
        self.engine()?
            .restore(bytes)
            .map_err(|e| NodeError::new(ErrorCode::Io, format!("restoring the DEM state: {e}")))
    }

    fn time_series(&self) -> Option<(&Path, f64)> {
        if let Some(d) = &self.discs {
            return Some((&self.out_dir, d.time()));
        }
        let e = self.engine.as_ref()?;
        Some((&self.out_dir, e.time()))
    }

    fn finish(&mut self) -> Result<BTreeMap<String, f64>, NodeError> {
        let out_dir = self.out_dir.clone();
        if let Some(d) = self.discs.as_mut() {
            d.write_final(&out_dir)
                .map_err(|e| NodeError::new(ErrorCode::Io, e.to_string()))?;
            return Ok(d.results().into_iter().collect());
        }
        match self.engine.as_mut() {
            Some(e) => {
                let io = |e: dem::DemError| NodeError::new(ErrorCode::Io, e.to_string());
                e.write_outputs(&out_dir).map_err(io)?;
                e.write_final_particles(&out_dir).map_err(io)?;
                Ok(e.results().into_iter().collect())
            }
            None => Ok(BTreeMap::new()),
        }
    }
}

fn main() -> std::process::ExitCode {
    proto::node::install_panic_hook("dem-node");
    proto::alloc::keep_message_buffers();
    let args = Args::parse();
    proto::node::init_logging();
    let hello = Hello {
        software: format!("dem-node {}", env!("CARGO_PKG_VERSION")),
        kind: NodeKind::Dem,
        capabilities: vec!["snapshot".into(), "checkpoint".into()],
        pid: std::process::id(),
    };
    let data_timeout = args.node.data_timeout();
    let node = DemNode {
        engine: None,
        discs: None,
        coupled: Vec::new(),
        out_dir: PathBuf::new(),
        data_timeout,
        substeps: 0,
        trace: None,
    };
    main_with(args.node, hello, node)
}
