//! Global sparse matrices over the free equations (fixed dofs eliminated, (2.54)–(2.57)):
//! sparsity pattern from node adjacency, deterministic parallel assembly, symmetric products
//! and the faer sparse Cholesky factorisation.

use crate::element::{self, ElementKind, Lame};
use crate::mesh::Mesh;
use crate::FemError;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::perm::PermRef;
use faer::sparse::linalg::amd;
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, LltRef, SymbolicCholesky,
    SymmetricOrdering,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, Side};
use rayon::prelude::*;
use std::sync::Arc;

/// Equation number of each dof (3 per node, node-major); `FIXED` for supported or unused dofs.
#[derive(Clone, Debug)]
pub struct DofMap {
    pub eq: Vec<u32>,
    pub n_eq: usize,
}

pub const FIXED: u32 = u32::MAX;

impl DofMap {
    /// Free-equation vector from a full dof vector.
    pub fn gather(&self, full: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; self.n_eq];
        for (d, &e) in self.eq.iter().enumerate() {
            if e != FIXED {
                out[e as usize] = full[d];
            }
        }
        out
    }
    /// Free dofs numbered node by node in `node_order` (which holds every node with a free
    /// dof), each node's free dofs consecutive.
    pub fn in_node_order(
        fixed: &[bool],
        used: &[bool],
        per_node: usize,
        node_order: &[u32],
    ) -> DofMap {
        let mut eq = vec![FIXED; fixed.len()];
        let mut n = 0u32;
        for &node in node_order {
            let node = node as usize;
            if !used[node] {
                continue;
            }
            for d in per_node * node..per_node * (node + 1) {
                if !fixed[d] {
                    eq[d] = n;
                    n += 1;
                }
            }
        }
        DofMap {
            eq,
            n_eq: n as usize,
        }
    }
    /// Writes free-equation values into a full dof vector, leaving the fixed dofs as they are.
    pub fn scatter_free(&self, free: &[f64], full: &mut [f64]) {
        for (d, &e) in self.eq.iter().enumerate() {
            if e != FIXED {
                full[d] = free[e as usize];
            }
        }
    }
    /// Writes free-equation values into a full dof vector (fixed dofs set to zero).
    pub fn scatter(&self, free: &[f64], full: &mut [f64]) {
        for (d, &e) in self.eq.iter().enumerate() {
            full[d] = if e != FIXED { free[e as usize] } else { 0.0 };
        }
    }
}

/// Symmetric matrix pattern stored in full (both triangles) compressed-column form with u32
/// indices; columns are the free equations, rows sorted.
#[derive(Clone, Debug)]
pub struct Pattern {
    pub n: usize,
    pub col_ptr: Vec<u32>,
    pub row_idx: Vec<u32>,
    /// Elimination order of the equations when no better one is found: the identity for a
    /// pattern from [`Pattern::for_elements`] (its equations are numbered in the geometric
    /// nested dissection); [`ensure_symbolic`] may replace it by AMD or METIS. A pattern built
    /// by hand (or a test) sets its own.
    pub order: Vec<u32>,
    /// The elements in the order of their lowest equation: [`assemble`] visits them so, and
    /// consecutive elements then share nodes and matrix entries (cache hits) whatever the
    /// mesh file's element numbering. Empty: index order.
    pub elem_order: Vec<u32>,
    /// The nodes' equation ranges: node i (in numbering order) owns the equations
    /// `node_first[i]..node_first[i + 1]` (the last entry is `n`). Empty: unknown (then the
    /// METIS ordering is not tried).
    pub node_first: Vec<u32>,
    /// Quadratic meshes: for each node (numbering order) that is no element's corner, the
    /// corners every element containing it shares (a mid-side node: the edge's two ends;
    /// u32::MAX pads); corners and nodes without a common corner have [u32::MAX; 2]. Empty:
    /// every node is a corner. METIS then orders the corners' graph only (a tet10 mesh has
    /// about 8 times more nodes than corners), and each mid-side node is eliminated just
    /// before the earlier of its ends: its neighbours are a subset of either end's, so this
    /// adds no fill.
    pub anchors: Vec<[u32; 2]>,
}

/// The node graph of a pattern: node i owns the equations `node_first[i]..node_first[i + 1]`;
/// full symmetric compressed columns with the diagonal, rows sorted.
struct NodeGraph {
    col_ptr: Vec<u32>,
    row_idx: Vec<u32>,
}

impl NodeGraph {
    /// None when the pattern does not know its nodes (`node_first` empty).
    fn of(p: &Pattern) -> Option<NodeGraph> {
        let nodes = p.node_first.len().checked_sub(1)?;
        let mut eq_node = vec![0u32; p.n];
        for i in 0..nodes {
            eq_node[p.node_first[i] as usize..p.node_first[i + 1] as usize].fill(i as u32);
        }
        let mut col_ptr = Vec::with_capacity(nodes + 1);
        col_ptr.push(0u32);
        let mut row_idx = Vec::new();
        for i in 0..nodes {
            // the column of the node's first equation lists every neighbour's equations,
            // sorted: each neighbour's equations are consecutive, and nodes are numbered in
            // equation order, so the neighbour nodes come out sorted
            let col = p.node_first[i] as usize;
            let mut last = u32::MAX;
            for &r in &p.row_idx[p.col_ptr[col] as usize..p.col_ptr[col + 1] as usize] {
                let m = eq_node[r as usize];
                if m != last {
                    row_idx.push(m);
                }
                last = m;
            }
            col_ptr.push(row_idx.len() as u32);
        }
        Some(NodeGraph { col_ptr, row_idx })
    }

    fn n(&self) -> usize {
        self.col_ptr.len() - 1
    }

    fn symbolic(&self) -> SymbolicSparseColMatRef<'_, u32> {
        SymbolicSparseColMatRef::new_checked(self.n(), self.n(), &self.col_ptr, None, &self.row_idx)
    }

    /// Entries of the Cholesky factor of the node graph eliminated in `order` (node i-th
    /// eliminated: `order[i]`): the fill of the equations' factor is about 9 times this for
    /// 3 dofs per node, so orderings compare on the small graph.
    fn fill(&self, order: &[u32]) -> Option<usize> {
        analyse_in_order(self.symbolic(), order)
            .ok()
            .map(|s| s.len_val())
    }

    /// Approximate minimum degree order (faer's AMD on the node graph: 9× fewer entries than
    /// the equations' graph, the same fill, since a node's equations are indistinguishable
    /// to minimum degree).
    fn amd(&self) -> Option<Vec<u32>> {
        let n = self.n();
        let mut perm = vec![0u32; n];
        let mut perm_inv = vec![0u32; n];
        let mut mem = MemBuffer::try_new(amd::order_scratch::<u32>(n, self.row_idx.len())).ok()?;
        amd::order(
            &mut perm,
            &mut perm_inv,
            self.symbolic(),
            amd::Control::default(),
            MemStack::new(&mut mem),
        )
        .ok()?;
        Some(perm)
    }

    /// METIS's nested dissection of the corners (the nodes whose `anchors` entry is empty;
    /// all nodes when `anchors` is empty), the other nodes placed just before the earlier of
    /// their anchors ([`Pattern::anchors`]).
    fn metis_anchored(&self, anchors: &[[u32; 2]]) -> Option<Vec<u32>> {
        const NONE: u32 = u32::MAX;
        if anchors.len() != self.n() {
            return self.metis();
        }
        let corners: Vec<u32> = (0..self.n() as u32)
            .filter(|&i| anchors[i as usize][0] == NONE)
            .collect();
        let mut compact = vec![NONE; self.n()];
        for (k, &c) in corners.iter().enumerate() {
            compact[c as usize] = k as u32;
        }
        let mut col_ptr = Vec::with_capacity(corners.len() + 1);
        col_ptr.push(0u32);
        let mut row_idx = Vec::new();
        for &c in &corners {
            let (a, b) = (
                self.col_ptr[c as usize] as usize,
                self.col_ptr[c as usize + 1] as usize,
            );
            row_idx.extend(
                self.row_idx[a..b]
                    .iter()
                    .map(|&m| compact[m as usize])
                    .filter(|&k| k != NONE),
            );
            col_ptr.push(row_idx.len() as u32);
        }
        let corner_order = NodeGraph { col_ptr, row_idx }.metis()?;
        let mut pos = vec![NONE; self.n()];
        for (k, &c) in corner_order.iter().enumerate() {
            pos[corners[c as usize] as usize] = k as u32;
        }
        // corners at (position, 1), the others at (their earlier anchor's position, 0)
        let mut keyed: Vec<(u32, u8, u32)> = (0..self.n() as u32)
            .map(|i| match anchors[i as usize] {
                [NONE, _] => (pos[i as usize], 1, i),
                [a, b] => {
                    let pb = if b == NONE { NONE } else { pos[b as usize] };
                    (pos[a as usize].min(pb), 0, i)
                }
            })
            .collect();
        keyed.sort_unstable();
        Some(keyed.into_iter().map(|(_, _, i)| i).collect())
    }

    /// METIS's multilevel nested dissection (METIS_NodeND).
    fn metis(&self) -> Option<Vec<u32>> {
        use metis_sys::idx_t;
        let n = self.n();
        if n == 0 {
            return Some(Vec::new());
        }
        let mut xadj: Vec<idx_t> = Vec::with_capacity(n + 1);
        xadj.push(0);
        let mut adjncy: Vec<idx_t> = Vec::with_capacity(self.row_idx.len());
        for i in 0..n {
            let (a, b) = (self.col_ptr[i] as usize, self.col_ptr[i + 1] as usize);
            adjncy.extend(
                self.row_idx[a..b]
                    .iter()
                    .filter(|&&m| m as usize != i)
                    .map(|&m| m as idx_t),
            );
            xadj.push(idx_t::try_from(adjncy.len()).ok()?);
        }
        let mut nv = idx_t::try_from(n).ok()?;
        let mut perm: Vec<idx_t> = vec![0; n];
        let mut iperm: Vec<idx_t> = vec![0; n];
        // SAFETY: xadj/adjncy describe a symmetric graph of nv vertices without self loops
        // (METIS's input contract), perm/iperm hold nv entries; null vertex weights and
        // options select METIS's defaults (a fixed seed: the same order on every run). METIS
        // only reads the graph and writes perm/iperm.
        let status = unsafe {
            metis_sys::METIS_NodeND(
                &mut nv,
                xadj.as_mut_ptr(),
                adjncy.as_mut_ptr(),
                std::ptr::null_mut(),
                std::ptr::null_mut(),
                perm.as_mut_ptr(),
                iperm.as_mut_ptr(),
            )
        };
        // perm[i]: the node eliminated i-th
        (status == metis_sys::rstatus_et_METIS_OK).then(|| perm.iter().map(|&v| v as u32).collect())
    }
}

