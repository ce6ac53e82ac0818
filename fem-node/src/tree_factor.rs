//! Tree-level parallel sparse Cholesky: the two halves under the top separator of the
//! elimination tree factorised side by side, one thread each, then the separator.
//!
//! faer parallelises a supernodal factorisation inside its dense blocks only; on a mesh of
//! ~10⁴ nodes those blocks are too small to pay for the hand-offs (docs/performance.md: the
//! 10 mm beam factorises faster on one thread than on two). The elimination tree offers
//! coarser work: with the equations in elimination order [A | B | S], where S is the chain of
//! the tree's top (its root down to the first node with two or more children, a separator of
//! the graph) and A, B the subtrees below it split into two groups of about equal work,
//! K_AB = 0 and
//!
//! ```text
//!     L = | L_AA             |      L_AA L_AAᵀ = K_AA,    L_SA = K_SA L_AA⁻ᵀ,
//!         |       L_BB       |      L_BB, L_SB likewise,
//!         | L_SA  L_SB  L_SS |      L_SS L_SSᵀ = K_SS − L_SA L_SAᵀ − L_SB L_SBᵀ.
//! ```
//!
//! faer factorises the principal submatrices K[A∪S] and K[B∪S] (both positive definite as
//! principal submatrices of K; one thread each, at the same time): their leading blocks are
//! L_AA, L_SA (resp. L_BB, L_SB) exactly, and their trailing blocks L₁, L₂ satisfy
//! L₁L₁ᵀ = K_SS − L_SA L_SAᵀ and likewise L₂, so the separator's Schur complement is
//! L₁L₁ᵀ + L₂L₂ᵀ − K_SS, a dense s × s matrix factorised by faer's dense Cholesky. The cost
//! beyond the halves is about s³ (each half's trailing block, the two products, the dense
//! factor): the split is taken only when the tree is balanced and the separator small enough
//! for that to pay ([`SplitPlan::new`]). The cancellation in the Schur complement costs
//! about log₁₀(‖K_SS‖/‖L_SS L_SSᵀ‖) digits, which the tests bound.
//!
//! A solve runs the forward substitution of both halves' own columns side by side (their
//! separator rows collect −L_SA y_A and −L_SB y_B), the dense separator solves, then both
//! backward substitutions side by side, supernode by supernode with faer's dense kernels.
//! Every result is independent of the thread count: the halves are computed the same way
//! whether `rayon::join` runs them on one thread or two.
//!
//! The halves are computed and applied in f64 ([`crate::assembly::Factor`]) or in f32 (the
//! preconditioner of [`crate::assembly::MixedFactor`], of the diagonally scaled matrix); the
//! separator's Schur complement and its dense factor are f64 either way, so its cancellation
//! costs no single-precision digits beyond those already in the halves' trailing blocks.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::matmul::matmul;
use faer::linalg::matmul::triangular::{self as tri, BlockStructure};
use faer::linalg::triangular_solve::{
    solve_lower_triangular_in_place, solve_upper_triangular_in_place,
};
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, SymbolicCholesky, SymbolicCholeskyRaw,
    SymmetricOrdering,
};
use faer::sparse::SymbolicSparseColMatRef;
use faer::{Accum, Mat, MatMut, MatRef, Par, Side};

use crate::assembly::Pattern;

const NONE: u32 = u32::MAX;

/// The largest separator planned (equations).
const MAX_SEPARATOR: usize = 2000;

/// One supernode of a half's factor: its columns `start..end`, the offset of its dense
/// column-major values (`end − start + pattern` rows), and its off-diagonal rows
/// `row_idx[p0..p0 + plen]` of the half's symbolic factor.
#[derive(Clone, Copy, Debug)]
struct Node {
    start: u32,
    end: u32,
    voff: usize,
    p0: u32,
    plen: u32,
}

