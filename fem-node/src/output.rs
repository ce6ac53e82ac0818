//! VTK XML unstructured grid (`.vtu`, ASCII) and CSV helpers.

use crate::element::von_mises;
use crate::mesh::Mesh;
use std::fmt::Write as _;
use std::io::Write;
use std::path::Path;

/// Writes the mesh with point data displacement/velocity and cell data stress / von Mises.
pub fn write_vtu(
    path: &Path,
    mesh: &Mesh,
    u: &[f64],
    v: &[f64],
    stress: &[[f64; 6]],
    cell_scalars: &[(&str, &[f64])],
) -> std::io::Result<()> {
    let types: Vec<u8> = mesh.kinds.iter().map(|k| k.vtk_type()).collect();
    let von: Vec<f64> = stress.iter().map(von_mises).collect();
    let flat: Vec<f64> = stress.iter().flatten().copied().collect();
    let mut cells = vec![("von_mises", 1, &von[..]), ("stress", 6, &flat[..])];
    cells.extend(cell_scalars.iter().map(|(n, d)| (*n, 1, *d)));
    write_grid(
        path,
        &mesh.nodes,
        &mesh.conn,
        &mesh.offsets[1..],
        &types,
        &[("displacement", u), ("velocity", v)],
        &cells,
    )
}

/// VTK's quadrilateral cell type.
pub const VTK_QUAD: u8 = 9;

/// Writes cells of one type with `per_cell` nodes each (`conn` flat): 3-component point
/// vectors (the first is the active one) and scalar cell data.
pub fn write_cells(
    path: &Path,
    points: &[[f64; 3]],
    conn: &[u32],
    per_cell: usize,
    vtk_type: u8,
    point_vectors: &[(&str, &[f64])],
    cell_scalars: &[(&str, &[f64])],
) -> std::io::Result<()> {
    let n = conn.len() / per_cell;
    let ends: Vec<usize> = (1..=n).map(|c| c * per_cell).collect();
    let cells: Vec<(&str, usize, &[f64])> = cell_scalars.iter().map(|(a, d)| (*a, 1, *d)).collect();
    write_grid(
        path,
        points,
        conn,
        &ends,
        &vec![vtk_type; n],
        point_vectors,
        &cells,
    )
}

