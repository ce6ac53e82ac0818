//! Isoparametric solid shapes shared by the engines: shape functions and their reference
//! derivatives (Abaqus/VTK node order: C3D4, C3D10, C3D8, C3D20), Gauss rules, and the inverse
//! map x → ξ that locates a point in an element (Wellmann (6.28): a Newton solve of
//! x = Σ N_I(ξ) x_I, inclusion from ξ).

/// The interpolation of an isoparametric solid element.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum IsoShape {
    Tet4,
    Tet10,
    Hex8,
    Hex20,
}

impl IsoShape {
    pub fn num_nodes(self) -> usize {
        match self {
            IsoShape::Tet4 => 4,
            IsoShape::Tet10 => 10,
            IsoShape::Hex8 => 8,
            IsoShape::Hex20 => 20,
        }
    }

    /// Reference coordinates of the nodes (tetrahedra on the unit tetrahedron, hexahedra on
    /// [−1, 1]³).
    pub fn reference_nodes(self) -> &'static [[f64; 3]] {
        match self {
            IsoShape::Tet4 => &TET_NODES[..4],
            IsoShape::Tet10 => &TET_NODES,
            IsoShape::Hex8 => &HEX_NODES[..8],
            IsoShape::Hex20 => &HEX_NODES,
        }
    }

    /// The element's reference centre.
    pub fn centre(self) -> [f64; 3] {
        match self {
            IsoShape::Tet4 | IsoShape::Tet10 => [0.25; 3],
            IsoShape::Hex8 | IsoShape::Hex20 => [0.0; 3],
        }
    }

    /// Whether the reference point `xi` lies in the element, with tolerance `tol` in ξ.
    pub fn contains(self, xi: [f64; 3], tol: f64) -> bool {
        match self {
            IsoShape::Tet4 | IsoShape::Tet10 => {
                xi.iter().all(|&c| c >= -tol) && xi[0] + xi[1] + xi[2] <= 1.0 + tol
            }
            IsoShape::Hex8 | IsoShape::Hex20 => xi.iter().all(|&c| c.abs() <= 1.0 + tol),
        }
    }
}

pub static TET_NODES: [[f64; 3]; 10] = [
    [0.0, 0.0, 0.0],
    [1.0, 0.0, 0.0],
    [0.0, 1.0, 0.0],
    [0.0, 0.0, 1.0],
    [0.5, 0.0, 0.0],
    [0.5, 0.5, 0.0],
    [0.0, 0.5, 0.0],
    [0.0, 0.0, 0.5],
    [0.5, 0.0, 0.5],
    [0.0, 0.5, 0.5],
];
pub static HEX_NODES: [[f64; 3]; 20] = [
    [-1.0, -1.0, -1.0],
    [1.0, -1.0, -1.0],
    [1.0, 1.0, -1.0],
    [-1.0, 1.0, -1.0],
    [-1.0, -1.0, 1.0],
    [1.0, -1.0, 1.0],
    [1.0, 1.0, 1.0],
    [-1.0, 1.0, 1.0],
    [0.0, -1.0, -1.0],
    [1.0, 0.0, -1.0],
    [0.0, 1.0, -1.0],
    [-1.0, 0.0, -1.0],
    [0.0, -1.0, 1.0],
    [1.0, 0.0, 1.0],
    [0.0, 1.0, 1.0],
    [-1.0, 0.0, 1.0],
    [-1.0, -1.0, 0.0],
    [1.0, -1.0, 0.0],
    [1.0, 1.0, 0.0],
    [-1.0, 1.0, 0.0],
];