/// One half: the principal submatrix K[own ∪ S], own equations first.
struct Half {
    /// The original equation of each local column: the half's own equations, then the
    /// separator's (both in the whole factor's elimination order).
    eqs: Vec<u32>,
    /// Number of own equations (the separator follows).
    own: usize,
    /// Lower triangle of the submatrix in local numbering, compressed columns.
    col_ptr: Vec<u32>,
    row_idx: Vec<u32>,
    /// For each entry, its index in the whole pattern's values.
    src: Vec<u32>,
    sym: SymbolicCholesky<u32>,
    /// The factor's supernodes (their off-diagonal rows are `sym`'s, [`Half::rows`]).
    nodes: Vec<Node>,
}

impl Half {
    /// The off-diagonal row indices of the supernodes of the half's factor.
    fn rows(&self) -> &[u32] {
        supernode_rows(&self.sym)
    }
}

/// faer's off-diagonal row indices of a supernodal factor (empty for a simplicial one, which
/// [`nodes_of`] refuses).
fn supernode_rows(sym: &SymbolicCholesky<u32>) -> &[u32] {
    match sym.raw() {
        SymbolicCholeskyRaw::Supernodal(s) => s.row_idx(),
        SymbolicCholeskyRaw::Simplicial(_) => &[],
    }
}

/// The split of a factorisation at the top of its elimination tree (module docs), computed
/// once per pattern beside the symbolic analysis.
pub struct SplitPlan {
    halves: [Half; 2],
    /// The separator's equations (original numbering) in elimination order.
    sep: Vec<u32>,
    /// Lower triangle of K_SS: (row, column) in separator numbering, entry in the pattern.
    kss: Vec<(u32, u32, u32)>,
    /// Predicted work of the split path over the whole factor's (for the debug log).
    pub predicted: f64,
}

/// The numeric factor of a [`SplitPlan`]: both halves' values (in `T`) and the separator's
/// dense Cholesky factor L_SS (in f64).
pub struct SplitFactor<T = f64> {
    values: [Vec<T>; 2],
    lss: Mat<f64>,
}

/// The scalar a split factor's halves are computed and applied in: f64, or f32 for the
/// mixed-precision preconditioner.
pub trait FactorScalar: faer::traits::RealField + Copy + Send + Sync {
    /// The nearest value of this type.
    fn of(x: f64) -> Self;
    /// The value in f64 (exact).
    fn wide(self) -> f64;
}

impl FactorScalar for f64 {
    fn of(x: f64) -> f64 {
        x
    }
    fn wide(self) -> f64 {
        self
    }
}

impl FactorScalar for f32 {
    fn of(x: f64) -> f32 {
        x as f32
    }
    fn wide(self) -> f64 {
        self as f64
    }
}

impl Node {
    /// The node's dense block (its columns' values, `end − start + plen` rows) in `values`,
    /// and the number of its columns that are the half's own (below `own`).
    fn block<'a, T>(&self, values: &'a [T], own: usize) -> (MatRef<'a, T>, usize) {
        let size = (self.end - self.start) as usize;
        let nrows = size + self.plen as usize;
        let ls = MatRef::from_column_major_slice(&values[self.voff..][..nrows * size], nrows, size);
        (ls, (self.end as usize).min(own) - self.start as usize)
    }
}

/// The structure of the transpose of the m × m matrix (`col_ptr`, `row_idx`), rows sorted.
fn transpose(m: usize, col_ptr: &[u32], row_idx: &[u32]) -> (Vec<u32>, Vec<u32>) {
    let mut ptr = vec![0u32; m + 1];
    for &i in row_idx {
        ptr[i as usize + 1] += 1;
    }
    for i in 0..m {
        ptr[i + 1] += ptr[i];
    }
    let mut next = ptr.clone();
    let mut rows = vec![0u32; row_idx.len()];
    for j in 0..m {
        for &i in &row_idx[col_ptr[j] as usize..col_ptr[j + 1] as usize] {
            rows[next[i as usize] as usize] = j as u32;
            next[i as usize] += 1;
        }
    }
    (ptr, rows)
}

