//! Wellmann's validation protocol for superquadric contact detection (W p. 40–41,
//! Table 3.1), shared by the unit test (1e5 pairs per class) and the benchmark (1e6).
//!
//! Body 1 sits at the origin with the global axes; a random direction c gives p1 = X1(c);
//! body 2 gets a random rotation T2, and its centre is placed so that its surface point with
//! normal −c is p2 = p1 − δc (a penetration δ, test 2) or p1 + gap·c (test 1, no contact).
//! The search starts from the centre line. Radii are uniform in (0.5, 3.0); the angularity
//! classes draw ε uniform in [1, 1], [0.7, 1.3], [0.3, 1.7].

use crate::generate::SplitMix64;
use crate::hertz_mindlin::V3;
use crate::narrow::superquadric::{detect, Detection, SearchSettings, SearchStats, SqBody};
use crate::shape::Superquadric;
use nalgebra::Matrix3;

/// ε range of Wellmann's angularity classes 1, 2, 3.
pub fn class_range(class: u32) -> (f64, f64) {
    match class {
        1 => (1.0, 1.0),
        2 => (0.7, 1.3),
        _ => (0.3, 1.7),
    }
}

/// Statistics of one protocol run.
#[derive(Debug, Clone, Default)]
pub struct ProtocolStats {
    pub pairs: u64,
    /// Test 2: mean relative error of δ, mean |p̃_i − p_i| (over both points), mean angle
    /// between the found and the constructed normal (degrees); worst relative error of δ.
    pub mean_overlap_error: f64,
    pub max_overlap_error: f64,
    pub mean_point_error: f64,
    pub mean_angle_deg: f64,
    /// Test 2: pairs needing ≥ 20 iterations, pairs with a restart, most restarts, pairs
    /// reported separated or failed (all wrong answers), mean iterations.
    pub at_least_20_iterations: u64,
    pub restarted: u64,
    /// Test 2: starts ending in a rejected local minimum, starts not converged in 50.
    pub local_minima: u64,
    pub not_converged: u64,
    pub max_restarts: u32,
    pub wrong: u64,
    pub mean_iterations: f64,
    /// Test 1: pairs excluded at the initial guess (0 iterations), needing ≥ 5 iterations,
    /// restarted, reported in contact (wrong).
    pub excluded_at_start: u64,
    pub separation_at_least_5: u64,
    pub separation_restarted: u64,
    pub separation_wrong: u64,
}

fn random_shape(rng: &mut SplitMix64, (lo, hi): (f64, f64)) -> Superquadric {
    let mut r = || 0.5 + 2.5 * rng.uniform();
    let radii = V3::new(r(), r(), r());
    let e1 = lo + (hi - lo) * rng.uniform();
    let e2 = lo + (hi - lo) * rng.uniform();
    Superquadric::new(radii, e1, e2).expect("class exponents are in range")
}

