//! Outputs of the disc engine: `discs.csv` (energies (2.55)–(2.61), contacts, the uniaxial
//! measurement, the macroscopic stress), and ParaView files: `discs_<step>.vtk` (centres with
//! radius, velocity, rotation, stress and strain tensors; show them with a Glyph filter,
//! "Scale by radius", or as points of the radius' size) and `contacts_<step>.vtk` (lines
//! between touching centres with their forces: the force chains), each with a `.pvd` series.

use super::{strain_norm, DiscEngine, DiscError};
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::Path;

/// What has been written and the rows waiting for the next write.
#[derive(Debug, Default)]
pub(super) struct OutputState {
    pub pending: Vec<Vec<f64>>,
    pub rows_written: u64,
    pub last_vtk_step: Option<u64>,
}

const COLUMNS: [&str; 20] = [
    "time",
    "step",
    "kinetic_energy",
    "contact_energy",
    "particle_energy",
    "external_work",
    "dissipated",
    "contacts",
    "bonds",
    "strain_max",
    "overlap_max",
    "stress_yy",
    "strain_yy",
    "strain_xx",
    "macro_stress_xx",
    "macro_stress_yy",
    "macro_stress_xy",
    "stress_xx",
    "stress_xy",
    "strain_xy",
];

/// The columns of `discs.csv`: [`COLUMNS`] and each wall's normal force and displacement.
pub(super) fn columns(e: &DiscEngine) -> Vec<String> {
    let mut c: Vec<String> = COLUMNS.iter().map(|s| s.to_string()).collect();
    for (name, _, _) in e.wall_readings() {
        c.push(format!("{name}.force"));
        c.push(format!("{name}.displacement"));
    }
    for (name, _, _) in e.probe_readings() {
        c.push(format!("{name}.ux"));
        c.push(format!("{name}.uy"));
    }
    c
}

/// One row of `discs.csv` for the current state (`dissipated` is W_ext − E_k − E_el, the
/// energy the dampers and friction took, (2.55)).
pub(super) fn row(e: &DiscEngine) -> Vec<f64> {
    let (ek, ec, ep, w) = (
        e.kinetic_energy(),
        e.contact_energy(),
        e.particle_energy(),
        e.external_work(),
    );
    let active = e.state.pair_state.iter().filter(|p| p.active);
    let contacts = active.clone().count() as f64;
    let overlap = active.map(|p| p.overlap).fold(0.0, f64::max);
    let bonds = e.state.pair_state.iter().filter(|p| p.bonded).count() as f64;
    let strain_max = e
        .strains()
        .iter()
        .map(|s| strain_norm(*s))
        .fold(0.0, f64::max);
    // σ_xx, σ_yy, σ_xy, ε_xx, ε_yy, ε_xy
    let m = e.measurement().unwrap_or([f64::NAN; 6]);
    let macro_ = e.macroscopic_stress();
    let mut r = vec![
        e.time(),
        e.steps() as f64,
        ek,
        ec,
        ep,
        w,
        w - ek - ec - ep,
        contacts,
        bonds,
        strain_max,
        overlap,
        m[1],
        m[4],
        m[3],
        macro_[0],
        macro_[1],
        macro_[2],
        m[0],
        m[2],
        m[5],
    ];
    for (_, force, shift) in e.wall_readings() {
        r.push(force);
        r.push(shift);
    }
    for (_, _, u) in e.probe_readings() {
        r.extend(u);
    }
    r
}

fn io(path: &Path, e: impl std::fmt::Display) -> DiscError {
    DiscError::Output {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}

/// Flushes the waiting CSV rows and writes the VTK files
/// when `vtk_every` steps have passed.
pub(super) fn write(e: &mut DiscEngine, dir: &Path) -> Result<(), DiscError> {
    std::fs::create_dir_all(dir).map_err(|err| io(dir, err))?;
    if !e.output.pending.is_empty() {
        let path = dir.join("discs.csv");
        let new = !path.exists();
        let mut s = String::new();
        if new {
            s.push_str(&columns(e).join(","));
            s.push('\n');
        }
        for r in e.output.pending.drain(..) {
            let cols: Vec<String> = r.iter().map(|v| format!("{v:.12e}")).collect();
            s.push_str(&cols.join(","));
            s.push('\n');
            e.output.rows_written += 1;
        }
        let mut f = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&path)
            .map_err(|err| io(&path, err))?;
        f.write_all(s.as_bytes()).map_err(|err| io(&path, err))?;
    }
    let every = e.cfg.output.vtk_every;
    let step = e.steps();
    let due = every > 0
        && e.output
            .last_vtk_step
            .is_none_or(|last| step >= last + every);
    if due {
        write_vtk_now(e, dir)?;
    }
    Ok(())
}

/// `discs_final.csv`: x,y,radius of every disc now (the `file` source of a later scene).
pub(super) fn write_final_discs(e: &DiscEngine, dir: &Path) -> Result<(), DiscError> {
    let mut s = String::from("x,y,radius\n");
    for (x, r) in e.state.x.iter().zip(&e.radius) {
        let _ = writeln!(s, "{:.17e},{:.17e},{:.17e}", x[0], x[1], r);
    }
    put(&dir.join("discs_final.csv"), &s)
}