/// The supernodes of `sym`, None for a simplicial factor.
fn nodes_of(sym: &SymbolicCholesky<u32>) -> Option<Vec<Node>> {
    let SymbolicCholeskyRaw::Supernodal(s) = sym.raw() else {
        return None;
    };
    let ns = s.n_supernodes();
    let (begin, cptr_rows, cptr_val) = (
        s.supernode_begin(),
        s.col_ptr_for_row_idx(),
        s.col_ptr_for_val(),
    );
    let nodes = (0..ns)
        .map(|k| Node {
            start: begin[k],
            end: s.supernode_end()[k],
            voff: cptr_val[k] as usize,
            p0: cptr_rows[k],
            plen: s.supernode(k).pattern().len() as u32,
        })
        .collect();
    Some(nodes)
}

impl SplitPlan {
    /// Plans the split of `sym` (the symbolic factor of `pattern`), or None when the factor is
    /// simplicial or [`SplitPlan::from_tree`] refuses.
    pub fn new(pattern: &Pattern, sym: &SymbolicCholesky<u32>) -> Option<SplitPlan> {
        let n = pattern.n;
        let nodes = nodes_of(sym)?;
        let rows = supernode_rows(sym);
        let (fwd, inv) = sym.perm()?.arrays();
        // the column elimination tree (positions in elimination order) and each column's
        // entry count in L
        let mut parent = vec![NONE; n];
        let mut work = vec![0.0f64; n];
        for nd in &nodes {
            let pat = &rows[nd.p0 as usize..(nd.p0 + nd.plen) as usize];
            for j in nd.start..nd.end {
                parent[j as usize] = if j + 1 < nd.end {
                    j + 1
                } else {
                    pat.first().copied().unwrap_or(NONE) // faer's rows are sorted
                };
                let c = (nd.end - j + nd.plen) as f64;
                work[j as usize] = c * c;
            }
        }
        Self::from_tree(pattern, fwd, inv, &parent, &work)
    }

