//! Gmsh `.msh` version 4.1 ASCII reader. Physical groups become named node sets (all nodes of
//! the group's elements, any dimension) and, for 3-D groups, element sets. A mesh without
//! volume elements is a surface mesh: its 4-node quadrangles are shells or membranes, its
//! 3-node triangles membranes, its 2-D groups their sets.

use super::{sort_dedup, Mesh};
use crate::element::ElementKind;
use crate::FemError;
use std::collections::{BTreeMap, HashMap};

struct Lines<'a> {
    file: &'a str,
    it: std::iter::Enumerate<std::str::Lines<'a>>,
    line: usize,
}

impl<'a> Lines<'a> {
    fn err(&self, line: usize, message: impl Into<String>) -> FemError {
        FemError::Mesh {
            file: self.file.into(),
            line,
            message: message.into(),
        }
    }
    /// Next non-empty line with its 1-based number.
    fn next(&mut self, what: &str) -> Result<(usize, &'a str), FemError> {
        for (i, l) in self.it.by_ref() {
            self.line = i + 1;
            let t = l.trim();
            if !t.is_empty() {
                return Ok((i + 1, t));
            }
        }
        Err(self.err(
            self.line,
            format!("unexpected end of file while reading {what}"),
        ))
    }
    fn numbers<T: std::str::FromStr>(&mut self, what: &str) -> Result<(usize, Vec<T>), FemError> {
        let (ln, l) = self.next(what)?;
        let mut v = Vec::new();
        for tok in l.split_whitespace() {
            v.push(
                tok.parse::<T>()
                    .map_err(|_| self.err(ln, format!("cannot parse '{tok}' in {what}")))?,
            );
        }
        Ok((ln, v))
    }
    fn expect_end(&mut self, section: &str) -> Result<(), FemError> {
        let (ln, l) = self.next(section)?;
        let want = format!("$End{}", &section[1..]);
        if l != want {
            return Err(self.err(ln, format!("expected {want}, found '{l}'")));
        }
        Ok(())
    }
}

/// Gmsh element type → (dimension, number of nodes, volume kind).
fn gmsh_type(t: i64) -> Option<(usize, usize, Option<ElementKind>)> {
    Some(match t {
        15 => (0, 1, None),
        1 => (1, 2, None),
        8 => (1, 3, None),
        2 => (2, 3, None),
        3 => (2, 4, None),
        9 => (2, 6, None),
        10 => (2, 9, None),
        16 => (2, 8, None),
        4 => (3, 4, Some(ElementKind::Tet4)),
        11 => (3, 10, Some(ElementKind::Tet10)),
        5 => (3, 8, Some(ElementKind::Hex8)),
        17 => (3, 20, Some(ElementKind::Hex20)),
        6 => (3, 6, None),
        7 => (3, 5, None),
        12 => (3, 27, None),
        13 => (3, 18, None),
        14 => (3, 14, None),
        18 => (3, 15, None),
        19 => (3, 13, None),
        _ => return None,
    })
}

/// Gmsh → Abaqus node order (`abaqus[i] = gmsh[perm[i]]`).
const TET10_PERM: [usize; 10] = [0, 1, 2, 3, 4, 5, 6, 7, 9, 8];
const HEX20_PERM: [usize; 20] = [
    0, 1, 2, 3, 4, 5, 6, 7, 8, 11, 13, 9, 16, 18, 19, 17, 10, 12, 14, 15,
];

