//! Global sparse matrices over the free equations (fixed dofs eliminated, (2.54)–(2.57)):
//! sparsity pattern from node adjacency, deterministic parallel assembly, symmetric products
//! and the faer sparse Cholesky factorisation.

use crate::element::{self, ElementKind, Lame};
use crate::mesh::Mesh;
use crate::FemError;
use faer::linalg::solvers::Solve;
use faer::sparse::linalg::solvers::{Llt, SymbolicLlt};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::Side;
use rayon::prelude::*;

/// Equation number of each dof (3 per node, node-major); `FIXED` for supported or unused dofs.
#[derive(Clone, Debug)]
pub struct DofMap {
    pub eq: Vec<u32>,
    pub n_eq: usize,
}

pub const FIXED: u32 = u32::MAX;

impl DofMap {
    /// Free dofs are those of nodes used by elements and not fixed.
    pub fn new(fixed: &[bool], used: &[bool]) -> DofMap {
        let mut eq = vec![FIXED; fixed.len()];
        let mut n = 0u32;
        for d in 0..fixed.len() {
            if !fixed[d] && used[d / 3] {
                eq[d] = n;
                n += 1;
            }
        }
        DofMap {
            eq,
            n_eq: n as usize,
        }
    }
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
}

impl Pattern {
    pub fn build(mesh: &Mesh, dofs: &DofMap) -> Result<Pattern, FemError> {
        let nn = mesh.num_nodes();
        // node → elements incidence (CSR)
        let mut count = vec![0u32; nn + 1];
        for &n in &mesh.conn {
            count[n as usize + 1] += 1;
        }
        for i in 0..nn {
            count[i + 1] += count[i];
        }
        let mut fill = count.clone();
        let mut node_elems = vec![0u32; mesh.conn.len()];
        for e in 0..mesh.num_elements() {
            for &n in mesh.element_nodes(e) {
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
                    v.extend_from_slice(mesh.element_nodes(e as usize));
                }
                v.sort_unstable();
                v.dedup();
                v
            })
            .collect();
        let mut col_ptr = Vec::with_capacity(dofs.n_eq + 1);
        col_ptr.push(0u32);
        let mut row_idx: Vec<u32> = Vec::new();
        for n in 0..nn {
            for c in 0..3 {
                if dofs.eq[3 * n + c] == FIXED {
                    continue;
                }
                for &m in &adj[n] {
                    for d in 0..3 {
                        let e = dofs.eq[3 * m as usize + d];
                        if e != FIXED {
                            row_idx.push(e);
                        }
                    }
                }
                if row_idx.len() > u32::MAX as usize {
                    return Err(FemError::Solver(
                        "matrix too large for 32-bit indices".into(),
                    ));
                }
                col_ptr.push(row_idx.len() as u32);
            }
        }
        Ok(Pattern {
            n: dofs.n_eq,
            col_ptr,
            row_idx,
        })
    }

    pub fn nnz(&self) -> usize {
        self.row_idx.len()
    }

    fn symbolic(&self) -> SymbolicSparseColMatRef<'_, u32> {
        SymbolicSparseColMatRef::new_checked(self.n, self.n, &self.col_ptr, None, &self.row_idx)
    }

    /// Position of entry (row, col) if present.
    #[inline]
    fn find(&self, row: u32, col: u32) -> Option<usize> {
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

/// Assembles K (2.56) or the consistent M (2.78) on `pattern`. Element matrices are computed in
/// parallel batches; the scatter is parallel over disjoint column ranges and adds element
/// contributions in element order, so results are identical for any thread count.
pub fn assemble(
    mesh: &Mesh,
    dofs: &DofMap,
    pattern: &Pattern,
    op: Operator,
    mat: Lame,
    rho: f64,
) -> Result<Vec<f64>, FemError> {
    let mut vals = vec![0.0; pattern.nnz()];
    let ne = mesh.num_elements();
    const BATCH: usize = 2048;
    let max_nn = 20;
    let stride = (3 * max_nn) * (3 * max_nn);
    let mut buf = vec![0.0; BATCH * stride];
    let parts = pattern.column_partitions(4 * rayon::current_num_threads().max(1));
    let mut start = 0;
    while start < ne {
        let end = (start + BATCH).min(ne);
        // 1. element matrices
        let res: Result<(), (usize, element::BadJacobian)> = buf[..(end - start) * stride]
            .par_chunks_mut(stride)
            .enumerate()
            .try_for_each_init(
                || (Vec::new(), Vec::new()),
                |(x, ke), (i, out)| {
                    let e = start + i;
                    mesh.element_coords(e, x);
                    let kind = mesh.kinds[e];
                    let nd = 3 * kind.num_nodes();
                    match op {
                        Operator::Stiffness => {
                            element::stiffness(kind, x, mat, ke).map_err(|b| (e, b))?;
                            out[..nd * nd].copy_from_slice(ke);
                        }
                        Operator::Mass => {
                            element::mass(kind, x, rho, ke).map_err(|b| (e, b))?;
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
        // 2. scatter, parallel over column ranges
        let mut slices: Vec<(usize, usize, &mut [f64])> = Vec::with_capacity(parts.len());
        let mut rest: &mut [f64] = &mut vals;
        let mut offset = 0usize;
        for &(c0, c1) in &parts {
            let a = pattern.col_ptr[c0] as usize;
            let b = pattern.col_ptr[c1] as usize;
            let (_, tail) = rest.split_at_mut(a - offset);
            let (mine, tail) = tail.split_at_mut(b - a);
            rest = tail;
            offset = b;
            slices.push((c0, c1, mine));
        }
        let buf_ref = &buf;
        slices.par_iter_mut().for_each(|(c0, c1, mine)| {
            let base = pattern.col_ptr[*c0] as usize;
            let mut eqs = [0u32; 60];
            for e in start..end {
                let nodes = mesh.element_nodes(e);
                let nd = 3 * nodes.len();
                for (a, &n) in nodes.iter().enumerate() {
                    for k in 0..3 {
                        eqs[3 * a + k] = dofs.eq[3 * n as usize + k];
                    }
                }
                let ke = &buf_ref[(e - start) * stride..];
                for (jl, &cj) in eqs[..nd].iter().enumerate() {
                    if cj == FIXED || (cj as usize) < *c0 || (cj as usize) >= *c1 {
                        continue;
                    }
                    for (il, &ri) in eqs[..nd].iter().enumerate() {
                        if ri == FIXED {
                            continue;
                        }
                        let p = pattern
                            .find(ri, cj)
                            .expect("pattern covers element couplings");
                        mine[p - base] += ke[il * nd + jl];
                    }
                }
            }
        });
        start = end;
    }
    Ok(vals)
}

/// Lumped (HRZ) nodal masses for every dof (3 per node).
pub fn lumped_mass(mesh: &Mesh, rho: f64) -> Result<Vec<f64>, FemError> {
    let per_elem: Vec<Result<Vec<f64>, FemError>> = (0..mesh.num_elements())
        .into_par_iter()
        .map(|e| {
            let mut x = Vec::new();
            mesh.element_coords(e, &mut x);
            let kind: ElementKind = mesh.kinds[e];
            let mut m = vec![0.0; kind.num_nodes()];
            element::lumped_mass(kind, &x, rho, &mut m).map_err(|b| FemError::Mesh {
                file: mesh.source.clone(),
                line: mesh.elem_lines[e],
                message: format!("element {} has det J = {:.3e}", mesh.elem_ids[e], b.det_j),
            })?;
            Ok(m)
        })
        .collect();
    let mut out = vec![0.0; 3 * mesh.num_nodes()];
    for (e, m) in per_elem.into_iter().enumerate() {
        let m = m?;
        for (a, &n) in mesh.element_nodes(e).iter().enumerate() {
            for k in 0..3 {
                out[3 * n as usize + k] += m[a];
            }
        }
    }
    Ok(out)
}

/// Sparse Cholesky factor (faer supernodal/simplicial LLᵀ with AMD fill-reducing ordering).
pub struct Factor {
    llt: Llt<u32, f64>,
}

impl Factor {
    /// Factorises the symmetric positive definite matrix; the symbolic analysis (ordering and
    /// elimination tree) is computed once per pattern and reused.
    pub fn new(
        pattern: &Pattern,
        vals: &[f64],
        symbolic: &mut Option<SymbolicLlt<u32>>,
    ) -> Result<Factor, FemError> {
        if symbolic.is_none() {
            *symbolic = Some(
                SymbolicLlt::try_new(pattern.symbolic(), Side::Lower)
                    .map_err(|e| FemError::Solver(format!("symbolic Cholesky failed: {e:?}")))?,
            );
        }
        let sym = symbolic.clone().expect("set above");
        let a = SparseColMatRef::new(pattern.symbolic(), vals);
        let llt = Llt::try_new_with_symbolic(sym, a, Side::Lower).map_err(|e| {
            FemError::Solver(format!(
                "Cholesky factorisation failed ({e:?}): the matrix is not positive definite — \
                 check that the supports remove all rigid-body motions"
            ))
        })?;
        Ok(Factor { llt })
    }

    /// Solves A x = b in place.
    pub fn solve_in_place(&self, b: &mut [f64]) {
        let col = faer::ColMut::from_slice_mut(b);
        self.llt.solve_in_place(col);
    }
}
