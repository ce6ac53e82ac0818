//! Abaqus / CalculiX `.inp` reader: *NODE, *ELEMENT (C3D4, C3D10, C3D8, C3D8I, C3D20),
//! *NSET / *ELSET (with GENERATE and nested set names); in a deck without volume elements,
//! surface elements (S4 / S4R / M3D4 / M3D4R quadrilaterals, S3 / S3R / M3D3 / STRI3 triangles)
//! and their *SHELL SECTION / *MEMBRANE SECTION thicknesses. Other keywords are skipped.

use super::{sort_dedup, Mesh};
use crate::element::ElementKind;
use crate::FemError;
use std::collections::HashMap;

enum Block {
    None,
    Node(Option<String>),
    Element {
        kind: ElementKind,
        elset: Option<String>,
    },
    /// Surface/line elements (CPS8, S4, T3D2, ...): not part of the model, but their ELSETs
    /// become node sets (e.g. the faces Gmsh exports for physical surfaces).
    AuxElement {
        elset: Option<String>,
        /// The element type (S4 / S4R: a shell if the deck has no volume elements).
        ty: String,
    },
    /// *SHELL SECTION or *MEMBRANE SECTION, ELSET=...: the next data line starts with the
    /// thickness; `refused` says why a model here cannot use it (COMPOSITE, OFFSET, NODAL
    /// THICKNESS).
    ShellSection {
        keyword: &'static str,
        elset: String,
        line: usize,
        done: bool,
        refused: Option<String>,
    },
    Nset {
        name: String,
        generate: bool,
    },
    Elset {
        name: String,
        generate: bool,
    },
    Skip,
}

/// Why a lower-dimensional element is neither a shell nor a membrane here.
fn unsupported_type(ty: &str) -> &'static str {
    if ["T3D", "B31", "B32"].iter().any(|p| ty.starts_with(p)) {
        "a truss or beam (a shell model takes 4-node S4 or S4R shells, a membrane M3D4/M3D3)"
    } else {
        "a surface element other than S4/S4R/M3D4/M3D4R or S3/S3R/M3D3/STRI3 (a shell model \
         takes 4-node S4 or S4R shells, a membrane M3D4/M3D3)"
    }
}

/// Four-node surface elements: shells (S4, S4R) and membranes (M3D4, M3D4R).
fn is_quad_type(ty: &str) -> bool {
    matches!(ty, "S4" | "S4R" | "M3D4" | "M3D4R")
}

/// Three-node surface elements (a membrane takes them; a shell model refuses them).
fn is_triangle_type(ty: &str) -> bool {
    matches!(ty, "S3" | "S3R" | "M3D3" | "STRI3")
}

/// Lower-dimensional element families that may appear in a deck next to the solid mesh.
fn is_auxiliary_type(ty: &str) -> bool {
    [
        "CPS", "CPE", "CAX", "CGAX", "S3", "S4", "S6", "S8", "STRI", "M3D", "SFM3D", "T3D", "B31",
        "B32", "R3D",
    ]
    .iter()
    .any(|p| ty.starts_with(p))
}

fn element_kind(ty: &str) -> Option<ElementKind> {
    Some(match ty {
        "C3D4" | "C3D4H" => ElementKind::Tet4,
        "C3D10" | "C3D10M" | "C3D10H" | "C3D10T" => ElementKind::Tet10,
        "C3D8" | "C3D8H" => ElementKind::Hex8,
        "C3D8I" => ElementKind::Hex8i,
        "C3D20" | "C3D20R" | "C3D20H" => ElementKind::Hex20,
        _ => return None,
    })
}

