//! Particle CSV files: the `kind = "file"` particle source and `particles_final.csv`.
//!
//! Format: a header line naming the columns, `x,y,z,radius` and optionally `vx,vy,vz` (all
//! three), in any order; one sphere per line; empty lines are skipped. Values are written with
//! Rust's shortest round-trip representation, so a bed written at the end of one run starts
//! the next one bitwise where it stopped (positions, radii, velocities; rotations start at
//! rest).

use crate::hertz_mindlin::V3;
use crate::particles::Particles;
use std::fmt::Write as _;
use std::path::Path;

/// One sphere read from a file.
#[derive(Debug, Clone, PartialEq)]
pub struct FileSphere {
    pub position: V3,
    pub radius: f64,
    pub velocity: V3,
    /// 1-based line of the file.
    pub line: usize,
}

/// An error at a 1-based line of the file (0: the file as a whole).
#[derive(Debug, Clone, PartialEq)]
pub struct FileError {
    pub line: usize,
    pub message: String,
}

const REQUIRED: [&str; 4] = ["x", "y", "z", "radius"];
const VELOCITY: [&str; 3] = ["vx", "vy", "vz"];

/// Parses the text of a particle file.
pub fn parse(text: &str) -> Result<Vec<FileSphere>, FileError> {
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
    for name in &names {
        if !REQUIRED.contains(name) && !VELOCITY.contains(name) {
            return Err(err(
                header_line,
                format!("unknown column `{name}`, expected x,y,z,radius and optionally vx,vy,vz"),
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
    let vel: Vec<usize> = VELOCITY.iter().filter_map(|n| col(n)).collect();
    if !(vel.is_empty() || vel.len() == 3) {
        return Err(err(
            header_line,
            "give all three of vx,vy,vz or none".into(),
        ));
    }
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
        let radius = num(req[3])?;
        if radius <= 0.0 {
            return Err(err(
                line,
                format!("column `radius`: must be > 0, got {radius}"),
            ));
        }
        let velocity = if vel.is_empty() {
            V3::zeros()
        } else {
            V3::new(num(vel[0])?, num(vel[1])?, num(vel[2])?)
        };
        out.push(FileSphere {
            position: V3::new(num(req[0])?, num(req[1])?, num(req[2])?),
            radius,
            velocity,
            line,
        });
    }
    Ok(out)
}

/// Largest overlap of two spheres of a file that is still accepted, as a fraction of the
/// smaller radius. A settled or compacted bed written with `final_particles` overlaps by a few
/// per cent of r at most (contact overlaps of a dense bed under load; fewer printed digits add
/// rounding on top); half a radius is far beyond any contact the engine holds and means
/// spheres written twice, a wrong column, or a lattice written at the wrong spacing.
pub const MAX_FILE_OVERLAP: f64 = 0.5;

/// Two spheres overlapping by more than `max_fraction` of the smaller radius, as
/// (index a, index b, overlap / smaller radius) with a < b, the first such pair in the order
/// of `a` (then `b`), or `None`. A cell grid of edge 2 r_max keeps it O(n) for a bed.
pub fn find_overlap(spheres: &[FileSphere], max_fraction: f64) -> Option<(usize, usize, f64)> {
    use std::collections::HashMap;
    let r_max = spheres.iter().map(|s| s.radius).fold(0.0, f64::max);
    if spheres.len() < 2 || r_max <= 0.0 {
        return None;
    }
    let h = 2.0 * r_max;
    let cell = |x: V3| [x.x, x.y, x.z].map(|c| (c / h).floor().clamp(-9.0e15, 9.0e15) as i64);
    let mut grid: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
    for (k, s) in spheres.iter().enumerate() {
        grid.entry(cell(s.position)).or_default().push(k);
    }
    for (a, s) in spheres.iter().enumerate() {
        let c = cell(s.position);
        let mut worst: Option<(usize, f64)> = None;
        for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let Some(others) = grid.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) else {
                        continue;
                    };
                    for &b in others.iter().filter(|&&b| b > a) {
                        let o = &spheres[b];
                        let overlap = s.radius + o.radius - (s.position - o.position).norm();
                        let fraction = overlap / s.radius.min(o.radius);
                        if fraction > max_fraction && worst.is_none_or(|(w, _)| b < w) {
                            worst = Some((b, fraction));
                        }
                    }
                }
            }
        }
        if let Some((b, fraction)) = worst {
            return Some((a, b, fraction));
        }
    }
    None
}

/// The particles in id order as a particle file with velocities.
pub fn format(p: &Particles) -> String {
    let mut order: Vec<usize> = (0..p.len()).collect();
    order.sort_unstable_by_key(|&k| p.id[k]);
    let mut s = String::with_capacity(64 + 120 * p.len());
    s.push_str("x,y,z,radius,vx,vy,vz\n");
    for k in order {
        let (x, v) = (p.position[k], p.velocity[k]);
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{}",
            x.x, x.y, x.z, p.radius[k], v.x, v.y, v.z
        );
    }
    s
}

/// Reads a particle file; errors carry the line. The file's size is checked against the
/// memory available before it is read: its text and the spheres parsed from it (56 B each,
/// one per line of at least ~30 characters) take about twice its size.
pub fn read(path: &Path) -> Result<Vec<FileSphere>, FileError> {
    let text = crate::resources::read_text_within_memory(path, "it")
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
}