/// [`Pattern::anchors`] of a solid mesh (empty when every node is a corner).
fn corner_anchors(mesh: &Mesh, dofs: &DofMap, p: &Pattern) -> Vec<[u32; 2]> {
    let nn = mesh.num_nodes();
    let ne = mesh.num_elements();
    let mut corner = vec![false; nn];
    let mut any_other = false;
    for e in 0..ne {
        let nodes = mesh.element_nodes(e);
        let nc = mesh.kinds[e].num_corners();
        for &n in &nodes[..nc] {
            corner[n as usize] = true;
        }
        any_other |= nodes.len() > nc;
    }
    if !any_other || p.node_first.is_empty() {
        return Vec::new();
    }
    // numbering index of each mesh node (through its first free equation)
    let mut index = vec![u32::MAX; nn];
    for (n, idx) in index.iter_mut().enumerate() {
        if let Some(e) = (0..3).map(|c| dofs.eq[3 * n + c]).find(|&e| e != FIXED) {
            *idx = p.node_first.partition_point(|&f| f <= e) as u32 - 1;
        }
    }
    const NONE: u32 = u32::MAX;
    // the common corners of the elements containing each non-corner node, as mesh nodes
    let mut common: Vec<Option<Vec<u32>>> = vec![None; nn];
    for e in 0..ne {
        let nodes = mesh.element_nodes(e);
        let corners = &nodes[..mesh.kinds[e].num_corners()];
        for &m in &nodes[corners.len()..] {
            let m = m as usize;
            if corner[m] {
                continue;
            }
            match &mut common[m] {
                Some(c) => c.retain(|x| corners.contains(x)),
                slot => *slot = Some(corners.to_vec()),
            }
        }
    }
    let mut anchors = vec![[NONE; 2]; p.node_first.len() - 1];
    for (m, c) in common.into_iter().enumerate() {
        let (Some(c), i) = (c, index[m]) else {
            continue;
        };
        if i == NONE {
            continue;
        }
        // ends that are themselves free nodes (a fixed corner has no place in the order)
        let ends: Vec<u32> = c
            .iter()
            .map(|&x| index[x as usize])
            .filter(|&x| x != NONE)
            .take(2)
            .collect();
        if let Some(&a) = ends.first() {
            anchors[i as usize] = [a, ends.get(1).copied().unwrap_or(NONE)];
        }
    }
    anchors
}

/// faer's symbolic Cholesky analysis of the symmetric pattern `a` eliminated in `order`
/// (`order[i]`: the row and column eliminated i-th).
fn analyse_in_order(
    a: SymbolicSparseColMatRef<'_, u32>,
    order: &[u32],
) -> Result<SymbolicCholesky<u32>, faer::sparse::FaerError> {
    let mut inv = vec![0u32; order.len()];
    for (i, &e) in order.iter().enumerate() {
        inv[e as usize] = i as u32;
    }
    factorize_symbolic_cholesky(
        a,
        Side::Lower,
        SymmetricOrdering::Custom(PermRef::new_checked(order, &inv, order.len())),
        CholeskySymbolicParams::default(),
    )
}

/// A node order expanded to the equations of `p`.
fn expand_nodes(p: &Pattern, nodes: &[u32]) -> Vec<u32> {
    let mut order = Vec::with_capacity(p.n);
    for &v in nodes {
        let v = v as usize;
        order.extend(p.node_first[v]..p.node_first[v + 1]);
    }
    order
}

/// The approximate-minimum-degree order of `p`'s equations (node by node). None when the
/// pattern does not know its nodes.
pub fn amd_order(p: &Pattern) -> Option<Vec<u32>> {
    let g = NodeGraph::of(p)?;
    Some(expand_nodes(p, &g.amd()?))
}

/// METIS's nested-dissection order of `p`'s equations (node by node). None when the pattern
/// does not know its nodes or METIS fails.
pub fn metis_order(p: &Pattern) -> Option<Vec<u32>> {
    let g = NodeGraph::of(p)?;
    Some(expand_nodes(p, &g.metis_anchored(&p.anchors)?))
}

impl Pattern {
    /// The equation numbering and pattern of a solid mesh with the dofs `fixed` (3 per node).
    pub fn build(mesh: &Mesh, fixed: &[bool]) -> Result<(DofMap, Pattern), FemError> {
        let (dofs, mut pattern) = Pattern::for_elements(
            &mesh.nodes,
            mesh.num_elements(),
            |e| mesh.element_nodes(e),
            fixed,
            &mesh.used_nodes(),
            3,
        )?;
        pattern.anchors = corner_anchors(mesh, &dofs, &pattern);
        Ok((dofs, pattern))
    }

