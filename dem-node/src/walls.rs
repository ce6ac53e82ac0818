//! Walls: infinite planes and triangle meshes (static from STL/box primitives, or coupled
//! meshes driven by FEM kinematics with a motion rule, Ullrich ch. 3.2–3.3).

use crate::hertz_mindlin::V3;
use serde::{Deserialize, Serialize};

/// How a coupled mesh moves during the substeps of a coupling window (τ from window start).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum MotionRule {
    /// Just-in-time coupling: x = P + Vτ + ½Aτ² (Ullrich Algorithm 3, line 8).
    Quadratic,
    /// Predictive coupling: x = P + Vτ with V the predictive velocity (eqs. 3.4–3.7).
    Linear,
}

/// Infinite plane; particles live on the side `normal` points to.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Plane {
    pub point: V3,
    pub normal: V3,
    pub material: u16,
    /// Velocity of a plane with a prescribed motion (zero otherwise).
    pub velocity: V3,
    /// False once the plane was removed (`remove_at`).
    pub active: bool,
}

/// A static wall: plane or mesh index.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WallRef {
    Plane(usize),
    Mesh(usize),
}

/// Prescribed rigid translation of a static wall (`[[dem.walls]] motion` and `remove_at`):
/// during [start, end) the displacement is u(τ) = v τ + A sin(ωτ), τ = t − start, ω = 2πf;
/// at rest before and frozen at u(end − start) after; the wall is absent from `remove_at` on.
/// A pure function of the time, so a restored snapshot puts the walls back exactly.
#[derive(Debug, Clone)]
pub struct PrescribedMotion {
    pub wall: WallRef,
    pub velocity: V3,
    /// Oscillation amplitude A (m) and angular frequency ω (rad/s).
    pub amplitude: V3,
    pub omega: f64,
    pub start: f64,
    /// +∞ when the motion never stops.
    pub end: f64,
    /// +∞ when the wall stays.
    pub remove_at: f64,
    /// Plane point or mesh node positions at rest before `start`.
    pub base: Vec<V3>,
    /// Further constant-velocity stages (velocity, start, end), each adding its displacement.
    pub stages: Vec<(V3, f64, f64)>,
    /// The wall's report name (`motion.name`), if reported.
    pub name: Option<String>,
}

impl PrescribedMotion {
    pub fn displacement(&self, t: f64) -> V3 {
        let tau = (t.min(self.end) - self.start).max(0.0);
        let mut u = self.velocity * tau;
        if self.omega > 0.0 {
            u += self.amplitude * (self.omega * tau).sin();
        }
        for &(v, start, end) in &self.stages {
            u += v * (t.min(end) - start).max(0.0);
        }
        u
    }

    pub fn velocity_at(&self, t: f64) -> V3 {
        let mut v = V3::zeros();
        if t >= self.start && t < self.end {
            v = self.velocity;
            if self.omega > 0.0 {
                v += self.amplitude * (self.omega * (self.omega * (t - self.start)).cos());
            }
        }
        for &(vs, start, end) in &self.stages {
            if t >= start && t < end {
                v += vs;
            }
        }
        v
    }

    /// Whether the wall ever moves (a velocity, an oscillation or a stage with a velocity).
    pub fn moves(&self) -> bool {
        self.velocity != V3::zeros()
            || self.amplitude != V3::zeros()
            || self.stages.iter().any(|s| s.0 != V3::zeros())
    }

    pub fn present(&self, t: f64) -> bool {
        t < self.remove_at
    }

    /// Puts the wall where it is at time t. Returns true if it appeared or disappeared.
    pub fn apply(&self, t: f64, planes: &mut [Plane], meshes: &mut [Mesh]) -> bool {
        let (d, v) = (self.displacement(t), self.velocity_at(t));
        place_wall(self.wall, &self.base, d, v, self.present(t), planes, meshes)
    }
}

/// Puts a rigidly translated wall at `base + d` with velocity `v` and presence `present`.
/// Returns true if it appeared or disappeared.
fn place_wall(
    wall: WallRef,
    base: &[V3],
    d: V3,
    v: V3,
    present: bool,
    planes: &mut [Plane],
    meshes: &mut [Mesh],
) -> bool {
    match wall {
        WallRef::Plane(k) => {
            let pl = &mut planes[k];
            pl.point = base[0] + d;
            pl.velocity = v;
            std::mem::replace(&mut pl.active, present) != present
        }
        WallRef::Mesh(k) => {
            let m = &mut meshes[k];
            for ((x, x0), u) in m.positions.iter_mut().zip(base).zip(&mut m.velocities) {
                *x = x0 + d;
                *u = v;
            }
            std::mem::replace(&mut m.active, present) != present
        }
    }
}

