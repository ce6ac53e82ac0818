//! Particle generation: explicit lists, simple-cubic lattices and random non-overlapping fills
//! of a box with a size distribution (deterministic, seeded). Settling is running the engine.

use crate::config::SizeDistribution;
use crate::hertz_mindlin::V3;
use std::collections::HashMap;

/// SplitMix64 (Steele, Lea, Flood 2014): tiny, fast, good enough for particle placement.
#[derive(Debug, Clone)]
pub struct SplitMix64(u64);

impl SplitMix64 {
    pub fn new(seed: u64) -> Self {
        SplitMix64(seed)
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }
    /// Standard normal (Box–Muller).
    pub fn normal(&mut self) -> f64 {
        let u1 = 1.0 - self.uniform(); // (0, 1]
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }
}

/// Draws one radius from the distribution.
pub fn sample_radius(d: &SizeDistribution, rng: &mut SplitMix64) -> f64 {
    match d {
        SizeDistribution::Constant { radius } => *radius,
        SizeDistribution::Uniform { min, max } => min + (max - min) * rng.uniform(),
        SizeDistribution::Normal {
            mean,
            std_dev,
            min,
            max,
        } => {
            if *std_dev == 0.0 {
                return mean.clamp(*min, *max);
            }
            for _ in 0..10_000 {
                let r = mean + std_dev * rng.normal();
                if r >= *min && r <= *max {
                    return r;
                }
            }
            // truncation window far in a tail: fall back to uniform in the window
            min + (max - min) * rng.uniform()
        }
        SizeDistribution::Table { radius, cumulative } => {
            let u = rng.uniform();
            let k = cumulative
                .partition_point(|&c| c <= u)
                .clamp(1, radius.len() - 1);
            let (c0, c1) = (cumulative[k - 1], cumulative[k]);
            let s = if c1 > c0 { (u - c0) / (c1 - c0) } else { 0.0 };
            radius[k - 1] + s * (radius[k] - radius[k - 1])
        }
    }
}

/// Simple-cubic lattice centres `first + (i, j, k)·spacing`.
pub fn lattice(first: V3, spacing: f64, count: [usize; 3]) -> Vec<V3> {
    let mut out = Vec::with_capacity(count[0] * count[1] * count[2]);
    for k in 0..count[2] {
        for j in 0..count[1] {
            for i in 0..count[0] {
                out.push(first + V3::new(i as f64, j as f64, k as f64) * spacing);
            }
        }
    }
    out
}