    /// The equation numbering and pattern of elements given by `element_nodes(e)`,
    /// e < `n_elements`, over nodes at `coords` with `per_node` dofs each (3 for solids, 6 for
    /// shells); a dof is free when it is not `fixed` and its node is `used`.
    ///
    /// The equations are numbered in the nested-dissection order of the nodes (a node's free
    /// dofs consecutive), so the factorisation's order is the identity and neighbouring nodes
    /// get nearby equations: an element's entries lie close together in the matrix whatever
    /// the mesh file's node numbering (a Gmsh tetrahedral mesh numbers its nodes far apart,
    /// which made the scatter of the element matrices miss the cache on almost every entry).
    pub fn for_elements<'a>(
        coords: &[[f64; 3]],
        n_elements: usize,
        element_nodes: impl Fn(usize) -> &'a [u32] + Sync,
        fixed: &[bool],
        used: &[bool],
        per_node: usize,
    ) -> Result<(DofMap, Pattern), FemError> {
        let nn = coords.len();
        let k = per_node;
        // node → elements incidence (CSR)
        let mut count = vec![0u32; nn + 1];
        for e in 0..n_elements {
            for &n in element_nodes(e) {
                count[n as usize + 1] += 1;
            }
        }
        for i in 0..nn {
            count[i + 1] += count[i];
        }
        let mut fill = count.clone();
        let mut node_elems = vec![0u32; count[nn] as usize];
        for e in 0..n_elements {
            for &n in element_nodes(e) {
                node_elems[fill[n as usize] as usize] = e as u32;
                fill[n as usize] += 1;
            }
        }
        // sorted neighbour nodes of each node, in parallel
        let adj: Vec<Vec<u32>> = (0..nn)
            .into_par_iter()
            .map(|n| {
                let mut v = Vec::new();
                for &e in &node_elems[count[n] as usize..count[n + 1] as usize] {
                    v.extend_from_slice(element_nodes(e as usize));
                }
                v.sort_unstable();
                v.dedup();
                v
            })
            .collect();
        drop(node_elems);
        let free = |n: usize| used[n] as usize * (0..k).filter(|&c| !fixed[k * n + c]).count();
        let active: Vec<bool> = (0..nn).map(|n| free(n) > 0).collect();
        let n_eq: usize = (0..nn).map(free).sum();
        let node_order = nested_dissection(coords, &adj, &active);
        let dofs = DofMap::in_node_order(fixed, used, k, &node_order);
        debug_assert_eq!(dofs.n_eq, n_eq);
        // first free equation of each node (its free equations are consecutive)
        let first: Vec<u32> = (0..nn)
            .map(|n| {
                (0..k)
                    .map(|c| dofs.eq[k * n + c])
                    .find(|&e| e != FIXED)
                    .unwrap_or(FIXED)
            })
            .collect();
        let mut col_ptr = Vec::with_capacity(n_eq + 1);
        col_ptr.push(0u32);
        let mut row_idx: Vec<u32> = Vec::new();
        let mut rows: Vec<u32> = Vec::new();
        let mut nbrs: Vec<u32> = Vec::new();
        // columns in equation order: the nodes in `node_order`, their free dofs in turn
        for &n in &node_order {
            let n = n as usize;
            nbrs.clear();
            nbrs.extend(
                adj[n]
                    .iter()
                    .copied()
                    .filter(|&m| first[m as usize] != FIXED),
            );
            nbrs.sort_unstable_by_key(|&m| first[m as usize]);
            rows.clear();
            for &m in &nbrs {
                for d in 0..k {
                    let e = dofs.eq[k * m as usize + d];
                    if e != FIXED {
                        rows.push(e);
                    }
                }
            }
            for c in 0..k {
                if dofs.eq[k * n + c] == FIXED {
                    continue;
                }
                row_idx.extend_from_slice(&rows);
                if row_idx.len() > u32::MAX as usize {
                    return Err(FemError::Solver(
                        "matrix too large for 32-bit indices".into(),
                    ));
                }
                col_ptr.push(row_idx.len() as u32);
            }
        }
        let key = |e: usize| {
            element_nodes(e)
                .iter()
                .map(|&n| first[n as usize])
                .min()
                .unwrap_or(FIXED)
        };
        let mut keyed: Vec<(u32, u32)> = (0..n_elements).map(|e| (key(e), e as u32)).collect();
        keyed.sort_unstable();
        let mut node_first: Vec<u32> = node_order.iter().map(|&n| first[n as usize]).collect();
        node_first.push(n_eq as u32);
        let pattern = Pattern {
            n: n_eq,
            col_ptr,
            row_idx,
            node_first,
            anchors: Vec::new(),
            order: (0..n_eq as u32).collect(),
            elem_order: keyed.into_iter().map(|(_, e)| e).collect(),
        };
        Ok((dofs, pattern))
    }

    pub fn nnz(&self) -> usize {
        self.row_idx.len()
    }

    fn symbolic(&self) -> SymbolicSparseColMatRef<'_, u32> {
        SymbolicSparseColMatRef::new_checked(self.n, self.n, &self.col_ptr, None, &self.row_idx)
    }

    /// Position of entry (row, col) if present.
    #[inline]
    pub fn find(&self, row: u32, col: u32) -> Option<usize> {
        let (a, b) = (
            self.col_ptr[col as usize] as usize,
            self.col_ptr[col as usize + 1] as usize,
        );
        self.row_idx[a..b].binary_search(&row).ok().map(|p| a + p)
    }

    /// y = A x for the symmetric matrix with values `vals` (column gather: parallel and
    /// deterministic).
    pub fn mul(&self, vals: &[f64], x: &[f64], y: &mut [f64]) {
        y.par_chunks_mut(4096).enumerate().for_each(|(ci, chunk)| {
            for (k, yj) in chunk.iter_mut().enumerate() {
                let j = ci * 4096 + k;
                let (a, b) = (self.col_ptr[j] as usize, self.col_ptr[j + 1] as usize);
                let mut s = 0.0;
                for p in a..b {
                    s += vals[p] * x[self.row_idx[p] as usize];
                }
                *yj = s;
            }
        });
    }

    /// ‖A‖∞ (the largest absolute row sum; of a symmetric matrix, the largest column sum).
    pub fn norm_inf(&self, vals: &[f64]) -> f64 {
        (0..self.n)
            .into_par_iter()
            .map(|j| {
                let (a, b) = (self.col_ptr[j] as usize, self.col_ptr[j + 1] as usize);
                vals[a..b].iter().map(|v| v.abs()).sum::<f64>()
            })
            .reduce(|| 0.0, f64::max)
    }

    /// Column ranges with roughly equal numbers of entries, for parallel scatter.
    fn column_partitions(&self, parts: usize) -> Vec<(usize, usize)> {
        let nnz = self.nnz().max(1);
        let mut out = Vec::new();
        let mut start = 0;
        for p in 1..=parts {
            let target = nnz * p / parts;
            let mut end = start;
            while end < self.n && (self.col_ptr[end] as usize) < target {
                end += 1;
            }
            if p == parts {
                end = self.n;
            }
            if end > start {
                out.push((start, end));
                start = end;
            }
        }
        out
    }
}

/// What to integrate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Operator {
    Stiffness,
    Mass,
}

/// Per-element material data of the linear operators: element e has stiffness
/// `lame[of[e]]` and density `density[of[e]]`.
#[derive(Clone, Copy, Debug)]
pub struct ElementProps<'a> {
    pub of: &'a [u32],
    pub lame: &'a [Lame],
    pub density: &'a [f64],
}

impl ElementProps<'_> {
    #[inline]
    pub fn lame(&self, e: usize) -> Lame {
        self.lame[self.of[e] as usize]
    }
    #[inline]
    pub fn density(&self, e: usize) -> f64 {
        self.density[self.of[e] as usize]
    }
}

/// Largest element matrix (hex20: 60×60).
pub const MAX_ELEMENT_MATRIX: usize = 60 * 60;

/// Assembles K (2.56) or the consistent M (2.78) on `pattern`. Element matrices are computed in
/// parallel batches; the scatter is parallel over disjoint column ranges and adds element
/// contributions in element order, so results are identical for any thread count.
pub fn assemble(
    mesh: &Mesh,
    dofs: &DofMap,
    pattern: &Pattern,
    op: Operator,
    props: ElementProps<'_>,
) -> Result<Vec<f64>, FemError> {
    let mut vals = vec![0.0; pattern.nnz()];
    let ne = mesh.num_elements();
    // the batch's element matrices packed at the mesh's largest matrix size (not hex20's
    // 60×60 for every mesh): 2,048 hex8 matrices are 9.4 MB and stay in the L3 cache between
    // the two passes instead of streaming 59 MB through memory
    const BATCH: usize = 2048;
    let stride = (0..ne)
        .map(|e| 3 * mesh.kinds[e].num_nodes())
        .max()
        .map_or(1, |nd| nd * nd);
    let mut buf = vec![0.0; BATCH.min(ne) * stride];
    let parts = pattern.column_partitions(4 * rayon::current_num_threads().max(1));
    let index_order: Vec<u32>;
    let order: &[u32] = if pattern.elem_order.len() == ne {
        &pattern.elem_order
    } else {
        index_order = (0..ne as u32).collect();
        &index_order
    };
    let mut start = 0;
    let (mut t_elem, mut t_scatter) = (std::time::Duration::ZERO, std::time::Duration::ZERO);
    while start < ne {
        let end = (start + BATCH).min(ne);
        let batch = &order[start..end];
        let t0 = std::time::Instant::now();
        // 1. element matrices
        let res: Result<(), (usize, element::BadJacobian)> = buf[..(end - start) * stride]
            .par_chunks_mut(stride)
            .enumerate()
            .try_for_each_init(
                || (Vec::new(), Vec::new(), Vec::new()),
                |(x, ke, sc), (i, out)| {
                    let e = batch[i] as usize;
                    mesh.element_coords(e, x);
                    let kind = mesh.kinds[e];
                    let nd = 3 * kind.num_nodes();
                    let scale = mesh.element_scale(e, sc);
                    match op {
                        Operator::Stiffness => {
                            element::stiffness(kind, x, props.lame(e), scale, ke)
                                .map_err(|b| (e, b))?;
                            out[..nd * nd].copy_from_slice(ke);
                        }
                        Operator::Mass => {
                            element::mass(kind, x, props.density(e), scale, ke)
                                .map_err(|b| (e, b))?;
                            let nn = kind.num_nodes();
                            out[..nd * nd].fill(0.0);
                            for a in 0..nn {
                                for b in 0..nn {
                                    for k in 0..3 {
                                        out[(3 * a + k) * nd + 3 * b + k] = ke[a * nn + b];
                                    }
                                }
                            }
                        }
                    }
                    Ok(())
                },
            );
        if let Err((e, b)) = res {
            return Err(FemError::Mesh {
                file: mesh.source.clone(),
                line: mesh.elem_lines[e],
                message: format!("element {} has det J = {:.3e}", mesh.elem_ids[e], b.det_j),
            });
        }
        t_elem += t0.elapsed();
        let t0 = std::time::Instant::now();
        // 2. scatter, parallel over column ranges
        scatter_batch(mesh, dofs, pattern, &parts, batch, &buf, stride, &mut vals);
        t_scatter += t0.elapsed();
        start = end;
    }
    if timing() {
        tracing::debug!("  assemble {op:?}: element matrices {t_elem:?}, scatter {t_scatter:?}");
    }
    Ok(vals)
}