/// The `.vtu` writer behind both: cell c has nodes `conn[ends[c − 1]..ends[c]]` and type
/// `types[c]`; `cell_arrays` are (name, components, flat values).
pub fn write_grid(
    path: &Path,
    points: &[[f64; 3]],
    conn: &[u32],
    ends: &[usize],
    types: &[u8],
    point_vectors: &[(&str, &[f64])],
    cell_arrays: &[(&str, usize, &[f64])],
) -> std::io::Result<()> {
    let mut s = String::with_capacity(64 * points.len() + 128 * ends.len());
    let _ = writeln!(s, "<?xml version=\"1.0\"?>");
    let _ = writeln!(s, "<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\">");
    let _ = writeln!(s, "<UnstructuredGrid>");
    let _ = writeln!(
        s,
        "<Piece NumberOfPoints=\"{}\" NumberOfCells=\"{}\">",
        points.len(),
        ends.len()
    );
    s.push_str(
        "<Points>\n<DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"ascii\">\n",
    );
    for p in points {
        let _ = writeln!(s, "{:e} {:e} {:e}", p[0], p[1], p[2]);
    }
    s.push_str("</DataArray>\n</Points>\n<Cells>\n<DataArray type=\"Int64\" Name=\"connectivity\" format=\"ascii\">\n");
    let mut start = 0;
    for &end in ends {
        let nodes: Vec<String> = conn[start..end].iter().map(|n| n.to_string()).collect();
        let _ = writeln!(s, "{}", nodes.join(" "));
        start = end;
    }
    s.push_str("</DataArray>\n<DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">\n");
    for end in ends {
        let _ = write!(s, "{end} ");
    }
    s.push_str("\n</DataArray>\n<DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">\n");
    for t in types {
        let _ = write!(s, "{t} ");
    }
    let active = point_vectors.first().map_or("", |p| p.0);
    let _ = writeln!(
        s,
        "\n</DataArray>\n</Cells>\n<PointData Vectors=\"{active}\">"
    );
    for (name, data) in point_vectors {
        let _ = writeln!(s, "<DataArray type=\"Float64\" Name=\"{name}\" NumberOfComponents=\"3\" format=\"ascii\">");
        for c in data.chunks(3) {
            let _ = writeln!(s, "{:e} {:e} {:e}", c[0], c[1], c[2]);
        }
        s.push_str("</DataArray>\n");
    }
    let scalars = cell_arrays.first().map_or("", |c| c.0);
    let _ = writeln!(s, "</PointData>\n<CellData Scalars=\"{scalars}\">");
    for (name, k, data) in cell_arrays {
        let _ = writeln!(
            s,
            "<DataArray type=\"Float64\" Name=\"{name}\" NumberOfComponents=\"{k}\" format=\"ascii\">"
        );
        for c in data.chunks(*k) {
            let row: Vec<String> = c.iter().map(|x| format!("{x:e}")).collect();
            let _ = writeln!(s, "{}", row.join(" "));
        }
        s.push_str("</DataArray>\n");
    }
    s.push_str("</CellData>\n</Piece>\n</UnstructuredGrid>\n</VTKFile>\n");
    std::fs::write(path, s)
}

/// ParaView collection of the written `.vtu` files with their times.
pub fn write_pvd(path: &Path, files: &[(f64, String)]) -> std::io::Result<()> {
    let mut s = String::from(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\">\n<Collection>\n",
    );
    for (t, f) in files {
        let _ = writeln!(s, "<DataSet timestep=\"{t:e}\" part=\"0\" file=\"{f}\"/>");
    }
    s.push_str("</Collection>\n</VTKFile>\n");
    std::fs::write(path, s)
}

/// A window output's I/O failure, naming the file.
pub(crate) fn io_error(e: std::io::Error, path: &Path) -> crate::FemError {
    crate::FemError::Io {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}

/// Creates a window's output folder.
pub(crate) fn create_dir(out_dir: &Path) -> Result<(), crate::FemError> {
    std::fs::create_dir_all(out_dir).map_err(|e| io_error(e, out_dir))
}

/// The probes of a thin structure (`kind`: "shell", "membrane") as (name, node): a node named
/// by its file id must be one of the structure's (`used`); a point takes the used node nearest
/// to it, which must lie within the structure's longest edge of it (from `cells`, each a
/// closed polygon of node indices).
pub(crate) fn thin_probes<'a>(
    probes: &[crate::config::Probe],
    mesh: &Mesh,
    used: &[bool],
    cells: impl Iterator<Item = &'a [u32]>,
    kind: &str,
) -> Result<Vec<(String, u32)>, crate::FemError> {
    let dist = |a: [f64; 3], b: [f64; 3]| {
        ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
    };
    let longest = cells
        .flat_map(|c| (0..c.len()).map(move |k| (c[k] as usize, c[(k + 1) % c.len()] as usize)))
        .map(|(a, b)| dist(mesh.nodes[a], mesh.nodes[b]))
        .fold(0.0, f64::max);
    let mut out = Vec::with_capacity(probes.len());
    for (i, p) in probes.iter().enumerate() {
        let node = if let Some(id) = p.node {
            mesh.node_ids
                .iter()
                .position(|&x| x == id)
                .filter(|&n| used[n])
                .ok_or_else(|| {
                    crate::FemError::Selection(format!(
                        "fem.probes[{i}] '{}': node {id} is not a {kind} node of {}",
                        p.name, mesh.source
                    ))
                })? as u32
        } else {
            let q = p.point.expect("validated");
            let (d, n) = (0..mesh.nodes.len())
                .filter(|&n| used[n])
                .map(|n| (dist(mesh.nodes[n], q), n as u32))
                .fold((f64::INFINITY, 0), |a, b| if b.0 < a.0 { b } else { a });
            if d > longest {
                return Err(crate::FemError::Selection(format!(
                    "fem.probes[{i}] '{}': point {q:?} is {d:.3e} m from the nearest {kind} \
                     node ({}), farther than the longest {kind} edge ({longest:.3e} m)",
                    p.name, mesh.node_ids[n as usize]
                )));
            }
            n
        };
        out.push((p.name.clone(), node));
    }
    Ok(out)
}

/// `fem_probes.csv`'s probe columns: `probe.<name>.ux`, `.uy`, `.uz` for each probe.
pub(crate) fn probe_header(text: &mut String, probes: &[(String, u32)]) {
    for (name, _) in probes {
        for c in ["ux", "uy", "uz"] {
            let _ = write!(text, ",probe.{name}.{c}");
        }
    }
}

/// The probes' displacements in a `fem_probes.csv` row: the first three of the `stride`
/// dofs of each probe's node in `u`.
pub(crate) fn probe_row(text: &mut String, probes: &[(String, u32)], u: &[f64], stride: usize) {
    for &(_, n) in probes {
        for c in 0..3 {
            let _ = write!(text, ",{:.9e}", u[stride * n as usize + c]);
        }
    }
}

/// The probes' displacements as `summary.json` results (`probe.<name>.ux`, …).
pub(crate) fn probe_results(
    r: &mut Vec<(String, f64)>,
    probes: &[(String, u32)],
    u: &[f64],
    stride: usize,
) {
    for (name, n) in probes {
        for (c, ax) in ["ux", "uy", "uz"].iter().enumerate() {
            r.push((format!("probe.{name}.{ax}"), u[stride * *n as usize + c]));
        }
    }
}

/// The sum of the interface forces (x, y, z per interface node) as `summary.json` results
/// `interface_force.x`, `.y`, `.z`.
pub(crate) fn interface_force_results(r: &mut Vec<(String, f64)>, forces: &[f64]) {
    let mut total = [0.0; 3];
    for (i, f) in forces.iter().enumerate() {
        total[i % 3] += f;
    }
    for (c, ax) in ["x", "y", "z"].iter().enumerate() {
        r.push((format!("interface_force.{ax}"), total[c]));
    }
}

/// Adds the `.vtu` file `name` written at `time` to the series and rewrites `fem.pvd`.
pub(crate) fn add_to_series(
    out_dir: &Path,
    files: &mut Vec<(f64, String)>,
    time: f64,
    name: String,
) -> Result<(), crate::FemError> {
    files.push((time, name));
    let pvd = out_dir.join("fem.pvd");
    write_pvd(&pvd, files).map_err(|e| io_error(e, &pvd))
}

/// Appends (or, with `truncate`, starts) a text file.
pub fn append(path: &Path, text: &str, truncate: bool) -> std::io::Result<()> {
    let mut f = std::fs::OpenOptions::new()
        .create(true)
        .write(true)
        .append(!truncate)
        .truncate(truncate)
        .open(path)?;
    f.write_all(text.as_bytes())
}
