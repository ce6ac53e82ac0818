//! Output: legacy VTK files (readable by ParaView) for particles and meshes, and a CSV time
//! series.

use crate::hertz_mindlin::V3;
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

/// Surface point of the superquadric `s` at the parameters (φ1, φ2), Wellmann (3.3):
/// X1 = sgn(cos φ1) r1 |cos φ1|^ε1 |cos φ2|^ε2, X2 = sgn(sin φ1) r2 |sin φ1|^ε1 |cos φ2|^ε2,
/// X3 = sgn(sin φ2) r3 |sin φ2|^ε2 (body frame).
fn superquadric_point(s: &crate::shape::Superquadric, phi1: f64, phi2: f64) -> V3 {
    let f = |c: f64, e: f64| c.signum() * c.abs().powf(e);
    let c2 = phi2.cos().abs().powf(s.eps2);
    V3::new(
        s.radii.x * f(phi1.cos(), s.eps1) * c2,
        s.radii.y * f(phi1.sin(), s.eps1) * c2,
        s.radii.z * f(phi2.sin(), s.eps2),
    )
}

/// Points (body frame) and cells of one superquadric tessellated on `n1` × `n2` intervals of
/// (φ1, φ2) ∈ [−π, π) × [−π/2, π/2] (3.3): n1 (n2 − 1) ring points and the two poles; quads
/// between the rings, triangles at the poles, all counter-clockwise seen from outside.
fn tessellate(s: &crate::shape::Superquadric, n1: usize, n2: usize) -> (Vec<V3>, Vec<Vec<usize>>) {
    use std::f64::consts::{FRAC_PI_2, PI};
    let mut points = Vec::with_capacity(n1 * (n2 - 1) + 2);
    points.push(V3::new(0.0, 0.0, -s.radii.z));
    for j in 1..n2 {
        let phi2 = -FRAC_PI_2 + PI * j as f64 / n2 as f64;
        for i in 0..n1 {
            let phi1 = -PI + 2.0 * PI * i as f64 / n1 as f64;
            points.push(superquadric_point(s, phi1, phi2));
        }
    }
    points.push(V3::new(0.0, 0.0, s.radii.z));
    let north = points.len() - 1;
    let ring = |i: usize, j: usize| 1 + (j - 1) * n1 + i % n1;
    let mut cells = Vec::with_capacity(n1 * n2);
    for i in 0..n1 {
        cells.push(vec![0, ring(i + 1, 1), ring(i, 1)]);
    }
    for j in 1..n2 - 1 {
        for i in 0..n1 {
            cells.push(vec![
                ring(i, j),
                ring(i + 1, j),
                ring(i + 1, j + 1),
                ring(i, j + 1),
            ]);
        }
    }
    for i in 0..n1 {
        cells.push(vec![ring(i, n2 - 1), ring(i + 1, n2 - 1), north]);
    }
    (points, cells)
}

/// A body's surface in its own frame: points and polygons (indices into the points).
type BodyMesh = (Vec<V3>, Vec<Vec<usize>>);

/// The superquadrics as their real surfaces, VTK legacy polydata: each superquadric
/// tessellated from its parameterisation (3.3) on `resolution` × `resolution`/2 intervals of
/// (φ1, φ2) (quads, triangles at the poles), turned by its orientation and placed at its
/// centre. Point data: `id` of the body, `velocity` of the material point (v + ω × r) and
/// `shape_index` (the body's template). Spheres are not in this file (they are the points of
/// [`write_particles_vtk`], drawn with the Glyph filter). `resolution` must be at least 8.
pub fn write_superquadrics_vtk(
    path: &Path,
    p: &Particles,
    time: f64,
    resolution: usize,
) -> Result<(), DemError> {
    if resolution < 8 {
        return Err(io_err(
            path,
            format!("tessellation resolution {resolution} < 8"),
        ));
    }
    let (n1, n2) = (resolution, resolution / 2);
    // every template's mesh once (body frame)
    let meshes: Vec<Option<BodyMesh>> = p
        .templates
        .iter()
        .map(|t| t.superquadric().map(|s| tessellate(s, n1, n2)))
        .collect();
    let mesh_of = |k: usize| {
        p.template(k)?;
        Some((meshes[p.shape[k] as usize].as_ref()?, 1.0))
    };
    write_bodies_vtk(path, p, time, "superquadrics", mesh_of)
}

