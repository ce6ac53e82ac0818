//! Output: legacy VTK files (readable by ParaView) for particles and meshes, and a CSV time
//! series.

use crate::particles::Particles;
use crate::walls::Mesh;
use crate::DemError;
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::Path;

fn io_err(path: &Path, e: impl std::fmt::Display) -> DemError {
    DemError::Output {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}

fn write_file(path: &Path, text: &str) -> Result<(), DemError> {
    std::fs::write(path, text).map_err(|e| io_err(path, e))
}

/// Particles as VTK legacy unstructured grid of vertices with radius, velocity, angular
/// velocity and id (use ParaView's Glyph filter with "radius" as scale array).
pub fn write_particles_vtk(path: &Path, p: &Particles, time: f64) -> Result<(), DemError> {
    let n = p.len();
    let mut s = String::with_capacity(120 * n + 256);
    let _ = writeln!(
        s,
        "# vtk DataFile Version 3.0\nDEM particles t={time:.9e}\nASCII\nDATASET UNSTRUCTURED_GRID"
    );
    let _ = writeln!(s, "POINTS {n} double");
    for x in &p.position {
        let _ = writeln!(s, "{:.9e} {:.9e} {:.9e}", x.x, x.y, x.z);
    }
    let _ = writeln!(s, "CELLS {n} {}", 2 * n);
    for k in 0..n {
        let _ = writeln!(s, "1 {k}");
    }
    let _ = writeln!(s, "CELL_TYPES {n}");
    for _ in 0..n {
        s.push_str("1\n");
    }
    let _ = writeln!(
        s,
        "POINT_DATA {n}\nSCALARS radius double 1\nLOOKUP_TABLE default"
    );
    for r in &p.radius {
        let _ = writeln!(s, "{r:.9e}");
    }
    let _ = writeln!(s, "SCALARS id int 1\nLOOKUP_TABLE default");
    for id in &p.id {
        let _ = writeln!(s, "{id}");
    }
    let _ = writeln!(s, "VECTORS velocity double");
    for v in &p.velocity {
        let _ = writeln!(s, "{:.9e} {:.9e} {:.9e}", v.x, v.y, v.z);
    }
    let _ = writeln!(s, "VECTORS angular_velocity double");
    for v in &p.angular_velocity {
        let _ = writeln!(s, "{:.9e} {:.9e} {:.9e}", v.x, v.y, v.z);
    }
    write_file(path, &s)
}

/// A triangle mesh as VTK legacy polydata, with the last nodal interface forces.
pub fn write_mesh_vtk(path: &Path, m: &Mesh) -> Result<(), DemError> {
    let n = m.positions.len();
    let nt = m.triangles.len();
    let mut s = String::with_capacity(80 * (n + nt) + 256);
    let _ = writeln!(
        s,
        "# vtk DataFile Version 3.0\nDEM mesh {}\nASCII\nDATASET POLYDATA",
        m.name
    );
    let _ = writeln!(s, "POINTS {n} double");
    for x in &m.positions {
        let _ = writeln!(s, "{:.9e} {:.9e} {:.9e}", x.x, x.y, x.z);
    }
    let _ = writeln!(s, "POLYGONS {nt} {}", 4 * nt);
    for t in &m.triangles {
        let _ = writeln!(s, "3 {} {} {}", t[0], t[1], t[2]);
    }
    let _ = writeln!(s, "POINT_DATA {n}\nVECTORS interface_force double");
    for f in &m.nodal_force_last {
        let _ = writeln!(s, "{:.9e} {:.9e} {:.9e}", f.x, f.y, f.z);
    }
    let _ = writeln!(s, "VECTORS velocity double");
    for v in &m.velocities {
        let _ = writeln!(s, "{:.9e} {:.9e} {:.9e}", v.x, v.y, v.z);
    }
    let _ = writeln!(
        s,
        "CELL_DATA {nt}\nSCALARS patch int 1\nLOOKUP_TABLE default"
    );
    for p in &m.patch {
        let _ = writeln!(s, "{p}");
    }
    write_file(path, &s)
}

/// `<dir>/<prefix>.pvd`: a ParaView collection of every `<prefix>_<step>.vtk` in `dir`, at time
/// step × `dt`, so that ParaView opens the whole run as one time series. Made from the folder's
/// files, so it also holds after a resumed run rewrote some of them.
pub fn write_pvd(dir: &Path, prefix: &str, dt: f64) -> Result<(), DemError> {
    let mut steps: Vec<(u64, String)> = std::fs::read_dir(dir)
        .map_err(|e| io_err(dir, e))?
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            let step = name
                .strip_prefix(prefix)?
                .strip_prefix('_')?
                .strip_suffix(".vtk")?
                .parse::<u64>()
                .ok()?;
            Some((step, name))
        })
        .collect();
    steps.sort();
    let mut s = String::from(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\">\n<Collection>\n",
    );
    for (step, name) in &steps {
        let _ = writeln!(
            s,
            "<DataSet timestep=\"{:e}\" part=\"0\" file=\"{name}\"/>",
            *step as f64 * dt
        );
    }
    s.push_str("</Collection>\n</VTKFile>\n");
    write_file(&dir.join(format!("{prefix}.pvd")), &s)
}

/// Appends one row (with a header for a new file) to a CSV file.
pub fn append_csv(path: &Path, columns: &[(String, f64)]) -> Result<(), DemError> {
    let new = !path.exists();
    let mut f = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
        .map_err(|e| io_err(path, e))?;
    let mut s = String::new();
    if new {
        s.push_str(
            &columns
                .iter()
                .map(|c| c.0.as_str())
                .collect::<Vec<_>>()
                .join(","),
        );
        s.push('\n');
    }
    s.push_str(
        &columns
            .iter()
            .map(|c| format!("{:.12e}", c.1))
            .collect::<Vec<_>>()
            .join(","),
    );
    s.push('\n');
    f.write_all(s.as_bytes()).map_err(|e| io_err(path, e))
}