    /// Plans the split of the factor of `pattern` eliminated in `fwd` (`fwd[p]`: the equation
    /// eliminated p-th, `inv` its inverse) whose elimination tree is `parent` (by position,
    /// `u32::MAX` at a root; a parent comes after its children) with `work[p]` the cost of
    /// column p (its entry count squared). None when the tree has no branch, the halves are
    /// unbalanced or the separator's dense work would eat the gain: the split's predicted
    /// critical path — the larger half plus about s³ for the separator — must be under 3/4 of
    /// the whole factorisation's work.
    pub fn from_tree(
        pattern: &Pattern,
        fwd: &[u32],
        inv: &[u32],
        parent: &[u32],
        work: &[f64],
    ) -> Option<SplitPlan> {
        let n = pattern.n;
        if n < 2 || fwd.len() != n || inv.len() != n || parent.len() != n || work.len() != n {
            return None;
        }
        let total: f64 = work.iter().sum();
        // subtree work, bottom-up (a parent comes after its children)
        let mut sub = work.to_vec();
        let mut children: Vec<Vec<u32>> = vec![Vec::new(); n];
        let mut roots = Vec::new();
        for j in 0..n {
            match parent[j] {
                NONE => roots.push(j as u32),
                p => {
                    sub[p as usize] += sub[j];
                    children[p as usize].push(j as u32);
                }
            }
        }
        // The separator: the top of the tree, grown from the roots by taking in the heaviest
        // subtree of the frontier (its root joins S, its children the frontier) until the
        // frontier's subtrees split into two groups of about equal work — on a nested
        // dissection the chain down to the first branch, on an unbalanced tree (AMD, METIS on
        // a small graph) more. Each frontier is split largest first into the lighter group,
        // and the frontier with the least predicted work wins: the larger group plus about
        // s³ for the separator's dense steps.
        let mut frontier = roots;
        let mut taken: Vec<u32> = Vec::new();
        // sorts the frontier heaviest first; each root's group and the groups' work
        let partition = |frontier: &mut Vec<u32>| -> (Vec<(u32, u32)>, [f64; 2]) {
            frontier.sort_by(|a, b| sub[*b as usize].total_cmp(&sub[*a as usize]));
            let mut w = [0.0f64; 2];
            let groups = frontier
                .iter()
                .map(|&k| {
                    let g = usize::from(w[1] < w[0]);
                    w[g] += sub[k as usize];
                    (k, g as u32)
                })
                .collect();
            (groups, w)
        };
        // (predicted, |S|, the frontier's roots with their groups)
        type Candidate = (f64, usize, Vec<(u32, u32)>);
        let mut best: Option<Candidate> = None;
        while !frontier.is_empty() {
            let s3 = (taken.len() as f64).powi(3);
            // a larger separator cannot win; and its dense blocks (five s × s matrices while
            // factorising) stay under 160 MB
            if best.as_ref().is_some_and(|b| s3 / total >= b.0) || taken.len() >= MAX_SEPARATOR {
                break;
            }
            let (groups, w) = partition(&mut frontier);
            if frontier.len() >= 2 {
                let predicted = (w[0].max(w[1]) + s3) / total;
                if best.as_ref().is_none_or(|b| predicted < b.0) {
                    best = Some((predicted, taken.len(), groups));
                }
            }
            // frontier is sorted heaviest first: take in its root
            let k = frontier.remove(0);
            taken.push(k);
            frontier.extend(std::mem::take(&mut children[k as usize]));
        }
        let (predicted, s, groups) = best?;
        if predicted > 0.75 {
            return None;
        }
        let mut label = vec![NONE; n];
        for (k, g) in groups {
            label[k as usize] = g;
        }
        let mut sep_pos: Vec<u32> = taken[..s].to_vec();
        sep_pos.sort_unstable(); // elimination order
        for &c in &sep_pos {
            label[c as usize] = 2;
        }
        // every other column takes its parent's group
        for j in (0..n).rev() {
            if label[j] == NONE && parent[j] != NONE {
                let p = label[parent[j] as usize];
                label[j] = p;
            }
        }
        // local numbering of each half: own positions ascending, then the separator's
        let mut local = vec![NONE; n]; // by position: index in its half (own) or in S
        let mut own_pos: [Vec<u32>; 2] = [Vec::new(), Vec::new()];
        for p in 0..n {
            match label[p] {
                g @ (0 | 1) => {
                    local[p] = own_pos[g as usize].len() as u32;
                    own_pos[g as usize].push(p as u32);
                }
                2 => {}
                _ => return None, // unreachable for a tree; refuse rather than guess
            }
        }
        for (k, &p) in sep_pos.iter().enumerate() {
            local[p as usize] = k as u32;
        }
        let sep: Vec<u32> = sep_pos.iter().map(|&p| fwd[p as usize]).collect();
        // K_SS's lower triangle
        let mut kss = Vec::new();
        for (jl, &e) in sep.iter().enumerate() {
            let e = e as usize;
            for q in pattern.col_ptr[e] as usize..pattern.col_ptr[e + 1] as usize {
                let rp = inv[pattern.row_idx[q] as usize] as usize;
                if label[rp] == 2 && local[rp] as usize >= jl {
                    kss.push((local[rp], jl as u32, q as u32));
                }
            }
        }
        let build = |g: u32| -> Option<Half> {
            let own = own_pos[g as usize].len();
            let mut eqs: Vec<u32> = own_pos[g as usize]
                .iter()
                .map(|&p| fwd[p as usize])
                .collect();
            eqs.extend_from_slice(&sep);
            let loc = |rp: usize| -> Option<u32> {
                match label[rp] {
                    2 => Some(own as u32 + local[rp]),
                    l if l == g => Some(local[rp]),
                    _ => None,
                }
            };
            let mut col_ptr = Vec::with_capacity(eqs.len() + 1);
            col_ptr.push(0u32);
            let (mut row_idx, mut src) = (Vec::new(), Vec::new());
            let mut col: Vec<(u32, u32)> = Vec::new();
            for (jl, &e) in eqs.iter().enumerate() {
                let e = e as usize;
                col.clear();
                for q in pattern.col_ptr[e] as usize..pattern.col_ptr[e + 1] as usize {
                    let rp = inv[pattern.row_idx[q] as usize] as usize;
                    match loc(rp) {
                        Some(r) if r as usize >= jl => col.push((r, q as u32)),
                        Some(_) => {}
                        // an entry between the two halves' own equations: not a tree split after
                        // all (the separator's columns meet both halves)
                        None if jl < own && label[rp] != 2 && label[rp] != g => return None,
                        None => {}
                    }
                }
                col.sort_unstable();
                row_idx.extend(col.iter().map(|c| c.0));
                src.extend(col.iter().map(|c| c.1));
                col_ptr.push(row_idx.len() as u32);
            }
            let m = eqs.len();
            // analysed in its own order without a permutation (faer reads the upper triangle
            // then), so that the numeric factorisation reads the lower triangle in place
            // instead of copying it into a permuted one
            let (ucol, urow) = transpose(m, &col_ptr, &row_idx);
            let sym = factorize_symbolic_cholesky(
                SymbolicSparseColMatRef::new_checked(m, m, &ucol, None, &urow),
                Side::Upper,
                SymmetricOrdering::Identity,
                CholeskySymbolicParams::default(),
            )
            .ok()?;
            let nodes = nodes_of(&sym)?;
            Some(Half {
                eqs,
                own,
                col_ptr,
                row_idx,
                src,
                sym,
                nodes,
            })
        };
        let (h0, h1) = rayon::join(|| build(0), || build(1));
        Some(SplitPlan {
            halves: [h0?, h1?],
            sep,
            kss,
            predicted,
        })
    }