/// The dilated polyhedra as their real surfaces (VTK legacy polydata, the point data of
/// [`write_superquadrics_vtk`]): every stone's dilated surface is the convex hull of its core
/// vertices each offset by the dilation radius in `2 × resolution` directions (a Fibonacci
/// sphere), so flat faces, edge cylinders and vertex caps show as they are (the points lie
/// on the exact surface).
pub fn write_polyhedra_vtk(
    path: &Path,
    p: &Particles,
    time: f64,
    resolution: usize,
) -> Result<(), DemError> {
    // one mesh per stone (unit size), scaled for each body as it is written
    let stones: Vec<BodyMesh> = p
        .stones
        .iter()
        .map(|s| {
            let (v, t) = s.surface(2 * resolution.max(4));
            (
                v,
                t.iter().map(|t| t.map(|k| k as usize).to_vec()).collect(),
            )
        })
        .collect();
    let mesh_of = |k: usize| match p.template(k)?.shape {
        crate::particles::Shape::Polyhedron { stone, scale } => {
            Some((&stones[stone as usize], scale))
        }
        crate::particles::Shape::Superquadric(_) => None,
    };
    write_bodies_vtk(path, p, time, "polyhedra", mesh_of)
}

/// The bodies for which `mesh_of` gives a mesh (body frame) and its scale, placed and turned.
fn write_bodies_vtk<'m>(
    path: &Path,
    p: &Particles,
    time: f64,
    title: &str,
    mesh_of: impl Fn(usize) -> Option<(&'m BodyMesh, f64)>,
) -> Result<(), DemError> {
    let bodies: Vec<usize> = (0..p.len()).filter(|&k| mesh_of(k).is_some()).collect();
    let (mut np, mut nc, mut size) = (0, 0, 0);
    for &k in &bodies {
        let ((v, c), _) = mesh_of(k).unwrap();
        np += v.len();
        nc += c.len();
        size += c.iter().map(|c| c.len() + 1).sum::<usize>();
    }
    let mut s = String::with_capacity(200 * np + 40 * nc + 256);
    let _ = writeln!(
        s,
        "# vtk DataFile Version 3.0\nDEM {title} t={time:.9e}\nASCII\nDATASET POLYDATA"
    );
    let _ = writeln!(s, "POINTS {np} double");
    let mut velocities = Vec::with_capacity(np);
    for &k in &bodies {
        let rot = p.orientation[k];
        let (x0, v0, w) = (p.position[k], p.velocity[k], p.angular_velocity[k]);
        let ((points, _), scale) = mesh_of(k).unwrap();
        for x in points {
            let r = rot * (x * scale);
            let x = x0 + r;
            let _ = writeln!(s, "{:.9e} {:.9e} {:.9e}", x.x, x.y, x.z);
            velocities.push(v0 + w.cross(&r));
        }
    }
    let _ = writeln!(s, "POLYGONS {nc} {size}");
    let mut offset = 0;
    for &k in &bodies {
        let ((v, cells), _) = mesh_of(k).unwrap();
        for cell in cells {
            let _ = write!(s, "{}", cell.len());
            for i in cell {
                let _ = write!(s, " {}", offset + i);
            }
            s.push('\n');
        }
        offset += v.len();
    }
    let _ = writeln!(s, "POINT_DATA {np}\nSCALARS id int 1\nLOOKUP_TABLE default");
    for &k in &bodies {
        for _ in 0..mesh_of(k).unwrap().0 .0.len() {
            let _ = writeln!(s, "{}", p.id[k]);
        }
    }
    let _ = writeln!(s, "SCALARS shape_index int 1\nLOOKUP_TABLE default");
    for &k in &bodies {
        for _ in 0..mesh_of(k).unwrap().0 .0.len() {
            let _ = writeln!(s, "{}", p.shape[k]);
        }
    }
    let _ = writeln!(s, "VECTORS velocity double");
    for v in &velocities {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shape::Superquadric;
    use nalgebra::UnitQuaternion;

    fn sq(r: [f64; 3], e1: f64, e2: f64) -> Superquadric {
        Superquadric::new(V3::new(r[0], r[1], r[2]), e1, e2).unwrap()
    }

    /// Two superquadrics (and a sphere, which is left out) written and read back: every point
    /// on its body's surface, F(Tᵀ(x − c)) = 1 to 1e-6, the counts of the header those of the
    /// data, ids and shape indices per point, velocities v + ω × r, every cell's vertices of
    /// one body.
    #[test]
    fn superquadric_surfaces_lie_on_the_bodies() {
        let mut p = Particles::default();
        let shapes = [sq([1.0, 0.5, 0.3], 0.3, 1.6), sq([0.2, 0.4, 0.6], 1.7, 0.2)];
        p.push(
            V3::new(9.0, 9.0, 9.0),
            V3::zeros(),
            V3::zeros(),
            0.5,
            1.0,
            0,
        );
        p.push_superquadric(
            V3::new(1.0, -2.0, 3.0),
            V3::new(0.5, 0.0, -1.0),
            V3::new(2.0, -1.0, 4.0),
            UnitQuaternion::from_euler_angles(0.3, -1.1, 2.0),
            shapes[0],
            1000.0,
            0,
        );
        p.push_superquadric(
            V3::new(-0.5, 0.25, 0.0),
            V3::zeros(),
            V3::new(0.0, 0.0, -3.0),
            UnitQuaternion::from_euler_angles(-2.0, 0.4, 0.1),
            shapes[1],
            1000.0,
            0,
        );
        p.permute(&[2, 0, 1]); // storage order differs from ids
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sq.vtk");
        assert!(write_superquadrics_vtk(&path, &p, 0.0, 7).is_err());
        let resolution = 16;
        write_superquadrics_vtk(&path, &p, 0.5, resolution).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(!text.contains("NaN") && !text.contains("inf"));
        let all: Vec<&str> = text.lines().collect();
        // the header line starting with `key` (its words) and the lines after it
        let section = |key: &str| -> (Vec<&str>, &[&str]) {
            let at = all.iter().position(|l| l.starts_with(key)).expect(key);
            (all[at].split_whitespace().collect(), &all[at + 1..])
        };
        let count = |w: &str| -> usize { w.parse().unwrap() };
        let (h, rest) = section("POINTS");
        let np = count(h[1]);
        let points = &rest[..np];
        assert!(rest[np].starts_with("POLYGONS"), "{} points", np);
        let (h, rest) = section("POLYGONS");
        let (nc, size) = (count(h[1]), count(h[2]));
        let cells = &rest[..nc];
        assert!(rest[nc].starts_with("POINT_DATA"), "{nc} cells");
        let npd = count(section("POINT_DATA").0[1]);
        let per = resolution * (resolution / 2 - 1) + 2;
        assert_eq!((np, points.len(), npd), (2 * per, 2 * per, 2 * per));
        assert_eq!((nc, cells.len()), (2 * resolution * resolution / 2, nc));
        let ints: Vec<Vec<usize>> = cells
            .iter()
            .map(|l| l.split_whitespace().map(|w| w.parse().unwrap()).collect())
            .collect();
        assert_eq!(size, ints.iter().map(Vec::len).sum::<usize>());
        for c in &ints {
            assert!(c[0] == 3 || c[0] == 4);
            assert_eq!(c.len(), c[0] + 1);
            let body = c[1] / per;
            assert!(c[1..].iter().all(|&v| v < np && v / per == body), "{c:?}");
        }
        // the point data blocks, in order
        let block = |name: &str| -> Vec<String> {
            let start = text.find(name).unwrap_or_else(|| panic!("no {name}"));
            text[start..]
                .lines()
                .skip(if name.starts_with("SCALARS") { 2 } else { 1 })
                .take(np)
                .map(str::to_owned)
                .collect()
        };
        let ids: Vec<u32> = block("SCALARS id int")
            .iter()
            .map(|l| l.parse().unwrap())
            .collect();
        let shape_index: Vec<u32> = block("SCALARS shape_index int")
            .iter()
            .map(|l| l.parse().unwrap())
            .collect();
        let vel = block("VECTORS velocity");
        let parse3 = |l: &str| {
            let v: Vec<f64> = l.split_whitespace().map(|w| w.parse().unwrap()).collect();
            V3::new(v[0], v[1], v[2])
        };
        let mut worst: f64 = 0.0;
        for (m, line) in points.iter().enumerate() {
            // storage order: id 2, then id 1 (the sphere, id 0, left out)
            let id = ids[m];
            assert_eq!(id, [2, 1][m / per], "point {m}");
            let k = p.id.iter().position(|&i| i == id).unwrap();
            assert_eq!(shape_index[m], p.shape[k]);
            let x = parse3(line);
            let r = x - p.position[k];
            let body = p.orientation[k].inverse_transform_vector(&r);
            let f = shapes[id as usize - 1].inside_outside(&body);
            worst = worst.max((f - 1.0).abs());
            let v = p.velocity[k] + p.angular_velocity[k].cross(&r);
            assert!((parse3(&vel[m]) - v).norm() < 1e-8, "velocity of point {m}");
        }
        assert!(worst < 1e-6, "|F − 1| up to {worst}");
        eprintln!("largest |F - 1| of the written points: {worst:.1e}");
    }

    /// How close the tessellation is: the volume of the polyhedron against (3.4) and the
    /// largest distance of a face centre from the surface (along the ray from the centre),
    /// relative to the largest semi-axis. Measured at resolution 16 / 32 / 64: sphere −6.3 /
    /// −1.6 / −0.40 % volume, gap 3.7 / 0.96 / 0.24 %; (1, 0.5, 0.3), ε = (0.3, 1.6): −3.9 /
    /// −0.99 / −0.25 %, gap 2.0 / 0.53 / 0.14 %; cube-like ε = 0.1: −1.8 / −0.43 / −0.11 %,
    /// gap 1.1 / 0.29 / 0.07 %. Second order: each doubling divides both by ~4.
    #[test]
    fn tessellation_error() {
        for (shape, volume16, gap16) in [
            (sq([1.0, 1.0, 1.0], 1.0, 1.0), 0.065, 0.04),
            (sq([1.0, 0.5, 0.3], 0.3, 1.6), 0.04, 0.021),
            (sq([1.0, 1.0, 1.0], 0.1, 0.1), 0.019, 0.012),
        ] {
            let mut last: Option<(f64, f64)> = None;
            for resolution in [16, 32, 64] {
                let (points, cells) = tessellate(&shape, resolution, resolution / 2);
                assert_eq!(cells.len(), resolution * resolution / 2);
                let mut volume = 0.0;
                let mut gap: f64 = 0.0;
                for c in &cells {
                    for t in 1..c.len() - 1 {
                        let (a, b, d) = (points[c[0]], points[c[t]], points[c[t + 1]]);
                        volume += a.dot(&b.cross(&d)) / 6.0;
                    }
                    let centre = c.iter().map(|&v| points[v]).sum::<V3>() / c.len() as f64;
                    // the ray from the body's centre through the face centre meets the
                    // surface at lo × centre (bisection)
                    let (mut lo, mut hi) = (0.0, 4.0);
                    for _ in 0..60 {
                        let mid = 0.5 * (lo + hi);
                        if shape.inside_outside(&(centre * mid)) < 1.0 {
                            lo = mid;
                        } else {
                            hi = mid;
                        }
                    }
                    gap = gap.max((lo - 1.0) * centre.norm());
                }
                let dv = (volume - shape.volume()) / shape.volume();
                let gap = gap / shape.radii.max();
                eprintln!(
                    "{:?} ε = ({}, {}), resolution {resolution}: volume {dv:+.2e}, face gap \
                     {gap:.2e}",
                    shape.radii.as_slice(),
                    shape.eps1,
                    shape.eps2,
                );
                assert!(dv < 0.0, "an inscribed polyhedron with outward faces: {dv}");
                match last {
                    None => assert!(-dv < volume16 && gap < gap16, "{dv} {gap}"),
                    Some((dv0, gap0)) => {
                        assert!(
                            dv0 / dv > 3.5 && gap0 / gap > 3.5,
                            "{dv0}/{dv} {gap0}/{gap}"
                        )
                    }
                }
                last = Some((dv, gap));
            }
        }
    }
}
