//! Small numerical kernels shared by the engines: the largest eigenvalue of a symmetric
//! operator by Lanczos (the FEM's explicit critical step and highest frequency, the 2-D disc
//! engine's critical step and DDEM iteration matrix).

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
        if (it + 1) % 5 == 0 || done || it + 1 == max_it.min(n) {
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
/// off-diagonal `betas`.
pub fn tridiagonal_max_eigenvalue(alphas: &[f64], betas: &[f64]) -> f64 {
    let k = alphas.len();
    let t = nalgebra::DMatrix::from_fn(k, k, |i, j| {
        if i == j {
            alphas[i]
        } else if i + 1 == j || j + 1 == i {
            betas[i.min(j)]
        } else {
            0.0
        }
    });
    t.symmetric_eigenvalues()
        .iter()
        .copied()
        .fold(f64::NEG_INFINITY, f64::max)
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
