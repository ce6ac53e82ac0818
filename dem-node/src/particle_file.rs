//! Particle CSV files: the `kind = "file"` particle source and `particles_final.csv`.
//!
//! Format: a header line naming the columns, `x,y,z,radius` and optionally the groups
//! `vx,vy,vz` (velocity), `qw,qx,qy,qz` (orientation body → global, a quaternion normalised
//! on read), `wx,wy,wz` (angular velocity) and `r1,r2,r3,eps1,eps2` (superquadric semi-axes
//! and exponents), each group all or none, columns in any order; one body per line; empty
//! lines are skipped. With the shape group, a line whose five shape fields are all empty is a
//! sphere of radius `radius`, one with all five given a superquadric (its `radius` field is
//! then not read: the file writes its bounding radius there, for information only).
//!
//! Dilated polyhedra add the group `stone,size`: a line with both given is a copy of stone
//! `stone` (0-based) of the file's stone library at size `size` (m, equivalent-volume
//! diameter), its `radius` field again for information only. The library is the JSON file
//! next to the CSV with the extension `.stones.json` (`particles_final.stones.json`): a list
//! of stones as [`crate::shape::Stone`] stores them (unit size, principal frame), so a bed of
//! stones reads back bitwise too. A line gives the superquadric group or the stone group,
//! not both.
//!
//! Values are written with Rust's shortest round-trip representation, so a bed written at the
//! end of one run starts the next one bitwise where it stopped. A bed of spheres only is
//! written as `x,y,z,radius,vx,vy,vz` (rotations start at rest); a bed with non-spherical
//! bodies also with orientation, angular velocity and shape, every body alike (spheres with
//! the identity and empty shape fields).

use crate::hertz_mindlin::V3;
use crate::narrow::superquadric::{detect, Detection, SearchSettings, SearchStats, SqBody};
use crate::particles::Particles;
use crate::shape::superquadric::{Superquadric, EXPONENT_MAX, EXPONENT_MIN};
use nalgebra::{Matrix3, Quaternion, UnitQuaternion};
use std::fmt::Write as _;
use std::path::Path;

/// One body read from a file.
#[derive(Debug, Clone, PartialEq)]
pub struct FileParticle {
    pub position: V3,
    /// A sphere's radius; a superquadric's bounding radius (computed, not read).
    pub radius: f64,
    pub velocity: V3,
    /// Orientation body → global, `None` if the file has no `qw,qx,qy,qz`.
    pub orientation: Option<UnitQuaternion<f64>>,
    /// Zero if the file has no `wx,wy,wz`.
    pub angular_velocity: V3,
    /// `None` for a sphere.
    pub shape: Option<Superquadric>,
    /// (stone, size) of a dilated polyhedron: the stone's index in the file's library.
    pub stone: Option<(u32, f64)>,
    /// 1-based line of the file.
    pub line: usize,
}

impl FileParticle {
    /// A sphere without orientation and rotation (as a file of spheres only gives it).
    pub fn sphere(position: V3, radius: f64, velocity: V3, line: usize) -> FileParticle {
        FileParticle {
            position,
            radius,
            velocity,
            orientation: None,
            angular_velocity: V3::zeros(),
            shape: None,
            stone: None,
            line,
        }
    }
}

/// An error at a 1-based line of the file (0: the file as a whole).
#[derive(Debug, Clone, PartialEq)]
pub struct FileError {
    pub line: usize,
    pub message: String,
}

const REQUIRED: [&str; 4] = ["x", "y", "z", "radius"];
const VELOCITY: [&str; 3] = ["vx", "vy", "vz"];
const ORIENTATION: [&str; 4] = ["qw", "qx", "qy", "qz"];
const ANGULAR_VELOCITY: [&str; 3] = ["wx", "wy", "wz"];
const SHAPE: [&str; 5] = ["r1", "r2", "r3", "eps1", "eps2"];
const STONE: [&str; 2] = ["stone", "size"];

/// A quaternion whose squared norm is within this of 1 is already unit (to the round-off of a
/// normalisation) and is kept as written, so a written state reads back bitwise; any other is
/// normalised.
const UNIT_TOLERANCE: f64 = 1e-14;