pub(super) fn parse(text: &str, file: &str) -> Result<Mesh, FemError> {
    let err = |line: usize, message: String| FemError::Mesh {
        file: file.into(),
        line,
        message,
    };
    let mut mesh = Mesh {
        source: file.to_string(),
        ..Default::default()
    };
    let mut node_index: HashMap<u64, (u32, usize)> = HashMap::new();
    let mut elem_index: HashMap<u64, (u32, usize)> = HashMap::new();
    // Set members are resolved at the end so sets may reference nodes/elements defined later.
    let mut nset_raw: Vec<(String, usize, String)> = Vec::new();
    let mut elset_raw: Vec<(String, usize, String, bool)> = Vec::new();
    let mut nset_gen: Vec<(String, usize, Vec<i64>)> = Vec::new();
    let mut block = Block::None;
    let mut aux_elems: HashMap<u64, Vec<u32>> = HashMap::new();
    let mut aux_sets: std::collections::BTreeMap<String, Vec<u32>> = Default::default();
    let mut shell_index: HashMap<u64, u32> = HashMap::new();
    // *SHELL SECTION / *MEMBRANE SECTION: (keyword, element set, line, thickness)
    let mut sections: Vec<(&'static str, String, usize, Result<f64, String>)> = Vec::new();
    // Element data may continue over several lines (trailing comma).
    let mut pending: Vec<u64> = Vec::new();
    let mut pending_line = 0usize;

    for (i, raw) in text.lines().enumerate() {
        let ln = i + 1;
        let line = raw.trim();
        if line.is_empty() || line.starts_with("**") {
            continue;
        }
        if let Some(kw) = line.strip_prefix('*') {
            if !pending.is_empty() {
                return Err(err(
                    pending_line,
                    "element definition is incomplete (missing nodes)".into(),
                ));
            }
            let mut parts = kw.split(',').map(|s| s.trim());
            let name = parts.next().unwrap_or("").to_ascii_uppercase();
            let mut params: HashMap<String, String> = HashMap::new();
            for p in parts {
                if p.is_empty() {
                    continue;
                }
                let mut kv = p.splitn(2, '=');
                let k = kv.next().unwrap_or("").trim().to_ascii_uppercase();
                let v = kv.next().unwrap_or("").trim().to_string();
                params.insert(k, v);
            }
            block = match name.as_str() {
                "NODE" => Block::Node(params.get("NSET").cloned()),
                "ELEMENT" => {
                    let ty = params
                        .get("TYPE")
                        .ok_or_else(|| err(ln, "*ELEMENT without TYPE=".into()))?
                        .to_ascii_uppercase();
                    match element_kind(&ty) {
                        Some(kind) => Block::Element { kind, elset: params.get("ELSET").cloned() },
                        None if is_auxiliary_type(&ty) => Block::AuxElement {
                            elset: params.get("ELSET").cloned(),
                            ty: ty.clone(),
                        },
                        None => {
                            return Err(err(
                                ln,
                                format!("unknown element type '{ty}' (supported: C3D4, C3D10, C3D8, C3D8I, C3D20, C3D20R)"),
                            ))
                        }
                    }
                }
                "NSET" => Block::Nset {
                    name: params
                        .get("NSET")
                        .cloned()
                        .ok_or_else(|| err(ln, "*NSET without NSET=".into()))?,
                    generate: params.contains_key("GENERATE"),
                },
                "ELSET" => Block::Elset {
                    name: params
                        .get("ELSET")
                        .cloned()
                        .ok_or_else(|| err(ln, "*ELSET without ELSET=".into()))?,
                    generate: params.contains_key("GENERATE"),
                },
                "SHELL SECTION" | "MEMBRANE SECTION" => Block::ShellSection {
                    keyword: if name == "SHELL SECTION" {
                        "*SHELL SECTION"
                    } else {
                        "*MEMBRANE SECTION"
                    },
                    elset: params.get("ELSET").cloned().unwrap_or_default(),
                    line: ln,
                    done: false,
                    refused: ["COMPOSITE", "OFFSET", "NODAL THICKNESS"]
                        .into_iter()
                        .find(|k| params.contains_key(*k))
                        .map(|k| format!("{k} is not supported (a homogeneous section on the mid-surface, one thickness per element set)"))
                        .or_else(|| (!params.contains_key("ELSET")).then(|| "no ELSET=".to_string())),
                },
                "INCLUDE" => {
                    return Err(err(
                        ln,
                        "*INCLUDE is not supported; inline the included file".into(),
                    ))
                }
                _ => Block::Skip,
            };
            continue;
        }
        let fields: Vec<&str> = line.split(',').map(|s| s.trim()).collect();
        match &block {
            Block::None => return Err(err(ln, format!("data line '{line}' before any keyword"))),
            Block::Skip => {}
            Block::Node(nset) => {
                let vals: Vec<&str> = fields.iter().copied().filter(|s| !s.is_empty()).collect();
                if vals.len() < 3 {
                    return Err(err(
                        ln,
                        format!("node line '{line}': expected 'id, x, y[, z]'"),
                    ));
                }
                let id: u64 = vals[0]
                    .parse()
                    .map_err(|_| err(ln, format!("bad node id '{}'", vals[0])))?;
                let mut x = [0.0; 3];
                for k in 0..(vals.len() - 1).min(3) {
                    x[k] = vals[k + 1].parse().map_err(|_| {
                        err(ln, format!("node {id}: bad coordinate '{}'", vals[k + 1]))
                    })?;
                }
                let idx = mesh.nodes.len() as u32;
                if let Some((_, prev)) = node_index.insert(id, (idx, ln)) {
                    return Err(err(
                        ln,
                        format!("duplicate node id {id} (first defined on line {prev})"),
                    ));
                }
                mesh.nodes.push(x);
                mesh.node_ids.push(id);
                if let Some(s) = nset {
                    mesh.node_sets.entry(s.clone()).or_default().push(idx);
                }
            }
            Block::Element { kind, elset } => {
                if pending.is_empty() {
                    pending_line = ln;
                }
                for f in fields.iter().filter(|s| !s.is_empty()) {
                    pending.push(
                        f.parse()
                            .map_err(|_| err(ln, format!("bad integer '{f}' in element data")))?,
                    );
                }
                let nn = kind.num_nodes();
                if pending.len() > nn + 1 {
                    return Err(err(
                        pending_line,
                        format!(
                            "element {}: {} nodes given, {} expects {nn}",
                            pending[0],
                            pending.len() - 1,
                            kind.name()
                        ),
                    ));
                }
                if pending.len() == nn + 1 {
                    let id = pending[0];
                    let mut nodes = Vec::with_capacity(nn);
                    for nid in &pending[1..] {
                        let (ix, _) = node_index.get(nid).ok_or_else(|| {
                            err(
                                pending_line,
                                format!("element {id} references missing node {nid}"),
                            )
                        })?;
                        nodes.push(*ix);
                    }
                    let e = mesh.kinds.len() as u32;
                    if let Some((_, prev)) = elem_index.insert(id, (e, pending_line)) {
                        return Err(err(
                            pending_line,
                            format!("duplicate element id {id} (first defined on line {prev})"),
                        ));
                    }
                    mesh.push_element(*kind, id, pending_line, &nodes);
                    if let Some(s) = elset {
                        mesh.elem_sets.entry(s.clone()).or_default().push(e);
                    }
                    pending.clear();
                } else if !line.ends_with(',') {
                    return Err(err(
                        pending_line,
                        format!(
                            "element {}: {} nodes given, {} expects {nn}",
                            pending[0],
                            pending.len() - 1,
                            kind.name()
                        ),
                    ));
                }
            }
            Block::ShellSection {
                keyword,
                elset,
                line: kw_line,
                done,
                refused,
            } => {
                // read only for shell models (applied at the end when the deck has no volume
                // elements); a solid deck's shell sections are skipped as before
                let parsed = if let Some(why) = refused {
                    Err(why.clone())
                } else if *done {
                    Err(format!(
                        "one data line (the thickness) expected, found another: '{line}'"
                    ))
                } else {
                    match fields[0].parse::<f64>() {
                        Ok(t) if t > 0.0 && t.is_finite() => Ok(t),
                        Ok(t) => Err(format!(
                            "ELSET={elset}: the thickness must be positive, got {t}"
                        )),
                        Err(_) => Err(format!("ELSET={elset}: bad thickness '{}'", fields[0])),
                    }
                };
                if !*done || parsed.is_err() {
                    sections.push((
                        *keyword,
                        elset.clone(),
                        if *done { ln } else { *kw_line },
                        parsed,
                    ));
                }
                block = Block::ShellSection {
                    keyword,
                    elset: elset.clone(),
                    line: *kw_line,
                    done: true,
                    refused: refused.clone(),
                };
            }
            Block::AuxElement { elset, ty } => {
                if pending.is_empty() {
                    pending_line = ln;
                }
                for f in fields.iter().filter(|s| !s.is_empty()) {
                    pending.push(
                        f.parse()
                            .map_err(|_| err(ln, format!("bad integer '{f}' in element data")))?,
                    );
                }
                if !line.ends_with(',') {
                    let id = pending[0];
                    let mut nodes = Vec::new();
                    for nid in &pending[1..] {
                        let (ix, _) = node_index.get(nid).ok_or_else(|| {
                            err(
                                pending_line,
                                format!("element {id} references missing node {nid}"),
                            )
                        })?;
                        nodes.push(*ix);
                    }
                    if let Some(s) = elset {
                        aux_sets
                            .entry(s.clone())
                            .or_default()
                            .extend_from_slice(&nodes);
                    }
                    if is_quad_type(ty) || is_triangle_type(ty) {
                        let want = if is_quad_type(ty) { 4 } else { 3 };
                        if nodes.len() != want {
                            return Err(err(
                                pending_line,
                                format!(
                                    "element {id}: {} nodes given, {ty} expects {want}",
                                    nodes.len()
                                ),
                            ));
                        }
                        let s = if want == 4 {
                            mesh.shells.push(
                                [nodes[0], nodes[1], nodes[2], nodes[3]],
                                id,
                                pending_line,
                            )
                        } else {
                            mesh.shells.push_triangle(
                                [nodes[0], nodes[1], nodes[2]],
                                id,
                                pending_line,
                            )
                        };
                        shell_index.insert(id, s);
                        if let Some(set) = elset {
                            mesh.shells.sets.entry(set.clone()).or_default().push(s);
                        }
                    } else {
                        mesh.shells
                            .unsupported
                            .push((id, pending_line, unsupported_type(ty)));
                    }
                    aux_elems.insert(id, nodes);
                    pending.clear();
                }
            }
            Block::Nset { name, generate } => {
                if *generate {
                    let v: Result<Vec<i64>, _> = fields
                        .iter()
                        .filter(|s| !s.is_empty())
                        .map(|s| s.parse::<i64>())
                        .collect();
                    let v = v.map_err(|_| {
                        err(
                            ln,
                            format!("*NSET {name}, GENERATE: expected 'first, last[, step]'"),
                        )
                    })?;
                    nset_gen.push((name.clone(), ln, v));
                } else {
                    for f in fields.iter().filter(|s| !s.is_empty()) {
                        nset_raw.push((name.clone(), ln, f.to_string()));
                    }
                }
            }
            Block::Elset { name, generate } => {
                for f in fields.iter().filter(|s| !s.is_empty()) {
                    elset_raw.push((name.clone(), ln, f.to_string(), *generate));
                }
            }
        }
    }
    if !pending.is_empty() {
        return Err(err(
            pending_line,
            "element definition is incomplete at end of file".into(),
        ));
    }
    // the ids of a range, produced one by one: a range longer than the mesh (`1, 1e15`) ends
    // at its first missing id instead of being collected into memory first
    let generate = |name: &str,
                    ln: usize,
                    v: &[i64]|
     -> Result<std::iter::StepBy<std::ops::RangeInclusive<u64>>, FemError> {
        if !(v.len() == 2 || v.len() == 3) || v[0] < 0 || v[1] < v[0] || (v.len() == 3 && v[2] <= 0)
        {
            return Err(err(ln, format!("set {name}, GENERATE: expected 'first, last[, step]' with first ≤ last, step > 0")));
        }
        let step = if v.len() == 3 { v[2] } else { 1 };
        Ok((v[0] as u64..=v[1] as u64).step_by(step as usize))
    };
    for (name, ln, v) in nset_gen {
        for id in generate(&name, ln, &v)? {
            let (ix, _) = node_index
                .get(&id)
                .ok_or_else(|| err(ln, format!("*NSET {name} references missing node {id}")))?;
            mesh.node_sets.entry(name.clone()).or_default().push(*ix);
        }
    }
    for (name, ln, tok) in nset_raw {
        if let Ok(id) = tok.parse::<u64>() {
            let (ix, _) = node_index
                .get(&id)
                .ok_or_else(|| err(ln, format!("*NSET {name} references missing node {id}")))?;
            mesh.node_sets.entry(name).or_default().push(*ix);
        } else {
            let members = mesh.node_set(&tok).cloned().ok_or_else(|| {
                err(
                    ln,
                    format!("*NSET {name} references unknown node set '{tok}'"),
                )
            })?;
            mesh.node_sets.entry(name).or_default().extend(members);
        }
    }
    // ELSET data: either GENERATE triples (one per line) or ids / set names.
    let mut gen_lines: HashMap<(String, usize), Vec<i64>> = HashMap::new();
    let mut order: Vec<(String, usize)> = Vec::new();
    for (name, ln, tok, gen) in elset_raw {
        if gen {
            let v = tok
                .parse::<i64>()
                .map_err(|_| err(ln, format!("*ELSET {name}, GENERATE: bad integer '{tok}'")))?;
            let key = (name.clone(), ln);
            if !gen_lines.contains_key(&key) {
                order.push(key.clone());
            }
            gen_lines.entry(key).or_default().push(v);
        } else if let Ok(id) = tok.parse::<u64>() {
            if let Some(nodes) = aux_elems.get(&id) {
                if let Some(&s) = shell_index.get(&id) {
                    mesh.shells.sets.entry(name.clone()).or_default().push(s);
                }
                aux_sets.entry(name).or_default().extend_from_slice(nodes);
                continue;
            }
            let (ix, _) = elem_index
                .get(&id)
                .ok_or_else(|| err(ln, format!("*ELSET {name} references missing element {id}")))?;
            mesh.elem_sets.entry(name).or_default().push(*ix);
        } else {
            let shells = mesh.shells.set(&tok).cloned();
            let members = mesh.elem_set(&tok).cloned();
            if members.is_none() && shells.is_none() {
                return Err(err(
                    ln,
                    format!("*ELSET {name} references unknown element set '{tok}'"),
                ));
            }
            if let Some(s) = shells {
                mesh.shells.sets.entry(name.clone()).or_default().extend(s);
            }
            if let Some(m) = members {
                mesh.elem_sets.entry(name).or_default().extend(m);
            }
        }
    }
    for key in order {
        let v = &gen_lines[&key];
        for id in generate(&key.0, key.1, v)? {
            if let Some(nodes) = aux_elems.get(&id) {
                if let Some(&s) = shell_index.get(&id) {
                    mesh.shells.sets.entry(key.0.clone()).or_default().push(s);
                }
                aux_sets
                    .entry(key.0.clone())
                    .or_default()
                    .extend_from_slice(nodes);
                continue;
            }
            let (ix, _) = elem_index.get(&id).ok_or_else(|| {
                err(
                    key.1,
                    format!("*ELSET {} references missing element {id}", key.0),
                )
            })?;
            mesh.elem_sets.entry(key.0.clone()).or_default().push(*ix);
        }
    }
    // Element sets of solid elements also define node sets (all their nodes), as do sets of
    // surface elements; explicit *NSETs of the same name take precedence.
    for (name, elems) in &mesh.elem_sets {
        if !mesh.node_sets.contains_key(name) && !aux_sets.contains_key(name) {
            let nodes: Vec<u32> = elems
                .iter()
                .flat_map(|&e| mesh.element_nodes(e as usize).to_vec())
                .collect();
            aux_sets.insert(name.clone(), nodes);
        }
    }
    for (name, nodes) in aux_sets {
        mesh.node_sets.entry(name).or_insert(nodes);
    }
    for v in mesh.node_sets.values_mut() {
        *v = sort_dedup(std::mem::take(v));
    }
    for v in mesh.elem_sets.values_mut() {
        *v = sort_dedup(std::mem::take(v));
    }
    for v in mesh.shells.sets.values_mut() {
        *v = sort_dedup(std::mem::take(v));
    }
    // shell sections matter only to a shell model (no volume elements)
    for (keyword, set, ln, t) in sections.into_iter().filter(|_| mesh.kinds.is_empty()) {
        let t = t.map_err(|why| err(ln, format!("{keyword}: {why}")))?;
        let members = mesh.shells.set(&set).cloned().ok_or_else(|| {
            err(
                ln,
                format!("{keyword}: unknown surface element set '{set}'"),
            )
        })?;
        for s in members {
            mesh.shells.thickness[s as usize] = t;
        }
    }
    mesh.settle_shells();
    Ok(mesh)
}