/// A wall moved by forces along one axis (`[[dem.walls]] load`, see
/// [`crate::config::WallLoad`]): a rigid body of mass m with m ü = F_c + m g·e + F(t), F_c the
/// axis component of the particles' contact forces on it, integrated by the same velocity
/// Verlet as the particles (Ullrich Algorithm 1).
#[derive(Debug, Clone)]
pub struct LoadedWall {
    pub name: String,
    pub wall: WallRef,
    /// Unit vector of the axis, e.
    pub axis: V3,
    pub mass: f64,
    pub force: f64,
    pub amplitude: f64,
    /// Angular frequency ω = 2πf of the harmonic force.
    pub omega: f64,
    pub start: f64,
    /// +∞ when the load is never released.
    pub end: f64,
    pub release: f64,
    pub remove_at: f64,
    /// Plane point or mesh node positions at rest before `start`.
    pub base: Vec<V3>,
    /// Strain control (velocity along the axis, from time) after force control.
    pub drive: Option<(f64, f64)>,
    /// Rise time of the applied force after `start` (0: at once).
    pub ramp: f64,
}

/// Dynamic state of a loaded wall (part of snapshots): displacement u and velocity v along
/// the axis, and the axis component of the contact force on it from the last force
/// evaluation (its acceleration follows, [`LoadedWall::acceleration`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct LoadedWallState {
    pub u: f64,
    pub v: f64,
    pub contact_force: f64,
}

impl LoadedWall {
    /// The factor of the load and weight at time t: 1 until `end`, then down linearly to 0
    /// over `release` (0 at once without one).
    fn load_scale(&self, t: f64) -> f64 {
        if t < self.end {
            1.0
        } else if self.release > 0.0 {
            (1.0 - (t - self.end) / self.release).max(0.0)
        } else {
            0.0
        }
    }

    /// The applied force F(t) along the axis: 0 before `start`, force + amplitude·sin(ωτ)
    /// until `end`, then scaled down to 0 over `release`.
    pub fn applied_force(&self, t: f64) -> f64 {
        let scale = self.load_scale(t);
        if t < self.start || scale == 0.0 {
            return 0.0;
        }
        let mut f = self.force;
        if self.omega > 0.0 {
            f += self.amplitude * (self.omega * (t - self.start)).sin();
        }
        if self.ramp > 0.0 {
            f *= ((t - self.start) / self.ramp).min(1.0);
        }
        f * scale
    }

    /// Whether the wall moves freely at time t (released, present, not driven).
    pub fn free(&self, t: f64) -> bool {
        t >= self.start && t < self.remove_at && !self.driven(t)
    }

    /// The velocity of a wall under strain control at time t (`drive`), if it is.
    pub fn driven_velocity(&self, t: f64) -> Option<f64> {
        self.drive
            .filter(|&(_, start)| t >= start && t < self.remove_at)
            .map(|(v, _)| v)
    }

    pub fn driven(&self, t: f64) -> bool {
        self.driven_velocity(t).is_some()
    }

    /// Acceleration along the axis at time t with contact force `contact` (0 while held).
    /// The weight is released with the load (the plate is lifted off gently): after
    /// `end + release` only the contact forces act.
    pub fn acceleration(&self, t: f64, contact: f64, gravity: &V3) -> f64 {
        if !self.free(t) {
            return 0.0;
        }
        let weight = gravity.dot(&self.axis) * self.load_scale(t);
        (contact + self.applied_force(t)) / self.mass + weight
    }

    /// Puts the wall at its state's displacement. Returns true if it appeared or disappeared.
    pub fn apply(
        &self,
        t: f64,
        st: &LoadedWallState,
        planes: &mut [Plane],
        meshes: &mut [Mesh],
    ) -> bool {
        let (d, v) = (self.axis * st.u, self.axis * st.v);
        place_wall(
            self.wall,
            &self.base,
            d,
            v,
            t < self.remove_at,
            planes,
            meshes,
        )
    }
}