/// Parses the text of a particle file.
pub fn parse(text: &str) -> Result<Vec<FileParticle>, FileError> {
    let err = |line: usize, message: String| FileError { line, message };
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(k, l)| (k + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty());
    let Some((header_line, header)) = lines.next() else {
        return Err(err(
            1,
            "empty file, expected the header `x,y,z,radius`".into(),
        ));
    };
    let names: Vec<&str> = header.split(',').map(str::trim).collect();
    let known = |name: &&str| {
        REQUIRED.contains(name)
            || VELOCITY.contains(name)
            || ORIENTATION.contains(name)
            || ANGULAR_VELOCITY.contains(name)
            || SHAPE.contains(name)
            || STONE.contains(name)
    };
    for name in &names {
        if !known(name) {
            return Err(err(
                header_line,
                format!(
                    "unknown column `{name}`, expected x,y,z,radius and optionally vx,vy,vz; \
                     qw,qx,qy,qz; wx,wy,wz; r1,r2,r3,eps1,eps2; stone,size"
                ),
            ));
        }
        if names.iter().filter(|n| *n == name).count() > 1 {
            return Err(err(header_line, format!("column `{name}` appears twice")));
        }
    }
    let col = |name: &str| names.iter().position(|n| *n == name);
    let mut req = [0usize; 4];
    for (slot, name) in req.iter_mut().zip(REQUIRED) {
        *slot = col(name).ok_or_else(|| {
            err(
                header_line,
                format!("missing column `{name}` (header must name x,y,z,radius)"),
            )
        })?;
    }
    // an optional group: all its columns or none
    let group = |group: &[&str]| -> Result<Vec<usize>, FileError> {
        let found: Vec<usize> = group.iter().filter_map(|n| col(n)).collect();
        if found.is_empty() || found.len() == group.len() {
            return Ok(found);
        }
        let missing: Vec<&str> = group.iter().copied().filter(|n| col(n).is_none()).collect();
        Err(err(
            header_line,
            format!(
                "give all {} of {} or none (missing `{}`)",
                group.len(),
                group.join(","),
                missing.join("`, `")
            ),
        ))
    };
    let vel = group(&VELOCITY)?;
    let ori = group(&ORIENTATION)?;
    let ang = group(&ANGULAR_VELOCITY)?;
    let shp = group(&SHAPE)?;
    let stn = group(&STONE)?;
    let mut out = Vec::new();
    for (line, text) in lines {
        let fields: Vec<&str> = text.split(',').map(str::trim).collect();
        if fields.len() != names.len() {
            return Err(err(
                line,
                format!(
                    "{} values, expected {} ({})",
                    fields.len(),
                    names.len(),
                    names.join(",")
                ),
            ));
        }
        let num = |c: usize| -> Result<f64, FileError> {
            let v: f64 = fields[c].parse().map_err(|_| {
                err(
                    line,
                    format!("column `{}`: `{}` is not a number", names[c], fields[c]),
                )
            })?;
            if v.is_finite() {
                Ok(v)
            } else {
                Err(err(
                    line,
                    format!("column `{}`: must be finite, got {v}", names[c]),
                ))
            }
        };
        let shape = if shp.is_empty() {
            None
        } else {
            parse_shape(&shp, &fields, &names, line, num)?
        };
        let stone = if stn.is_empty() {
            None
        } else {
            parse_stone(&stn, &fields, line, num)?
        };
        if shape.is_some() && stone.is_some() {
            return Err(err(
                line,
                "both a superquadric (r1,r2,r3,eps1,eps2) and a stone (stone,size) are given: \
                 a body is one or the other"
                    .into(),
            ));
        }
        let radius = match &shape {
            Some(s) => s.bounding_radius(),
            // a stone's bounding radius comes with its library (the field is informative)
            None if stone.is_some() => num(req[3]).unwrap_or(0.0),
            None => {
                let radius = num(req[3])?;
                if radius <= 0.0 {
                    return Err(err(
                        line,
                        format!("column `radius`: must be > 0, got {radius}"),
                    ));
                }
                radius
            }
        };
        let velocity = if vel.is_empty() {
            V3::zeros()
        } else {
            V3::new(num(vel[0])?, num(vel[1])?, num(vel[2])?)
        };
        let position = V3::new(num(req[0])?, num(req[1])?, num(req[2])?);
        let orientation = if ori.is_empty() {
            None
        } else {
            let q = Quaternion::new(num(ori[0])?, num(ori[1])?, num(ori[2])?, num(ori[3])?);
            Some(unit_quaternion(q).ok_or_else(|| {
                err(
                    line,
                    "columns qw,qx,qy,qz: the orientation quaternion is zero (no rotation is \
                     1,0,0,0)"
                        .into(),
                )
            })?)
        };
        let angular_velocity = if ang.is_empty() {
            V3::zeros()
        } else {
            V3::new(num(ang[0])?, num(ang[1])?, num(ang[2])?)
        };
        out.push(FileParticle {
            position,
            radius,
            velocity,
            orientation,
            angular_velocity,
            shape,
            stone,
            line,
        });
    }
    Ok(out)
}

/// The stone fields of a line (`stone`, `size`): both empty, not a stone; both given, the
/// stone index and a size > 0.
fn parse_stone(
    stn: &[usize],
    fields: &[&str],
    line: usize,
    num: impl Fn(usize) -> Result<f64, FileError>,
) -> Result<Option<(u32, f64)>, FileError> {
    let err = |message: String| FileError { line, message };
    match (fields[stn[0]].is_empty(), fields[stn[1]].is_empty()) {
        (true, true) => return Ok(None),
        (false, false) => {}
        _ => {
            return Err(err(
                "columns stone,size: give both (a dilated polyhedron) or neither".into(),
            ))
        }
    }
    let index: u32 = fields[stn[0]].parse().map_err(|_| {
        err(format!(
            "column `stone`: `{}` is not a stone index (0, 1, 2, …)",
            fields[stn[0]]
        ))
    })?;
    let size = num(stn[1])?;
    if size <= 0.0 {
        return Err(err(format!("column `size`: must be > 0, got {size}")));
    }
    Ok(Some((index, size)))
}

