//! Bagi's macroscopic strain of a disc assembly (Madan (4.4)–(4.6)): a Delaunay triangulation
//! of the initial centres (spade), in each triangle the constant strain of the linear
//! interpolation of the centres' displacements — the line integral (4.5) with u linear along
//! each edge — and their area-weighted mean (4.6).
//!
//! The weighted sum is formed without dividing by the triangles' areas: S_k ε^k = ½ Σ_a (u_a ⊗
//! a_a + a_a ⊗ u_a) with a_a = S_k ∇N_a = ½ ẑ × (the edge opposite a), so the thin triangles a
//! box's hull leaves along its sides add their (small) share without round-off trouble.

use spade::{DelaunayTriangulation, HasPosition, Point2, Triangulation};

type V2 = [f64; 2];

/// A centre and its disc's index.
struct Site {
    p: Point2<f64>,
    id: u32,
}

impl HasPosition for Site {
    type Scalar = f64;
    fn position(&self) -> Point2<f64> {
        self.p
    }
}

/// The triangles of the initial centres with S_k ∇N of each corner.
#[derive(Debug, Clone)]
pub struct BagiMesh {
    /// Corner discs of each triangle.
    pub triangles: Vec<[u32; 3]>,
    /// S_k ∇N_a of each corner.
    arms: Vec<[V2; 3]>,
    /// Σ S_k (m²).
    pub area: f64,
}

impl BagiMesh {
    /// The triangulation of `x` (None: fewer than three centres, or all on one line).
    pub fn new(x: &[V2]) -> Option<Self> {
        let sites: Vec<Site> = x
            .iter()
            .enumerate()
            .map(|(i, p)| Site {
                p: Point2::new(p[0], p[1]),
                id: i as u32,
            })
            .collect();
        let t = DelaunayTriangulation::<Site>::bulk_load(sites).ok()?;
        let mut triangles = Vec::with_capacity(t.num_inner_faces());
        let mut arms = Vec::with_capacity(t.num_inner_faces());
        let mut area = 0.0;
        for f in t.inner_faces() {
            let v = f.vertices();
            let ids = v.map(|h| h.data().id);
            let p = ids.map(|i| x[i as usize]);
            // twice the signed area (counter-clockwise corners: positive)
            let twice = (p[1][0] - p[0][0]) * (p[2][1] - p[0][1])
                - (p[2][0] - p[0][0]) * (p[1][1] - p[0][1]);
            let s = 0.5 * twice;
            if s == 0.0 {
                continue;
            }
            // S ∇N_a = ½ (y_b − y_c, x_c − x_b) for the corners a, b, c in order; with the
            // sign of the orientation so that Σ S ∇N_a ⊗ x_a = S I
            let sign = s.signum();
            let arm = |a: usize| {
                let (b, c) = ((a + 1) % 3, (a + 2) % 3);
                [
                    0.5 * sign * (p[b][1] - p[c][1]),
                    0.5 * sign * (p[c][0] - p[b][0]),
                ]
            };
            triangles.push(ids);
            arms.push([arm(0), arm(1), arm(2)]);
            area += s.abs();
        }
        if triangles.is_empty() {
            return None;
        }
        Some(BagiMesh {
            triangles,
            arms,
            area,
        })
    }

    /// Keeps the triangles whose three corners `keep` accepts (an interior average that leaves
    /// a free boundary's loose discs out); false if none is left.
    pub fn retain(&mut self, keep: impl Fn(u32) -> bool) -> bool {
        let mut k = 0;
        for j in 0..self.triangles.len() {
            if self.triangles[j].iter().all(|&p| keep(p)) {
                self.triangles[k] = self.triangles[j];
                self.arms[k] = self.arms[j];
                k += 1;
            }
        }
        self.triangles.truncate(k);
        self.arms.truncate(k);
        self.area = (0..k).map(|j| self.area_of(j)).sum();
        k > 0
    }

    /// S_k ε^k of triangle k for the displacements `u` of the discs: (ε_xx, ε_yy, ε_xy) times
    /// the area.
    fn weighted(&self, k: usize, u: &[V2]) -> [f64; 3] {
        let mut g = [[0.0; 2]; 2];
        for (c, &p) in self.triangles[k].iter().enumerate() {
            let a = self.arms[k][c];
            let up = u[p as usize];
            for i in 0..2 {
                for j in 0..2 {
                    g[i][j] += up[i] * a[j];
                }
            }
        }
        [g[0][0], g[1][1], 0.5 * (g[0][1] + g[1][0])]
    }

    /// The strain ε^k of each triangle (4.4)–(4.5).
    pub fn triangle_strains(&self, u: &[V2]) -> Vec<[f64; 3]> {
        (0..self.triangles.len())
            .map(|k| {
                let s = self.area_of(k);
                self.weighted(k, u).map(|c| c / s)
            })
            .collect()
    }

    /// S_k.
    pub fn area_of(&self, k: usize) -> f64 {
        // S ∇N_0 · (x_1 − x_0) ... equals S; recover it from the arms: S = 2 |a_1 × a_2|
        let [_, a1, a2] = self.arms[k];
        2.0 * (a1[0] * a2[1] - a1[1] * a2[0]).abs()
    }