/// Angle below which two triangles sharing an edge are treated as one smooth face even when
/// the edge is slightly concave (1°): a deformed flat FEM surface stays one contact patch.
pub const NEARLY_COPLANAR_RAD: f64 = 1.0 * std::f64::consts::PI / 180.0;

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Mesh {
    pub name: String,
    pub material: u16,
    pub coupled: bool,
    pub triangles: Vec<[u32; 3]>,
    /// Current node positions and velocities.
    pub positions: Vec<V3>,
    pub velocities: Vec<V3>,
    /// Window kinematics P, V, A and rule.
    pub window_p: Vec<V3>,
    pub window_v: Vec<V3>,
    pub window_a: Vec<V3>,
    pub rule: MotionRule,
    /// Time τ since the window kinematics were set, = `window_steps` × Δt (not a running sum,
    /// so the motion rule is evaluated at exactly kΔt).
    pub tau: f64,
    pub window_steps: u64,
    /// Contact patch of each triangle (see `triangle_contact`).
    pub patch: Vec<u32>,
    /// Nodal forces exerted by particles on the nodes: current step, last completed step,
    /// and the sum over the substeps of the current window (Ullrich eq. 3.8).
    pub nodal_force_step: Vec<V3>,
    pub nodal_force_last: Vec<V3>,
    pub nodal_force_sum: Vec<V3>,
    pub window_substeps: u64,
    /// Work the particles' forces did on the mesh since the window kinematics were set,
    /// Σ_steps Δt Σ_nodes f·v (the DEM side of the interface energy audit) [J].
    #[serde(default)]
    pub window_work: f64,
    /// Node positions at the last neighbour-list build (Wellmann eq. 4.10).
    pub positions_at_build: Vec<V3>,
    /// False once a static wall was removed (`remove_at`): no contacts.
    pub active: bool,
}

impl Mesh {
    pub fn new(
        name: &str,
        material: u16,
        coupled: bool,
        positions: Vec<V3>,
        triangles: Vec<[u32; 3]>,
    ) -> Mesh {
        let n = positions.len();
        let patch = compute_patches(&positions, &triangles);
        Mesh {
            name: name.to_string(),
            material,
            coupled,
            triangles,
            velocities: vec![V3::zeros(); n],
            window_p: positions.clone(),
            window_v: vec![V3::zeros(); n],
            window_a: vec![V3::zeros(); n],
            rule: MotionRule::Linear,
            tau: 0.0,
            window_steps: 0,
            patch,
            nodal_force_step: vec![V3::zeros(); n],
            nodal_force_last: vec![V3::zeros(); n],
            nodal_force_sum: vec![V3::zeros(); n],
            window_substeps: 0,
            window_work: 0.0,
            positions_at_build: positions.clone(),
            positions,
            active: true,
        }
    }

    /// Node positions and velocities at window time τ by the window's motion rule.
    pub fn move_to(&mut self, tau: f64) {
        match self.rule {
            MotionRule::Quadratic => {
                for k in 0..self.positions.len() {
                    self.positions[k] = self.window_p[k]
                        + self.window_v[k] * tau
                        + self.window_a[k] * (0.5 * tau * tau);
                    self.velocities[k] = self.window_v[k] + self.window_a[k] * tau;
                }
            }
            MotionRule::Linear => {
                for k in 0..self.positions.len() {
                    self.positions[k] = self.window_p[k] + self.window_v[k] * tau;
                    self.velocities[k] = self.window_v[k];
                }
            }
        }
    }

    pub fn corners(&self, t: usize) -> [V3; 3] {
        let [a, b, c] = self.triangles[t];
        [
            self.positions[a as usize],
            self.positions[b as usize],
            self.positions[c as usize],
        ]
    }

    /// Largest node displacement since the last neighbour-list build.
    pub fn max_displacement_since_build(&self) -> f64 {
        let mut m = 0.0f64;
        for (x, x0) in self.positions.iter().zip(&self.positions_at_build) {
            m = m.max((x - x0).norm());
        }
        m
    }
}

fn find(parent: &mut [u32], mut x: u32) -> u32 {
    while parent[x as usize] != x {
        parent[x as usize] = parent[parent[x as usize] as usize];
        x = parent[x as usize];
    }
    x
}

