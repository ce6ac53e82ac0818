//! Small numerical kernels shared by the engines: the largest eigenvalue of a symmetric
//! operator by Lanczos (the FEM's explicit critical step and highest frequency, the 2-D disc
//! engine's critical step and DDEM iteration matrix); isoparametric solid shapes and the
//! location of a point in an element ([`iso`]).

pub mod iso;

/// The dot product.
pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// A deterministic pseudo-random vector in [−½, ½)ⁿ (xorshift64 from `seed`): Lanczos start
/// vectors, so that a run's limits are the same every time.
pub fn start_vector(n: usize, mut seed: u64) -> Vec<f64> {
    (0..n)
        .map(|_| {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        })
        .collect()
}

/// Largest eigenvalue θ of an operator A that is self-adjoint in the M inner product
/// (K⁻¹M or M⁻¹K), by Lanczos with the M-norm; `apply` computes y = A x given x. With
/// `apply_to_mass`, `apply` receives M x instead of x (A = K⁻¹M reuses the product).
pub fn lanczos_largest(
    n: usize,
    mut apply: impl FnMut(&[f64], &mut [f64]),
    mass_mul: impl Fn(&[f64], &mut [f64]),
    apply_to_mass: bool,
    max_it: usize,
    tol: f64,
) -> f64 {
    let mut q = start_vector(n, 0x2545_F491_4F6C_DD1D);
    let mut mq = vec![0.0; n];
    mass_mul(&q, &mut mq);
    let nq = dot(&q, &mq).sqrt();
    q.iter_mut().for_each(|x| *x /= nq);
    mq.iter_mut().for_each(|x| *x /= nq);
    let mut q_prev = vec![0.0; n];
    let (mut w, mut mw) = (vec![0.0; n], vec![0.0; n]);
    let (mut alphas, mut betas) = (Vec::new(), Vec::new());
    let mut beta = 0.0;
    let mut last = f64::NAN;
    for it in 0..max_it.min(n) {
        apply(if apply_to_mass { &mq } else { &q }, &mut w);
        for i in 0..n {
            w[i] -= beta * q_prev[i];
        }
        // ⟨q, w⟩_M = (M q)·w
        let alpha = dot(&mq, &w);
        for i in 0..n {
            w[i] -= alpha * q[i];
        }
        alphas.push(alpha);
        mass_mul(&w, &mut mw);
        let b = dot(&w, &mw).max(0.0).sqrt();
        let done = b <= 1e-13 * alpha.abs();
        if (it + 1) % 2 == 0 || done || it + 1 == max_it.min(n) {
            let top = tridiagonal_max_eigenvalue(&alphas, &betas);
            if done || (top - last).abs() <= tol * top.abs() {
                return top;
            }
            last = top;
        }
        betas.push(b);
        std::mem::swap(&mut q_prev, &mut q);
        for i in 0..n {
            q[i] = w[i] / b;
            mq[i] = mw[i] / b;
        }
        beta = b;
    }
    tridiagonal_max_eigenvalue(&alphas, &betas)
}

/// Largest eigenvalue of the symmetric tridiagonal matrix with diagonal `alphas` and
/// off-diagonal `betas`, by bisection on Sturm sequence counts (O(k) per count, ~100 counts:
/// cheap enough to test a Lanczos run for convergence at every step).
pub fn tridiagonal_max_eigenvalue(alphas: &[f64], betas: &[f64]) -> f64 {
    let k = alphas.len();
    if k == 0 {
        return f64::NAN;
    }
    let b = |i: usize| if i < k - 1 { betas[i].abs() } else { 0.0 };
    // Gershgorin bounds
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for (i, a) in alphas.iter().enumerate() {
        let r = b(i) + if i > 0 { b(i - 1) } else { 0.0 };
        lo = lo.min(a - r);
        hi = hi.max(a + r);
    }
    let scale = lo.abs().max(hi.abs()).max(f64::MIN_POSITIVE);
    // the number of eigenvalues below x (Sturm: negative pivots of T − x I)
    let below = |x: f64| {
        let mut count = 0;
        let mut d = 1.0;
        for (i, a) in alphas.iter().enumerate() {
            let off = if i > 0 { b(i - 1) * b(i - 1) } else { 0.0 };
            d = a - x - if i > 0 { off / d } else { 0.0 };
            if d == 0.0 {
                d = -f64::EPSILON * scale;
            }
            if d < 0.0 {
                count += 1;
            }
        }
        count
    };
    // the largest eigenvalue: the smallest x with all k below
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi || hi - lo <= 2.0 * f64::EPSILON * scale {
            break;
        }
        if below(mid) == k {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    0.5 * (lo + hi)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_largest_eigenvalue_of_a_spring_chain_is_found() {
        // fixed-fixed chain of n unit masses and springs: λ_k = 4 sin²(kπ / (2(n + 1)))
        let n = 200;
        let apply = |x: &[f64], y: &mut [f64]| {
            for i in 0..n {
                let l = if i > 0 { x[i - 1] } else { 0.0 };
                let r = if i + 1 < n { x[i + 1] } else { 0.0 };
                y[i] = 2.0 * x[i] - l - r;
            }
        };
        let top = lanczos_largest(n, apply, |x, y| y.copy_from_slice(x), false, 300, 1e-12);
        let exact = 4.0
            * (n as f64 * std::f64::consts::PI / (2.0 * (n as f64 + 1.0)))
                .sin()
                .powi(2);
        assert!((top - exact).abs() < 1e-9 * exact, "{top} vs {exact}");
        // a diagonal mass: the generalised problem K x = λ M x with M = 2: half of it
        let top = lanczos_largest(
            n,
            |x, y| {
                apply(x, y);
                y.iter_mut().for_each(|v| *v /= 2.0)
            },
            |x, y| y.iter_mut().zip(x).for_each(|(v, u)| *v = 2.0 * u),
            false,
            300,
            1e-12,
        );
        assert!((top - exact / 2.0).abs() < 1e-9 * exact, "{top}");
    }
}

#[cfg(test)]
mod tridiagonal {
    use super::*;

    #[test]
    fn bisection_finds_the_largest_eigenvalue_of_tridiagonal_matrices() {
        // the spring chain: 2 on the diagonal, −1 off it
        let n = 50;
        let top = tridiagonal_max_eigenvalue(&vec![2.0; n], &vec![-1.0; n - 1]);
        let exact = 4.0
            * (n as f64 * std::f64::consts::PI / (2.0 * (n as f64 + 1.0)))
                .sin()
                .powi(2);
        assert!((top - exact).abs() < 1e-13 * exact, "{top} vs {exact}");
        // against a dense solver on an irregular one, with a zero off-diagonal entry
        let a = [3.0, -1.0, 0.5, 7.0, 2.0, 2.0];
        let b = [0.3, 1.7, 0.0, -2.5, 0.1];
        let t = nalgebra::DMatrix::from_fn(6, 6, |i, j| {
            if i == j {
                a[i]
            } else if i + 1 == j || j + 1 == i {
                b[i.min(j)]
            } else {
                0.0
            }
        });
        let dense = t
            .symmetric_eigenvalues()
            .iter()
            .copied()
            .fold(f64::NEG_INFINITY, f64::max);
        let top = tridiagonal_max_eigenvalue(&a, &b);
        assert!(
            (top - dense).abs() < 1e-13 * dense.abs(),
            "{top} vs {dense}"
        );
        assert_eq!(tridiagonal_max_eigenvalue(&[-4.0], &[]), -4.0);
    }
}