/// Column ranges of `pattern` for [`scatter_batch`] (a few per thread).
pub fn scatter_parts(pattern: &Pattern) -> Vec<(usize, usize)> {
    pattern.column_partitions(4 * rayon::current_num_threads().max(1))
}

/// Adds the element matrices of `elements` (row-major, the matrix of `elements[i]` at
/// `buf[i * stride..]`) into `vals`, in parallel over the column ranges `parts` and in the
/// order of `elements` within each: the same sums for any thread count.
#[allow(clippy::too_many_arguments)]
pub fn scatter_batch(
    mesh: &Mesh,
    dofs: &DofMap,
    pattern: &Pattern,
    parts: &[(usize, usize)],
    elements: &[u32],
    buf: &[f64],
    stride: usize,
    vals: &mut [f64],
) {
    let mut slices: Vec<(usize, usize, &mut [f64])> = Vec::with_capacity(parts.len());
    let mut rest: &mut [f64] = vals;
    let mut offset = 0usize;
    for &(c0, c1) in parts {
        let a = pattern.col_ptr[c0] as usize;
        let b = pattern.col_ptr[c1] as usize;
        let (_, tail) = rest.split_at_mut(a - offset);
        let (mine, tail) = tail.split_at_mut(b - a);
        rest = tail;
        offset = b;
        slices.push((c0, c1, mine));
    }
    slices.par_iter_mut().for_each(|(c0, c1, mine)| {
        let base = pattern.col_ptr[*c0] as usize;
        let mut eqs = [0u32; 60];
        // per element node: its first free equation and its free local dofs. The free
        // equations of one node are consecutive, so they are consecutive rows of every column:
        // one search per (node, column) instead of one per (dof, column).
        let mut first = [FIXED; 20];
        let mut free = [[0usize; 3]; 20];
        let mut n_free = [0usize; 20];
        for (i, &e) in elements.iter().enumerate() {
            let nodes = mesh.element_nodes(e as usize);
            let nd = 3 * nodes.len();
            let mut in_range = false;
            for (a, &n) in nodes.iter().enumerate() {
                first[a] = FIXED;
                n_free[a] = 0;
                for k in 0..3 {
                    let q = dofs.eq[3 * n as usize + k];
                    eqs[3 * a + k] = q;
                    if q != FIXED {
                        if first[a] == FIXED {
                            first[a] = q;
                        }
                        free[a][n_free[a]] = 3 * a + k;
                        n_free[a] += 1;
                        in_range |= (q as usize) >= *c0 && (q as usize) < *c1;
                    }
                }
            }
            if !in_range {
                continue;
            }
            let ke = &buf[i * stride..];
            // the free columns of one node have the same rows (the node's neighbours), so
            // node a's block sits at the same offset in each of them: searched once per
            // (column node, row node) pair
            let mut offset = [0usize; 20];
            for b in 0..nodes.len() {
                let mut searched = false;
                for &jl in &free[b][..n_free[b]] {
                    let cj = eqs[jl];
                    if (cj as usize) < *c0 || (cj as usize) >= *c1 {
                        continue;
                    }
                    let col = pattern.col_ptr[cj as usize] as usize;
                    if !searched {
                        for a in 0..nodes.len() {
                            if first[a] != FIXED {
                                offset[a] = pattern
                                    .find(first[a], cj)
                                    .expect("pattern covers element couplings")
                                    - col;
                            }
                        }
                        searched = true;
                    }
                    for a in 0..nodes.len() {
                        if first[a] == FIXED {
                            continue;
                        }
                        let p = col + offset[a] - base;
                        for (t, &il) in free[a][..n_free[a]].iter().enumerate() {
                            mine[p + t] += ke[il * nd + jl];
                        }
                    }
                }
            }
        }
    });
}

/// Lumped (HRZ) nodal masses for every dof (3 per node).
pub fn lumped_mass(mesh: &Mesh, props: ElementProps<'_>) -> Result<Vec<f64>, FemError> {
    const MAX_NODES: usize = 20;
    let ne = mesh.num_elements();
    // per element its nodal masses (fixed-size rows, scratch per thread: no allocation per
    // element), then added in element order: the same sums for any thread count
    let mut per_elem = vec![[0.0f64; MAX_NODES]; ne];
    per_elem.par_iter_mut().enumerate().try_for_each_init(
        || (Vec::new(), Vec::new()),
        |(x, sc), (e, out)| {
            mesh.element_coords(e, x);
            let kind: ElementKind = mesh.kinds[e];
            let scale = mesh.element_scale(e, sc);
            element::lumped_mass(kind, x, props.density(e), scale, out).map_err(|b| {
                FemError::Mesh {
                    file: mesh.source.clone(),
                    line: mesh.elem_lines[e],
                    message: format!("element {} has det J = {:.3e}", mesh.elem_ids[e], b.det_j),
                }
            })
        },
    )?;
    let mut out = vec![0.0; 3 * mesh.num_nodes()];
    for (e, m) in per_elem.iter().enumerate() {
        for (a, &n) in mesh.element_nodes(e).iter().enumerate() {
            for k in 0..3 {
                out[3 * n as usize + k] += m[a];
            }
        }
    }
    Ok(out)
}

/// Geometric nested dissection of the node graph: recursively split the active nodes at the
/// median along each of the three axes, and keep the split whose vertex separator is smallest:
/// the nodes of one half adjacent to the other half (the smaller of the two sides' boundary
/// layers), ordered after both halves. Only nodes within one element's reach of the cut can
/// be adjacent across it, so only those have their neighbours scanned. For the slender,
/// structured meshes of the scenes this gives far less fill than minimum degree.
pub fn nested_dissection(coords: &[[f64; 3]], adj: &[Vec<u32>], active: &[bool]) -> Vec<u32> {
    // leaves ordered by minimum degree (48 nodes: 7 % less fill than larger leaves on the
    // 10 mm beam, where 256 / 1,024 / 4,096 gave +1 / +9 / +41 %)
    const LEAF: usize = 48;
    let mut local = vec![u32::MAX; coords.len()];
    let mut out = Vec::with_capacity(coords.len());
    // side[n]: which half of the current split node n is in (tagged with the split's id)
    let mut side = vec![(u32::MAX, false); coords.len()];
    let mut call_id = 0u32;
    // the longest reach of an edge of the node graph along each axis
    let mut reach = [0.0f64; 3];
    for (n, nb) in adj.iter().enumerate() {
        for &m in nb {
            for k in 0..3 {
                reach[k] = reach[k].max((coords[n][k] - coords[m as usize][k]).abs());
            }
        }
    }
    enum Task {
        Split(Vec<u32>),
        Emit(Vec<u32>),
    }
    let all: Vec<u32> = (0..coords.len() as u32)
        .filter(|&n| active[n as usize])
        .collect();
    let mut stack = vec![Task::Split(all)];
    while let Some(task) = stack.pop() {
        let mut nodes = match task {
            Task::Emit(v) => {
                out.extend(v);
                continue;
            }
            Task::Split(v) => v,
        };
        if nodes.len() <= LEAF {
            leaf_order(adj, &nodes, &mut local, &mut out);
            continue;
        }
        // the best split: (separator size, axis, cut, separator on the upper side)
        let mut best: Option<(usize, usize, f64, bool)> = None;
        let mid = nodes.len() / 2;
        for axis in 0..3 {
            nodes.select_nth_unstable_by(mid, |&a, &b| {
                coords[a as usize][axis].total_cmp(&coords[b as usize][axis])
            });
            let cut = coords[nodes[mid] as usize][axis];
            let lo = nodes
                .iter()
                .filter(|&&n| coords[n as usize][axis] < cut)
                .count();
            if lo == 0 || lo == nodes.len() {
                continue; // all coordinates equal along this axis
            }
            call_id += 1;
            for &n in &nodes {
                side[n as usize] = (call_id, coords[n as usize][axis] >= cut);
            }
            // boundary layers of both halves, from the nodes within reach of the cut
            let (mut lower, mut upper) = (0usize, 0usize);
            for &n in &nodes {
                let x = coords[n as usize][axis];
                if (x - cut).abs() > reach[axis] {
                    continue;
                }
                let up = x >= cut;
                if adj[n as usize]
                    .iter()
                    .any(|&m| side[m as usize] == (call_id, !up))
                {
                    if up {
                        upper += 1;
                    } else {
                        lower += 1;
                    }
                }
            }
            let (size, on_upper) = if upper < lower {
                (upper, true)
            } else {
                (lower, false)
            };
            if best.is_none_or(|b| size < b.0) {
                best = Some((size, axis, cut, on_upper));
            }
        }
        let Some((_, axis, cut, on_upper)) = best else {
            // every node at one point (degenerate): stop splitting
            out.extend(nodes);
            continue;
        };
        call_id += 1;
        for &n in &nodes {
            side[n as usize] = (call_id, coords[n as usize][axis] >= cut);
        }
        let mut sep = Vec::new();
        let (mut left, mut right) = (Vec::new(), Vec::new());
        for &n in &nodes {
            let up = side[n as usize].1;
            let x = coords[n as usize][axis];
            let in_sep = up == on_upper
                && (x - cut).abs() <= reach[axis]
                && adj[n as usize]
                    .iter()
                    .any(|&m| side[m as usize] == (call_id, !up));
            if in_sep {
                sep.push(n);
            } else if up {
                right.push(n);
            } else {
                left.push(n);
            }
        }
        // order: left, right, separator (the stack is LIFO)
        stack.push(Task::Emit(sep));
        stack.push(Task::Split(right));
        stack.push(Task::Split(left));
    }
    out
}