/// The stone library that goes with the particle file `csv`: `<stem>.stones.json` beside it.
pub fn stones_path(csv: &Path) -> std::path::PathBuf {
    let stem = csv
        .file_stem()
        .map_or_else(|| "particles".into(), |s| s.to_string_lossy().to_string());
    csv.with_file_name(format!("{stem}.stones.json"))
}

/// Reads a stone library (see the module documentation), checking every stone.
pub fn read_stones(path: &Path) -> Result<Vec<crate::shape::Stone>, FileError> {
    let text = crate::resources::read_text_within_memory(path, "it")
        .map_err(|message| FileError { line: 0, message })?;
    let stones: Vec<crate::shape::Stone> = serde_json::from_str(&text).map_err(|e| FileError {
        line: e.line(),
        message: format!("not a stone library (a JSON list of stones): {e}"),
    })?;
    for (k, s) in stones.iter().enumerate() {
        s.check().map_err(|e| FileError {
            line: 0,
            message: format!("stone {k}: {e}"),
        })?;
    }
    Ok(stones)
}

/// The particles' stone library as JSON (see the module documentation).
pub fn format_stones(p: &Particles) -> String {
    serde_json::to_string(&p.stones).expect("stones serialise")
}

/// The shape fields of a line (columns `shp` in the order of [`SHAPE`]): all empty, a sphere
/// (`None`); all given, a superquadric.
fn parse_shape(
    shp: &[usize],
    fields: &[&str],
    names: &[&str],
    line: usize,
    num: impl Fn(usize) -> Result<f64, FileError>,
) -> Result<Option<Superquadric>, FileError> {
    let err = |message: String| FileError { line, message };
    let given = shp.iter().filter(|&&c| !fields[c].is_empty()).count();
    if given == 0 {
        return Ok(None);
    }
    if given < shp.len() {
        let empty = shp.iter().find(|&&c| fields[c].is_empty()).unwrap();
        return Err(err(format!(
            "column `{}` is empty but other shape columns are given: a superquadric needs all \
             five of r1,r2,r3,eps1,eps2, a sphere none",
            names[*empty]
        )));
    }
    let mut v = [0.0; 5];
    for (k, &c) in shp.iter().enumerate() {
        v[k] = num(c)?;
        if k < 3 && v[k] <= 0.0 {
            return Err(err(format!(
                "column `{}`: a semi-axis must be > 0, got {}",
                names[c], v[k]
            )));
        }
        if k >= 3 && !(EXPONENT_MIN..=EXPONENT_MAX).contains(&v[k]) {
            return Err(err(format!(
                "column `{}`: exponent {} outside the convex range [{EXPONENT_MIN}, \
                 {EXPONENT_MAX}] (0 is a cuboid and 2 an octahedron, with edges)",
                names[c], v[k]
            )));
        }
    }
    Superquadric::new(V3::new(v[0], v[1], v[2]), v[3], v[4])
        .map(Some)
        .ok_or_else(|| err(format!("not a convex superquadric: {v:?}")))
}

/// `q` as a unit quaternion: kept as it is if already unit to round-off, else normalised
/// (scaled by its largest component first, so no square overflows); `None` if zero.
fn unit_quaternion(q: Quaternion<f64>) -> Option<UnitQuaternion<f64>> {
    if (q.norm_squared() - 1.0).abs() <= UNIT_TOLERANCE {
        return Some(UnitQuaternion::new_unchecked(q));
    }
    let m = q.coords.amax();
    if m == 0.0 {
        return None;
    }
    Some(UnitQuaternion::new_normalize(q / m))
}

/// Largest overlap of two bodies of a file that is still accepted, as a fraction of the
/// smaller radius (for a superquadric: its inscribed radius). A settled or compacted bed
/// written with `final_particles` overlaps by a few per cent of r at most (contact overlaps
/// of a dense bed under load; fewer printed digits add rounding on top); half a radius is far
/// beyond any contact the engine holds and means bodies written twice, a wrong column, or a
/// lattice written at the wrong spacing.
pub const MAX_FILE_OVERLAP: f64 = 0.5;

/// Two bodies overlapping by more than `max_fraction` of the smaller radius, as
/// (index a, index b, overlap / smaller radius) with a < b, the first such pair in the order
/// of `a` (then `b`), or `None`. Two spheres: overlap r_a + r_b − |x_a − x_b|. A pair with a
/// superquadric (whose bounding spheres may overlap while the bodies interlock without
/// touching): the penetration of the exact contact detection
/// ([`crate::narrow::superquadric::detect`]), as a fraction of the smaller inscribed radius;
/// only pairs whose bounding spheres overlap are searched. A cell grid of edge 2 r_max
/// (largest bounding radius) keeps it O(n) for a bed.
pub fn find_overlap(particles: &[FileParticle], max_fraction: f64) -> Option<(usize, usize, f64)> {
    find_overlap_with_stones(particles, &[], max_fraction)
}

