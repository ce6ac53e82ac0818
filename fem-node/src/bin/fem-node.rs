//! `fem-node`: the FEM engine as a node of a co-simulation run. A thin adapter: it speaks
//! `proto` over zenoh and calls the `fem` engine; all mechanics is in the library.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use clap::Parser;
use fem::Structure;
use proto::cli::NodeArgs;
use proto::node::{main_with, total, NodeError, Solver, Trace, WindowReport};
use proto::participant::{Participant, Side};
use proto::{
    AdvanceWindow, ErrorCode, Hello, Init, InterfaceKinematics, InterfaceMesh, Label, NodeKind,
    PROTOCOL_VERSION,
};

#[derive(Parser)]
#[command(
    name = "fem-node",
    version,
    about = "FEM solver node of a cosim run (started by `cosim run`)"
)]
struct Args {
    #[command(flatten)]
    node: NodeArgs,
}

struct FemNode {
    model: Option<Box<dyn Structure>>,
    /// The single coupled interface of this node (name, nodes).
    interface: Option<(String, usize)>,
    out_dir: PathBuf,
    data_timeout: std::time::Duration,
    trace: Option<Trace>,
    /// The scene's table and folder, for the pure-FEM reference of a one-way solve.
    config: Option<(fem::config::FemConfig, PathBuf)>,
    /// Results of that reference, reported with the model's own.
    reference: BTreeMap<String, f64>,
    /// Model time of the last output row, so that `finish` does not repeat it.
    last_output_time: Option<f64>,
    /// The interface energy audit: the window index and interface displacement (flat xyz,
    /// end − start) of the last window, to pair forces that arrive a window later with the
    /// motion they were computed on (predictive). Part of the node's snapshot.
    last_displacement: Option<(u64, Vec<f64>)>,
}

/// What a FEM node's snapshot holds: the model's state and the audit's memory.
#[derive(serde::Serialize, serde::Deserialize)]
struct NodeState {
    model: Vec<u8>,
    last_displacement: Option<(u64, Vec<f64>)>,
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Ullrich ch. 4 / REFERENCE A3: the pure-FEM solution under the same total interface load
/// applied as a uniform pressure on the interface surface. Returns the reference model's
/// results (`pressure_equivalent.*`) and the coupled/pure relative differences of the probes.
fn pressure_equivalent(
    cfg: &fem::config::FemConfig,
    base: &Path,
    coupled: &dyn Structure,
) -> Result<BTreeMap<String, f64>, NodeError> {
    let Some(iface) = cfg.interface.as_ref() else {
        return Ok(BTreeMap::new());
    };
    let results: BTreeMap<String, f64> = coupled.results().into_iter().collect();
    let total = [
        results.get("interface_force.x").copied().unwrap_or(0.0),
        results.get("interface_force.y").copied().unwrap_or(0.0),
        results.get("interface_force.z").copied().unwrap_or(0.0),
    ];
    // area and area-weighted normal the pressure pushes against
    let (area, normal) = coupled.pressure_surface();
    if area <= 0.0 {
        return Ok(BTreeMap::new());
    }
    // pressure pushes into the body: minus the load's component along the outward normal
    let n_len = (normal[0] * normal[0] + normal[1] * normal[1] + normal[2] * normal[2])
        .sqrt()
        .max(f64::MIN_POSITIVE);
    let pressure =
        -(total[0] * normal[0] + total[1] * normal[1] + total[2] * normal[2]) / n_len / area;
    let mut reference_cfg = cfg.clone();
    reference_cfg.interface = None;
    reference_cfg.loads.push(fem::config::Load::Pressure {
        on: iface.on.clone(),
        value: pressure,
        history: None,
    });
    let mut reference =
        fem::build(&reference_cfg, base).map_err(|e| fem_error(ErrorCode::Internal, e))?;
    reference
        .solve_static()
        .map_err(|e| fem_error(ErrorCode::Internal, e))?;
    let mut out = BTreeMap::from([("pressure_equivalent.pressure".to_string(), pressure)]);
    let reference_results = reference.results();
    // components below a millionth of the largest displacement are round-off, not results
    let scale = reference_results
        .iter()
        .find(|(k, _)| k == "max_displacement")
        .map(|(_, v)| *v)
        .unwrap_or(0.0);
    for (k, v) in reference_results {
        if let Some(coupled_value) = results.get(&k).filter(|_| k.starts_with("probe.")) {
            if v.abs() > 1e-6 * scale {
                out.insert(
                    format!("coupled_vs_pressure.{k}"),
                    (coupled_value - v) / v.abs(),
                );
            }
        }
        out.insert(format!("pressure_equivalent.{k}"), v);
    }
    Ok(out)
}

fn scene_error(e: impl std::fmt::Display) -> NodeError {
    NodeError::new(ErrorCode::Scene, e.to_string())
}

fn fem_error(code: ErrorCode, e: impl std::fmt::Display) -> NodeError {
    NodeError::new(code, e.to_string())
}

impl FemNode {
    fn model(&mut self) -> Result<&mut Box<dyn Structure>, NodeError> {
        self.model.as_mut().ok_or_else(|| {
            NodeError::new(ErrorCode::Protocol, "a window command came before `init`")
        })
    }