/// Shape functions N and their reference derivatives dN/dξ at `xi`.
pub fn shape(kind: IsoShape, xi: [f64; 3], n: &mut [f64], dn: &mut [[f64; 3]]) {
    let [r, s, t] = xi;
    match kind {
        IsoShape::Tet4 => {
            n[..4].copy_from_slice(&[1.0 - r - s - t, r, s, t]);
            dn[0] = [-1.0, -1.0, -1.0];
            dn[1] = [1.0, 0.0, 0.0];
            dn[2] = [0.0, 1.0, 0.0];
            dn[3] = [0.0, 0.0, 1.0];
        }
        IsoShape::Tet10 => {
            // Barycentric L_1..L_4 and their gradients in (r, s, t).
            let l = [1.0 - r - s - t, r, s, t];
            let dl = [
                [-1.0, -1.0, -1.0],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [0.0, 0.0, 1.0],
            ];
            for a in 0..4 {
                n[a] = l[a] * (2.0 * l[a] - 1.0);
                for k in 0..3 {
                    dn[a][k] = (4.0 * l[a] - 1.0) * dl[a][k];
                }
            }
            const EDGES: [(usize, usize); 6] = [(0, 1), (1, 2), (2, 0), (0, 3), (1, 3), (2, 3)];
            for (m, &(i, j)) in EDGES.iter().enumerate() {
                n[4 + m] = 4.0 * l[i] * l[j];
                for k in 0..3 {
                    dn[4 + m][k] = 4.0 * (dl[i][k] * l[j] + l[i] * dl[j][k]);
                }
            }
        }
        IsoShape::Hex8 => {
            for a in 0..8 {
                let [ra, sa, ta] = HEX_NODES[a];
                let (fr, fs, ft) = (1.0 + ra * r, 1.0 + sa * s, 1.0 + ta * t);
                n[a] = 0.125 * fr * fs * ft;
                dn[a] = [
                    0.125 * ra * fs * ft,
                    0.125 * sa * fr * ft,
                    0.125 * ta * fr * fs,
                ];
            }
        }
        IsoShape::Hex20 => {
            for a in 0..20 {
                let [ra, sa, ta] = HEX_NODES[a];
                if a < 8 {
                    let (fr, fs, ft) = (1.0 + ra * r, 1.0 + sa * s, 1.0 + ta * t);
                    let g = ra * r + sa * s + ta * t - 2.0;
                    n[a] = 0.125 * fr * fs * ft * g;
                    dn[a] = [
                        0.125 * ra * fs * ft * (g + fr),
                        0.125 * sa * fr * ft * (g + fs),
                        0.125 * ta * fr * fs * (g + ft),
                    ];
                } else if ra == 0.0 {
                    let (fs, ft) = (1.0 + sa * s, 1.0 + ta * t);
                    n[a] = 0.25 * (1.0 - r * r) * fs * ft;
                    dn[a] = [
                        -0.5 * r * fs * ft,
                        0.25 * (1.0 - r * r) * sa * ft,
                        0.25 * (1.0 - r * r) * fs * ta,
                    ];
                } else if sa == 0.0 {
                    let (fr, ft) = (1.0 + ra * r, 1.0 + ta * t);
                    n[a] = 0.25 * (1.0 - s * s) * fr * ft;
                    dn[a] = [
                        0.25 * (1.0 - s * s) * ra * ft,
                        -0.5 * s * fr * ft,
                        0.25 * (1.0 - s * s) * fr * ta,
                    ];
                } else {
                    let (fr, fs) = (1.0 + ra * r, 1.0 + sa * s);
                    n[a] = 0.25 * (1.0 - t * t) * fr * fs;
                    dn[a] = [
                        0.25 * (1.0 - t * t) * ra * fs,
                        0.25 * (1.0 - t * t) * fr * sa,
                        -0.5 * t * fr * fs,
                    ];
                }
            }
        }
    }
}

/// Gauss–Legendre points and weights on [−1, 1] (n = 1 … 4).
pub fn gauss_1d(n: usize) -> Vec<(f64, f64)> {
    match n {
        1 => vec![(0.0, 2.0)],
        2 => {
            let a = 1.0 / 3f64.sqrt();
            vec![(-a, 1.0), (a, 1.0)]
        }
        3 => {
            let a = (0.6f64).sqrt();
            vec![(-a, 5.0 / 9.0), (0.0, 8.0 / 9.0), (a, 5.0 / 9.0)]
        }
        4 => {
            let a = ((3.0 - 2.0 * (1.2f64).sqrt()) / 7.0).sqrt();
            let b = ((3.0 + 2.0 * (1.2f64).sqrt()) / 7.0).sqrt();
            let wa = (18.0 + 30f64.sqrt()) / 36.0;
            let wb = (18.0 - 30f64.sqrt()) / 36.0;
            vec![(-b, wb), (-a, wa), (a, wa), (b, wb)]
        }
        _ => unreachable!("gauss rule of order {n} not tabulated"),
    }
}