/// [`find_overlap`] for a file with dilated polyhedra (`stones` its library; every stone
/// index valid): a pair with a polyhedron overlaps by the fraction δ_d/(r_ds,1 + r_ds,2) of
/// what the model allows (the cores meeting is the whole of it, and more: ∞).
pub fn find_overlap_with_stones(
    particles: &[FileParticle],
    stones: &[crate::shape::Stone],
    max_fraction: f64,
) -> Option<(usize, usize, f64)> {
    use std::collections::HashMap;
    let bounding: Vec<f64> = particles
        .iter()
        .map(|s| match (s.shape, s.stone) {
            (Some(q), _) => q.bounding_radius(),
            (None, Some((k, size))) => stones[k as usize].circumradius * size,
            (None, None) => s.radius,
        })
        .collect();
    let r_max = bounding.iter().copied().fold(0.0, f64::max);
    if particles.len() < 2 || r_max <= 0.0 {
        return None;
    }
    let h = 2.0 * r_max;
    let cell = |x: V3| [x.x, x.y, x.z].map(|c| (c / h).floor().clamp(-9.0e15, 9.0e15) as i64);
    let mut grid: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
    for (k, s) in particles.iter().enumerate() {
        grid.entry(cell(s.position)).or_default().push(k);
    }
    let mut candidates = Vec::new();
    for (a, s) in particles.iter().enumerate() {
        let c = cell(s.position);
        candidates.clear();
        for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    if let Some(others) = grid.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) {
                        candidates.extend(others.iter().copied().filter(|&b| b > a));
                    }
                }
            }
        }
        // the smallest b first: the exact search of a shaped pair runs only until one is found
        candidates.sort_unstable();
        for &b in &candidates {
            let o = &particles[b];
            let fraction =
                if s.shape.is_none() && o.shape.is_none() && s.stone.is_none() && o.stone.is_none()
                {
                    let overlap = s.radius + o.radius - (s.position - o.position).norm();
                    overlap / s.radius.min(o.radius)
                } else if bounding[a] + bounding[b] <= (s.position - o.position).norm() {
                    continue;
                } else if s.stone.is_some() || o.stone.is_some() {
                    stone_overlap_fraction(s, o, stones)
                } else {
                    shaped_overlap_fraction(s, o)
                };
            if fraction > max_fraction {
                return Some((a, b, fraction));
            }
        }
    }
    None
}

/// Overlap of a pair with a dilated polyhedron over the sum of the dilations (∞ when the
/// cores meet); 0 if separated.
fn stone_overlap_fraction(
    a: &FileParticle,
    b: &FileParticle,
    stones: &[crate::shape::Stone],
) -> f64 {
    use crate::narrow::polyhedron::{detect_pair, Core, PolyBody, PolyDetection, POINT_CORE};
    let body = |p: &FileParticle| -> Option<PolyBody<'_>> {
        let (core, dilation) = match (p.stone, &p.shape) {
            (Some((k, size)), _) => {
                let s = &stones[k as usize];
                (
                    Core::Points {
                        vertices: &s.vertices,
                        scale: size,
                    },
                    s.dilation * size,
                )
            }
            (None, Some(_)) => return None, // no superquadric–stone check in files
            (None, None) => (
                Core::Points {
                    vertices: &POINT_CORE,
                    scale: 1.0,
                },
                p.radius,
            ),
        };
        Some(PolyBody {
            core,
            dilation,
            position: p.position,
            orientation: p.orientation.unwrap_or_else(UnitQuaternion::identity),
        })
    };
    let (Some(x), Some(y)) = (body(a), body(b)) else {
        return 0.0;
    };
    match detect_pair(&x, &y, None) {
        PolyDetection::Contact { overlap, .. } => overlap / (x.dilation + y.dilation),
        PolyDetection::Separated { .. } => 0.0,
        PolyDetection::CoresIntersect { .. } => f64::INFINITY,
    }
}

/// Penetration of two bodies (at least one a superquadric) by the exact contact detection,
/// over the smaller inscribed radius; 0 if separated.
fn shaped_overlap_fraction(a: &FileParticle, b: &FileParticle) -> f64 {
    let as_shape = |p: &FileParticle| {
        p.shape
            .or_else(|| Superquadric::new(V3::repeat(p.radius), 1.0, 1.0))
            .expect("a sphere of positive finite radius is a superquadric")
    };
    let rotation = |p: &FileParticle| {
        p.orientation
            .map_or_else(Matrix3::identity, |q| q.to_rotation_matrix().into_inner())
    };
    let (sa, sb) = (as_shape(a), as_shape(b));
    let body = |p: &FileParticle, shape| SqBody {
        shape,
        position: p.position,
        rotation: rotation(p),
    };
    let inscribed = sa.inscribed_radius().min(sb.inscribed_radius());
    let mut stats = SearchStats::default();
    match detect(
        &body(a, &sa),
        &body(b, &sb),
        None,
        &SearchSettings::default(),
        &mut stats,
    ) {
        Detection::Contact(c) => c.overlap.max(0.0) / inscribed,
        Detection::Separated { .. } => 0.0,
    }
}