/// Random sequential addition of non-overlapping spheres inside [min, max] (whole spheres),
/// largest first, avoiding `existing` spheres too. Returns (centre, radius) or a message.
///
/// With a `period` (the edges of a periodic cell [0, L], W §5.1.1) the centres lie anywhere
/// in the cell and spheres must not overlap any image of another.
#[allow(clippy::too_many_arguments)]
pub fn fill_box(
    min: V3,
    max: V3,
    cylinder: Option<f64>,
    radii: &mut [f64],
    seed: u64,
    existing: &[(V3, f64)],
    period: Option<V3>,
) -> Result<Vec<(V3, f64)>, String> {
    let axis = 0.5 * (min + max);
    radii.sort_by(|a, b| b.total_cmp(a));
    let r_max = radii
        .first()
        .copied()
        .unwrap_or(0.0)
        .max(existing.iter().map(|e| e.1).fold(0.0, f64::max));
    if radii.is_empty() {
        return Ok(Vec::new());
    }
    let h = 2.0 * r_max;
    let key = |x: &V3| -> (i64, i64, i64) {
        (
            (x.x / h).floor() as i64,
            (x.y / h).floor() as i64,
            (x.z / h).floor() as i64,
        )
    };
    let mut grid: HashMap<(i64, i64, i64), Vec<(V3, f64)>> = HashMap::new();
    // a sphere and, in a periodic cell, its images within reach of the cell
    let images = |x: V3| -> Vec<V3> {
        let Some(l) = period else {
            return vec![x];
        };
        let mut out = Vec::new();
        for sx in -1..=1 {
            for sy in -1..=1 {
                for sz in -1..=1 {
                    let y = x + V3::new(sx as f64 * l.x, sy as f64 * l.y, sz as f64 * l.z);
                    if (0..3).all(|a| y[a] > -h && y[a] < l[a] + h) {
                        out.push(y);
                    }
                }
            }
        }
        out
    };
    for e in existing {
        for y in images(e.0) {
            grid.entry(key(&y)).or_default().push((y, e.1));
        }
    }
    let mut rng = SplitMix64::new(seed);
    let mut out = Vec::with_capacity(radii.len());
    const ATTEMPTS: usize = 20_000;
    for (k, &r) in radii.iter().enumerate() {
        // a periodic cell: centres anywhere in it (a sphere may cross its faces)
        let inset = if period.is_some() { 0.0 } else { r };
        let lo = min + V3::repeat(inset);
        let hi = max - V3::repeat(inset);
        if (0..3).any(|a| hi[a] < lo[a]) {
            return Err(format!(
                "a sphere of radius {r} m does not fit into the region"
            ));
        }
        if let Some(rc) = cylinder {
            if r >= rc {
                return Err(format!(
                    "a sphere of radius {r} m does not fit into the cylinder of radius {rc} m"
                ));
            }
        }
        let mut placed = false;
        for _ in 0..ATTEMPTS {
            let x = V3::new(
                lo.x + (hi.x - lo.x) * rng.uniform(),
                lo.y + (hi.y - lo.y) * rng.uniform(),
                lo.z + (hi.z - lo.z) * rng.uniform(),
            );
            if let Some(rc) = cylinder {
                let d = ((x.x - axis.x).powi(2) + (x.y - axis.y).powi(2)).sqrt();
                if d > rc - r {
                    continue;
                }
            }
            let c = key(&x);
            let mut free = true;
            'search: for dz in -1..=1 {
                for dy in -1..=1 {
                    for dx in -1..=1 {
                        if let Some(list) = grid.get(&(c.0 + dx, c.1 + dy, c.2 + dz)) {
                            for (y, ry) in list {
                                if (x - y).norm_squared() < (r + ry) * (r + ry) {
                                    free = false;
                                    break 'search;
                                }
                            }
                        }
                    }
                }
            }
            if free {
                for y in images(x) {
                    grid.entry(key(&y)).or_default().push((y, r));
                }
                out.push((x, r));
                placed = true;
                break;
            }
        }
        if !placed {
            return Err(format!(
                "placed {k} of {} spheres, then {ATTEMPTS} random positions for the next \
                 (radius {r} m) all overlapped: the region is too small or too dense \
                 (random sequential addition jams near a solid fraction of ~0.35)",
                radii.len()
            ));
        }
    }
    Ok(out)
}

/// A uniformly random unit vector (rejection from the unit ball).
pub fn random_unit_vector(rng: &mut SplitMix64) -> V3 {
    loop {
        let v = V3::new(
            2.0 * rng.uniform() - 1.0,
            2.0 * rng.uniform() - 1.0,
            2.0 * rng.uniform() - 1.0,
        );
        let n2 = v.norm_squared();
        if n2 > 1e-4 && n2 <= 1.0 {
            return v / n2.sqrt();
        }
    }
}

/// A uniformly random rotation (a normalised 4-D Gaussian).
pub fn random_orientation(rng: &mut SplitMix64) -> crate::particles::Orientation {
    loop {
        let q = nalgebra::Quaternion::new(rng.normal(), rng.normal(), rng.normal(), rng.normal());
        if q.norm() > 1e-6 {
            return nalgebra::UnitQuaternion::from_quaternion(q);
        }
    }
}

/// A drawn non-spherical body.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Drawn {
    Superquadric(crate::shape::Superquadric),
    /// Stone `stone` of the particles' library at size `scale` (equivalent-volume diameter).
    Polyhedron {
        stone: u32,
        scale: f64,
        bounding: f64,
        volume: f64,
    },
}