    /// Size of the separator (the dense block).
    pub fn separator(&self) -> usize {
        self.sep.len()
    }

    /// Supernodes of the halves' factors that hold both own and separator columns (their
    /// own columns are substituted, the rest belong to the dense separator).
    pub fn straddling_supernodes(&self) -> usize {
        self.halves
            .iter()
            .map(|h| {
                h.nodes
                    .iter()
                    .filter(|nd| (nd.start as usize) < h.own && (nd.end as usize) > h.own)
                    .count()
            })
            .sum()
    }

    /// Entries of both halves' factors.
    pub fn factor_nnz(&self) -> usize {
        self.halves.iter().map(|h| h.sym.len_val()).sum()
    }

    /// Numeric factorisation in `T` of the matrix with `vals` on the pattern the plan was made
    /// for, scaled symmetrically by `scale` (entry (i, j) times `scale[i]·scale[j]`) if given.
    pub fn factorize<T: FactorScalar>(
        &self,
        vals: &[f64],
        scale: Option<&[f64]>,
    ) -> Result<SplitFactor<T>, String> {
        let half = |h: &Half| -> Result<(Vec<T>, Mat<f64>), String> {
            let m = h.eqs.len();
            let mut sub = Vec::new();
            sub.try_reserve_exact(h.src.len())
                .map_err(|_| "out of memory for a half of the split factor".to_string())?;
            match scale {
                None => sub.extend(h.src.iter().map(|&q| T::of(vals[q as usize]))),
                Some(s) => {
                    for (jl, &ej) in h.eqs.iter().enumerate() {
                        let sj = s[ej as usize];
                        let range = h.col_ptr[jl] as usize..h.col_ptr[jl + 1] as usize;
                        sub.extend(h.row_idx[range.clone()].iter().zip(&h.src[range]).map(
                            |(&il, &q)| {
                                T::of(vals[q as usize] * s[h.eqs[il as usize] as usize] * sj)
                            },
                        ));
                    }
                }
            }
            let a = SymbolicSparseColMatRef::new_checked(m, m, &h.col_ptr, None, &h.row_idx);
            let values = crate::assembly::numeric_llt_seq(&h.sym, a, &sub)?;
            drop(sub);
            // the trailing block L_h and its product L_h L_hᵀ (lower triangle), in f64
            let s = m - h.own;
            let mut lh = Mat::<f64>::zeros(s, s);
            let rows = h.rows();
            for nd in &h.nodes {
                if (nd.end as usize) <= h.own {
                    continue;
                }
                let size = (nd.end - nd.start) as usize;
                let nrows = size + nd.plen as usize;
                let pat = &rows[nd.p0 as usize..(nd.p0 + nd.plen) as usize];
                for j in (nd.start as usize).max(h.own)..nd.end as usize {
                    let c = j - nd.start as usize;
                    let col = &values[nd.voff + c * nrows..][..nrows];
                    for r in c..size {
                        lh[(nd.start as usize + r - h.own, j - h.own)] = col[r].wide();
                    }
                    for (k, &i) in pat.iter().enumerate() {
                        lh[(i as usize - h.own, j - h.own)] = col[size + k].wide();
                    }
                }
            }
            let mut g = Mat::<f64>::zeros(s, s);
            tri::matmul(
                g.as_mut(),
                BlockStructure::TriangularLower,
                Accum::Replace,
                lh.as_ref(),
                BlockStructure::TriangularLower,
                lh.transpose(),
                BlockStructure::TriangularUpper,
                1.0,
                Par::Seq,
            );
            Ok((values, g))
        };
        let (r0, r1) = rayon::join(|| half(&self.halves[0]), || half(&self.halves[1]));
        let ((v0, mut schur), (v1, g1)) = (r0?, r1?);
        // L_SS L_SSᵀ = L₁L₁ᵀ + L₂L₂ᵀ − K_SS (lower triangle)
        for j in 0..schur.ncols() {
            for i in j..schur.nrows() {
                schur[(i, j)] += g1[(i, j)];
            }
        }
        for &(i, j, q) in &self.kss {
            let scaled = match scale {
                None => vals[q as usize],
                Some(s) => {
                    vals[q as usize]
                        * s[self.sep[i as usize] as usize]
                        * s[self.sep[j as usize] as usize]
                }
            };
            // K_SS as the halves saw it (rounded to T), so that the split factors the very
            // matrix the whole factor in T would
            schur[(i as usize, j as usize)] -= T::of(scaled).wide();
        }
        let s = self.sep.len();
        let mut buf = MemBuffer::try_new(
            faer::linalg::cholesky::llt::factor::cholesky_in_place_scratch::<f64>(
                s,
                Par::Seq,
                Default::default(),
            ),
        )
        .map_err(|_| "out of memory for the separator's Cholesky workspace".to_string())?;
        faer::linalg::cholesky::llt::factor::cholesky_in_place(
            schur.as_mut(),
            Default::default(),
            Par::Seq,
            MemStack::new(&mut buf),
            Default::default(),
        )
        .map_err(|e| format!("Cholesky factorisation of the top separator failed ({e:?})"))?;
        Ok(SplitFactor {
            values: [v0, v1],
            lss: schur,
        })
    }