/// The particles in id order as a particle file with velocities; with non-spherical bodies
/// also with orientation, angular velocity and shape (see the module documentation).
/// With dilated polyhedra the stone group too; their library is [`format_stones`].
pub fn format(p: &Particles) -> String {
    let mut order: Vec<usize> = (0..p.len()).collect();
    order.sort_unstable_by_key(|&k| p.id[k]);
    let shaped = p.has_shapes();
    let stones = !p.stones.is_empty();
    let mut s = String::with_capacity(64 + if shaped { 400 } else { 120 } * p.len());
    if shaped {
        s.push_str("x,y,z,radius,vx,vy,vz,qw,qx,qy,qz,wx,wy,wz,r1,r2,r3,eps1,eps2");
        s.push_str(if stones { ",stone,size\n" } else { "\n" });
    } else {
        s.push_str("x,y,z,radius,vx,vy,vz\n");
    }
    for k in order {
        let (x, v) = (p.position[k], p.velocity[k]);
        let _ = write!(
            s,
            "{},{},{},{},{},{},{}",
            x.x, x.y, x.z, p.radius[k], v.x, v.y, v.z
        );
        if shaped {
            let (q, w) = (p.orientation[k].quaternion(), p.angular_velocity[k]);
            let _ = write!(
                s,
                ",{},{},{},{},{},{},{}",
                q.w, q.i, q.j, q.k, w.x, w.y, w.z
            );
            match p.template(k).and_then(|t| t.superquadric()) {
                Some(q) => {
                    let _ = write!(
                        s,
                        ",{},{},{},{},{}",
                        q.radii.x, q.radii.y, q.radii.z, q.eps1, q.eps2
                    );
                }
                None => s.push_str(",,,,,"),
            }
            if stones {
                match p.template(k).map(|t| t.shape) {
                    Some(crate::particles::Shape::Polyhedron { stone, scale }) => {
                        let _ = write!(s, ",{stone},{scale}");
                    }
                    _ => s.push_str(",,"),
                }
            }
        }
        s.push('\n');
    }
    s
}

