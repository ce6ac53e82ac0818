//! Particle shapes (the shape layer): what a shape can do — bounding radius, mass
//! properties, surface point from a normal — apart from the bodies that carry it.
//!
//! Spheres keep their own fused kernel in `resolve_forces`; the other shapes go through
//! their narrow phase ([`crate::narrow`]) and the elliptic contact law.

pub mod superquadric;

pub use superquadric::Superquadric;
