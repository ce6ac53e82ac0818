//! Narrow phase for the non-spherical shapes: the exact contact geometry (points, normal,
//! overlap, curvatures) of a listed pair, apart from the contact law that turns it into
//! forces. Spheres do not come here: their geometry is one distance, fused into their kernel.

pub mod polyhedron;
pub mod protocol;
pub mod superquadric;
pub mod superquadric_patch;