/// Reads a particle file; errors carry the line. The memory is checked twice before it is
/// allocated: the file's size before its text is read (the text and a first estimate of what
/// is parsed from it take about twice its size), then its lines × the size of a
/// [`FileParticle`] before they are parsed (a short line of a sphere, ~30 characters, gives
/// a record several times its length).
pub fn read(path: &Path) -> Result<Vec<FileParticle>, FileError> {
    let text = crate::resources::read_text_within_memory(path, "it")
        .map_err(|message| FileError { line: 0, message })?;
    let lines = text.lines().count();
    crate::resources::check_memory(
        &format!("its {lines} lines"),
        (text.len() + lines * std::mem::size_of::<FileParticle>()) as f64,
        crate::resources::available_memory(),
    )
    .map_err(|message| FileError { line: 0, message })?;
    parse(&text)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn columns_in_any_order_with_optional_velocity() {
        let s = parse("radius, z,y,x\n0.5,3,2,1\n\n0.25,0,0,0\n").unwrap();
        assert_eq!(s.len(), 2);
        assert_eq!(s[0].position, V3::new(1.0, 2.0, 3.0));
        assert_eq!((s[0].radius, s[0].velocity), (0.5, V3::zeros()));
        let s = parse("x,y,z,radius,vx,vy,vz\n0,0,0,1,1,-2,3e-1\n").unwrap();
        assert_eq!(s[0].velocity, V3::new(1.0, -2.0, 0.3));
    }

    #[test]
    fn bad_files_name_the_line() {
        let e = |t: &str| parse(t).unwrap_err();
        assert_eq!(e("").line, 1);
        let h = e("x,y,z\n1,2,3\n");
        assert!(h.line == 1 && h.message.contains("`radius`"), "{h:?}");
        let h = e("x,y,z,radius,id\n");
        assert!(h.message.contains("unknown column `id`"), "{h:?}");
        let h = e("x,y,z,radius,vx\n");
        assert!(h.message.contains("vx,vy,vz"), "{h:?}");
        let h = e("x,y,z,radius\n1,2,3,0.1\n1,2,3\n");
        assert!(
            h.line == 3 && h.message.contains("3 values, expected 4"),
            "{h:?}"
        );
        let h = e("x,y,z,radius\n\n1,2,abc,0.1\n");
        assert!(h.line == 3 && h.message.contains("`z`: `abc`"), "{h:?}");
        let h = e("x,y,z,radius\n1,2,3,-0.1\n");
        assert!(h.line == 2 && h.message.contains("> 0"), "{h:?}");
        let h = e("x,y,z,radius\n1,inf,3,0.1\n");
        assert!(h.line == 2 && h.message.contains("finite"), "{h:?}");
    }

    use crate::generate::SplitMix64;

    fn sq(r: [f64; 3], e1: f64, e2: f64) -> Superquadric {
        Superquadric::new(V3::new(r[0], r[1], r[2]), e1, e2).unwrap()
    }

    fn random_orientation(rng: &mut SplitMix64) -> UnitQuaternion<f64> {
        // as the engine makes them: a normalised product
        let q = Quaternion::new(rng.normal(), rng.normal(), rng.normal(), rng.normal());
        UnitQuaternion::new_normalize(q)
    }

    fn random_v3(rng: &mut SplitMix64, scale: f64) -> V3 {
        V3::new(rng.normal(), rng.normal(), rng.normal()) * scale
    }

    const SHAPED_HEADER: &str = "x,y,z,radius,vx,vy,vz,qw,qx,qy,qz,wx,wy,wz,r1,r2,r3,eps1,eps2";

    /// A mixed bed (spheres and superquadrics, stored out of id order) written and read back:
    /// positions, velocities, orientations, angular velocities and shapes bitwise equal.
    #[test]
    fn mixed_bodies_round_trip_bitwise() {
        let mut rng = SplitMix64::new(21);
        let mut p = Particles::default();
        for k in 0..400 {
            let (x, v, w) = (
                random_v3(&mut rng, 0.1),
                random_v3(&mut rng, 1.0),
                random_v3(&mut rng, 30.0),
            );
            if k % 3 == 0 {
                p.push(x, v, w, 1e-3 * (1.0 + rng.uniform()), 2500.0, 0);
            } else {
                let s = sq(
                    [
                        1e-3 * (0.5 + rng.uniform()),
                        1e-3 * (0.5 + rng.uniform()),
                        1e-3 * (0.5 + rng.uniform()),
                    ],
                    0.1 + 1.8 * rng.uniform(),
                    0.1 + 1.8 * rng.uniform(),
                );
                let q = random_orientation(&mut rng);
                p.push_superquadric(x, v, w, q, s, 2500.0, 0);
            }
        }
        let perm: Vec<u32> = (0..p.len() as u32).rev().collect();
        p.permute(&perm);
        let text = format(&p);
        assert!(text.starts_with(&format!("{SHAPED_HEADER}\n")));
        let read = parse(&text).unwrap();
        assert_eq!(read.len(), p.len());
        let bits = |v: &V3| v.map(f64::to_bits);
        for f in &read {
            let k =
                p.id.iter()
                    .position(|&id| id as usize == f.line - 2)
                    .unwrap();
            assert_eq!(bits(&f.position), bits(&p.position[k]));
            assert_eq!(bits(&f.velocity), bits(&p.velocity[k]));
            assert_eq!(bits(&f.angular_velocity), bits(&p.angular_velocity[k]));
            assert_eq!(f.radius.to_bits(), p.radius[k].to_bits());
            let (qf, qp) = (f.orientation.unwrap(), p.orientation[k]);
            assert_eq!(
                qf.coords.map(f64::to_bits),
                qp.coords.map(f64::to_bits),
                "line {}",
                f.line
            );
            match (f.shape, p.template(k)) {
                (None, None) => {}
                (Some(a), Some(t)) => {
                    let b = *t.superquadric().unwrap();
                    assert_eq!(bits(&a.radii), bits(&b.radii));
                    assert_eq!(
                        (a.eps1.to_bits(), a.eps2.to_bits()),
                        (b.eps1.to_bits(), b.eps2.to_bits())
                    );
                    assert_eq!(a, b);
                }
                other => panic!("line {}: shape {other:?}", f.line),
            }
        }
        // id 0, a sphere: the identity and five empty shape fields
        let sphere = text.lines().nth(1).unwrap();
        assert!(
            sphere.contains(",1,0,0,0,") && sphere.ends_with(",,,,,"),
            "{sphere}"
        );
        // quaternions normalised by the engine read back bitwise (kept, not renormalised)
        for _ in 0..100_000 {
            let q = random_orientation(&mut rng);
            let c = q.coords;
            let text = std::format!("{},{},{},{}", c.w, c.x, c.y, c.z);
            let v: Vec<f64> = text.split(',').map(|t| t.parse().unwrap()).collect();
            let back = unit_quaternion(Quaternion::new(v[0], v[1], v[2], v[3])).unwrap();
            assert_eq!(back.coords.map(f64::to_bits), c.map(f64::to_bits));
        }
    }

    /// A bed of spheres is written exactly as before shapes existed (angular velocity and
    /// orientation not written).
    #[test]
    fn sphere_only_format_unchanged() {
        let mut p = Particles::default();
        p.push(
            V3::new(1.0, 2.5, -3.0),
            V3::new(0.1, 0.0, -0.0),
            V3::new(5.0, 6.0, 7.0),
            0.5,
            1000.0,
            0,
        );
        p.push(
            V3::new(1e-3, 0.30000000000000004, 2.0 / 3.0),
            V3::zeros(),
            V3::zeros(),
            0.25,
            1000.0,
            0,
        );
        p.permute(&[1, 0]);
        assert_eq!(
            format(&p),
            "x,y,z,radius,vx,vy,vz\n\
             1,2.5,-3,0.5,0.1,0,-0\n\
             0.001,0.30000000000000004,0.6666666666666666,0.25,0,0,0\n"
        );
        let read = parse(&format(&p)).unwrap();
        assert!(read
            .iter()
            .all(|f| f.orientation.is_none() && f.shape.is_none()));
        assert_eq!(read[1].angular_velocity, V3::zeros());
    }

    #[test]
    fn optional_groups_in_any_order_and_quaternions_normalised() {
        let s = parse(
            "eps2,wz,qz,r1,x,wx,qy,y,radius,eps1,z,wy,r3,qx,qw,r2\n\
             ,0,0,,1,0,0,2,0.1,,3,0,,0,2,\n\
             0.5,3,0,1,0,1,0,0,99,1.5,0,2,0.25,1,1,0.5\n",
        )
        .unwrap();
        assert_eq!(s[0].shape, None);
        assert_eq!(s[0].radius, 0.1);
        assert_eq!(s[0].position, V3::new(1.0, 2.0, 3.0));
        assert_eq!(s[0].orientation, Some(UnitQuaternion::identity()));
        let b = &s[1];
        assert_eq!(b.shape, Some(sq([1.0, 0.5, 0.25], 1.5, 0.5)));
        assert_eq!(
            b.radius,
            b.shape.unwrap().bounding_radius(),
            "radius not read"
        );
        assert_eq!(b.angular_velocity, V3::new(1.0, 2.0, 3.0));
        let q = b.orientation.unwrap();
        let half = std::f64::consts::FRAC_1_SQRT_2;
        assert!((q.coords - nalgebra::Vector4::new(half, 0.0, 0.0, half)).norm() < 1e-15);
        // huge and tiny components are normalised without overflow or underflow
        for c in ["1e200", "1e-200"] {
            let s = parse(&format!("x,y,z,radius,qw,qx,qy,qz\n0,0,0,1,{c},0,0,0\n")).unwrap();
            assert_eq!(s[0].orientation, Some(UnitQuaternion::identity()), "{c}");
        }
    }

    #[test]
    fn bad_shape_orientation_and_groups_name_line_and_column() {
        let e = |t: &str| parse(t).unwrap_err();
        let h = e("x,y,z,radius,qw,qx,qy\n");
        assert!(
            h.line == 1 && h.message.contains("qw,qx,qy,qz") && h.message.contains("`qz`"),
            "{h:?}"
        );
        let h = e("x,y,z,radius,wx,wz\n");
        assert!(h.line == 1 && h.message.contains("`wy`"), "{h:?}");
        let h = e("x,y,z,radius,r1,r2,r3,eps2\n");
        assert!(h.line == 1 && h.message.contains("`eps1`"), "{h:?}");
        let shaped = |row: &str| format!("x,y,z,radius,r1,r2,r3,eps1,eps2\n0,0,0,1,,,,,\n{row}\n");
        let h = e(&shaped("0,0,5,1,1,1,1,1,"));
        assert!(
            h.line == 3 && h.message.contains("column `eps2` is empty"),
            "{h:?}"
        );
        let h = e(&shaped("0,0,5,1,1,,1,,"));
        assert!(h.line == 3 && h.message.contains("column `r2`"), "{h:?}");
        let h = e(&shaped("0,0,5,1,1,1,1,0.05,1"));
        assert!(
            h.line == 3 && h.message.contains("column `eps1`") && h.message.contains("[0.1, 1.9]"),
            "{h:?}"
        );
        let h = e(&shaped("0,0,5,1,1,1,1,1,1.95"));
        assert!(
            h.line == 3 && h.message.contains("column `eps2`") && h.message.contains("[0.1, 1.9]"),
            "{h:?}"
        );
        let h = e(&shaped("0,0,5,1,1,-1,1,1,1"));
        assert!(
            h.line == 3 && h.message.contains("column `r2`") && h.message.contains("> 0"),
            "{h:?}"
        );
        let h = e(&shaped("0,0,5,1,0,1,1,1,1"));
        assert!(h.line == 3 && h.message.contains("column `r1`"), "{h:?}");
        let h = e(&shaped("0,0,5,1,1,1,x,1,1"));
        assert!(h.line == 3 && h.message.contains("`r3`: `x`"), "{h:?}");
        // a sphere line in a shaped file still needs its radius
        let h = e(&shaped("0,0,5,0,,,,,"));
        assert!(h.line == 3 && h.message.contains("`radius`"), "{h:?}");
        let h = e("x,y,z,radius,qw,qx,qy,qz\n0,0,0,1,1,0,0,0\n\n0,0,5,1,0,0,0,-0\n");
        assert!(
            h.line == 4 && h.message.contains("qw,qx,qy,qz") && h.message.contains("zero"),
            "{h:?}"
        );
        let h = e("x,y,z,radius,qw,qx,qy,qz\n0,0,0,1,1,NaN,0,0\n");
        assert!(
            h.line == 2 && h.message.contains("`qx`") && h.message.contains("finite"),
            "{h:?}"
        );
    }

    fn body(x: V3, q: UnitQuaternion<f64>, s: Superquadric, line: usize) -> FileParticle {
        FileParticle {
            position: x,
            radius: s.bounding_radius(),
            velocity: V3::zeros(),
            orientation: Some(q),
            angular_velocity: V3::zeros(),
            shape: Some(s),
            stone: None,
            line,
        }
    }

    /// Two needles (semi-axes 1, 0.2, 0.2) side by side: their bounding spheres (radius 1)
    /// overlap by far more than half an inscribed radius (0.2) at any of these distances, the
    /// bodies only when closer than 0.4.
    #[test]
    fn superquadric_overlap_is_the_real_one() {
        let needle = sq([1.0, 0.2, 0.2], 0.6, 1.0);
        let id = UnitQuaternion::identity();
        let pair = |dx: f64, gap: f64| {
            vec![
                body(V3::zeros(), id, needle, 1),
                body(V3::new(dx, gap, 0.0), id, needle, 2),
            ]
        };
        for gap in [0.45, 0.41, 0.35] {
            // 0.35: touching by 0.05 = 0.25 of r_in, accepted
            assert_eq!(
                find_overlap(&pair(0.1, gap), MAX_FILE_OVERLAP),
                None,
                "{gap}"
            );
        }
        assert!(find_overlap(&pair(0.1, 0.25), MAX_FILE_OVERLAP).is_some());
        let (a, b, f) = find_overlap(&pair(0.0, 0.25), MAX_FILE_OVERLAP).expect("overlap 0.15");
        assert_eq!((a, b), (0, 1));
        assert!((f - 0.75).abs() < 1e-8, "{f}");
        // crossed at the same centre (bounding spheres identical) and written twice
        let turned = UnitQuaternion::from_axis_angle(&V3::z_axis(), 1.0);
        let crossed = vec![
            body(V3::zeros(), id, needle, 1),
            body(V3::new(0.0, 0.0, 0.25), turned, needle, 2),
        ];
        let (_, _, f) = find_overlap(&crossed, MAX_FILE_OVERLAP).unwrap();
        assert!((f - 0.75).abs() < 1e-8, "{f}");
        let crossed_apart = vec![
            body(V3::zeros(), id, needle, 1),
            body(V3::new(0.0, 0.0, 0.45), turned, needle, 2),
        ];
        assert_eq!(find_overlap(&crossed_apart, MAX_FILE_OVERLAP), None);
        let twice = vec![
            body(V3::new(1.0, 2.0, 3.0), turned, needle, 1),
            body(V3::new(1.0, 2.0, 3.0), turned, needle, 2),
        ];
        let (_, _, f) = find_overlap(&twice, MAX_FILE_OVERLAP).unwrap();
        assert!(f > 1.9, "{f}");
        // a sphere (radius 0.2) beside the needle and at its tip
        let sphere = |x: V3| FileParticle::sphere(x, 0.2, V3::zeros(), 2);
        let beside = |y: f64| {
            vec![
                body(V3::zeros(), id, needle, 1),
                sphere(V3::new(0.0, y, 0.0)),
            ]
        };
        assert_eq!(find_overlap(&beside(0.45), MAX_FILE_OVERLAP), None);
        let (_, _, f) = find_overlap(&beside(0.25), MAX_FILE_OVERLAP).unwrap();
        assert!((f - 0.75).abs() < 1e-8, "{f}");
        let tip = vec![
            body(V3::zeros(), id, needle, 1),
            sphere(V3::new(1.05, 0.0, 0.0)),
        ];
        let (_, _, f) = find_overlap(&tip, MAX_FILE_OVERLAP).unwrap();
        assert!((f - 0.75).abs() < 1e-8, "{f}");
    }

    /// A row of 2000 parallel needles 0.41 apart (all bounding spheres overlap their
    /// neighbours', no body touches another) passes, one needle moved onto its neighbour is
    /// found as the first pair, and a sphere bed keeps the sphere rule.
    #[test]
    fn overlap_search_in_a_bed_of_needles() {
        let needle = sq([1.0, 0.2, 0.2], 0.6, 1.0);
        let id = UnitQuaternion::identity();
        let mut bed: Vec<FileParticle> = (0..2000)
            .map(|k| {
                let x = V3::new(0.0, 0.41 * (k % 40) as f64, 0.41 * (k / 40) as f64);
                body(x, id, needle, k + 2)
            })
            .collect();
        assert_eq!(find_overlap(&bed, MAX_FILE_OVERLAP), None);
        bed[1234].position.y -= 0.2;
        let (a, b, _) = find_overlap(&bed, MAX_FILE_OVERLAP).unwrap();
        assert_eq!((a, b), (1233, 1234));
        let spheres: Vec<FileParticle> = (0..3)
            .map(|k| FileParticle::sphere(V3::new(0.16 * k as f64, 0.0, 0.0), 0.1, V3::zeros(), k))
            .collect();
        assert_eq!(find_overlap(&spheres, MAX_FILE_OVERLAP), None);
        let (a, b, f) = find_overlap(&spheres, 0.3).unwrap();
        assert_eq!((a, b), (0, 1));
        assert!((f - 0.4).abs() < 1e-12);
    }
}