    /// Publishes the interface's state (P, V, A at `time`) labelled `label`. How the users move
    /// their meshes from it is the schedule's business (proto::motion), not this node's.
    async fn write_kinematics(
        &self,
        p: &Participant,
        label: Label,
        time: f64,
        (positions, velocities, accelerations): (Vec<f64>, Vec<f64>, Vec<f64>),
    ) -> Result<(), NodeError> {
        let Some((name, _)) = &self.interface else {
            return Ok(());
        };
        p.write_kinematics(&InterfaceKinematics {
            version: PROTOCOL_VERSION,
            run_id: p.run_id().to_string(),
            interface: name.clone(),
            window: label.window,
            iteration: label.iteration,
            time,
            positions: positions.into(),
            velocities: velocities.into(),
            accelerations: accelerations.into(),
        })
        .await?;
        Ok(())
    }
}

impl Solver for FemNode {
    async fn init(
        &mut self,
        p: &mut Participant,
        init: &Init,
    ) -> Result<(BTreeMap<String, f64>, Vec<String>), NodeError> {
        let cfg = init.scene_table(fem::parse_scene_table)?;
        let base = init.scene_dir();
        let mut model =
            fem::build(&cfg, base).map_err(|e| scene_error(format!("{}: {e}", init.scene_path)))?;
        self.config = Some((cfg.clone(), base.to_path_buf()));
        self.out_dir = init.node_out_dir(p.node())?;
        self.trace = init.trace.then(Trace::default);
        let mine: Vec<_> = init
            .interfaces
            .iter()
            .filter(|i| i.provider == p.node())
            .collect();
        if mine.len() > 1 {
            return Err(scene_error(format!(
                "{}: coupling.interfaces gives node `{}` {} interfaces ({}); a FEM node provides one surface (give each structure its own node)",
                init.scene_path,
                p.node(),
                mine.len(),
                mine.iter().map(|i| format!("`{}`", i.name)).collect::<Vec<_>>().join(", ")
            )));
        }
        let opened = p.open_interfaces(&init.interfaces).await?;
        if let Some((decl, side)) = opened.first() {
            if *side != Side::Provider {
                return Err(scene_error(format!(
                    "{}: interface `{}` names the FEM node `{}` as a user; a FEM node provides its surface (set provider = \"{}\")",
                    init.scene_path,
                    decl.name,
                    p.node(),
                    p.node()
                )));
            }
            let name = &decl.name;
            let m = model.interface_mesh();
            match (decl.kind, m.volume.is_some()) {
                (proto::InterfaceKind::Volume, false) => {
                    return Err(scene_error(format!(
                        "{}: interface `{name}` is a volume interface but the FEM model has no \
                         [fem.overlap]",
                        init.scene_path
                    )))
                }
                (proto::InterfaceKind::Surface, true) => {
                    return Err(scene_error(format!(
                        "{}: the FEM model overlaps particles ([fem.overlap]) but interface \
                         `{name}` is declared a surface: give it kind = \"volume\" in \
                         coupling.interfaces",
                        init.scene_path
                    )))
                }
                _ => {}
            }
            let mesh = InterfaceMesh {
                version: PROTOCOL_VERSION,
                run_id: p.run_id().to_string(),
                interface: name.clone(),
                node_ids: m.node_ids,
                positions: m.positions.into(),
                triangles: m.triangles,
                volume: m.volume.map(|v| proto::VolumeElements {
                    shape: v.shape,
                    elements: v.elements,
                    weights: v.weights.into(),
                    penalty: v.penalty,
                }),
            };
            self.interface = Some((name.clone(), mesh.num_nodes()));
            p.provide_mesh(&mesh).await?;
            p.wait_for_peers(self.data_timeout).await?;
        }
        let limits = model
            .limits()
            .map_err(|e| scene_error(format!("{}: {e}", init.scene_path)))?;
        let warnings = model.warnings();
        self.model = Some(model);
        Ok((limits, warnings))
    }

