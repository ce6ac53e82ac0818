//! Particles as structure-of-arrays (spheres). A sphere's orientation changes nothing in its
//! contacts, so none is stored or integrated (shapes that need one will carry it); the angular
//! velocity is, for the tangential and rolling contact terms.

use crate::hertz_mindlin::V3;
use serde::{Deserialize, Serialize};

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
    }

    pub fn kinetic_energy(&self) -> f64 {
        // serial sum in storage order: deterministic for any thread count
        let mut e = 0.0;
        for k in 0..self.len() {
            e += 0.5 * self.mass[k] * self.velocity[k].norm_squared()
                + 0.5 * self.inertia[k] * self.angular_velocity[k].norm_squared();
        }
        e
    }

    /// Bytes of per-particle state (for the benchmark's memory figure).
    pub fn bytes_per_particle() -> usize {
        // id, 5 vectors (x, v, ω, F, T), r, m, I, material
        4 + 5 * 24 + 3 * 8 + 2
    }
}