    /// The sample's strain ε̄ = Σ S_k ε^k / S (4.6): (ε_xx, ε_yy, ε_xy), tensor shear.
    pub fn strain(&self, u: &[V2]) -> [f64; 3] {
        let mut sum = [0.0; 3];
        for k in 0..self.triangles.len() {
            for (s, w) in sum.iter_mut().zip(self.weighted(k, u)) {
                *s += w;
            }
        }
        sum.map(|c| c / self.area)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scatter(n: usize) -> Vec<V2> {
        // a deterministic irregular cloud
        let mut s = 12345u64;
        let mut r = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        (0..n).map(|_| [r() * 0.05, r() * 0.03]).collect()
    }

    #[test]
    fn an_affine_displacement_gives_its_strain_in_every_triangle_and_on_average() {
        let x = scatter(500);
        let m = BagiMesh::new(&x).unwrap();
        // u = H x + c with a non-symmetric H: the strain is sym(H), the spin is not strain
        let h = [[2e-3, 7e-4], [-3e-4, -1.5e-3]];
        let u: Vec<V2> = x
            .iter()
            .map(|p| {
                [
                    h[0][0] * p[0] + h[0][1] * p[1] + 1e-3,
                    h[1][0] * p[0] + h[1][1] * p[1] - 2e-3,
                ]
            })
            .collect();
        let want = [h[0][0], h[1][1], 0.5 * (h[0][1] + h[1][0])];
        let e = m.strain(&u);
        for k in 0..3 {
            assert!((e[k] - want[k]).abs() < 1e-12, "{e:?} vs {want:?}");
        }
        for t in m.triangle_strains(&u) {
            for k in 0..3 {
                assert!((t[k] - want[k]).abs() < 1e-9, "{t:?} vs {want:?}");
            }
        }
        // the triangles tile the convex hull: the area lies below the bounding box's and
        // every centre is a corner of some triangle
        assert!(
            m.area < 0.05 * 0.03 && m.area > 0.9 * 0.05 * 0.03,
            "{}",
            m.area
        );
        let mut seen = vec![false; x.len()];
        for t in &m.triangles {
            for &p in t {
                seen[p as usize] = true;
            }
        }
        assert!(seen.iter().all(|&s| s));
    }

    #[test]
    fn the_mean_strain_is_the_hull_boundary_integral_of_a_nonlinear_field() {
        // (4.6) of the piecewise-linear field equals (1/2S) ∮ (u n + n u) dL over the hull:
        // a rectangle's corners plus interior points, u nonlinear inside
        let mut x = vec![[0.0, 0.0], [0.04, 0.0], [0.04, 0.02], [0.0, 0.02]];
        x.extend(
            scatter(200)
                .iter()
                .map(|p| [0.001 + 0.7 * p[0], 0.001 + 0.6 * p[1]]),
        );
        let m = BagiMesh::new(&x).unwrap();
        let u: Vec<V2> = x
            .iter()
            .enumerate()
            .map(|(i, p)| {
                if i < 4 {
                    // the corners: an affine field
                    [1e-3 * p[0], -2e-3 * p[1] + 5e-4 * p[0]]
                } else {
                    [(p[0] * 300.0).sin() * 1e-4, (p[1] * 500.0).cos() * 1e-4]
                }
            })
            .collect();
        let e = m.strain(&u);
        // the hull is the rectangle whose edges interpolate the affine corner field
        assert!((m.area - 0.04 * 0.02).abs() < 1e-15);
        let want = [1e-3, -2e-3, 0.5 * 5e-4];
        for k in 0..3 {
            assert!((e[k] - want[k]).abs() < 1e-12, "{e:?} vs {want:?}");
        }
    }

    #[test]
    fn an_interior_average_keeps_the_triangles_of_the_kept_corners() {
        let x = scatter(300);
        let mut m = BagiMesh::new(&x).unwrap();
        let all = m.area;
        let inside = |p: u32| {
            let q = x[p as usize];
            q[0] > 0.01 && q[0] < 0.04 && q[1] > 0.01 && q[1] < 0.02
        };
        assert!(m.retain(inside));
        assert!(
            m.area < 0.5 * all && m.area > 0.1 * all,
            "{} of {all}",
            m.area
        );
        assert!(m.triangles.iter().flatten().all(|&p| inside(p)));
        // still exact for an affine field
        let u: Vec<V2> = x.iter().map(|p| [3e-4 * p[1], -1e-3 * p[1]]).collect();
        let e = m.strain(&u);
        assert!(
            (e[0]).abs() < 1e-15 && (e[1] + 1e-3).abs() < 1e-15 && (e[2] - 1.5e-4).abs() < 1e-15
        );
        assert!(!m.retain(|_| false));
    }

    #[test]
    fn collinear_centres_have_no_triangulation() {
        let x: Vec<V2> = (0..10).map(|i| [i as f64 * 1e-3, 0.0]).collect();
        assert!(BagiMesh::new(&x).is_none());
        assert!(BagiMesh::new(&x[..2]).is_none());
    }
}