    async fn advance(
        &mut self,
        p: &mut Participant,
        w: &AdvanceWindow,
    ) -> Result<WindowReport, NodeError> {
        let t_wait = Instant::now();
        let forces = match (w.input, &self.interface) {
            (Some(label), Some((name, nodes))) => {
                let (name, nodes) = (name.clone(), *nodes);
                Some(
                    p.read_forces(&name, label, nodes, self.data_timeout)
                        .await?,
                )
            }
            _ => None,
        };
        let wait_s = t_wait.elapsed().as_secs_f64();
        let out_dir = self.out_dir.clone();
        if let (Some(f), Some(trace)) = (&forces, self.trace.as_mut()) {
            let path = out_dir.join(format!("trace_{}_received_forces.csv", f.interface));
            let prefix = [f.window.to_string(), f.averaged.to_string()];
            trace.row(
                &path,
                "window,averaged,fx,fy,fz",
                &prefix,
                &total(f.forces.as_slice()),
            )?;
        }
        let model = self.model.as_mut().ok_or_else(|| {
            NodeError::new(ErrorCode::Protocol, "a window command came before `init`")
        })?;
        let received = forces.as_ref().map(|f| f.window);
        if let Some(f) = forces {
            model
                .set_interface_forces(f.forces.as_slice())
                .map_err(|e| fem_error(ErrorCode::Protocol, e))?;
        }
        let start_positions = model.interface_kinematics().0;
        if w.static_solve {
            model
                .solve_static()
                .map_err(|e| fem_error(ErrorCode::Unstable, format!("window {}: {e}", w.window)))?;
            // one-way coupling: compare with the pure-FEM solve under the same total load
            if let Some((cfg, base)) = &self.config {
                self.reference = pressure_equivalent(cfg, base, model.as_ref())?;
            }
        } else {
            model
                .advance(w.dt)
                .map_err(|e| fem_error(ErrorCode::Unstable, format!("window {}: {e}", w.window)))?;
        }
        let t_end = model.time();
        let (pos, vel, acc) = model.interface_kinematics();
        // the kinematics leave first: the partner waits for them, for the outputs and the
        // audit below nobody waits (they were on every window's critical path)
        if let Some(label) = w.output {
            self.write_kinematics(p, label, t_end, (pos.clone(), vel.clone(), acc.clone()))
                .await?;
        }
        let model = self.model.as_mut().ok_or_else(|| {
            NodeError::new(ErrorCode::Protocol, "a window command came before `init`")
        })?;
        model
            .write_outputs(&out_dir)
            .map_err(|e| fem_error(ErrorCode::Io, e))?;
        self.last_output_time = Some(t_end);
        // the interface energy audit: the work of the interface loads over this step (they are
        // held constant through it), f · Δx; and the work of the forces just received over
        // the displacement of the window they were computed in (this one for just-in-time,
        // the previous one for predictive): with force averaging and predictive motion the
        // DEM's own account of its work equals the latter to round-off (docs/coupling.md)
        let displacement: Vec<f64> = pos
            .iter()
            .zip(&start_positions)
            .map(|(e, s)| e - s)
            .collect();
        let mut audit = Vec::new();
        if let Some((name, _)) = &self.interface {
            let held = model.held_interface_forces();
            audit.push((format!("interface_work.{name}"), dot(held, &displacement)));
            let paired = match (received, &self.last_displacement) {
                (Some(k), _) if k == w.window => Some(&displacement),
                (Some(k), Some((j, d))) if k == *j => Some(d),
                _ => None,
            };
            if let Some(d) = paired {
                audit.push((format!("interface_work_received.{name}"), dot(held, d)));
            }
        }
        self.last_displacement = Some((w.window, displacement));
        if let (Some(trace), Some((name, _))) = (self.trace.as_mut(), &self.interface) {
            let path = out_dir.join(format!("trace_{name}_mesh.csv"));
            let mut row = vec![t_end];
            row.extend(pos.iter().chain(&vel).chain(&acc));
            trace.row(
                &path,
                "window,t_end,positions...,velocities...,accelerations...",
                &[w.window.to_string()],
                &row,
            )?;
        }
        let mut monitor = BTreeMap::from([(
            "max_interface_speed".to_string(),
            vel.chunks_exact(3)
                .map(|v| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt())
                .fold(0.0, f64::max),
        )]);
        monitor.extend(audit);
        Ok(WindowReport {
            wait_s,
            t_end,
            monitor,
        })
    }