    /// Solves A x = b in place with the factor `f` of this plan (in its own precision; for a
    /// factor of the scaled matrix, b and x are scaled alike).
    pub fn solve_in_place<T: FactorScalar>(&self, f: &SplitFactor<T>, b: &mut [T]) {
        // forward substitution of the half's own columns: z's separator rows collect −L_S· y
        let forward = |h: &Half, values: &[T]| -> Vec<T> {
            let mut z: Vec<T> = h.eqs[..h.own].iter().map(|&e| b[e as usize]).collect();
            z.resize(h.eqs.len(), T::zero());
            let rows = h.rows();
            let mut tmp: Vec<T> = Vec::new();
            for nd in &h.nodes {
                if nd.start as usize >= h.own {
                    break;
                }
                let (ls, c) = nd.block(values, h.own);
                let (start, size) = (nd.start as usize, (nd.end - nd.start) as usize);
                solve_lower_triangular_in_place(
                    ls.get(..c, ..c),
                    MatMut::from_column_major_slice_mut(&mut z[start..start + c], c, 1),
                    Par::Seq,
                );
                let rest = ls.get(c.., ..c);
                tmp.clear();
                tmp.resize(rest.nrows(), T::zero());
                matmul(
                    MatMut::from_column_major_slice_mut(&mut tmp, rest.nrows(), 1),
                    Accum::Replace,
                    rest,
                    MatRef::from_column_major_slice(&z[start..start + c], c, 1),
                    T::one(),
                    Par::Seq,
                );
                let (inner, below) = tmp.split_at(size - c);
                for (zi, &t) in z[start + c..start + size].iter_mut().zip(inner) {
                    *zi -= t;
                }
                for (&i, &t) in rows[nd.p0 as usize..(nd.p0 + nd.plen) as usize]
                    .iter()
                    .zip(below)
                {
                    z[i as usize] -= t;
                }
            }
            z
        };
        let (mut z0, mut z1) = rayon::join(
            || forward(&self.halves[0], &f.values[0]),
            || forward(&self.halves[1], &f.values[1]),
        );
        // the separator: b_S − L_SA y_A − L_SB y_B, then L_SS L_SSᵀ x_S = that (in f64)
        let (o0, o1) = (self.halves[0].own, self.halves[1].own);
        let mut xs: Vec<f64> = self
            .sep
            .iter()
            .enumerate()
            .map(|(k, &e)| b[e as usize].wide() + z0[o0 + k].wide() + z1[o1 + k].wide())
            .collect();
        {
            let s = xs.len();
            let mut rhs = faer::MatMut::from_column_major_slice_mut(&mut xs, s, 1);
            solve_lower_triangular_in_place(f.lss.as_ref(), rhs.as_mut(), Par::Seq);
            solve_upper_triangular_in_place(f.lss.transpose(), rhs.as_mut(), Par::Seq);
        }
        for (z, o) in [(&mut z0, o0), (&mut z1, o1)] {
            for (zi, &x) in z[o..].iter_mut().zip(&xs) {
                *zi = T::of(x);
            }
        }
        // backward substitution of the half's own columns, the separator's x known
        let backward = |h: &Half, values: &[T], z: &mut [T]| {
            let rows = h.rows();
            let mut tmp: Vec<T> = Vec::new();
            for nd in h.nodes.iter().rev() {
                if nd.start as usize >= h.own {
                    continue;
                }
                let (ls, c) = nd.block(values, h.own);
                let (start, size) = (nd.start as usize, (nd.end - nd.start) as usize);
                let rest = ls.get(c.., ..c);
                tmp.clear();
                tmp.extend_from_slice(&z[start + c..start + size]);
                tmp.extend(
                    rows[nd.p0 as usize..(nd.p0 + nd.plen) as usize]
                        .iter()
                        .map(|&i| z[i as usize]),
                );
                let mut top = MatMut::from_column_major_slice_mut(&mut z[start..start + c], c, 1);
                matmul(
                    top.as_mut(),
                    Accum::Add,
                    rest.transpose(),
                    MatRef::from_column_major_slice(&tmp, rest.nrows(), 1),
                    -T::one(),
                    Par::Seq,
                );
                solve_upper_triangular_in_place(ls.get(..c, ..c).transpose(), top, Par::Seq);
            }
        };
        rayon::join(
            || backward(&self.halves[0], &f.values[0], &mut z0),
            || backward(&self.halves[1], &f.values[1], &mut z1),
        );
        for (h, z) in self.halves.iter().zip([&z0, &z1]) {
            for (&e, &v) in h.eqs[..h.own].iter().zip(z.iter()) {
                b[e as usize] = v;
            }
        }
        for (&e, &x) in self.sep.iter().zip(&xs) {
            b[e as usize] = T::of(x);
        }
    }
}