impl Drawn {
    pub fn bounding_radius(&self) -> f64 {
        match self {
            Drawn::Superquadric(s) => s.bounding_radius(),
            Drawn::Polyhedron { bounding, .. } => *bounding,
        }
    }

    pub fn volume(&self) -> f64 {
        match self {
            Drawn::Superquadric(s) => s.volume(),
            Drawn::Polyhedron { volume, .. } => *volume,
        }
    }
}

/// Draws a body of the source `shape` with the volume of a sphere of radius `r_eq` and its
/// orientation: a superquadric ([`sample_superquadric`]) or a copy of a random stone of
/// `library` (indices into `stones`) scaled to the equivalent-volume diameter 2 `r_eq`.
/// `None` for a sphere source.
pub fn sample_body(
    shape: &crate::config::ShapeConfig,
    r_eq: f64,
    rng: &mut SplitMix64,
    library: &[u32],
    stones: &[crate::shape::Stone],
) -> Option<(Drawn, crate::particles::Orientation)> {
    match shape {
        crate::config::ShapeConfig::Polyhedron {
            random_orientation: random,
            ..
        } => {
            let pick = ((rng.uniform() * library.len() as f64) as usize).min(library.len() - 1);
            let stone = library[pick];
            let s = &stones[stone as usize];
            let scale = 2.0 * r_eq;
            let q = if *random {
                random_orientation(rng)
            } else {
                crate::particles::Orientation::identity()
            };
            Some((
                Drawn::Polyhedron {
                    stone,
                    scale,
                    bounding: s.circumradius * scale,
                    volume: s.volume * scale.powi(3),
                },
                q,
            ))
        }
        _ => sample_superquadric(shape, r_eq, rng).map(|(b, q)| (Drawn::Superquadric(b), q)),
    }
}

/// Draws a superquadric of the source `shape` with the volume of a sphere of radius `r_eq`
/// (Wellmann §3.4.4: ratios uniform in [1, elongation], exponents uniform in
/// [1 − angularity, 1 + angularity], then scaled to the size), and its orientation. `None`
/// for a sphere source.
pub fn sample_superquadric(
    shape: &crate::config::ShapeConfig,
    r_eq: f64,
    rng: &mut SplitMix64,
) -> Option<(crate::shape::Superquadric, crate::particles::Orientation)> {
    let crate::config::ShapeConfig::Superquadric {
        semi_axes,
        aspect,
        elongation,
        exponents,
        angularity,
        exponent_range,
        random_orientation: random,
    } = shape
    else {
        return None;
    };
    let ratios = match (semi_axes, aspect, elongation) {
        (Some(d), ..) => V3::new(
            sample_radius(&d[0], rng),
            sample_radius(&d[1], rng),
            sample_radius(&d[2], rng),
        ),
        (None, Some(a), _) => V3::from(*a),
        (None, None, Some(e)) => V3::new(
            1.0 + (e - 1.0) * rng.uniform(),
            1.0 + (e - 1.0) * rng.uniform(),
            1.0 + (e - 1.0) * rng.uniform(),
        ),
        (None, None, None) => V3::repeat(1.0),
    };
    let [e1, e2] = match (exponents, angularity, exponent_range) {
        (Some(e), ..) => *e,
        (None, Some(a), _) => [
            1.0 + a * (2.0 * rng.uniform() - 1.0),
            1.0 + a * (2.0 * rng.uniform() - 1.0),
        ],
        (None, None, Some([lo, hi])) => [
            lo + (hi - lo) * rng.uniform(),
            lo + (hi - lo) * rng.uniform(),
        ],
        (None, None, None) => [1.0, 1.0],
    };
    let unit = crate::shape::Superquadric::new(ratios, e1, e2)?;
    let body = if semi_axes.is_some() {
        unit // drawn to size
    } else {
        let scale = (4.0 / 3.0 * std::f64::consts::PI * r_eq.powi(3) / unit.volume()).cbrt();
        crate::shape::Superquadric::new(ratios * scale, e1, e2)?
    };
    let q = if *random {
        random_orientation(rng)
    } else {
        crate::particles::Orientation::identity()
    };
    Some((body, q))
}