/// Appends the nodes of a nested-dissection leaf in the minimum-degree order of the graph
/// they induce (`local` is scratch: u32::MAX everywhere, restored on return).
fn leaf_order(adj: &[Vec<u32>], nodes: &[u32], local: &mut [u32], out: &mut Vec<u32>) {
    for (i, &n) in nodes.iter().enumerate() {
        local[n as usize] = i as u32;
    }
    let mut col_ptr = Vec::with_capacity(nodes.len() + 1);
    col_ptr.push(0u32);
    let mut row_idx = Vec::new();
    for &n in nodes {
        let start = row_idx.len();
        row_idx.extend(
            adj[n as usize]
                .iter()
                .map(|&m| local[m as usize])
                .filter(|&c| c != u32::MAX),
        );
        row_idx[start..].sort_unstable();
        col_ptr.push(row_idx.len() as u32);
    }
    for &n in nodes {
        local[n as usize] = u32::MAX;
    }
    match (NodeGraph { col_ptr, row_idx }).amd() {
        Some(perm) => out.extend(perm.iter().map(|&i| nodes[i as usize])),
        None => out.extend_from_slice(nodes),
    }
}

/// Sparse Cholesky factor LLᵀ computed by faer (simplicial or supernodal, chosen by faer),
/// with our nested-dissection ordering or faer's AMD, whichever gives less fill; factors of
/// [`SPLIT_FROM`]..[`PARALLEL_FACTOR_FROM`] entries whose elimination tree splits well are
/// computed as two halves side by side ([`crate::tree_factor`]).
pub struct Factor {
    symbolic: Symbolic,
    values: FactorValues<f64>,
}

/// A factor's values in `T`: whole (faer's factor of the plan's whole analysis) or the tree
/// split's two halves.
enum FactorValues<T> {
    Whole(Vec<T>),
    Split(crate::tree_factor::SplitFactor<T>),
}

impl<T: crate::tree_factor::FactorScalar> FactorValues<T> {
    /// The workspace [`FactorValues::solve_in_place`] needs (none for a split factor).
    fn scratch(&self, plan: &FactorPlan) -> MemBuffer {
        MemBuffer::new(match self {
            FactorValues::Whole(_) => {
                let full = plan.full_computed();
                full.solve_in_place_scratch::<T>(1, factor_par(full.len_val()))
            }
            FactorValues::Split(_) => faer::dyn_stack::StackReq::empty(),
        })
    }

    /// Solves (L Lᵀ) x = b in place with these values of `plan`'s factor.
    fn solve_in_place(&self, plan: &FactorPlan, b: &mut [T], buf: &mut MemBuffer) {
        match self {
            FactorValues::Whole(values) => {
                let full = plan.full_computed();
                let n = b.len();
                LltRef::new(full, values).solve_in_place_with_conj(
                    Conj::No,
                    faer::MatMut::from_column_major_slice_mut(b, n, 1),
                    factor_par(full.len_val()),
                    MemStack::new(buf),
                );
            }
            FactorValues::Split(f) => plan
                .split()
                .expect("a split factor has its plan")
                .solve_in_place(f, b),
        }
    }
}

/// The symbolic analysis of one pattern (ordering, elimination tree, supernodes) and, where
/// it pays, the split of its tree into two halves factorised side by side.
pub struct FactorPlan {
    /// The whole factor's symbolic analysis: computed with the plan when there is no tree
    /// split, else when first asked for.
    full: std::sync::OnceLock<SymbolicCholesky<u32>>,
    /// The elimination order of the equations.
    order: Vec<u32>,
    /// The tree split, planned with the analysis: both [`Factor`] (f64) and [`MixedFactor`]
    /// (f32) factorise as its two halves side by side.
    split: Option<crate::tree_factor::SplitPlan>,
}

impl FactorPlan {
    /// The whole factor's symbolic analysis (of `pattern`, the pattern this plan is for).
    pub fn full(&self, pattern: &Pattern) -> Result<&SymbolicCholesky<u32>, FemError> {
        if let Some(sym) = self.full.get() {
            return Ok(sym);
        }
        let sym = analyse_in_order(pattern.symbolic(), &self.order)
            .map_err(|e| FemError::Solver(format!("symbolic Cholesky failed: {e:?}")))?;
        Ok(self.full.get_or_init(|| sym))
    }

    /// The whole factor's symbolic analysis once [`FactorPlan::full`] has computed it.
    fn full_computed(&self) -> &SymbolicCholesky<u32> {
        self.full
            .get()
            .expect("the whole factor's analysis precedes its numeric factor")
    }

    /// Entries of the factor: the whole's, or with a tree split both halves' (each holds the
    /// separator's block).
    pub fn factor_nnz(&self) -> usize {
        match (self.split(), self.full.get()) {
            (Some(s), _) => s.factor_nnz(),
            (None, Some(sym)) => sym.len_val(),
            (None, None) => unreachable!("a plan without a split has its whole factor"),
        }
    }

    /// The tree split the factors use, if any.
    pub fn split(&self) -> Option<&crate::tree_factor::SplitPlan> {
        self.split.as_ref()
    }
}

fn describe_split(split: Option<&crate::tree_factor::SplitPlan>) -> String {
    match split {
        Some(s) => format!(
            "tree split: separator {}, halves' nnz(L) {}, predicted {:.2} of the whole's work",
            s.separator(),
            s.factor_nnz(),
            s.predicted,
        ),
        None => "no tree split".into(),
    }
}

/// Cached symbolic analysis of one pattern.
pub type Symbolic = Arc<FactorPlan>;

/// Factors of at least this many entries (and fewer than [`PARALLEL_FACTOR_FROM`]) are
/// factorised as two halves side by side when their elimination tree splits well: below it
/// the dense separator and the hand-offs cost more than the halves save.
pub const SPLIT_FROM: usize = 2_000_000;

fn timing() -> bool {
    tracing::enabled!(tracing::Level::DEBUG)
}

/// The symbolic analysis of `pattern` (computed once, then reused) with the elimination
/// order that fills least among: the pattern's own (geometric nested dissection: the
/// equations are numbered in it), AMD, and — where AMD beats bisection, i.e. the mesh is
/// irregular (an unstructured tetrahedral part) — METIS's multilevel nested dissection (the
/// Gmsh bracket of bench/gmsh: 1.62e8 against AMD's 2.23e8 and bisection's 2.75e8; on the
/// structured meshes METIS matches bisection and costs more time, so it is not run there).
/// On quadratic meshes METIS orders the corners only ([`Pattern::anchors`]): on the bracket
/// 0.12 s instead of 1.1 s for 9 % more fill than METIS on all nodes, 0.75 s faster in all.
/// The orders are compared on the node graph (9× smaller); one analysis of the equations
/// follows.
pub fn ensure_symbolic(
    pattern: &Pattern,
    symbolic: &mut Option<Symbolic>,
) -> Result<Symbolic, FemError> {
    if symbolic.is_none() {
        let sizes = if tree_split_enabled() {
            SPLIT_FROM..PARALLEL_FACTOR_FROM
        } else {
            0..0
        };
        *symbolic = Some(analyse(pattern, sizes)?);
    }
    Ok(symbolic.clone().expect("set above"))
}