/// Runs both tests of the protocol with `pairs` pairs each for angularity `class`.
pub fn run(class: u32, pairs: u64, seed: u64, settings: &SearchSettings) -> ProtocolStats {
    let range = class_range(class);
    let mut rng = SplitMix64::new(seed ^ (class as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
    let mut st = ProtocolStats {
        pairs,
        ..Default::default()
    };
    let mut iterations = 0u64;
    for test in [1, 2] {
        for _ in 0..pairs {
            let s1 = random_shape(&mut rng, range);
            let s2 = random_shape(&mut rng, range);
            let c = crate::generate::random_unit_vector(&mut rng);
            let p1 = s1.point(&c);
            let t2 = crate::generate::random_orientation(&mut rng)
                .to_rotation_matrix()
                .into_inner();
            let (p2, delta) = if test == 1 {
                (p1 + c * (0.25 * rng.uniform()), 0.0)
            } else {
                let delta = 1.75e-3 * rng.uniform();
                (p1 - c * delta, delta)
            };
            let x2 = p2 - t2 * s2.point(&(-t2.tr_mul(&c)));
            let b1 = SqBody {
                shape: &s1,
                position: V3::zeros(),
                rotation: Matrix3::identity(),
            };
            let b2 = SqBody {
                shape: &s2,
                position: x2,
                rotation: t2,
            };
            let mut stats = SearchStats::default();
            let found = detect(&b1, &b2, None, settings, &mut stats);
            if test == 1 {
                match found {
                    Detection::Separated { .. } => {}
                    Detection::Contact(_) => st.separation_wrong += 1,
                }
                st.excluded_at_start += (stats.iterations == 0 && stats.restarts == 0) as u64;
                st.separation_at_least_5 += (stats.iterations >= 5) as u64;
                st.separation_restarted += (stats.restarts > 0) as u64;
                continue;
            }
            iterations += stats.iterations as u64;
            st.at_least_20_iterations += (stats.iterations >= 20) as u64;
            st.restarted += (stats.restarts > 0) as u64;
            st.local_minima += stats.local_minima as u64;
            st.not_converged += stats.not_converged as u64;
            st.max_restarts = st.max_restarts.max(stats.restarts);
            match found {
                Detection::Contact(k) if !stats.failed => {
                    let rel = (k.overlap - delta).abs() / delta;
                    st.mean_overlap_error += rel;
                    st.max_overlap_error = st.max_overlap_error.max(rel);
                    st.mean_point_error += 0.5 * ((k.p1 - p1).norm() + (k.p2 - p2).norm());
                    st.mean_angle_deg += k.normal.dot(&c).clamp(-1.0, 1.0).acos().to_degrees();
                }
                _ => st.wrong += 1,
            }
        }
    }
    let ok = (pairs - st.wrong).max(1) as f64;
    st.mean_overlap_error /= ok;
    st.mean_point_error /= ok;
    st.mean_angle_deg /= ok;
    st.mean_iterations = iterations as f64 / pairs.max(1) as f64;
    st
}

#[cfg(test)]
mod tests {
    use super::*;

    /// W Table 3.1 (1e6 pairs per class there, 1e5 here; the benchmark runs 1e6): the mean
    /// errors must be at or below the table's (rel. δ 2.34e-6 / 2.40e-6 / 32.1e-6, points
    /// 4.34e-8 / 4.40e-8 / 37.2e-8, angle 4.21e-3° / 5.05e-3° / 18.2e-3°), no pair may be
    /// answered wrongly, and the iteration statistics must be no worse than the text's:
    /// separated pairs needing ≥ 5 iterations 1.1 / 1.1 / 3.7 %, touching pairs needing ≥ 20
    /// iterations 0.4 / 0.4 / 4.5 %, starts ending in a local minimum or without convergence
    /// 193 / 198 / 9219 per 1e6, at most 2 / 2 / 15 restarts.
    ///
    /// Not compared: the share of separated pairs excluded at the initial guess (W: 88.1 /
    /// 85.2 / 78.2 %). It is a property of the construction, not of the algorithm (the centre
    /// line is a separating axis or not before any iteration), and the construction as
    /// described gives ≈ 50 % for every class here; W's must have differed in a detail the
    /// text does not give (see the issue note).
    #[test]
    fn contact_detection_random_pairs_table_3_1() {
        let pairs = 100_000u64;
        // (δ error, point error, angle °, ≥5 it. separated, ≥20 it. touching, bad starts per
        // pair, restarts)
        let table = [
            (2.34e-6, 4.34e-8, 4.21e-3, 0.011, 0.004, 193e-6, 2),
            (2.40e-6, 4.40e-8, 5.05e-3, 0.011, 0.004, 198e-6, 2),
            (32.1e-6, 37.2e-8, 18.2e-3, 0.037, 0.045, 9219e-6, 15),
        ];
        for class in 1..=3u32 {
            let st = run(class, pairs, 2011, &SearchSettings::default());
            let (de, pe, ae, sep5, touch20, bad, restarts) = table[class as usize - 1];
            eprintln!("class {class}: {st:#?}");
            let share = |k: u64| k as f64 / pairs as f64;
            assert_eq!(
                st.wrong, 0,
                "class {class}: contacts missed or not converged"
            );
            assert_eq!(
                st.separation_wrong, 0,
                "class {class}: separated pairs in contact"
            );
            assert!(
                st.mean_overlap_error <= de,
                "class {class}: δ error {}",
                st.mean_overlap_error
            );
            assert!(
                st.mean_point_error <= pe,
                "class {class}: point error {}",
                st.mean_point_error
            );
            assert!(
                st.mean_angle_deg <= ae,
                "class {class}: angle {}",
                st.mean_angle_deg
            );
            assert!(
                share(st.separation_at_least_5) <= sep5,
                "class {class}: {st:?}"
            );
            assert!(
                share(st.at_least_20_iterations) <= touch20,
                "class {class}: {st:?}"
            );
            assert!(
                share(st.local_minima + st.not_converged) <= bad,
                "class {class}: {st:?}"
            );
            assert!(st.max_restarts <= restarts, "class {class}: {st:?}");
        }
    }
}
