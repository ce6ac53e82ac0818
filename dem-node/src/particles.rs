//! Particles (bodies) as structure-of-arrays: centre, velocity, orientation, angular velocity,
//! mass, inertia, material and a shape id, apart from the table of shape templates the
//! non-spherical bodies point into (the shape layer, DESIGN "DEM bodies and shapes").
//!
//! A sphere (shape id [`SPHERE`]) is its `radius`; its orientation changes nothing in its
//! contacts, so it stays the identity and is not integrated; its angular velocity is, for
//! the tangential and rolling contact terms. A superquadric's `radius` is its bounding radius
//! (the broad phase's, Wellmann 3.47), `inertia` the smallest principal moment, and its
//! template holds the shape and the principal moments (3.5)–(3.7); its rotation follows
//! Wellmann's scheme ([`crate::rotation`]). A dilated polyhedron's template is a scaled copy
//! of a [`Stone`] of the `stones` library (many bodies share a stone); its `radius` is its
//! bounding radius too.

use crate::hertz_mindlin::V3;
use crate::shape::{Stone, Superquadric};
use nalgebra::UnitQuaternion;
use serde::{Deserialize, Serialize};

/// Shape id of a sphere.
pub const SPHERE: u32 = u32::MAX;

/// Orientation body → global.
pub type Orientation = UnitQuaternion<f64>;

/// A non-spherical body's shape.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
pub enum Shape {
    Superquadric(Superquadric),
    /// Stone `stone` of [`Particles::stones`] at size `scale` (m, the equivalent-volume
    /// diameter): core vertices × scale, dilation radius × scale.
    Polyhedron {
        stone: u32,
        scale: f64,
    },
}

/// A non-spherical body's shape and principal moments of inertia (body frame).
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
pub struct ShapeTemplate {
    pub shape: Shape,
    pub principal_inertia: V3,
}

impl ShapeTemplate {
    /// The superquadric, `None` for another shape.
    #[inline]
    pub fn superquadric(&self) -> Option<&Superquadric> {
        match &self.shape {
            Shape::Superquadric(s) => Some(s),
            Shape::Polyhedron { .. } => None,
        }
    }
}

#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct Particles {
    /// Stable identity (insertion order); the storage order changes when the broad phase sorts
    /// particles by grid cell.
    pub id: Vec<u32>,
    pub position: Vec<V3>,
    pub velocity: Vec<V3>,
    pub angular_velocity: Vec<V3>,
    pub radius: Vec<f64>,
    pub mass: Vec<f64>,
    /// Moment of inertia about the centre, 2/5 m r² for a solid sphere.
    pub inertia: Vec<f64>,
    pub material: Vec<u16>,
    /// Total force and torque of the last force evaluation (gravity included).
    pub force: Vec<V3>,
    pub torque: Vec<V3>,
    /// Orientation body → global (identity for spheres).
    #[serde(default)]
    pub orientation: Vec<Orientation>,
    /// [`SPHERE`] or an index into `templates`.
    #[serde(default)]
    pub shape: Vec<u32>,
    #[serde(default)]
    pub templates: Vec<ShapeTemplate>,
    /// The stones the polyhedral templates are copies of (unit size).
    #[serde(default)]
    pub stones: Vec<Stone>,
}

impl Particles {
    pub fn len(&self) -> usize {
        self.position.len()
    }

    pub fn is_empty(&self) -> bool {
        self.position.is_empty()
    }

    pub fn push(
        &mut self,
        position: V3,
        velocity: V3,
        omega: V3,
        radius: f64,
        density: f64,
        material: u16,
    ) {
        let mass = density * 4.0 / 3.0 * std::f64::consts::PI * radius.powi(3);
        self.id.push(self.position.len() as u32);
        self.position.push(position);
        self.velocity.push(velocity);
        self.angular_velocity.push(omega);
        self.radius.push(radius);
        self.mass.push(mass);
        self.inertia.push(0.4 * mass * radius * radius);
        self.material.push(material);
        self.force.push(V3::zeros());
        self.torque.push(V3::zeros());
        self.orientation.push(Orientation::identity());
        self.shape.push(SPHERE);
    }

    /// Adds a superquadric body of `density` (mass and inertia by (3.4)–(3.7)).
    #[allow(clippy::too_many_arguments)] // one body's state, as `push`
    pub fn push_superquadric(
        &mut self,
        position: V3,
        velocity: V3,
        omega: V3,
        orientation: Orientation,
        shape: Superquadric,
        density: f64,
        material: u16,
    ) {
        let (mass, principal_inertia) = shape.mass_properties(density);
        let body = ShapeTemplate {
            shape: Shape::Superquadric(shape),
            principal_inertia,
        };
        let state = (position, velocity, omega, orientation);
        self.push_shaped(state, shape.bounding_radius(), mass, body, material);
    }