/// Tensor Gauss rule of n points per direction on the cube [−1, 1]³.
pub fn hex_rule(n: usize) -> Vec<([f64; 3], f64)> {
    let g = gauss_1d(n);
    let mut out = Vec::new();
    for &(z, wz) in &g {
        for &(y, wy) in &g {
            for &(x, wx) in &g {
                out.push(([x, y, z], wx * wy * wz));
            }
        }
    }
    out
}

/// Collapsed-cube (Duffy) Gauss rule on the unit tetrahedron, exact for degree 2n−3.
pub fn tet_collapsed_rule(n: usize) -> Vec<([f64; 3], f64)> {
    let g: Vec<(f64, f64)> = gauss_1d(n)
        .into_iter()
        .map(|(x, w)| (0.5 * (x + 1.0), 0.5 * w))
        .collect();
    let mut out = Vec::new();
    for &(u, wu) in &g {
        for &(v, wv) in &g {
            for &(w, ww) in &g {
                let x = u;
                let y = v * (1.0 - u);
                let z = w * (1.0 - u) * (1.0 - v);
                out.push(([x, y, z], wu * wv * ww * (1.0 - u) * (1.0 - u) * (1.0 - v)));
            }
        }
    }
    out
}

/// One-point rule on the unit tetrahedron.
pub fn tet_rule_1() -> Vec<([f64; 3], f64)> {
    vec![([0.25, 0.25, 0.25], 1.0 / 6.0)]
}

/// Four-point rule on the unit tetrahedron (degree 2).
pub fn tet_rule_4() -> Vec<([f64; 3], f64)> {
    let a = 0.585_410_196_624_968_5;
    let b = 0.138_196_601_125_010_5;
    vec![
        ([b, b, b], 1.0 / 24.0),
        ([a, b, b], 1.0 / 24.0),
        ([b, a, b], 1.0 / 24.0),
        ([b, b, a], 1.0 / 24.0),
    ]
}

/// A point located in an element by [`locate`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Located {
    /// Reference coordinates.
    pub xi: [f64; 3],
    /// Whether ξ lies in the element (within the tolerance given to [`locate`]).
    pub inside: bool,
}

/// The reference coordinates ξ of the point `p` in the element with nodes `x` (in the shape's
/// node order): Newton's method on x(ξ) = Σ N_I(ξ) x_I = p (Wellmann (6.28)) from the element
/// centre. `None` when the iteration does not converge in 30 steps or meets a singular
/// Jacobian (a point far outside a distorted element); otherwise ξ and whether it lies in the
/// element within `tol` (in ξ units).
pub fn locate(kind: IsoShape, x: &[[f64; 3]], p: [f64; 3], tol: f64) -> Option<Located> {
    let nn = kind.num_nodes();
    assert_eq!(x.len(), nn, "locate: {} nodes for a {kind:?}", x.len());
    let mut n = [0.0; 20];
    let mut dn = [[0.0; 3]; 20];
    let mut xi = kind.centre();
    // the element's size, for a scale-free convergence test
    let mut size2 = 0.0f64;
    for a in 1..nn {
        let d = [x[a][0] - x[0][0], x[a][1] - x[0][1], x[a][2] - x[0][2]];
        size2 = size2.max(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    }
    for _ in 0..30 {
        shape(kind, xi, &mut n[..nn], &mut dn[..nn]);
        let mut r = [-p[0], -p[1], -p[2]];
        let mut j = [[0.0; 3]; 3];
        for a in 0..nn {
            for i in 0..3 {
                r[i] += n[a] * x[a][i];
                for k in 0..3 {
                    j[i][k] += x[a][i] * dn[a][k];
                }
            }
        }
        let jm = nalgebra::Matrix3::from_fn(|i, k| j[i][k]);
        let d = jm.lu().solve(&nalgebra::Vector3::from(r))?;
        if !d.iter().all(|c| c.is_finite()) {
            return None;
        }
        for (c, dc) in xi.iter_mut().zip(d.iter()) {
            *c -= dc;
        }
        let r2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2];
        if d.norm() < 1e-13 || r2 <= 1e-28 * size2 {
            return Some(Located {
                xi,
                inside: kind.contains(xi, tol),
            });
        }
    }
    None
}

