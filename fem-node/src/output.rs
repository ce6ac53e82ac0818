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
    let mut s = String::with_capacity(64 * mesh.num_nodes() + 128 * mesh.num_elements());
    let _ = writeln!(s, "<?xml version=\"1.0\"?>");
    let _ = writeln!(s, "<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\">");
    let _ = writeln!(s, "<UnstructuredGrid>");
    let _ = writeln!(
        s,
        "<Piece NumberOfPoints=\"{}\" NumberOfCells=\"{}\">",
        mesh.num_nodes(),
        mesh.num_elements()
    );
    s.push_str(
        "<Points>\n<DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"ascii\">\n",
    );
    for p in &mesh.nodes {
        let _ = writeln!(s, "{:e} {:e} {:e}", p[0], p[1], p[2]);
    }
    s.push_str("</DataArray>\n</Points>\n<Cells>\n<DataArray type=\"Int64\" Name=\"connectivity\" format=\"ascii\">\n");
    for e in 0..mesh.num_elements() {
        let nodes: Vec<String> = mesh
            .element_nodes(e)
            .iter()
            .map(|n| n.to_string())
            .collect();
        let _ = writeln!(s, "{}", nodes.join(" "));
    }
    s.push_str("</DataArray>\n<DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">\n");
    for e in 0..mesh.num_elements() {
        let _ = write!(s, "{} ", mesh.offsets[e + 1]);
    }
    s.push_str("\n</DataArray>\n<DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">\n");
    for k in &mesh.kinds {
        let _ = write!(s, "{} ", k.vtk_type());
    }
    s.push_str("\n</DataArray>\n</Cells>\n<PointData Vectors=\"displacement\">\n");
    for (name, data) in [("displacement", u), ("velocity", v)] {
        let _ = writeln!(s, "<DataArray type=\"Float64\" Name=\"{name}\" NumberOfComponents=\"3\" format=\"ascii\">");
        for c in data.chunks(3) {
            let _ = writeln!(s, "{:e} {:e} {:e}", c[0], c[1], c[2]);
        }
        s.push_str("</DataArray>\n");
    }
    s.push_str("</PointData>\n<CellData Scalars=\"von_mises\">\n");
    s.push_str("<DataArray type=\"Float64\" Name=\"von_mises\" format=\"ascii\">\n");
    for st in stress {
        let _ = write!(s, "{:e} ", von_mises(st));
    }
    s.push_str("\n</DataArray>\n");
    s.push_str(
        "<DataArray type=\"Float64\" Name=\"stress\" NumberOfComponents=\"6\" format=\"ascii\">\n",
    );
    for st in stress {
        let _ = writeln!(
            s,
            "{:e} {:e} {:e} {:e} {:e} {:e}",
            st[0], st[1], st[2], st[3], st[4], st[5]
        );
    }
    s.push_str("</DataArray>\n");
    for (name, data) in cell_scalars {
        let _ = writeln!(
            s,
            "<DataArray type=\"Float64\" Name=\"{name}\" format=\"ascii\">"
        );
        for v in data.iter() {
            let _ = write!(s, "{v:e} ");
        }
        s.push_str("\n</DataArray>\n");
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