/// `COSIM_TREE_SPLIT=0` (or off/false/no) keeps every factor whole: for comparisons and
/// diagnosis (FEM.md).
fn tree_split_enabled() -> bool {
    !matches!(
        std::env::var("COSIM_TREE_SPLIT")
            .as_deref()
            .map(str::to_ascii_lowercase)
            .as_deref(),
        Ok("0" | "off" | "false" | "no")
    )
}

/// The symbolic analysis of [`ensure_symbolic`], with the tree split planned when the
/// factor's size lies in `split_sizes` (tests pass their own range).
pub fn analyse(
    pattern: &Pattern,
    split_sizes: std::ops::Range<usize>,
) -> Result<Symbolic, FemError> {
    let t0 = std::time::Instant::now();
    let mut chosen = "nested dissection";
    let mut order: Option<Vec<u32>> = None;
    let mut fills = String::new();
    // the node graph, the chosen node order (None: the numbering) and its fill
    let mut node_choice: Option<(NodeGraph, Option<Vec<u32>>, usize)> = None;
    if let Some(g) = NodeGraph::of(pattern) {
        let identity: Vec<u32> = (0..g.n() as u32).collect();
        let (nd, amd) = rayon::join(
            || g.fill(&identity),
            || g.amd().and_then(|o| g.fill(&o).map(|f| (o, f))),
        );
        fills = format!("nested dissection {nd:?}");
        let t_fills = t0.elapsed();
        let mut best: Option<(Option<Vec<u32>>, usize)> = nd.map(|f| (None, f));
        if let (Some(nd), Some((amd_nodes, amd))) = (nd, amd) {
            fills += &format!(", AMD {amd}");
            if amd < nd {
                chosen = "AMD";
                let mut best_nodes = (amd_nodes, amd);
                let t_m = std::time::Instant::now();
                let metis = g.metis_anchored(&pattern.anchors);
                fills += &format!(
                    " (node graph, AMD and fills {t_fills:?}, METIS {:?})",
                    t_m.elapsed()
                );
                if let Some(m) = metis {
                    if let Some(f) = g.fill(&m) {
                        fills += &format!(", METIS {f}");
                        if f < amd {
                            chosen = "METIS";
                            best_nodes = (m, f);
                        }
                    }
                }
                order = Some(expand_nodes(pattern, &best_nodes.0));
                best = Some((Some(best_nodes.0), best_nodes.1));
            }
        }
        node_choice = best.map(|(o, f)| (g, o, f));
    }
    let order = order.unwrap_or_else(|| pattern.order.clone());
    // The tree split is planned on the node graph's elimination tree (9× smaller than the
    // equations'; a node's equations are one chain of it), where the node fill puts the
    // factor (about 9× the node fill for 3 equations per node) in range; the whole factor's
    // symbolic analysis is then left until something asks for it.
    let t_split = std::time::Instant::now();
    let had_nodes = node_choice.is_some();
    let mut split = match node_choice {
        // d² entries per node-graph entry for d equations per node (3 for solids, 6 for shells)
        Some((g, node_order, fill))
            if split_sizes.contains(&(fill * (pattern.n / g.n().max(1)).pow(2))) =>
        {
            split_on_nodes(pattern, &g, node_order.as_deref(), &order)
        }
        _ => None,
    };
    let full = std::sync::OnceLock::new();
    // without a split the whole factor's analysis runs now, beside the assembly
    if split.is_none() {
        let sym = analyse_in_order(pattern.symbolic(), &order)
            .map_err(|e| FemError::Solver(format!("symbolic Cholesky failed: {e:?}")))?;
        // a pattern without its nodes: planned on the equations' tree
        if !had_nodes && split_sizes.contains(&sym.len_val()) {
            split = crate::tree_factor::SplitPlan::new(pattern, &sym);
        }
        let _ = full.set(sym);
    }
    if timing() {
        tracing::debug!(
            "  ordering: {chosen}, {} (node-graph fills: {fills}), {:?}; {}, planned in {:?}",
            match full.get() {
                Some(sym) => format!("nnz(L) = {}", sym.len_val()),
                None => "whole factor not analysed".into(),
            },
            t0.elapsed(),
            describe_split(split.as_ref()),
            t_split.elapsed()
        );
    }
    Ok(Arc::new(FactorPlan { full, order, split }))
}

/// The tree split of the factor of `pattern` in the equation order `order`, planned on the
/// elimination tree of its node graph `g` in `node_order` (None: the numbering): faer's
/// elimination tree and column counts of the node graph (no symbolic factor), expanded to
/// the equations — each node's equations a chain whose last one hangs below the first of
/// the parent node's, column counts about three times the node's.
fn split_on_nodes(
    pattern: &Pattern,
    g: &NodeGraph,
    node_order: Option<&[u32]>,
    order: &[u32],
) -> Option<crate::tree_factor::SplitPlan> {
    use faer::sparse::linalg::cholesky::simplicial::{
        prefactorize_symbolic_cholesky, prefactorize_symbolic_cholesky_scratch,
    };
    let nn = g.n();
    let identity: Vec<u32>;
    let node_order = match node_order {
        Some(o) => o,
        None => {
            identity = (0..nn as u32).collect();
            &identity
        }
    };
    // the equation order must be the node order expanded
    let mut first = Vec::with_capacity(nn + 1);
    first.push(0u32);
    for &v in node_order {
        let (a, b) = (
            pattern.node_first[v as usize],
            pattern.node_first[v as usize + 1],
        );
        if b <= a || order.get(*first.last()? as usize) != Some(&a) {
            return None;
        }
        first.push(first.last()? + (b - a));
    }
    if *first.last()? as usize != pattern.n {
        return None;
    }
    let mut npos = vec![0u32; nn];
    for (p, &v) in node_order.iter().enumerate() {
        npos[v as usize] = p as u32;
    }
    // the upper triangle of the node graph in node_order
    let mut col_ptr = Vec::with_capacity(nn + 1);
    col_ptr.push(0u32);
    let mut rows = Vec::with_capacity(g.row_idx.len() / 2 + nn);
    for &v in node_order {
        let start = rows.len();
        let pj = npos[v as usize];
        rows.extend(
            g.row_idx[g.col_ptr[v as usize] as usize..g.col_ptr[v as usize + 1] as usize]
                .iter()
                .map(|&m| npos[m as usize])
                .filter(|&pi| pi <= pj),
        );
        rows[start..].sort_unstable();
        col_ptr.push(rows.len() as u32);
    }
    let a = SymbolicSparseColMatRef::new_checked(nn, nn, &col_ptr, None, &rows);
    let mut etree = vec![0i32; nn];
    let mut counts = vec![0u32; nn];
    let mut mem = MemBuffer::try_new(prefactorize_symbolic_cholesky_scratch::<u32>(
        nn,
        rows.len(),
    ))
    .ok()?;
    prefactorize_symbolic_cholesky::<u32>(&mut etree, &mut counts, a, MemStack::new(&mut mem));
    const NONE: u32 = u32::MAX;
    let n = pattern.n;
    let mut parent = vec![NONE; n];
    let mut work = vec![0.0f64; n];
    for p in 0..nn {
        let (a, b) = (first[p], first[p + 1]);
        // a node column of count c is about (equations per node) × c equations long
        let c = (b - a) as f64 * counts[p] as f64;
        for e in a..b {
            parent[e as usize] = if e + 1 < b {
                e + 1
            } else if etree[p] >= 0 {
                first[etree[p] as usize]
            } else {
                NONE
            };
            let ce = c - (e - a) as f64;
            work[e as usize] = ce * ce;
        }
    }
    let mut inv = vec![0u32; n];
    for (p, &e) in order.iter().enumerate() {
        inv[e as usize] = p as u32;
    }
    crate::tree_factor::SplitPlan::from_tree(pattern, order, &inv, &parent, &work)
}

/// Factors with fewer entries than this are factorised and solved on one thread: faer
/// parallelises inside the dense blocks of the supernodes, which are too small here to pay for
/// the hand-offs. The 10 mm beam (1.55e7 entries; docs/performance.md) factorises in 217–230 ms
/// on one thread against 251–273 ms on two on a quiet 2-core machine; the 5 mm beam and the
/// tet10 bracket (1.6–2.5e8) keep both threads. Also makes the small factors' round-off
/// independent of the thread count.
const PARALLEL_FACTOR_FROM: usize = 40_000_000;