    /// Appends a non-spherical body: its state (x, v, ω, orientation), bounding radius, mass
    /// and template.
    fn push_shaped(
        &mut self,
        (position, velocity, omega, orientation): (V3, V3, V3, Orientation),
        radius: f64,
        mass: f64,
        template: ShapeTemplate,
        material: u16,
    ) {
        self.id.push(self.position.len() as u32);
        self.position.push(position);
        self.velocity.push(velocity);
        self.angular_velocity.push(omega);
        self.radius.push(radius);
        self.mass.push(mass);
        self.inertia.push(template.principal_inertia.min());
        self.material.push(material);
        self.force.push(V3::zeros());
        self.torque.push(V3::zeros());
        self.orientation.push(orientation);
        self.shape.push(self.templates.len() as u32);
        self.templates.push(template);
    }

    /// Adds a drawn body (a superquadric or a stone copy) of `density`.
    #[allow(clippy::too_many_arguments)] // one body's state, as `push`
    pub fn push_drawn(
        &mut self,
        position: V3,
        velocity: V3,
        omega: V3,
        orientation: Orientation,
        body: crate::generate::Drawn,
        density: f64,
        material: u16,
    ) {
        match body {
            crate::generate::Drawn::Superquadric(s) => {
                self.push_superquadric(position, velocity, omega, orientation, s, density, material)
            }
            crate::generate::Drawn::Polyhedron { stone, scale, .. } => self.push_polyhedron(
                position,
                velocity,
                omega,
                orientation,
                stone,
                scale,
                density,
                material,
            ),
        }
    }

    /// Adds `stone` to the library; returns its index for [`Particles::push_polyhedron`].
    pub fn add_stone(&mut self, stone: Stone) -> u32 {
        self.stones.push(stone);
        (self.stones.len() - 1) as u32
    }

    /// Adds a dilated polyhedron: stone `stone` (of [`Particles::add_stone`]) at size `scale`
    /// (m) and `density`.
    #[allow(clippy::too_many_arguments)] // one body's state, as `push`
    pub fn push_polyhedron(
        &mut self,
        position: V3,
        velocity: V3,
        omega: V3,
        orientation: Orientation,
        stone: u32,
        scale: f64,
        density: f64,
        material: u16,
    ) {
        let s = &self.stones[stone as usize];
        let (mass, radius) = (density * s.volume * scale.powi(3), s.circumradius * scale);
        let body = ShapeTemplate {
            shape: Shape::Polyhedron { stone, scale },
            principal_inertia: s.inertia * (density * scale.powi(5)),
        };
        let state = (position, velocity, omega, orientation);
        self.push_shaped(state, radius, mass, body, material);
    }

    /// The (stone, scale) of body k if it is a dilated polyhedron.
    #[inline]
    pub fn polyhedron(&self, k: usize) -> Option<(&Stone, f64)> {
        match self.template(k)?.shape {
            Shape::Polyhedron { stone, scale } => Some((&self.stones[stone as usize], scale)),
            Shape::Superquadric(_) => None,
        }
    }

    /// Volume of body k.
    pub fn volume(&self, k: usize) -> f64 {
        match self.template(k).map(|t| t.shape) {
            None => 4.0 / 3.0 * std::f64::consts::PI * self.radius[k].powi(3),
            Some(Shape::Superquadric(s)) => s.volume(),
            Some(Shape::Polyhedron { stone, scale }) => {
                self.stones[stone as usize].volume * scale.powi(3)
            }
        }
    }

    /// Radius of the smallest lump of body k that vibrates (its Rayleigh time step's): a
    /// sphere's radius, a superquadric's smallest semi-axis, a polyhedron's inscribed radius.
    pub fn vibration_radius(&self, k: usize) -> f64 {
        match self.template(k).map(|t| t.shape) {
            None => self.radius[k],
            Some(Shape::Superquadric(s)) => s.radii.min(),
            Some(Shape::Polyhedron { stone, scale }) => {
                self.stones[stone as usize].inradius() * scale
            }
        }
    }

    /// True if some body is not a sphere (the shaped pipeline runs).
    pub fn has_shapes(&self) -> bool {
        !self.templates.is_empty()
    }

    /// The template of body k, `None` for a sphere.
    #[inline]
    pub fn template(&self, k: usize) -> Option<&ShapeTemplate> {
        self.templates.get(self.shape[k] as usize)
    }