    async fn publish(&mut self, p: &mut Participant, label: Label) -> Result<(), NodeError> {
        let model = self.model()?;
        let time = model.time();
        let kin = model.interface_kinematics();
        self.write_kinematics(p, label, time, kin).await
    }

    fn snapshot(&self) -> Result<Vec<u8>, NodeError> {
        let model = self
            .model
            .as_ref()
            .map(|m| m.snapshot())
            .ok_or_else(|| NodeError::new(ErrorCode::Protocol, "snapshot before `init`"))?;
        let state = NodeState {
            model,
            last_displacement: self.last_displacement.clone(),
        };
        rmp_serde::to_vec(&state).map_err(|e| {
            fem_error(
                ErrorCode::Internal,
                format!("encoding the FEM node state: {e}"),
            )
        })
    }

    fn restore(&mut self, bytes: &[u8]) -> Result<(), NodeError> {
        let state: NodeState = rmp_serde::from_slice(bytes)
            .map_err(|e| fem_error(ErrorCode::Io, format!("restoring the FEM state: {e}")))?;
        self.model()?
            .restore(&state.model)
            .map_err(|e| fem_error(ErrorCode::Io, format!("restoring the FEM state: {e}")))?;
        self.last_displacement = state.last_displacement;
        Ok(())
    }

    fn time_series(&self) -> Option<(&Path, f64)> {
        let m = self.model.as_ref()?;
        Some((&self.out_dir, m.time()))
    }

    fn finish(&mut self) -> Result<BTreeMap<String, f64>, NodeError> {
        let out_dir = self.out_dir.clone();
        match self.model.as_mut() {
            Some(m) => {
                // the state after the last window is already written (time series row, VTU)
                if self.last_output_time != Some(m.time()) {
                    m.write_outputs(&out_dir)
                        .map_err(|e| fem_error(ErrorCode::Io, e))?;
                }
                let mut results: BTreeMap<String, f64> = m.results().into_iter().collect();
                results.extend(std::mem::take(&mut self.reference));
                Ok(results)
            }
            None => Ok(BTreeMap::new()),
        }
    }
}

fn main() -> std::process::ExitCode {
    proto::node::install_panic_hook("fem-node");
    proto::alloc::keep_message_buffers();
    let args = Args::parse();
    proto::node::init_logging();
    let hello = Hello {
        software: format!("fem-node {}", env!("CARGO_PKG_VERSION")),
        kind: NodeKind::Fem,
        capabilities: vec![
            "snapshot".into(),
            "checkpoint".into(),
            "static".into(),
            "dynamic".into(),
        ],
        pid: std::process::id(),
    };
    let data_timeout = args.node.data_timeout();
    let node = FemNode {
        model: None,
        interface: None,
        out_dir: PathBuf::new(),
        data_timeout,
        trace: None,
        config: None,
        reference: BTreeMap::new(),
        last_output_time: None,
        last_displacement: None,
    };
    main_with(args.node, hello, node)
}
