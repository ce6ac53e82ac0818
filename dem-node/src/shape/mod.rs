//! Particle shapes (the shape layer): what a shape can do — bounding radius, mass
//! properties, surface point from a normal (superquadrics) or support point (polyhedra) —
//! apart from the bodies that carry it.
//!
//! Spheres keep their own fused kernel in `resolve_forces`; the other shapes go through
//! their narrow phase ([`crate::narrow`]) and their contact law.

pub mod polyhedron;
pub mod superquadric;

pub use polyhedron::Stone;
pub use superquadric::Superquadric;