/// The parallelism of faer's numeric factorisation and solves for a factor of `nnz` entries.
fn factor_par(nnz: usize) -> faer::Par {
    if nnz < PARALLEL_FACTOR_FROM {
        faer::Par::Seq
    } else {
        faer::get_global_parallelism()
    }
}

/// Numeric LLᵀ factorisation of (`pattern`, `vals`) on the symbolic analysis `sym`, in the
/// precision of `T` (f64 for [`Factor`], f32 for [`MixedFactor`]). The error says what failed;
/// the caller says why it may have.
fn numeric_llt<T: faer::traits::ComplexField + Copy>(
    sym: &SymbolicCholesky<u32>,
    pattern: &Pattern,
    vals: &[T],
) -> Result<Vec<T>, String> {
    numeric_llt_on(sym, pattern.symbolic(), vals, factor_par(sym.len_val()))
}

/// [`numeric_llt`] of a matrix given by its structure `a`, on one thread.
pub(crate) fn numeric_llt_seq<T: faer::traits::ComplexField + Copy>(
    sym: &SymbolicCholesky<u32>,
    a: SymbolicSparseColMatRef<'_, u32>,
    vals: &[T],
) -> Result<Vec<T>, String> {
    numeric_llt_on(sym, a, vals, faer::Par::Seq)
}

fn numeric_llt_on<T: faer::traits::ComplexField + Copy>(
    sym: &SymbolicCholesky<u32>,
    a: SymbolicSparseColMatRef<'_, u32>,
    vals: &[T],
    par: faer::Par,
) -> Result<Vec<T>, String> {
    let mut values = Vec::new();
    values
        .try_reserve_exact(sym.len_val())
        .map_err(|_| "out of memory for the Cholesky factor".to_string())?;
    values.resize(sym.len_val(), T::zero_impl());
    let mut buf =
        MemBuffer::try_new(sym.factorize_numeric_llt_scratch::<T>(par, Default::default()))
            .map_err(|_| "out of memory for the Cholesky workspace".to_string())?;
    sym.factorize_numeric_llt::<T>(
        &mut values,
        SparseColMatRef::new(a, vals),
        Side::Lower,
        Default::default(),
        par,
        MemStack::new(&mut buf),
        Default::default(),
    )
    .map_err(|e| format!("Cholesky factorisation failed ({e:?})"))?;
    Ok(values)
}

impl Factor {
    /// Factorises the symmetric positive definite matrix; the symbolic analysis is computed
    /// once per pattern and reused.
    pub fn new(
        pattern: &Pattern,
        vals: &[f64],
        symbolic: &mut Option<Symbolic>,
    ) -> Result<Factor, FemError> {
        let t0 = std::time::Instant::now();
        let sym = ensure_symbolic(pattern, symbolic)?;
        let t_sym = t0.elapsed();
        let not_pd = |e: String| {
            FemError::Solver(format!(
                "{e}: the matrix is not positive definite — check that the supports remove all \
                 rigid-body motions"
            ))
        };
        let values = match sym.split() {
            Some(plan) => FactorValues::Split(plan.factorize(vals, None).map_err(not_pd)?),
            None => {
                FactorValues::Whole(numeric_llt(sym.full(pattern)?, pattern, vals).map_err(not_pd)?)
            }
        };
        if timing() {
            tracing::debug!(
                "  cholesky n={} nnz(A)={} nnz(L)={}{}: symbolic {:?}, numeric {:?}",
                pattern.n,
                pattern.nnz(),
                sym.factor_nnz(),
                if sym.split().is_some() {
                    " (two halves)"
                } else {
                    ""
                },
                t_sym,
                t0.elapsed() - t_sym
            );
        }
        Ok(Factor {
            symbolic: sym,
            values,
        })
    }

    /// Entries of the factor L (the fill of the chosen ordering; both halves' with a tree
    /// split).
    pub fn factor_nnz(&self) -> usize {
        self.symbolic.factor_nnz()
    }

    /// Whether the factor was computed as two halves side by side ([`crate::tree_factor`]).
    pub fn is_split(&self) -> bool {
        matches!(self.values, FactorValues::Split(_))
    }

    /// Solves A x = b in place.
    pub fn solve_in_place(&self, b: &mut [f64]) {
        let mut buf = self.values.scratch(&self.symbolic);
        self.values.solve_in_place(&self.symbolic, b, &mut buf);
    }
}

/// Dot product in fixed 4096-element chunks: the same sum for any thread count.
fn dot(x: &[f64], y: &[f64]) -> f64 {
    x.par_chunks(4096)
        .zip(y.par_chunks(4096))
        .map(|(a, c)| a.iter().zip(c).map(|(p, q)| p * q).sum::<f64>())
        .collect::<Vec<f64>>()
        .iter()
        .sum()
}

/// Outcome of a [`MixedFactor::solve`]: PCG iterations and the final relative residual.
#[derive(Clone, Copy, Debug)]
pub struct RefinedSolve {
    pub iterations: usize,
    pub relative_residual: f64,
}

/// Mixed-precision solver for large static systems: faer's sparse Cholesky factor computed
/// and stored in f32 (half the memory and about half the time of the f64 factor) used as the
/// preconditioner of conjugate gradients on the f64 system, which restores full accuracy in a
/// few iterations while κ(A)·ε_f32 ≪ 1 (Higham, *Accuracy and Stability*, ch. 12). Shares the
/// symbolic analysis with [`Factor`], and like it factorises as two halves side by side where
/// the plan has a tree split ([`crate::tree_factor`]; its separator in f64).
pub struct MixedFactor {
    symbolic: Symbolic,
    values: FactorValues<f32>,
    /// ‖A‖∞ of the matrix factored (computed at the first solve).
    a_norm: std::sync::OnceLock<f64>,
    /// The symmetric diagonal scaling S = diag(A)^(-1/2): the f32 factor is that of S A S,
    /// whose unit diagonal loses less to single precision than A's stiffness spread.
    scale: Vec<f64>,
}

impl MixedFactor {
    /// Factorises A in f32. Fails (and the caller falls back to [`Factor`]) when A is not
    /// positive definite in single precision or memory runs out.
    pub fn new(
        pattern: &Pattern,
        vals: &[f64],
        symbolic: &mut Option<Symbolic>,
    ) -> Result<MixedFactor, FemError> {
        let sym = ensure_symbolic(pattern, symbolic)?;
        let t0 = std::time::Instant::now();
        let scale: Vec<f64> = (0..pattern.n)
            .map(|j| {
                let d = pattern.find(j as u32, j as u32).map_or(0.0, |p| vals[p]);
                if d > 0.0 {
                    1.0 / d.sqrt()
                } else {
                    1.0 // not positive definite: the factorisation says so
                }
            })
            .collect();
        let not_pd =
            |e: String| FemError::Solver(format!("{e}: not positive definite in single precision"));
        if let Some(plan) = sym.split() {
            let values = plan.factorize::<f32>(vals, Some(&scale)).map_err(not_pd)?;
            if timing() {
                tracing::debug!(
                    "  f32 cholesky n={} nnz(L)={} (two halves): numeric {:?}",
                    pattern.n,
                    plan.factor_nnz(),
                    t0.elapsed()
                );
            }
            return Ok(MixedFactor {
                symbolic: sym,
                values: FactorValues::Split(values),
                a_norm: std::sync::OnceLock::new(),
                scale,
            });
        }
        let mut a32 = vec![0.0f32; vals.len()];
        a32.par_chunks_mut(4096)
            .enumerate()
            .for_each(|(ci, chunk)| {
                let base = ci * 4096;
                // the column of each entry: binary search once per chunk, then walk
                let mut j = pattern.col_ptr.partition_point(|&c| c as usize <= base) - 1;
                for (k, out) in chunk.iter_mut().enumerate() {
                    let p = base + k;
                    while pattern.col_ptr[j + 1] as usize <= p {
                        j += 1;
                    }
                    let i = pattern.row_idx[p] as usize;
                    *out = (vals[p] * scale[i] * scale[j]) as f32;
                }
            });
        let values = numeric_llt(sym.full(pattern)?, pattern, &a32).map_err(not_pd)?;
        if timing() {
            tracing::debug!(
                "  f32 cholesky n={} nnz(L)={}: numeric {:?}",
                pattern.n,
                sym.full_computed().len_val(),
                t0.elapsed()
            );
        }
        Ok(MixedFactor {
            symbolic: sym,
            values: FactorValues::Whole(values),
            a_norm: std::sync::OnceLock::new(),
            scale,
        })
    }

