//! STL reader (ASCII and binary). Errors name the file and the line (ASCII) or byte offset
//! (binary).

use crate::hertz_mindlin::V3;
use crate::DemError;
use std::collections::HashMap;
use std::path::Path;

/// A welded triangle soup: node positions and triangles indexing them.
#[derive(Debug, Clone, Default)]
pub struct TriangleMesh {
    pub positions: Vec<V3>,
    pub triangles: Vec<[u32; 3]>,
}

impl TriangleMesh {
    /// Merges bit-identical vertices (STL stores every corner separately) so that neighbouring
    /// triangles share nodes; indices are assigned in order of first appearance.
    pub fn weld(corners: &[[V3; 3]]) -> TriangleMesh {
        let mut map: HashMap<[u64; 3], u32> = HashMap::new();
        let mut mesh = TriangleMesh::default();
        for tri in corners {
            let mut t = [0u32; 3];
            for (k, c) in tri.iter().enumerate() {
                // +0.0 and -0.0 are the same point
                let key = [
                    (c.x + 0.0).to_bits(),
                    (c.y + 0.0).to_bits(),
                    (c.z + 0.0).to_bits(),
                ];
                let next = mesh.positions.len() as u32;
                let id = *map.entry(key).or_insert(next);
                if id == next {
                    mesh.positions.push(*c);
                }
                t[k] = id;
            }
            if t[0] != t[1] && t[1] != t[2] && t[0] != t[2] {
                mesh.triangles.push(t);
            }
        }
        mesh
    }
}

fn err(path: &Path, location: String, message: String) -> DemError {
    DemError::Stl {
        file: path.display().to_string(),
        location,
        message,
    }
}

/// Reads an STL file, detecting binary vs ASCII by the size rule 84 + 50·n.
pub fn read_stl(path: &Path) -> Result<TriangleMesh, DemError> {
    let bytes = std::fs::read(path).map_err(|e| err(path, "open".into(), e.to_string()))?;
    parse_stl(&bytes, path)
}

pub fn parse_stl(bytes: &[u8], path: &Path) -> Result<TriangleMesh, DemError> {
    let binary_size_matches = bytes.len() >= 84 && {
        let n = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as usize;
        bytes.len() == 84 + 50 * n
    };
    let starts_solid = bytes.len() >= 5 && bytes[..5].eq_ignore_ascii_case(b"solid");
    let corners = if binary_size_matches || !starts_solid {
        parse_binary(bytes, path)?
    } else {
        parse_ascii(bytes, path)?
    };
    if corners.is_empty() {
        return Err(err(path, "end of file".into(), "no triangles".into()));
    }
    Ok(TriangleMesh::weld(&corners))
}

fn parse_binary(bytes: &[u8], path: &Path) -> Result<Vec<[V3; 3]>, DemError> {
    if bytes.len() < 84 {
        return Err(err(
            path,
            format!("byte {}", bytes.len()),
            "binary STL shorter than its 84-byte header".into(),
        ));
    }
    let n = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as usize;
    let need = 84 + 50 * n;
    if bytes.len() < need {
        return Err(err(
            path,
            format!("byte {}", bytes.len()),
            format!(
                "binary STL declares {n} triangles ({need} bytes) but has {} bytes",
                bytes.len()
            ),
        ));
    }
    let mut out = Vec::with_capacity(n);
    for t in 0..n {
        let base = 84 + 50 * t + 12; // skip the facet normal
        let mut tri = [V3::zeros(); 3];
        for (v, corner) in tri.iter_mut().enumerate() {
            for a in 0..3 {
                let o = base + 12 * v + 4 * a;
                let x = f32::from_le_bytes([bytes[o], bytes[o + 1], bytes[o + 2], bytes[o + 3]]);
                if !x.is_finite() {
                    return Err(err(
                        path,
                        format!("byte {o}"),
                        format!("non-finite coordinate in triangle {t}"),
                    ));
                }
                corner[a] = x as f64;
            }
        }
        out.push(tri);
    }
    Ok(out)
}

fn parse_ascii(bytes: &[u8], path: &Path) -> Result<Vec<[V3; 3]>, DemError> {
    let text = std::str::from_utf8(bytes).map_err(|e| {
        err(
            path,
            format!("byte {}", e.valid_up_to()),
            "ASCII STL is not valid UTF-8".into(),
        )
    })?;
    let mut out = Vec::new();
    let mut corners: Vec<V3> = Vec::with_capacity(3);
    let mut in_loop = false;
    for (ln, line) in text.lines().enumerate() {
        let line_no = ln + 1;
        let mut words = line.split_whitespace();
        let Some(head) = words.next() else { continue };
        let at = || format!("line {line_no}");
        match head.to_ascii_lowercase().as_str() {
            "solid" | "endsolid" | "facet" => {}
            "outer" => {
                in_loop = true;
                corners.clear();
            }
            "vertex" => {
                if !in_loop {
                    return Err(err(path, at(), "`vertex` outside `outer loop`".into()));
                }
                let mut c = V3::zeros();
                for a in 0..3 {
                    let w = words
                        .next()
                        .ok_or_else(|| err(path, at(), "vertex needs 3 coordinates".into()))?;
                    c[a] = w
                        .parse::<f64>()
                        .map_err(|_| err(path, at(), format!("bad coordinate `{w}`")))?;
                    if !c[a].is_finite() {
                        return Err(err(path, at(), format!("non-finite coordinate `{w}`")));
                    }
                }
                corners.push(c);
            }
            "endloop" => {
                if corners.len() != 3 {
                    return Err(err(
                        path,
                        at(),
                        format!("facet has {} vertices, expected 3", corners.len()),
                    ));
                }
                out.push([corners[0], corners[1], corners[2]]);
                in_loop = false;
            }
            "endfacet" => {}
            other => return Err(err(path, at(), format!("unexpected keyword `{other}`"))),
        }
    }
    if in_loop {
        return Err(err(
            path,
            "end of file".into(),
            "unterminated `outer loop`".into(),
        ));
    }
    Ok(out)
}
