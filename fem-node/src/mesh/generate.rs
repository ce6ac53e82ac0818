//! Structured box meshes (hex8, hex8i, hex20, tet4, tet10) for scenes and tests.

use super::Mesh;
use crate::element::ElementKind;

/// Box `[origin, origin + size]` with `div` elements per direction. Node sets: `xmin`, `xmax`,
/// `ymin`, `ymax`, `zmin`, `zmax` (nodes on those faces) and `all`; element set `all`.
/// Tetrahedral meshes split every cell into 6 Kuhn tetrahedra (conforming).
pub fn box_mesh(origin: [f64; 3], size: [f64; 3], div: [usize; 3], kind: ElementKind) -> Mesh {
    let quadratic = matches!(kind, ElementKind::Hex20 | ElementKind::Tet10);
    let r = if quadratic { 2 } else { 1 };
    let g = [r * div[0] + 1, r * div[1] + 1, r * div[2] + 1];
    let gid = |i: usize, j: usize, k: usize| (k * g[1] + j) * g[0] + i;
    let mut conn_grid: Vec<Vec<usize>> = Vec::new();
    for k in 0..div[2] {
        for j in 0..div[1] {
            for i in 0..div[0] {
                let (i0, j0, k0) = (r * i, r * j, r * k);
                // corner c = (a, b, c) ∈ {0,1}³ in fine-grid units
                let c = |a: usize, b: usize, cc: usize| [i0 + r * a, j0 + r * b, k0 + r * cc];
                match kind {
                    ElementKind::Hex8
                    | ElementKind::Hex8i
                    | ElementKind::Hex8b
                    | ElementKind::Hex20 => {
                        let corners = [
                            c(0, 0, 0),
                            c(1, 0, 0),
                            c(1, 1, 0),
                            c(0, 1, 0),
                            c(0, 0, 1),
                            c(1, 0, 1),
                            c(1, 1, 1),
                            c(0, 1, 1),
                        ];
                        let mut nodes: Vec<usize> =
                            corners.iter().map(|p| gid(p[0], p[1], p[2])).collect();
                        if kind == ElementKind::Hex20 {
                            const EDGES: [(usize, usize); 12] = [
                                (0, 1),
                                (1, 2),
                                (2, 3),
                                (3, 0),
                                (4, 5),
                                (5, 6),
                                (6, 7),
                                (7, 4),
                                (0, 4),
                                (1, 5),
                                (2, 6),
                                (3, 7),
                            ];
                            for (a, b) in EDGES {
                                let m = mid(corners[a], corners[b]);
                                nodes.push(gid(m[0], m[1], m[2]));
                            }
                        }
                        conn_grid.push(nodes);
                    }
                    ElementKind::Tet4 | ElementKind::Tet10 => {
                        // Kuhn triangulation: monotone paths (0,0,0) → (1,1,1), one per axis order
                        const PERMS: [[usize; 3]; 6] = [
                            [0, 1, 2],
                            [0, 2, 1],
                            [1, 0, 2],
                            [1, 2, 0],
                            [2, 0, 1],
                            [2, 1, 0],
                        ];
                        for p in PERMS {
                            let mut v = [[0usize; 3]; 4];
                            let mut cur = [0usize; 3];
                            v[0] = c(0, 0, 0);
                            for s in 0..3 {
                                cur[p[s]] = 1;
                                v[s + 1] = c(cur[0], cur[1], cur[2]);
                            }
                            // orient positively
                            let vol = signed_volume(&v);
                            if vol < 0 {
                                v.swap(1, 2);
                            }
                            let mut nodes: Vec<usize> =
                                v.iter().map(|q| gid(q[0], q[1], q[2])).collect();
                            if kind == ElementKind::Tet10 {
                                for (a, b) in [(0, 1), (1, 2), (2, 0), (0, 3), (1, 3), (2, 3)] {
                                    let m = mid(v[a], v[b]);
                                    nodes.push(gid(m[0], m[1], m[2]));
                                }
                            }
                            conn_grid.push(nodes);
                        }
                    }
                }
            }
        }
    }
    // Compact: keep only grid points used by elements (hex20 skips face/body centres).
    let total = g[0] * g[1] * g[2];
    let mut new_index = vec![u32::MAX; total];
    let mut used = vec![false; total];
    for e in &conn_grid {
        for &n in e {
            used[n] = true;
        }
    }
    let mut mesh = Mesh {
        source: format!("<generated {} box>", kind.name()),
        ..Default::default()
    };
    for k in 0..g[2] {
        for j in 0..g[1] {
            for i in 0..g[0] {
                let n = gid(i, j, k);
                if !used[n] {
                    continue;
                }
                new_index[n] = mesh.nodes.len() as u32;
                mesh.node_ids.push(mesh.nodes.len() as u64 + 1);
                let f = [i, j, k];
                let mut x = [0.0; 3];
                for a in 0..3 {
                    x[a] = origin[a] + size[a] * f[a] as f64 / (g[a] - 1) as f64;
                }
                mesh.nodes.push(x);
                let names = [["xmin", "xmax"], ["ymin", "ymax"], ["zmin", "zmax"]];
                for a in 0..3 {
                    if f[a] == 0 {
                        mesh.node_sets
                            .entry(names[a][0].into())
                            .or_default()
                            .push(new_index[n]);
                    }
                    if f[a] == g[a] - 1 {
                        mesh.node_sets
                            .entry(names[a][1].into())
                            .or_default()
                            .push(new_index[n]);
                    }
                }
            }
        }
    }
    mesh.node_sets
        .insert("all".into(), (0..mesh.nodes.len() as u32).collect());
    for (e, nodes) in conn_grid.iter().enumerate() {
        let local: Vec<u32> = nodes.iter().map(|&n| new_index[n]).collect();
        mesh.push_element(kind, e as u64 + 1, 0, &local);
    }
    mesh.elem_sets
        .insert("all".into(), (0..mesh.kinds.len() as u32).collect());
    mesh
}