/// Groups triangles into contact patches: neighbours across an edge join when the edge is
/// convex seen from the front (normal) side, or nearly coplanar (< 1°, either way). One
/// particle makes at most one contact per patch, at the closest point of the patch; across a
/// convex or coplanar edge that closest point moves continuously, so the force neither jumps
/// nor double-counts (see `triangle_contact`). Concave edges separate patches, so a sphere in
/// a corner touches both faces. Patch id = smallest triangle index of the group.
pub fn compute_patches(positions: &[V3], triangles: &[[u32; 3]]) -> Vec<u32> {
    let nt = triangles.len();
    let mut edges: Vec<(u32, u32, u32)> = Vec::with_capacity(3 * nt);
    for (t, tri) in triangles.iter().enumerate() {
        for e in 0..3 {
            let (a, b) = (tri[e], tri[(e + 1) % 3]);
            edges.push((a.min(b), a.max(b), t as u32));
        }
    }
    edges.sort_unstable();
    let normal = |t: usize| -> V3 {
        let [a, b, c] = triangles[t];
        let (pa, pb, pc) = (
            positions[a as usize],
            positions[b as usize],
            positions[c as usize],
        );
        (pb - pa)
            .cross(&(pc - pa))
            .try_normalize(0.0)
            .unwrap_or_else(V3::zeros)
    };
    let mut parent: Vec<u32> = (0..nt as u32).collect();
    let cos_flat = NEARLY_COPLANAR_RAD.cos();
    let mut k = 0;
    while k < edges.len() {
        let mut m = k + 1;
        while m < edges.len() && edges[m].0 == edges[k].0 && edges[m].1 == edges[k].1 {
            m += 1;
        }
        if m - k == 2 {
            let (ta, tb) = (edges[k].2 as usize, edges[k + 1].2 as usize);
            let (na, nb) = (normal(ta), normal(tb));
            // consistent orientation: the shared edge is traversed in opposite directions
            let dir = |t: usize| {
                let tri = triangles[t];
                (0..3)
                    .find(|&e| {
                        let (a, b) = (tri[e], tri[(e + 1) % 3]);
                        a.min(b) == edges[k].0 && a.max(b) == edges[k].1
                    })
                    .map(|e| tri[e] == edges[k].0)
                    .unwrap_or(true)
            };
            let consistent = dir(ta) != dir(tb);
            let opposite_b = triangles[tb]
                .iter()
                .copied()
                .find(|&v| v != edges[k].0 && v != edges[k].1)
                .unwrap_or(edges[k].0);
            let w = (positions[opposite_b as usize] - positions[edges[k].0 as usize]).dot(&na);
            let nearly_flat = na.dot(&nb) >= cos_flat;
            let convex = w < 0.0;
            if consistent && (nearly_flat || convex) {
                let (ra, rb) = (find(&mut parent, ta as u32), find(&mut parent, tb as u32));
                if ra != rb {
                    // keep the smaller index as root so patch ids are the group minimum
                    let (lo, hi) = (ra.min(rb), ra.max(rb));
                    parent[hi as usize] = lo;
                }
            }
        }
        k = m;
    }
    (0..nt as u32).map(|t| find(&mut parent, t)).collect()
}

/// Axis-aligned box [min, max] as 12 triangles with inward normals, leaving out `open` faces.
pub fn box_mesh(min: V3, max: V3, open: &[String]) -> (Vec<V3>, Vec<[u32; 3]>) {
    let corner = |i: u32| -> V3 {
        V3::new(
            if i & 1 != 0 { max.x } else { min.x },
            if i & 2 != 0 { max.y } else { min.y },
            if i & 4 != 0 { max.z } else { min.z },
        )
    };
    let positions: Vec<V3> = (0..8).map(corner).collect();
    // each face as a quad (a, b, c, d) ordered so that (b−a)×(d−a) points into the box
    let faces: [(&str, [u32; 4]); 6] = [
        ("-x", [0, 2, 6, 4]),
        ("+x", [1, 5, 7, 3]),
        ("-y", [0, 4, 5, 1]),
        ("+y", [2, 3, 7, 6]),
        ("-z", [0, 1, 3, 2]),
        ("+z", [4, 6, 7, 5]),
    ];
    let mut tris = Vec::new();
    for (name, [a, b, c, d]) in faces {
        if open.iter().any(|o| o == name) {
            continue;
        }
        tris.push([a, b, c]);
        tris.push([a, c, d]);
    }
    (positions, tris)
}

/// A cylinder about the z axis from `centre` (bottom) up by `height`: `segments` flat facets
/// with corners on `radius`, two triangles each, normals towards the axis.
pub fn cylinder_mesh(
    centre: V3,
    radius: f64,
    height: f64,
    segments: u32,
) -> (Vec<V3>, Vec<[u32; 3]>) {
    let n = segments;
    let mut positions = Vec::with_capacity(2 * n as usize);
    for level in [0.0, height] {
        for i in 0..n {
            let a = 2.0 * std::f64::consts::PI * i as f64 / n as f64;
            positions.push(centre + V3::new(radius * a.cos(), radius * a.sin(), level));
        }
    }
    let mut tris = Vec::with_capacity(2 * n as usize);
    for i in 0..n {
        let (a, b) = (i, (i + 1) % n);
        let (c, d) = (n + b, n + a);
        // (a, b, c, d) runs counter-clockwise seen from outside: reversed, it faces the axis
        tris.push([a, d, c]);
        tris.push([a, c, b]);
    }
    (positions, tris)
}