    /// Whether the f32 factor was computed as two halves side by side.
    pub fn is_split(&self) -> bool {
        matches!(self.values, FactorValues::Split(_))
    }

    /// z = S (L Lᵀ)⁻¹ S r in single precision (L Lᵀ ≈ S A S).
    fn precondition(&self, r: &[f64], z: &mut [f64], work: &mut [f32], buf: &mut MemBuffer) {
        for ((w, &v), &s) in work.iter_mut().zip(r).zip(&self.scale) {
            *w = (v * s) as f32;
        }
        self.values.solve_in_place(&self.symbolic, work, buf);
        for ((zi, &w), &s) in z.iter_mut().zip(work.iter()).zip(&self.scale) {
            *zi = w as f64 * s;
        }
    }

    /// Solves A x = b in place (b in, x out) by preconditioned conjugate gradients in f64 with
    /// A = (`pattern`, `vals`), the matrix this factor was computed from. The CG recurrence's
    /// residual drifts from the true b − A x, so CG restarts from the true residual (up to
    /// three rounds) until ‖b − A x‖/‖b‖ ≤ `tol`, x is backward stable with a residual within
    /// `accept`, or a round no longer halves it; fails when it is still above `accept` after
    /// `max_iter` iterations in all.
    pub fn solve(
        &self,
        pattern: &Pattern,
        vals: &[f64],
        b: &mut [f64],
        tol: f64,
        accept: f64,
        max_iter: usize,
    ) -> Result<RefinedSolve, FemError> {
        let n = b.len();
        let t0 = std::time::Instant::now();
        let bnorm = dot(b, b).sqrt();
        if bnorm == 0.0 {
            return Ok(RefinedSolve {
                iterations: 0,
                relative_residual: 0.0,
            });
        }
        let mut buf = self.values.scratch(&self.symbolic);
        let mut work = vec![0.0f32; n];
        let mut x = vec![0.0; n];
        let mut r = b.to_vec();
        let mut q = vec![0.0; n];
        let mut dx = vec![0.0; n];
        let mut it = 0;
        let mut rel = 1.0;
        let a_norm = *self.a_norm.get_or_init(|| pattern.norm_inf(vals));
        let inf = |v: &[f64]| v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        for _round in 0..3 {
            it += self.pcg(
                pattern,
                vals,
                &mut r,
                &mut dx,
                &mut q,
                &mut work,
                &mut buf,
                1e-3 * tol,
                // the backward-stability floor of this round's residual (dsposv's test below),
                // once the residual is acceptable
                a_norm * f64::EPSILON * (n as f64).sqrt(),
                inf(&x),
                accept * bnorm,
                max_iter - it.min(max_iter),
            );
            for (xi, d) in x.iter_mut().zip(&dx) {
                *xi += d;
            }
            pattern.mul(vals, &x, &mut q);
            for ((ri, bi), ax) in r.iter_mut().zip(b.iter()).zip(&q) {
                *ri = bi - ax;
            }
            let before = rel;
            rel = dot(&r, &r).sqrt() / bnorm;
            // LAPACK's mixed-precision refinement rules (dsposv): stop at the tolerance, when
            // x is backward stable (‖r‖∞ ≤ ‖x‖∞ ‖A‖∞ ε √n: the f64 round-off floor of b − A x,
            // which another round cannot lower), or when a round no longer halves the residual
            let floor = inf(&x) * a_norm * f64::EPSILON * (n as f64).sqrt();
            if rel <= tol
                || (inf(&r) <= floor && rel <= accept)
                || rel > 0.5 * before
                || it >= max_iter
            {
                break;
            }
        }
        if timing() {
            tracing::debug!(
                "  mixed-precision PCG: {it} iterations, relative residual {rel:.2e}, {:?}",
                t0.elapsed()
            );
        }
        if !(rel <= accept) {
            return Err(FemError::Solver(format!(
                "mixed-precision solve did not converge: relative residual {rel:.2e} after \
                 {it} iterations (wanted {accept:.0e})"
            )));
        }
        b.copy_from_slice(&x);
        Ok(RefinedSolve {
            iterations: it,
            relative_residual: rel,
        })
    }

    /// Preconditioned CG for A dx = r from dx = 0 (r is overwritten by the recurrence's
    /// residual). Stops at ‖r‖ ≤ `tol`·‖r₀‖, at the backward-stability floor
    /// ‖r‖∞ ≤ `floor_per_x`·‖x₀ + dx‖∞ (`x_inf` = ‖x₀‖∞, the solution of the earlier rounds;
    /// below it the true residual no longer follows the recurrence's: further iterations
    /// only polish round-off) once ‖r‖ ≤ `acceptable` (the bound has a √n in it and can lie
    /// above what the caller accepts), when the residual stops falling, or after `max_iter`
    /// iterations; returns the iterations done.
    #[allow(clippy::too_many_arguments)]
    fn pcg(
        &self,
        pattern: &Pattern,
        vals: &[f64],
        r: &mut [f64],
        x: &mut [f64],
        q: &mut [f64],
        work: &mut [f32],
        buf: &mut MemBuffer,
        tol: f64,
        floor_per_x: f64,
        x_inf: f64,
        acceptable: f64,
        max_iter: usize,
    ) -> usize {
        let n = r.len();
        x.fill(0.0);
        let r0 = dot(r, r).sqrt();
        let mut z = vec![0.0; n];
        self.precondition(r, &mut z, work, buf);
        let mut p = z.clone();
        let mut rz = dot(r, &z);
        let mut best = f64::INFINITY;
        let mut since_best = 0;
        let mut it = 0;
        while it < max_iter && r0 > 0.0 {
            it += 1;
            pattern.mul(vals, &p, q);
            let pq = dot(&p, q);
            if !(pq > 0.0) {
                break; // breakdown: converged to round-off, or A not SPD in f64 arithmetic
            }
            let alpha = rz / pq;
            x.par_iter_mut()
                .zip(r.par_iter_mut())
                .zip(p.par_iter().zip(q.par_iter()))
                .for_each(|((xi, ri), (pi, qi))| {
                    *xi += alpha * pi;
                    *ri -= alpha * qi;
                });
            let rel = dot(r, r).sqrt() / r0;
            if rel <= tol {
                break;
            }
            let (r_inf, dx_inf) = r
                .par_iter()
                .zip(x.par_iter())
                .map(|(a, b)| (a.abs(), b.abs()))
                .reduce(|| (0.0, 0.0), |a, b| (a.0.max(b.0), a.1.max(b.1)));
            if r_inf <= floor_per_x * x_inf.max(dx_inf) && rel * r0 <= acceptable {
                break;
            }
            if rel < 0.5 * best {
                best = rel;
                since_best = 0;
            } else {
                since_best += 1;
                if since_best >= 8 {
                    break; // stagnated
                }
            }
            self.precondition(r, &mut z, work, buf);
            let rz_new = dot(r, &z);
            let beta = rz_new / rz;
            rz = rz_new;
            p.par_iter_mut()
                .zip(z.par_iter())
                .for_each(|(pi, zi)| *pi = zi + beta * *pi);
        }
        it
    }
}

/// Sparse LU factor (faer, partial pivoting, COLAMD ordering) of a general matrix on the
/// full pattern: the tangent of a non-associative plastic material is not symmetric, and a
/// softening one need not be positive definite.
pub struct LuFactor {
    lu: faer::sparse::linalg::solvers::Lu<u32, f64>,
}

/// Cached symbolic LU analysis of one pattern.
pub type SymbolicLu = faer::sparse::linalg::solvers::SymbolicLu<u32>;

impl LuFactor {
    pub fn new(
        pattern: &Pattern,
        vals: &[f64],
        symbolic: &mut Option<SymbolicLu>,
    ) -> Result<LuFactor, FemError> {
        if symbolic.is_none() {
            *symbolic = Some(
                SymbolicLu::try_new(pattern.symbolic())
                    .map_err(|e| FemError::Solver(format!("symbolic LU failed: {e:?}")))?,
            );
        }
        let sym = symbolic.clone().expect("set above");
        let lu = faer::sparse::linalg::solvers::Lu::try_new_with_symbolic(
            sym,
            SparseColMatRef::new(pattern.symbolic(), vals),
        )
        .map_err(|e| FemError::Solver(format!("LU factorisation failed ({e:?})")))?;
        Ok(LuFactor { lu })
    }

    /// Solves A x = b in place.
    pub fn solve_in_place(&self, b: &mut [f64]) {
        use faer::linalg::solvers::Solve;
        let n = b.len();
        let rhs = faer::MatMut::from_column_major_slice_mut(b, n, 1);
        self.lu.solve_in_place(rhs);
    }
}