fn mid(a: [usize; 3], b: [usize; 3]) -> [usize; 3] {
    [(a[0] + b[0]) / 2, (a[1] + b[1]) / 2, (a[2] + b[2]) / 2]
}

fn signed_volume(v: &[[usize; 3]; 4]) -> i64 {
    let d = |a: usize, k: usize| v[a][k] as i64 - v[0][k] as i64;
    let (a, b, c) = (
        [d(1, 0), d(1, 1), d(1, 2)],
        [d(2, 0), d(2, 1), d(2, 2)],
        [d(3, 0), d(3, 1), d(3, 2)],
    );
    a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
        + a[2] * (b[0] * c[1] - b[1] * c[0])
}

/// A rectangle of 4-node shells: `size` has one zero component, the normal axis n; the two
/// in-plane axes a = n + 1, b = n + 2 (cyclic) carry `div` = [divisions along the lower, the
/// higher axis index] shells. Corners run counter-clockwise about +n, so the directors point
/// along +n. Node sets: the in-plane edges (`xmin`, `xmax`, ...) and `all`; shell set `all`.
pub fn plate_mesh(origin: [f64; 3], size: [f64; 3], div: [usize; 2]) -> Mesh {
    let n = (0..3).find(|&k| size[k] == 0.0).unwrap_or(2);
    let (a, b) = ((n + 1) % 3, (n + 2) % 3);
    // divisions along a and b (div is ordered by axis index)
    let (da, db) = if a < b {
        (div[0], div[1])
    } else {
        (div[1], div[0])
    };
    let mut mesh = Mesh {
        source: "<generated mitc4 plate>".into(),
        ..Default::default()
    };
    let names = [["xmin", "xmax"], ["ymin", "ymax"], ["zmin", "zmax"]];
    let id = |i: usize, j: usize| (j * (da + 1) + i) as u32;
    for j in 0..=db {
        for i in 0..=da {
            let mut x = origin;
            x[a] += size[a] * i as f64 / da as f64;
            x[b] += size[b] * j as f64 / db as f64;
            let node = id(i, j);
            mesh.nodes.push(x);
            mesh.node_ids.push(node as u64 + 1);
            for (axis, f, last) in [(a, i, da), (b, j, db)] {
                if f == 0 {
                    mesh.node_sets
                        .entry(names[axis][0].into())
                        .or_default()
                        .push(node);
                }
                if f == last {
                    mesh.node_sets
                        .entry(names[axis][1].into())
                        .or_default()
                        .push(node);
                }
            }
        }
    }
    mesh.node_sets
        .insert("all".into(), (0..mesh.nodes.len() as u32).collect());
    for j in 0..db {
        for i in 0..da {
            let e = mesh.shells.len() as u64 + 1;
            mesh.shells.push(
                [id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)],
                e,
                0,
            );
        }
    }
    mesh.shells
        .sets
        .insert("all".into(), (0..mesh.shells.len() as u32).collect());
    mesh
}

/// A cylinder of 4-node surface elements about the z axis through `origin` (its bottom
/// centre): `div` = [around, along]; corners counter-clockwise seen from outside, so the
/// normals point outwards. Node sets `bottom`, `top` (the end rings) and `all`; element set
/// `all`.
pub fn cylinder_mesh(origin: [f64; 3], radius: f64, height: f64, div: [usize; 2]) -> Mesh {
    let (na, nl) = (div[0], div[1]);
    let mut mesh = Mesh {
        source: "<generated membrane cylinder>".into(),
        ..Default::default()
    };
    let id = |i: usize, j: usize| (j * na + i % na) as u32;
    for j in 0..=nl {
        for i in 0..na {
            let theta = 2.0 * std::f64::consts::PI * i as f64 / na as f64;
            let node = id(i, j);
            mesh.nodes.push([
                origin[0] + radius * theta.cos(),
                origin[1] + radius * theta.sin(),
                origin[2] + height * j as f64 / nl as f64,
            ]);
            mesh.node_ids.push(node as u64 + 1);
            if j == 0 {
                mesh.node_sets
                    .entry("bottom".into())
                    .or_default()
                    .push(node);
            }
            if j == nl {
                mesh.node_sets.entry("top".into()).or_default().push(node);
            }
        }
    }
    mesh.node_sets
        .insert("all".into(), (0..mesh.nodes.len() as u32).collect());
    for j in 0..nl {
        for i in 0..na {
            let e = mesh.shells.len() as u64 + 1;
            mesh.shells.push(
                [id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)],
                e,
                0,
            );
        }
    }
    mesh.shells
        .sets
        .insert("all".into(), (0..mesh.shells.len() as u32).collect());
    mesh
}