pub(super) fn parse(text: &str, file: &str) -> Result<Mesh, FemError> {
    let mut ls = Lines {
        file,
        it: text.lines().enumerate(),
        line: 0,
    };
    let mut mesh = Mesh {
        source: file.to_string(),
        ..Default::default()
    };
    let mut phys_names: HashMap<(usize, i64), String> = HashMap::new();
    // (dim, entity tag) → physical tags
    let mut entity_phys: HashMap<(usize, i64), Vec<i64>> = HashMap::new();
    let mut node_index: HashMap<u64, u32> = HashMap::new();
    // physical (dim, tag) → nodes / 3-D elements
    let mut group_nodes: BTreeMap<(usize, i64), Vec<u32>> = BTreeMap::new();
    let mut group_elems: BTreeMap<(usize, i64), Vec<u32>> = BTreeMap::new();
    let mut seen_format = false;
    let mut elements_seen = false;
    let mut elem_id_seen: HashMap<u64, usize> = HashMap::new();
    while let Some((i, l)) = ls.it.next() {
        let ln = i + 1;
        ls.line = ln;
        let l = l.trim();
        if l.is_empty() {
            continue;
        }
        match l {
            "$MeshFormat" => {
                let (fl, v) = ls.next("$MeshFormat")?;
                let toks: Vec<&str> = v.split_whitespace().collect();
                if toks.len() < 3 || !toks[0].starts_with('4') {
                    return Err(ls.err(
                        fl,
                        format!("unsupported MeshFormat '{v}' (need version 4.1)"),
                    ));
                }
                if toks[1] != "0" {
                    return Err(
                        ls.err(fl, "binary .msh files are not supported; save as ASCII 4.1")
                    );
                }
                ls.expect_end("$MeshFormat")?;
                seen_format = true;
            }
            "$PhysicalNames" => {
                let (_, n) = ls.numbers::<usize>("$PhysicalNames count")?;
                for _ in 0..n.first().copied().unwrap_or(0) {
                    let (pl, line) = ls.next("$PhysicalNames")?;
                    let mut parts = line.splitn(3, char::is_whitespace);
                    let dim = parts.next().and_then(|s| s.parse::<usize>().ok());
                    let tag = parts.next().and_then(|s| s.parse::<i64>().ok());
                    let name = parts.next().map(|s| s.trim().trim_matches('"').to_string());
                    match (dim, tag, name) {
                        (Some(d), Some(t), Some(nm)) => {
                            phys_names.insert((d, t), nm);
                        }
                        _ => {
                            return Err(ls.err(pl, format!("malformed physical name line '{line}'")))
                        }
                    }
                }
                ls.expect_end("$PhysicalNames")?;
            }
            "$Entities" => {
                let (el, c) = ls.numbers::<usize>("$Entities counts")?;
                if c.len() != 4 {
                    return Err(ls.err(el, "expected 'numPoints numCurves numSurfaces numVolumes'"));
                }
                for dim in 0..4 {
                    for _ in 0..c[dim] {
                        let (pl, v) = ls.numbers::<f64>("$Entities")?;
                        // point: tag x y z nphys ...; others: tag 6×bbox nphys ...
                        let at = if dim == 0 { 4 } else { 7 };
                        if v.len() <= at {
                            return Err(ls.err(pl, "truncated entity line"));
                        }
                        let np = v[at] as usize;
                        if v.len() < at + 1 + np {
                            return Err(ls.err(pl, "truncated physical tag list"));
                        }
                        let tags: Vec<i64> =
                            v[at + 1..at + 1 + np].iter().map(|&t| t as i64).collect();
                        entity_phys.insert((dim, v[0] as i64), tags);
                    }
                }
                ls.expect_end("$Entities")?;
            }
            "$Nodes" => {
                let (hl, h) = ls.numbers::<u64>("$Nodes header")?;
                if h.len() != 4 {
                    return Err(ls.err(
                        hl,
                        "expected 'numEntityBlocks numNodes minNodeTag maxNodeTag'",
                    ));
                }
                // a count from the file, not trusted for allocation: every node needs at
                // least a few bytes of the text, so reserve no more than the text could hold
                mesh.nodes.reserve((h[1] as usize).min(text.len() / 4));
                for _ in 0..h[0] {
                    let (bl, b) = ls.numbers::<i64>("$Nodes block header")?;
                    if b.len() != 4 {
                        return Err(ls.err(
                            bl,
                            "expected 'entityDim entityTag parametric numNodesInBlock'",
                        ));
                    }
                    let parametric = b[2] != 0;
                    let n = b[3] as usize;
                    let mut tags = Vec::with_capacity(n.min(text.len() / 2));
                    while tags.len() < n {
                        let (tl, t) = ls.numbers::<u64>("node tags")?;
                        for id in t {
                            if node_index
                                .insert(id, mesh.nodes.len() as u32 + tags.len() as u32)
                                .is_some()
                            {
                                return Err(ls.err(tl, format!("duplicate node id {id}")));
                            }
                            tags.push(id);
                        }
                    }
                    for &id in &tags {
                        let (cl, x) = ls.numbers::<f64>("node coordinates")?;
                        let need = if parametric {
                            3 + b[0].max(0) as usize
                        } else {
                            3
                        };
                        if x.len() < 3 || (parametric && x.len() < need) {
                            return Err(ls.err(cl, format!("node {id}: expected x y z")));
                        }
                        mesh.nodes.push([x[0], x[1], x[2]]);
                        mesh.node_ids.push(id);
                    }
                }
                ls.expect_end("$Nodes")?;
            }
            "$Elements" => {
                elements_seen = true;
                let (hl, h) = ls.numbers::<u64>("$Elements header")?;
                if h.len() != 4 {
                    return Err(ls.err(hl, "expected 'numEntityBlocks numElements minTag maxTag'"));
                }
                for _ in 0..h[0] {
                    let (bl, b) = ls.numbers::<i64>("$Elements block header")?;
                    if b.len() != 4 {
                        return Err(ls.err(
                            bl,
                            "expected 'entityDim entityTag elementType numElementsInBlock'",
                        ));
                    }
                    let (dim, ent, ty, n) = (b[0] as usize, b[1], b[2], b[3] as usize);
                    let (tdim, nn, kind) = gmsh_type(ty)
                        .ok_or_else(|| ls.err(bl, format!("unknown Gmsh element type {ty}")))?;
                    if tdim == 3 && kind.is_none() {
                        return Err(ls.err(
                            bl,
                            format!("unsupported volume element type {ty} (supported: tet4 = 4, tet10 = 11, hex8 = 5, hex20 = 17)"),
                        ));
                    }
                    let phys = entity_phys.get(&(dim, ent)).cloned().unwrap_or_default();
                    let mut local = vec![0u32; nn];
                    for _ in 0..n {
                        let (el, v) = ls.numbers::<u64>("element")?;
                        if v.len() != nn + 1 {
                            return Err(ls.err(
                                el,
                                format!(
                                    "element {}: expected {nn} nodes for type {ty}, found {}",
                                    v.first().copied().unwrap_or(0),
                                    v.len().saturating_sub(1)
                                ),
                            ));
                        }
                        for (k, id) in v[1..].iter().enumerate() {
                            local[k] = *node_index.get(id).ok_or_else(|| {
                                ls.err(el, format!("element {} references missing node {id}", v[0]))
                            })?;
                        }
                        for &p in &phys {
                            group_nodes
                                .entry((dim, p))
                                .or_default()
                                .extend_from_slice(&local);
                        }
                        if tdim == 2 {
                            // surface elements: shells if the mesh turns out to have no
                            // volume elements (`settle_shells`), otherwise only faces
                            if nn == 4 || nn == 3 {
                                let s = if nn == 4 {
                                    mesh.shells.push(
                                        [local[0], local[1], local[2], local[3]],
                                        v[0],
                                        el,
                                    )
                                } else {
                                    mesh.shells.push_triangle(
                                        [local[0], local[1], local[2]],
                                        v[0],
                                        el,
                                    )
                                };
                                for &p in &phys {
                                    mesh.shells
                                        .sets
                                        .entry(group_name_of(&phys_names, (dim, p)))
                                        .or_default()
                                        .push(s);
                                }
                            } else {
                                mesh.shells.unsupported.push((v[0], el, "a Gmsh element of type 9/10/16 (4-node quadrangles, type 3, make shells and membranes; 3-node triangles, type 2, membranes)"));
                            }
                        }
                        if let Some(kind) = kind {
                            if let Some(prev) = elem_id_seen.insert(v[0], el) {
                                return Err(ls.err(
                                    el,
                                    format!("duplicate element id {} (first on line {prev})", v[0]),
                                ));
                            }
                            let nodes: Vec<u32> = match kind {
                                ElementKind::Tet10 => {
                                    TET10_PERM.iter().map(|&k| local[k]).collect()
                                }
                                ElementKind::Hex20 => {
                                    HEX20_PERM.iter().map(|&k| local[k]).collect()
                                }
                                _ => local.clone(),
                            };
                            let e = mesh.kinds.len() as u32;
                            mesh.push_element(kind, v[0], el, &nodes);
                            for &p in &phys {
                                group_elems.entry((dim, p)).or_default().push(e);
                            }
                        }
                    }
                }
                ls.expect_end("$Elements")?;
            }
            s if s.starts_with("$End") => {
                return Err(ls.err(ln, format!("unexpected '{s}'")));
            }
            s if s.starts_with('$') => {
                // Skip sections we do not need ($Periodic, $NodeData, ...).
                let end = format!("$End{}", &s[1..]);
                loop {
                    let (_, l) = ls.next(s)?;
                    if l == end {
                        break;
                    }
                }
            }
            other => {
                return Err(ls.err(
                    ln,
                    format!("unexpected content '{other}' outside a section"),
                ))
            }
        }
    }
    if !seen_format {
        return Err(ls.err(1, "missing $MeshFormat section: not a Gmsh .msh file"));
    }
    if !elements_seen {
        return Err(ls.err(ls.line, "missing $Elements section"));
    }
    let group_name = |key: &(usize, i64)| group_name_of(&phys_names, *key);
    for (key, nodes) in group_nodes {
        let name = group_name(&key);
        let set = mesh.node_sets.entry(name).or_default();
        set.extend(nodes);
        let v = std::mem::take(set);
        *set = sort_dedup(v);
    }
    for (key, elems) in group_elems {
        mesh.elem_sets
            .entry(group_name(&key))
            .or_default()
            .extend(elems);
    }
    mesh.settle_shells();
    Ok(mesh)
}

/// A physical group's name, or its tag when it has none.
fn group_name_of(names: &HashMap<(usize, i64), String>, key: (usize, i64)) -> String {
    names
        .get(&key)
        .cloned()
        .unwrap_or_else(|| format!("{}", key.1))
}