    /// Fills orientation and shape for states written before bodies had them (all spheres).
    pub fn complete_shape_columns(&mut self) {
        let n = self.len();
        if self.orientation.len() != n {
            self.orientation = vec![Orientation::identity(); n];
        }
        if self.shape.len() != n {
            self.shape = vec![SPHERE; n];
        }
    }

    /// Reorders every array so that new index k holds old particle `perm[k]`.
    pub fn permute(&mut self, perm: &[u32]) {
        fn apply<T: Clone>(v: &mut Vec<T>, perm: &[u32]) {
            let new: Vec<T> = perm.iter().map(|&k| v[k as usize].clone()).collect();
            *v = new;
        }
        apply(&mut self.id, perm);
        apply(&mut self.position, perm);
        apply(&mut self.velocity, perm);
        apply(&mut self.angular_velocity, perm);
        apply(&mut self.radius, perm);
        apply(&mut self.mass, perm);
        apply(&mut self.inertia, perm);
        apply(&mut self.material, perm);
        apply(&mut self.force, perm);
        apply(&mut self.torque, perm);
        apply(&mut self.orientation, perm);
        apply(&mut self.shape, perm);
        self.order_templates();
    }

    /// Renumbers the shape templates in the order of the bodies that use them (shared ones
    /// stay shared, unused ones go): the contact search reads a body's template with its
    /// state, and after the cell sort those reads then stream instead of jumping through
    /// an array as large as the bodies (150 MB at a million superquadrics).
    fn order_templates(&mut self) {
        if self.templates.is_empty() {
            return;
        }
        let mut new_index = vec![u32::MAX; self.templates.len()];
        let mut templates = Vec::with_capacity(self.templates.len());
        for s in self.shape.iter_mut().filter(|s| **s != SPHERE) {
            let old = *s as usize;
            if new_index[old] == u32::MAX {
                new_index[old] = templates.len() as u32;
                templates.push(self.templates[old]);
            }
            *s = new_index[old];
        }
        self.templates = templates;
    }

    pub fn kinetic_energy(&self) -> f64 {
        // serial sum in storage order: deterministic for any thread count
        let mut e = 0.0;
        for k in 0..self.len() {
            let w = &self.angular_velocity[k];
            let rot = match self.template(k) {
                None => 0.5 * self.inertia[k] * w.norm_squared(),
                Some(t) => {
                    let h = crate::rotation::angular_momentum(
                        &self.orientation[k],
                        w,
                        &t.principal_inertia,
                    );
                    0.5 * w.dot(&h)
                }
            };
            e += 0.5 * self.mass[k] * self.velocity[k].norm_squared() + rot;
        }
        e
    }

    /// Bytes of per-particle state (for the benchmark's memory figure).
    pub fn bytes_per_particle() -> usize {
        // id, 5 vectors (x, v, ω, F, T), r, m, I, material, orientation, shape id
        4 + 5 * 24 + 3 * 8 + 2 + 32 + 4
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn templates_follow_their_bodies_when_the_bodies_are_reordered() {
        let mut p = Particles::default();
        let sq = |a: f64| Superquadric::new(V3::new(a, 1.0, 1.0), 0.8, 1.2).unwrap();
        let q = Orientation::identity();
        for k in 0..4 {
            if k == 1 {
                p.push(V3::zeros(), V3::zeros(), V3::zeros(), 0.5, 1000.0, 0);
            } else {
                let x = V3::new(k as f64, 0.0, 0.0);
                p.push_superquadric(
                    x,
                    V3::zeros(),
                    V3::zeros(),
                    q,
                    sq(1.0 + k as f64),
                    1000.0,
                    0,
                );
            }
        }
        let radii = |p: &Particles| -> Vec<f64> {
            (0..p.len())
                .map(|k| {
                    p.template(k)
                        .map_or(0.0, |t| t.superquadric().unwrap().radii.x)
                })
                .collect()
        };
        assert_eq!(radii(&p), [1.0, 0.0, 3.0, 4.0]);
        p.permute(&[3, 1, 0, 2]);
        // every body kept its own shape, and the templates are in body order
        assert_eq!(radii(&p), [4.0, 0.0, 1.0, 3.0]);
        assert_eq!(p.shape, [0, SPHERE, 1, 2]);
        assert_eq!(p.templates.len(), 3);
        // a template no body uses any more goes
        p.shape[3] = p.shape[2];
        p.permute(&[0, 1, 2, 3]);
        assert_eq!(p.templates.len(), 2);
        assert_eq!(radii(&p), [4.0, 0.0, 1.0, 1.0]);
    }
}