/// The VTK files of the current state (the last state of a run, or a due one).
pub(super) fn write_vtk_now(e: &mut DiscEngine, dir: &Path) -> Result<(), DiscError> {
    std::fs::create_dir_all(dir).map_err(|err| io(dir, err))?;
    let step = e.steps();
    write_discs_vtk(&dir.join(format!("discs_{step:09}.vtk")), e)?;
    write_contacts_vtk(&dir.join(format!("contacts_{step:09}.vtk")), e)?;
    for prefix in ["discs", "contacts"] {
        crate::output::write_pvd(dir, prefix, e.time_step()).map_err(|err| io(dir, err))?;
    }
    e.output.last_vtk_step = Some(step);
    Ok(())
}

fn put(path: &Path, s: &str) -> Result<(), DiscError> {
    std::fs::write(path, s).map_err(|err| io(path, err))
}

/// A 2-D symmetric tensor σ̃ = [xx, yy, xy] as the nine entries of a 3-D one (zz = 0: the
/// in-plane part).
fn tensor(s: &mut String, t: [f64; 3]) {
    let _ = writeln!(
        s,
        "{:e} {:e} 0\n{:e} {:e} 0\n0 0 0\n",
        t[0], t[2], t[2], t[1]
    );
}

/// The discs as VTK legacy polydata: one vertex per disc at its centre (z = 0) with `radius`,
/// `velocity`, `rotation`, `stress` (Pa) and `strain` tensors (in-plane parts), `fixed`.
pub fn write_discs_vtk(path: &Path, e: &DiscEngine) -> Result<(), DiscError> {
    let n = e.num_discs();
    let st = &e.state;
    let mut s = String::with_capacity(200 * n + 256);
    let _ = writeln!(
        s,
        "# vtk DataFile Version 3.0\ncosim discs t = {:e} s\nASCII\nDATASET POLYDATA\nPOINTS {n} double",
        e.time()
    );
    for x in &st.x {
        let _ = writeln!(s, "{:e} {:e} 0", x[0], x[1]);
    }
    let _ = writeln!(s, "VERTICES {n} {}", 2 * n);
    for p in 0..n {
        let _ = writeln!(s, "1 {p}");
    }
    let _ = writeln!(
        s,
        "POINT_DATA {n}\nSCALARS radius double 1\nLOOKUP_TABLE default"
    );
    for r in &e.radius {
        let _ = writeln!(s, "{r:e}");
    }
    let _ = writeln!(s, "VECTORS velocity double");
    for v in &st.v {
        let _ = writeln!(s, "{:e} {:e} 0", v[0], v[1]);
    }
    let _ = writeln!(s, "SCALARS rotation double 1\nLOOKUP_TABLE default");
    for t in &st.theta {
        let _ = writeln!(s, "{t:e}");
    }
    let _ = writeln!(s, "SCALARS fixed int 1\nLOOKUP_TABLE default");
    for f in &e.free {
        let _ = writeln!(s, "{}", f.iter().any(|k| !k) as i32);
    }
    let _ = writeln!(s, "TENSORS stress double");
    for t in &st.stress {
        tensor(&mut s, *t);
    }
    let _ = writeln!(s, "TENSORS strain double");
    for t in e.strains() {
        // ε̃_3 = 2 ε_xy
        tensor(&mut s, [t[0], t[1], 0.5 * t[2]]);
    }
    put(path, &s)
}

/// The touching pairs as lines between the centres, with `normal_force`, `tangential_force`
/// (N, compression positive), `overlap` (m) and `bonded`.
fn write_contacts_vtk(path: &Path, e: &DiscEngine) -> Result<(), DiscError> {
    let st = &e.state;
    let n = e.num_discs();
    let active: Vec<usize> = (0..st.pairs.len())
        .filter(|&k| st.pair_state[k].active)
        .collect();
    let m = active.len();
    // a contact across a periodic side ends at its partner's image: an extra point
    let mut ends = Vec::with_capacity(m);
    let mut extra = Vec::new();
    for &k in &active {
        let (i, j) = (st.pairs[k].0 as usize, st.pairs[k].1 as usize);
        match e.across(i, j) {
            None => ends.push((i, j)),
            Some(d) => {
                ends.push((i, n + extra.len()));
                extra.push([st.x[i][0] + d[0], st.x[i][1] + d[1]]);
            }
        }
    }
    let mut s = String::with_capacity(60 * (n + m) + 256);
    let _ = writeln!(
        s,
        "# vtk DataFile Version 3.0\ncosim disc contacts t = {:e} s\nASCII\nDATASET POLYDATA\nPOINTS {} double",
        e.time(),
        n + extra.len()
    );
    for x in st.x.iter().chain(&extra) {
        let _ = writeln!(s, "{:e} {:e} 0", x[0], x[1]);
    }
    let _ = writeln!(s, "LINES {m} {}", 3 * m);
    for (a, b) in ends {
        let _ = writeln!(s, "2 {a} {b}");
    }
    let _ = writeln!(s, "CELL_DATA {m}");
    type Field = fn(&super::PairState) -> f64;
    let fields: [(&str, Field); 4] = [
        ("normal_force", |p| p.fn_total),
        ("tangential_force", |p| p.ft_total),
        ("overlap", |p| p.overlap),
        ("bonded", |p| p.bonded as i32 as f64),
    ];
    for (name, f) in fields {
        let _ = writeln!(s, "SCALARS {name} double 1\nLOOKUP_TABLE default");
        for &k in &active {
            let _ = writeln!(s, "{:e}", f(&st.pair_state[k]));
        }
    }
    put(path, &s)
}