/// Shape function values at `xi` into `n` (its length is the shape's node count).
pub fn values(kind: IsoShape, xi: [f64; 3], n: &mut [f64]) {
    let mut dn = [[0.0; 3]; 20];
    shape(kind, xi, n, &mut dn[..n.len()]);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A distorted hexahedron and a tetrahedron: ξ found by `locate` maps back to the point,
    /// points outside are reported outside.
    #[test]
    fn locate_inverts_the_map() {
        let hex = [
            [0.0, 0.0, 0.0],
            [1.2, 0.1, 0.0],
            [1.1, 1.0, 0.1],
            [-0.1, 0.9, 0.0],
            [0.1, 0.0, 1.0],
            [1.0, -0.1, 1.1],
            [1.2, 1.1, 0.9],
            [0.0, 1.0, 1.2],
        ];
        let tet10: Vec<[f64; 3]> = {
            let c = [
                [0.0, 0.0, 0.0],
                [2.0, 0.0, 0.0],
                [0.0, 1.5, 0.0],
                [0.2, 0.1, 1.0],
            ];
            let mid = |a: usize, b: usize| {
                [
                    0.5 * (c[a][0] + c[b][0]),
                    0.5 * (c[a][1] + c[b][1]) + 0.02,
                    0.5 * (c[a][2] + c[b][2]),
                ]
            };
            let mut v = c.to_vec();
            for (a, b) in [(0, 1), (1, 2), (2, 0), (0, 3), (1, 3), (2, 3)] {
                v.push(mid(a, b));
            }
            v
        };
        for (kind, x) in [(IsoShape::Hex8, &hex[..]), (IsoShape::Tet10, &tet10[..])] {
            let nn = kind.num_nodes();
            for xi in [
                [0.3, -0.7, 0.2],
                [0.1, 0.2, 0.3],
                [0.9, 0.05, 0.02],
                [1.3, 0.1, 0.1],
            ] {
                let mut n = vec![0.0; nn];
                values(kind, xi, &mut n);
                let mut p = [0.0; 3];
                for a in 0..nn {
                    for i in 0..3 {
                        p[i] += n[a] * x[a][i];
                    }
                }
                let l = locate(kind, x, p, 1e-9).expect("converges");
                for k in 0..3 {
                    assert!(
                        (l.xi[k] - xi[k]).abs() < 1e-10,
                        "{kind:?} {xi:?} -> {:?}",
                        l.xi
                    );
                }
                assert_eq!(l.inside, kind.contains(xi, 0.0), "{kind:?} {xi:?}");
            }
        }
    }

    /// Partition of unity and linear completeness at random points.
    #[test]
    fn shape_functions_reproduce_linear_fields() {
        for kind in [
            IsoShape::Tet4,
            IsoShape::Tet10,
            IsoShape::Hex8,
            IsoShape::Hex20,
        ] {
            let nn = kind.num_nodes();
            let mut n = vec![0.0; nn];
            for xi in [[0.1, 0.2, 0.3], [0.25, 0.05, 0.6]] {
                values(kind, xi, &mut n);
                let sum: f64 = n.iter().sum();
                assert!((sum - 1.0).abs() < 1e-14);
                for (k, xk) in xi.iter().enumerate() {
                    let v: f64 = (0..nn).map(|a| n[a] * kind.reference_nodes()[a][k]).sum();
                    assert!((v - xk).abs() < 1e-14, "{kind:?}");
                }
            }
        }
    }
}
