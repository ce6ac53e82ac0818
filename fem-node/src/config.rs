//! The `[fem]` table of a scene file. SI units throughout (m, Pa, kg/m³, N, s).
//! See `fem-node/FEM.md` for the format with examples.

use crate::element::ElementKind;
use crate::history::History;
use serde::de::{self, MapAccess, Visitor};
use serde::{Deserialize, Deserializer, Serialize};
use std::collections::BTreeMap;
use std::fmt;

/// A scene-file error with its 1-based position (the one type of every crate).
pub use scenefile::SceneError;

/// `[fem]`: the structure of a scene.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct FemConfig {
    /// Mesh file (`"beam.msh"`, `"beam.inp"`, relative to the scene file) or a generated box.
    pub mesh: MeshSpec,
    /// The material of every element no `[[fem.sections]]` entry assigns (linear elastic).
    #[serde(default)]
    pub material: Option<Material>,
    /// Named materials (`[fem.materials.<name>]` with `model = ...`), assigned to element
    /// sets by `sections`.
    #[serde(default)]
    pub materials: BTreeMap<String, MaterialSpec>,
    /// Element set → material assignments.
    #[serde(default)]
    pub sections: Vec<Section>,
    /// Newton–Raphson controls of nonlinear models.
    #[serde(default)]
    pub newton: NewtonConfig,
    /// `"static"` (default), `"dynamic"`, `"explicit"`, or a table with `type` and parameters.
    #[serde(default)]
    pub analysis: Analysis,
    /// Fixed displacement components (zero) on selected nodes.
    #[serde(default)]
    pub supports: Vec<Support>,
    /// External loads, each scaled by an optional history.
    #[serde(default)]
    pub loads: Vec<Load>,
    /// Named load histories referenced by `loads[].history` or `{ type = "ref", name = ... }`.
    #[serde(default)]
    pub histories: BTreeMap<String, History>,
    /// Coupled part of the exterior surface (default: all of it).
    #[serde(default)]
    pub interface: Option<InterfaceSpec>,
    /// `[fem.overlap]`: the model's interface is a volume overlap with particles (Arlequin,
    /// Wellmann ch. 6) instead of a surface.
    #[serde(default)]
    pub overlap: Option<OverlapSpec>,
    /// Points whose displacement is reported (CSV, summary).
    #[serde(default)]
    pub probes: Vec<Probe>,
    /// Strain maxima reported each output (CSV, summary).
    #[serde(default)]
    pub strain_gauges: Vec<StrainGauge>,
    #[serde(default)]
    pub output: Output,
    /// Linear solver of static analyses (`solver = "auto" | "direct" | "mixed"`).
    #[serde(default)]
    pub solver: LinearSolver,
    /// `[fem.shell]`: the section of shell meshes (MITC4; FEM.md "Thin structures").
    #[serde(default)]
    pub shell: Option<ShellSection>,
    /// `[fem.membrane]`: the structure is a finite-strain Ogden membrane (FEM.md "Membranes").
    #[serde(default)]
    pub membrane: Option<MembraneSection>,
}

/// `[fem.membrane]`: thickness, density and incompressible Ogden law of a membrane
/// structure (Wellmann ch. 4.3.4: the confining rubber of the triaxial test; the membrane of
/// `crate::membrane`).
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct MembraneSection {
    /// Reference thickness t₀ [m] of every element the mesh file gives none (an Abaqus
    /// *MEMBRANE SECTION or *SHELL SECTION gives its own, which wins).
    pub thickness: Option<f64>,
    /// Density ρ [kg/m³].
    #[serde(alias = "rho")]
    pub density: f64,
    /// Ogden terms `[[μ₁, α₁], ...]` (μ_p in Pa; 1 to 3 terms, each μ_p α_p > 0); a
    /// neo-Hookean membrane of shear modulus G is `[[G, 2.0]]`.
    pub ogden: Vec<[f64; 2]>,
}

/// `[fem.shell]`: the section of the shells of a shell mesh.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ShellSection {
    /// Thickness [m] of every shell the mesh file gives none (Abaqus *SHELL SECTION gives
    /// its own, which wins).
    pub thickness: Option<f64>,
    /// Geometrically nonlinear (large rotations, Green–Lagrange strains; Newton iterations
    /// under `[fem.newton]`). Default false: linear.
    #[serde(default)]
    pub nonlinear: bool,
}

/// Which reference surfaces of a shell the DEM sees (Ullrich Fig. 2.6).
#[derive(Clone, Copy, Debug, Default, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum ShellFaces {
    /// The surface at +t/2 along the director (corners counter-clockwise seen from it).
    Top,
    /// The surface at −t/2.
    Bottom,
    #[default]
    Both,
}

/// How static analyses solve K u = F.
#[derive(Clone, Copy, Debug, Default, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum LinearSolver {
    /// `mixed` from [`LinearSolver::AUTO_MIXED_FROM`] free equations on (a one-shot static
    /// solve: from [`LinearSolver::AUTO_MIXED_ONE_SHOT_FROM`]), `direct` below.
    #[default]
    Auto,
    /// Sparse Cholesky in f64 (faer).
    Direct,
    /// Sparse Cholesky in f32 as the preconditioner of f64 conjugate gradients: half the
    /// factor's memory, the f64 answer; falls back to `direct` when it does not converge.
    Mixed,
}

impl LinearSolver {
    /// Size from which `auto` picks `mixed`: where the factor's memory starts to matter.
    pub const AUTO_MIXED_FROM: usize = 100_000;
    /// Size from which `auto` picks `mixed` for a one-shot static solve (a stand-alone static
    /// analysis, the closing solve of one-way coupling and its pressure-equivalent reference):
    /// solved once, the f32 factor's half-size and faster factorisation win; a structure
    /// re-solved every coupling window keeps the f64 factor below [`Self::AUTO_MIXED_FROM`],
    /// whose single triangular solve per window is cheaper than the conjugate gradients'
    /// three or four (docs/performance.md, *FEM*).
    pub const AUTO_MIXED_ONE_SHOT_FROM: usize = 20_000;
    /// Whether a static solve of `n_eq` equations uses the mixed-precision solver
    /// (`one_shot`: a solve not repeated every window).
    pub fn mixed_for(self, n_eq: usize, one_shot: bool) -> bool {
        match self {
            LinearSolver::Auto => {
                n_eq >= Self::AUTO_MIXED_FROM || one_shot && n_eq >= Self::AUTO_MIXED_ONE_SHOT_FROM
            }
            LinearSolver::Direct => false,
            LinearSolver::Mixed => true,
        }
    }
}

/// Mesh source.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub enum MeshSpec {
    /// A `.msh` (Gmsh 4.1 ASCII) or `.inp` (Abaqus/CalculiX) file; `hex8_incompatible`
    /// switches C3D8 hexahedra to the incompatible-modes formulation, `hex8_bbar` to the
    /// mean-dilatation B̄ one.
    File {
        path: String,
        hex8_incompatible: bool,
        hex8_bbar: bool,
    },
    /// Structured box `[origin, origin + size]` [m] with element edge ≈ `element_size` [m]
    /// (or explicit `divisions`).
    Box {
        size: [f64; 3],
        origin: [f64; 3],
        element_size: Option<f64>,
        divisions: Option<[usize; 3]>,
        element: ElementKind,
    },
    /// Structured rectangle of MITC4 shells (`element = "mitc4"`): `size` has one zero
    /// component, the normal axis (the shells' directors point along +axis); the mid-surface
    /// lies at `origin`'s coordinate on it.
    Plate {
        size: [f64; 3],
        origin: [f64; 3],
        element_size: Option<f64>,
        divisions: Option<[usize; 3]>,
    },
    /// Structured cylindrical membrane about the z axis (`element = "m3d4"` quadrilaterals or
    /// `"m3d3"` triangles, two per quadrilateral): `radius`, `height` [m], bottom centre
    /// `origin`, `divisions = [around, along]`. Normals point outwards; node sets `bottom`,
    /// `top`, `all`.
    Cylinder {
        radius: f64,
        height: f64,
        origin: [f64; 3],
        divisions: [usize; 2],
        triangles: bool,
    },
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct MeshTable {
    file: Option<String>,
    #[serde(default)]
    hex8: Option<Hex8Formulation>,
    size: Option<[f64; 3]>,
    origin: Option<[f64; 3]>,
    element_size: Option<f64>,
    /// Three counts for a box or plate, [around, along] for a membrane cylinder.
    divisions: Option<Vec<usize>>,
    /// A volume element kind, "mitc4" for a plate of shells, "m3d4"/"m3d3" for a cylinder of
    /// membranes.
    element: Option<String>,
    radius: Option<f64>,
    height: Option<f64>,
}

#[derive(Deserialize, Clone, Copy, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
enum Hex8Formulation {
    Full,
    Incompatible,
    Bbar,
}

impl<'de> Deserialize<'de> for MeshSpec {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = MeshSpec;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str(
                    "a mesh file path or a table { size, element_size, element } / { file }",
                )
            }
            fn visit_str<E: de::Error>(self, s: &str) -> Result<MeshSpec, E> {
                Ok(MeshSpec::File {
                    path: s.to_string(),
                    hex8_incompatible: false,
                    hex8_bbar: false,
                })
            }
            fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<MeshSpec, A::Error> {
                let t = MeshTable::deserialize(de::value::MapAccessDeserializer::new(map))?;
                if let Some(path) = t.file {
                    if t.size.is_some()
                        || t.element_size.is_some()
                        || t.divisions.is_some()
                        || t.element.is_some()
                        || t.origin.is_some()
                        || t.radius.is_some()
                        || t.height.is_some()
                    {
                        return Err(de::Error::custom("mesh: give either `file` or a generated box (`size`, `element_size`, `element`), not both"));
                    }
                    return Ok(MeshSpec::File {
                        path,
                        hex8_incompatible: t.hex8 == Some(Hex8Formulation::Incompatible),
                        hex8_bbar: t.hex8 == Some(Hex8Formulation::Bbar),
                    });
                }
                if let Some(kind @ ("m3d4" | "m3d3")) = t.element.as_deref() {
                    let (Some(radius), Some(height)) = (t.radius, t.height) else {
                        return Err(de::Error::custom(format!(
                            "mesh: a generated membrane (element = \"{kind}\") is a cylinder: \
                             give radius, height, divisions = [around, along] (and origin, its \
                             bottom centre)"
                        )));
                    };
                    if t.size.is_some() || t.element_size.is_some() || t.hex8.is_some() {
                        return Err(de::Error::custom(
                            "mesh: a membrane cylinder takes radius, height, divisions and origin \
                             (not size, element_size or hex8)",
                        ));
                    }
                    let d = match t.divisions.as_deref() {
                        Some(&[around, along]) => [around, along],
                        _ => return Err(de::Error::custom(
                            "mesh.divisions: a membrane cylinder needs divisions = [around, along]",
                        )),
                    };
                    return Ok(MeshSpec::Cylinder {
                        radius,
                        height,
                        origin: t.origin.unwrap_or([0.0; 3]),
                        divisions: d,
                        triangles: kind == "m3d3",
                    });
                }
                if t.radius.is_some() || t.height.is_some() {
                    return Err(de::Error::custom(
                        "mesh: radius and height describe a membrane cylinder (element = \"m3d4\" or \"m3d3\")",
                    ));
                }
                let size = t
                    .size
                    .ok_or_else(|| de::Error::custom("mesh: missing `file` or box `size`"))?;
                let divisions = match t.divisions.as_deref() {
                    None => None,
                    Some(&[a, b, c]) => Some([a, b, c]),
                    Some(d) => {
                        return Err(de::Error::custom(format!(
                            "mesh.divisions: a box or plate takes three counts [x, y, z], got {d:?}"
                        )))
                    }
                };
                if t.hex8.is_some() {
                    return Err(de::Error::custom(
                        "mesh.hex8 applies to mesh files; for a box use element = \"hex8i\" or \"hex8b\"",
                    ));
                }
                let origin = t.origin.unwrap_or([0.0; 3]);
                let element = match t.element.as_deref() {
                    None => ElementKind::Hex8,
                    Some("mitc4") => {
                        return Ok(MeshSpec::Plate {
                            size,
                            origin,
                            element_size: t.element_size,
                            divisions,
                        })
                    }
                    Some(name) => ElementKind::deserialize(de::value::StrDeserializer::<
                        de::value::Error,
                    >::new(name))
                    .map_err(|_| {
                        de::Error::custom(format!(
                            "mesh.element: unknown element \"{name}\", expected one of tet4, \
                             tet10, hex8, hex8i, hex8b, hex20 (volumes), mitc4 (shells) or \
                             m3d4, m3d3 (membrane cylinders)"
                        ))
                    })?,
                };
                Ok(MeshSpec::Box {
                    size,
                    origin,
                    element_size: t.element_size,
                    divisions,
                    element,
                })
            }
        }
        d.deserialize_any(V)
    }
}

/// Isotropic linear elastic material.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Material {
    /// Young's modulus E [Pa].
    #[serde(alias = "E")]
    pub youngs_modulus: f64,
    /// Poisson's ratio ν, −1 < ν < 0.5.
    #[serde(alias = "nu")]
    pub poisson_ratio: f64,
    /// Density ρ [kg/m³].
    #[serde(alias = "rho")]
    pub density: f64,
}

/// `[fem.materials.<name>]`: a constitutive model and its parameters (FEM.md "Materials").
/// Angles in degrees.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(tag = "model", rename_all = "snake_case", deny_unknown_fields)]
pub enum MaterialSpec {
    /// Isotropic linear elasticity (Ullrich (2.35)–(2.37)).
    LinearElastic {
        #[serde(alias = "E")]
        youngs_modulus: f64,
        #[serde(alias = "nu")]
        poisson_ratio: f64,
        #[serde(alias = "rho")]
        density: f64,
    },
    /// Compressible Neo-Hooke (Wellmann §2.1.4), finite strain; E, ν are the small-strain
    /// moduli.
    NeoHooke {
        #[serde(alias = "E")]
        youngs_modulus: f64,
        #[serde(alias = "nu")]
        poisson_ratio: f64,
        #[serde(alias = "rho")]
        density: f64,
    },
    /// Decoupled Mooney–Rivlin, finite strain: c₁ = (1 − c) G/2, c₂ = c G/2 with
    /// c = `second_invariant_share` (Wellmann's c, §4.3.3), G and K from E, ν.
    MooneyRivlin {
        #[serde(alias = "E")]
        youngs_modulus: f64,
        #[serde(alias = "nu")]
        poisson_ratio: f64,
        #[serde(alias = "c")]
        second_invariant_share: f64,
        #[serde(alias = "rho")]
        density: f64,
    },
    /// Decoupled Ogden, finite strain: `terms = [[μ₁, α₁], ...]` (1 to 3 terms, μ_p in Pa);
    /// the bulk modulus follows from the small-strain shear modulus ½ Σ μ_p α_p and ν.
    Ogden {
        terms: Vec<[f64; 2]>,
        #[serde(alias = "nu")]
        poisson_ratio: f64,
        #[serde(alias = "rho")]
        density: f64,
    },
    /// Non-associative Mohr–Coulomb perfect plasticity, small strain (Wellmann (2.31)–(2.37),
    /// (2.32) corrected).
    MohrCoulomb {
        #[serde(alias = "E")]
        youngs_modulus: f64,
        #[serde(alias = "nu")]
        poisson_ratio: f64,
        /// φ [°].
        friction_angle: f64,
        /// ψ [°], 0 ≤ ψ ≤ φ.
        dilation_angle: f64,
        /// c [Pa].
        cohesion: f64,
        #[serde(alias = "rho")]
        density: f64,
    },
}

impl MaterialSpec {
    pub fn density(&self) -> f64 {
        match self {
            MaterialSpec::LinearElastic { density, .. }
            | MaterialSpec::NeoHooke { density, .. }
            | MaterialSpec::MooneyRivlin { density, .. }
            | MaterialSpec::Ogden { density, .. }
            | MaterialSpec::MohrCoulomb { density, .. } => *density,
        }
    }
}

/// `[[fem.sections]]`: the elements of a set get a material.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Section {
    /// Element set of the mesh (Gmsh 3-D physical group, Abaqus *ELSET) by name, `"all"`, or
    /// a selector table (`{ box = ... }`, `{ plane = ... }`: the elements whose nodes are all
    /// selected).
    pub elements: SectionElements,
    /// A name under `[fem.materials]`.
    pub material: String,
}

/// Which elements a section covers.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(untagged)]
pub enum SectionElements {
    Set(String),
    Select(Selector),
}

/// `[fem.newton]`: controls of the Newton–Raphson iterations of nonlinear models.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct NewtonConfig {
    /// Converged when ‖R‖ ≤ this × the force scale (max of ‖F_ext‖ and ‖f_int‖ incl.
    /// reactions) ...
    pub force_tolerance: f64,
    /// ... and the last correction ‖δu‖ ≤ this × ‖Δu‖ of the increment.
    pub displacement_tolerance: f64,
    /// Iterations per increment before it is cut back.
    pub max_iterations: u32,
    /// Load increments per static solve (per `advance`); cut-backs halve them as needed.
    pub increments: u32,
    /// Halvings of a failed increment (static) or time step (Bossak) before giving up.
    pub max_cutbacks: u32,
    /// Use the Newton path even when every material is linear (verification).
    pub always: bool,
    /// `"full"` (default): a new tangent every iteration (quadratic convergence);
    /// `"modified"`: one factor per increment or time step, refreshed only when an iteration
    /// cuts the residual by less than 4× (fewer factorisations, more iterations).
    pub tangent: TangentUpdate,
}

/// How often Newton iterations factorise the tangent.
#[derive(Clone, Copy, Debug, Default, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum TangentUpdate {
    #[default]
    Full,
    Modified,
}

impl Default for NewtonConfig {
    fn default() -> Self {
        NewtonConfig {
            force_tolerance: 1e-8,
            displacement_tolerance: 1e-8,
            max_iterations: 25,
            increments: 1,
            max_cutbacks: 10,
            always: false,
            tangent: TangentUpdate::Full,
        }
    }
}

/// Analysis type and its parameters.
#[derive(Clone, Debug, Serialize, PartialEq, Default)]
pub enum Analysis {
    /// K u = F(t) at each `advance` (2.28).
    #[default]
    Static,
    /// Bossak–Newmark (Wood–Bossak–Zienkiewicz, REFERENCE A6).
    Dynamic {
        /// α_B ∈ [−1/3, 0]; γ = 1/2 − α_B, β = (1 − α_B)²/4. Default −0.1.
        alpha_b: f64,
        /// Rayleigh damping C = a M + b K (2.84): a [1/s], b [s].
        rayleigh_a: f64,
        rayleigh_b: f64,
        /// Consistent (default) or lumped mass matrix.
        lumped_mass: bool,
        /// Longest step (s): a longer coupling window is stepped in equal substeps no longer
        /// than this (the interface forces held), so the structure's own dynamics do not
        /// depend on the window (adaptive windows). None: one step per window.
        max_step: Option<f64>,
    },
    /// Central differences with lumped mass; substeps of `safety` × critical Δt.
    Explicit {
        safety: f64,
        rayleigh_a: f64,
        rayleigh_b: f64,
    },
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct AnalysisTable {
    #[serde(rename = "type")]
    kind: String,
    alpha_b: Option<f64>,
    rayleigh_a: Option<f64>,
    rayleigh_b: Option<f64>,
    mass: Option<String>,
    safety: Option<f64>,
    /// s.
    max_step: Option<f64>,
}

fn analysis_from(t: AnalysisTable) -> Result<Analysis, String> {
    let only = |allowed: &[&str]| -> Result<(), String> {
        let given = [
            ("alpha_b", t.alpha_b.is_some()),
            ("rayleigh_a", t.rayleigh_a.is_some()),
            ("rayleigh_b", t.rayleigh_b.is_some()),
            ("mass", t.mass.is_some()),
            ("safety", t.safety.is_some()),
            ("max_step", t.max_step.is_some()),
        ];
        for (name, set) in given {
            if set && !allowed.contains(&name) {
                return Err(format!(
                    "analysis.{name} does not apply to analysis type \"{}\"",
                    t.kind
                ));
            }
        }
        Ok(())
    };
    match t.kind.as_str() {
        "static" => {
            only(&[])?;
            Ok(Analysis::Static)
        }
        "dynamic" => {
            only(&["alpha_b", "rayleigh_a", "rayleigh_b", "mass", "max_step"])?;
            if let Some(h) = t.max_step {
                if !(h > 0.0 && h.is_finite()) {
                    return Err(format!("analysis.max_step: must be a positive time in s, got {h}"));
                }
            }
            let lumped = match t.mass.as_deref() {
                None | Some("consistent") => false,
                Some("lumped") => true,
                Some(o) => return Err(format!("analysis.mass: unknown value \"{o}\", expected \"consistent\" or \"lumped\"")),
            };
            Ok(Analysis::Dynamic {
                alpha_b: t.alpha_b.unwrap_or(-0.1),
                rayleigh_a: t.rayleigh_a.unwrap_or(0.0),
                rayleigh_b: t.rayleigh_b.unwrap_or(0.0),
                lumped_mass: lumped,
                max_step: t.max_step,
            })
        }
        "explicit" => {
            only(&["safety", "rayleigh_a", "rayleigh_b"])?;
            Ok(Analysis::Explicit {
                safety: t.safety.unwrap_or(0.9),
                rayleigh_a: t.rayleigh_a.unwrap_or(0.0),
                rayleigh_b: t.rayleigh_b.unwrap_or(0.0),
            })
        }
        o => Err(format!("analysis.type: unknown analysis \"{o}\", expected \"static\", \"dynamic\" or \"explicit\"")),
    }
}

impl<'de> Deserialize<'de> for Analysis {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Analysis;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("\"static\", \"dynamic\", \"explicit\" or a table with `type`")
            }
            fn visit_str<E: de::Error>(self, s: &str) -> Result<Analysis, E> {
                analysis_from(AnalysisTable {
                    kind: s.to_string(),
                    alpha_b: None,
                    rayleigh_a: None,
                    rayleigh_b: None,
                    mass: None,
                    safety: None,
                    max_step: None,
                })
                .map_err(E::custom)
            }
            fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<Analysis, A::Error> {
                let t = AnalysisTable::deserialize(de::value::MapAccessDeserializer::new(map))?;
                analysis_from(t).map_err(de::Error::custom)
            }
        }
        d.deserialize_any(V)
    }
}

/// Node / face selection: exactly one of `set`, `box`, `plane`.
#[derive(Clone, Debug, Deserialize, Serialize, Default, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Selector {
    /// Named node set of the mesh (Gmsh physical group, Abaqus *NSET, box face `xmin` ...).
    pub set: Option<String>,
    /// Nodes inside the axis-aligned box [m] (inclusive).
    #[serde(rename = "box")]
    pub bbox: Option<BoxSelector>,
    /// Nodes with |x_axis − value| ≤ tol [m].
    pub plane: Option<PlaneSelector>,
}

#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct BoxSelector {
    pub min: [f64; 3],
    pub max: [f64; 3],
}

#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct PlaneSelector {
    /// "x", "y" or "z".
    pub axis: Axis,
    pub value: f64,
    /// Default 1e-6 × the mesh's bounding-box diagonal.
    pub tol: Option<f64>,
}

#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum Axis {
    X,
    Y,
    Z,
}

impl Axis {
    pub fn index(self) -> usize {
        match self {
            Axis::X => 0,
            Axis::Y => 1,
            Axis::Z => 2,
        }
    }
}

/// `[[fem.supports]]`: fixes displacement components of the selected nodes to zero.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Support {
    pub on: Selector,
    /// Components to fix (default all three).
    #[serde(default = "all_axes")]
    pub fix: Vec<Axis>,
    /// Prescribed displacement [m] of the fixed components (x, y, z; the others must be 0),
    /// scaled by `history(t)` (default 1): a support that moves. Default zero.
    #[serde(default)]
    pub displacement: Option<[f64; 3]>,
    /// History scaling `displacement`.
    #[serde(default)]
    pub history: Option<String>,
    /// Shell meshes: rotations held about these axes (default all three, whatever `fix`
    /// holds: with the default `fix`, a clamp; `rotations = []` for a hinge; `fix = []` with
    /// rotations for a support of rotations only, e.g. a symmetry plane).
    #[serde(default)]
    pub rotations: Option<Vec<Axis>>,
    /// Membranes: the `fix`ed components are free until `start`, then move at `velocity`
    /// [m/s] from wherever they are (a ring clamped to a triaxial cell's platen, which
    /// settles under a load and is then driven at a constant rate).
    #[serde(default)]
    pub drive: Option<SupportDrive>,
    /// Volume meshes: report the support's reaction force (the sum over its nodes of
    /// K u − F on the fixed components; a component two supports fix reports to the first) as
    /// `reaction.<name>.{x,y,z}` in the results and in `fem_probes.csv` (a triaxial sample's
    /// boundary stress: reaction / face area).
    #[serde(default)]
    pub name: Option<String>,
}

/// `[[fem.supports]] drive = { velocity = [..], start = .. }` (membranes).
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SupportDrive {
    pub velocity: [f64; 3],
    pub start: f64,
}

fn all_axes() -> Vec<Axis> {
    vec![Axis::X, Axis::Y, Axis::Z]
}

/// `[[fem.loads]]`, scaled by `history(t)` (default 1).
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum Load {
    /// Uniform pressure [Pa] on the exterior faces whose nodes are all selected; positive
    /// pushes into the body. Consistent nodal loads.
    Pressure {
        on: Selector,
        value: f64,
        #[serde(default)]
        history: Option<String>,
    },
    /// Nodal force [N]: `per_node` on every selected node, or `total` split equally.
    Force {
        on: Selector,
        #[serde(default)]
        per_node: Option<[f64; 3]>,
        #[serde(default)]
        total: Option<[f64; 3]>,
        #[serde(default)]
        history: Option<String>,
    },
    /// Body force ρ g [N/m³] from an acceleration field g [m/s²] (e.g. [0, 0, −9.81]).
    Gravity {
        acceleration: [f64; 3],
        #[serde(default)]
        history: Option<String>,
    },
}

/// A force load's force [N] on each of `count` selected nodes: `per_node`, or `total` split
/// equally (the scene's validation gives exactly one).
pub fn nodal_force(
    per_node: &Option<[f64; 3]>,
    total: &Option<[f64; 3]>,
    count: usize,
) -> [f64; 3] {
    match (per_node, total) {
        (Some(p), _) => *p,
        (None, Some(t)) => t.map(|v| v / count as f64),
        (None, None) => unreachable!("validated: per_node or total"),
    }
}

/// `[fem.interface]`: the coupled part of the exterior surface.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct InterfaceSpec {
    pub on: Selector,
    /// Shell meshes: the reference surfaces the DEM sees (default both).
    #[serde(default)]
    pub faces: Option<ShellFaces>,
}

/// `[fem.overlap]`: the overlap Ω^C of the mesh with a particle region (Wellmann ch. 6). The
/// particles alone fill `de_region` (Ω^DE \ Ω^FE, which the mesh must not cover); the weight
/// of the particles is w = 1 − d / width at a node at distance d from that box (1 on the box,
/// 0 from `width` on), interpolated in the elements (6.27); the elements with a node of w > 0
/// form the overlap, every FE integral is weighted by 1 − w (6.3).
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct OverlapSpec {
    pub de_region: BoxSelector,
    /// Thickness of the overlap [m] (Wellmann: one or two element layers).
    pub width: f64,
    /// The penalty ε of (6.23) [Pa/m² = N/m⁴] (default Wellmann's converged 1e8 Pa/mm²).
    #[serde(default = "default_overlap_penalty")]
    pub penalty: f64,
    /// Remove the mesh's elements that lie in `de_region` (all their nodes inside) instead of
    /// refusing them: a box mesh with a pocket for the particles (default false).
    #[serde(default)]
    pub carve: bool,
}

fn default_overlap_penalty() -> f64 {
    1e14
}

/// `[[fem.probes]]`: a named node (by file id) or the node nearest to a point.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Probe {
    pub name: String,
    pub node: Option<u64>,
    pub point: Option<[f64; 3]>,
}

/// `[[fem.strain_gauges]]`: the largest strains over a part of the mesh (default all of it),
/// reported as `strain.<name>.max_principal`, `.min_principal`, `.von_mises`.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct StrainGauge {
    pub name: String,
    /// Elements whose nodes are all selected (a `set` naming an element set selects its
    /// elements); default every element.
    #[serde(default)]
    pub on: Option<Selector>,
}

/// `[fem.output]`.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Output {
    /// Write a `.vtu` every this many coupling windows (0 = never). Default 1.
    #[serde(default = "one")]
    pub vtu_every: u64,
    /// Append probe rows to `fem_probes.csv` after each window. Default true.
    #[serde(default = "yes")]
    pub csv: bool,
}

fn one() -> u64 {
    1
}
fn yes() -> bool {
    true
}

impl Default for Output {
    fn default() -> Self {
        Output {
            vtu_every: 1,
            csv: true,
        }
    }
}

/// Parses the `[fem]` table of a whole scene file; other top-level tables are ignored.
/// `Ok(None)` when there is no `[fem]` table.
pub fn parse_scene_section(text: &str) -> Result<Option<FemConfig>, SceneError> {
    parse_scene_table(text, "fem")
}

/// Parses the top-level table `table` of a whole scene file with the `[fem]` schema (a scene
/// with several structures has one such table per FEM node, named by the node's id). Errors
/// give the file's line and column and the field's path under `table`.
pub fn parse_scene_table(text: &str, table: &str) -> Result<Option<FemConfig>, SceneError> {
    let parsed: Option<FemConfig> = scenefile::named_table(text, table).map_err(|e| {
        let offset = e.span().map(|s| s.start).unwrap_or(0);
        let mut message = e.message().trim().to_string();
        if let Some(path) = scenefile::path_at(text, offset) {
            if !message.contains(&path) {
                message = format!("{path}: {message}");
            }
        }
        SceneError::at(text, offset, "", message)
    })?;
    let Some(cfg) = parsed else {
        return Ok(None);
    };
    if let Err((path, msg)) = cfg.validate() {
        // the checks name paths under `fem`; this table may have another name
        let path = match path.strip_prefix("fem") {
            Some(rest) if table != "fem" => format!("{table}{rest}"),
            _ => path,
        };
        let at = scenefile::locate(text, &scenefile::split_path(&path)).map_or(0, |r| r.start);
        return Err(SceneError::at(text, at, "", format!("{path}: {msg}")));
    }
    Ok(Some(cfg))
}

fn check_membrane(m: &MembraneSection) -> Result<(), (String, String)> {
    if let Some(t) = m.thickness.filter(|t| !(t.is_finite() && *t > 0.0)) {
        return Err((
            "fem.membrane.thickness".into(),
            format!("must be > 0 m, got {t}"),
        ));
    }
    check_density("fem.membrane", m.density)?;
    if m.ogden.is_empty() || m.ogden.len() > 3 {
        return Err((
            "fem.membrane.ogden".into(),
            format!("give 1 to 3 terms [μ_p (Pa), α_p], got {}", m.ogden.len()),
        ));
    }
    for (p, [mu, alpha]) in m.ogden.iter().enumerate() {
        if !(mu.is_finite() && alpha.is_finite() && *alpha != 0.0 && mu * alpha > 0.0) {
            return Err((
                format!("fem.membrane.ogden[{p}]"),
                format!(
                    "each term needs μ_p α_p > 0 (Ogden's stability condition; α_p ≠ 0), got \
                     μ = {mu}, α = {alpha}"
                ),
            ));
        }
    }
    Ok(())
}

fn check_elastic(base: &str, e: f64, nu: f64) -> Result<(), (String, String)> {
    if !(e.is_finite() && e > 0.0) {
        return Err((
            format!("{base}.youngs_modulus"),
            format!("must be > 0 Pa, got {e}"),
        ));
    }
    check_poisson(base, nu)
}

fn check_poisson(base: &str, nu: f64) -> Result<(), (String, String)> {
    if !(nu > -1.0 && nu < 0.5) {
        return Err((
            format!("{base}.poisson_ratio"),
            format!("must satisfy −1 < ν < 0.5, got {nu}"),
        ));
    }
    Ok(())
}

fn check_density(base: &str, rho: f64) -> Result<(), (String, String)> {
    if !(rho.is_finite() && rho > 0.0) {
        return Err((
            format!("{base}.density"),
            format!("must be > 0 kg/m³, got {rho}"),
        ));
    }
    Ok(())
}

/// Parameter checks of one `[fem.materials.<name>]` table (`base` is its path).
fn check_material(base: &str, m: &MaterialSpec) -> Result<(), (String, String)> {
    check_density(base, m.density())?;
    match m {
        MaterialSpec::LinearElastic {
            youngs_modulus,
            poisson_ratio,
            ..
        }
        | MaterialSpec::NeoHooke {
            youngs_modulus,
            poisson_ratio,
            ..
        } => check_elastic(base, *youngs_modulus, *poisson_ratio),
        MaterialSpec::MooneyRivlin {
            youngs_modulus,
            poisson_ratio,
            second_invariant_share: c,
            ..
        } => {
            check_elastic(base, *youngs_modulus, *poisson_ratio)?;
            if !(*c >= 0.0 && *c <= 1.0) {
                return Err((
                    format!("{base}.second_invariant_share"),
                    format!("must lie in [0, 1] (c₁ = (1 − c) G/2 and c₂ = c G/2 must not be negative), got {c}"),
                ));
            }
            Ok(())
        }
        MaterialSpec::Ogden {
            terms,
            poisson_ratio,
            ..
        } => {
            check_poisson(base, *poisson_ratio)?;
            if terms.is_empty() || terms.len() > 3 {
                return Err((
                    format!("{base}.terms"),
                    format!("give 1 to 3 terms [μ_p, α_p], got {}", terms.len()),
                ));
            }
            for (p, [mu, alpha]) in terms.iter().enumerate() {
                if !(mu.is_finite() && alpha.is_finite()) || *alpha == 0.0 {
                    return Err((
                        format!("{base}.terms[{p}]"),
                        format!("μ and α must be finite and α ≠ 0, got [{mu}, {alpha}]"),
                    ));
                }
                if !(mu * alpha > 0.0) {
                    return Err((
                        format!("{base}.terms[{p}]"),
                        format!(
                            "μ_p α_p = {} must be > 0 for every term (Ogden's stability condition)",
                            mu * alpha
                        ),
                    ));
                }
            }
            Ok(())
        }
        MaterialSpec::MohrCoulomb {
            youngs_modulus,
            poisson_ratio,
            friction_angle,
            dilation_angle,
            cohesion,
            ..
        } => {
            check_elastic(base, *youngs_modulus, *poisson_ratio)?;
            if !(friction_angle.is_finite() && dilation_angle.is_finite() && cohesion.is_finite()) {
                return Err((
                    format!("{base}.friction_angle"),
                    "friction_angle, dilation_angle and cohesion must be finite".into(),
                ));
            }
            crate::material::mohr_coulomb::MohrCoulomb::check(
                *youngs_modulus,
                *poisson_ratio,
                friction_angle.to_radians(),
                dilation_angle.to_radians(),
                *cohesion,
            )
            .map_err(|(field, msg)| (format!("{base}.{field}"), msg))
        }
    }
}

impl FemConfig {
    /// `field` names history `h`: it must be one of `[fem.histories]`.
    fn check_history(&self, field: &str, h: &str) -> Result<(), (String, String)> {
        if self.histories.contains_key(h) {
            return Ok(());
        }
        Err((
            field.to_string(),
            format!(
                "unknown history '{h}' (defined in [fem.histories]: {})",
                self.histories
                    .keys()
                    .cloned()
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        ))
    }

    /// Value checks; the error carries the field path (e.g. `fem.material.poisson_ratio`).
    pub fn validate(&self) -> Result<(), (String, String)> {
        if let Some(m) = &self.material {
            check_elastic("fem.material", m.youngs_modulus, m.poisson_ratio)?;
            check_density("fem.material", m.density)?;
        }
        for (name, m) in &self.materials {
            check_material(&format!("fem.materials.{name}"), m)?;
        }
        for (i, sec) in self.sections.iter().enumerate() {
            if !self.materials.contains_key(&sec.material) {
                let known: Vec<&str> = self.materials.keys().map(String::as_str).collect();
                return Err((
                    format!("fem.sections[{i}].material"),
                    format!(
                        "no material \"{}\" under [fem.materials] (defined: {})",
                        sec.material,
                        if known.is_empty() {
                            "none".to_string()
                        } else {
                            known.join(", ")
                        }
                    ),
                ));
            }
            match &sec.elements {
                SectionElements::Set(name) if name.trim().is_empty() => {
                    return Err((
                        format!("fem.sections[{i}].elements"),
                        "empty element set name".into(),
                    ));
                }
                SectionElements::Set(_) => {}
                SectionElements::Select(sel) => {
                    check_selector(sel, &format!("fem.sections[{i}].elements"))?
                }
            }
        }
        if let Some(m) = &self.membrane {
            check_membrane(m)?;
            if m.thickness.is_none() && matches!(self.mesh, MeshSpec::Cylinder { .. }) {
                return Err((
                    "fem.membrane.thickness".into(),
                    "missing: a generated cylinder has no section to take it from (give t₀ in m)"
                        .into(),
                ));
            }
            if self.material.is_some() || !self.materials.is_empty() || !self.sections.is_empty() {
                return Err((
                    "fem.membrane".into(),
                    "a membrane's material is its [fem.membrane] ogden terms and density; \
                     remove [fem.material] / [fem.materials] / [[fem.sections]]"
                        .into(),
                ));
            }
        } else if matches!(self.mesh, MeshSpec::Cylinder { .. }) {
            return Err((
                "fem.membrane".into(),
                "a generated cylinder (element = \"m3d4\" / \"m3d3\") is a membrane: give \
                 [fem.membrane] thickness, density and ogden terms"
                    .into(),
            ));
        }
        if self.material.is_none() && self.sections.is_empty() && self.membrane.is_none() {
            return Err((
                "fem.material".into(),
                "missing: give [fem.material] (linear elastic, every element) or \
                 [fem.materials.<name>] with [[fem.sections]] assigning them"
                    .into(),
            ));
        }
        let n = &self.newton;
        for (field, v) in [
            ("force_tolerance", n.force_tolerance),
            ("displacement_tolerance", n.displacement_tolerance),
        ] {
            if !(v.is_finite() && v > 0.0 && v < 1.0) {
                return Err((
                    format!("fem.newton.{field}"),
                    format!("must lie in (0, 1), got {v}"),
                ));
            }
        }
        if n.max_iterations == 0 || n.increments == 0 {
            return Err((
                format!(
                    "fem.newton.{}",
                    if n.max_iterations == 0 {
                        "max_iterations"
                    } else {
                        "increments"
                    }
                ),
                "must be ≥ 1".into(),
            ));
        }
        if n.max_cutbacks > 30 {
            return Err((
                "fem.newton.max_cutbacks".into(),
                format!("at most 30 (an increment of 2⁻³⁰), got {}", n.max_cutbacks),
            ));
        }
        match &self.mesh {
            MeshSpec::File { path, .. } => {
                if path.trim().is_empty() {
                    return Err(("fem.mesh".into(), "empty mesh file path".into()));
                }
            }
            MeshSpec::Cylinder {
                radius,
                height,
                origin,
                divisions,
                ..
            } => {
                for (field, v) in [("radius", radius), ("height", height)] {
                    if !(v.is_finite() && *v > 0.0) {
                        return Err((
                            format!("fem.mesh.{field}"),
                            format!("must be > 0 m, got {v}"),
                        ));
                    }
                }
                if origin.iter().any(|o| !o.is_finite()) {
                    return Err(("fem.mesh.origin".into(), "must be finite".into()));
                }
                if divisions[0] < 3 || divisions[1] < 1 {
                    return Err((
                        "fem.mesh.divisions".into(),
                        format!("[around, along] must be at least [3, 1], got {divisions:?}"),
                    ));
                }
                if divisions[0] as u64 * divisions[1] as u64 > 10_000_000 {
                    return Err((
                        "fem.mesh.divisions".into(),
                        format!("{divisions:?} makes more than 1e7 membranes"),
                    ));
                }
            }
            MeshSpec::Plate { size, origin, .. } => {
                let zeros = size.iter().filter(|&&s| s == 0.0).count();
                if zeros != 1 || size.iter().any(|&s| !(s.is_finite() && s >= 0.0)) {
                    return Err((
                        "fem.mesh.size".into(),
                        format!(
                            "a plate of shells (element = \"mitc4\") has two sizes > 0 m and one \
                             0 (its normal axis), got {size:?}"
                        ),
                    ));
                }
                if origin.iter().any(|o| !o.is_finite()) {
                    return Err(("fem.mesh.origin".into(), "must be finite".into()));
                }
                let div = self
                    .mesh
                    .plate_divisions()
                    .map_err(|m| ("fem.mesh".to_string(), m))?;
                let nodes = (div[0] as u64 + 1) * (div[1] as u64 + 1);
                crate::resources::check_memory(
                    &format!("the generated plate ({div:?} shells, {nodes} nodes)"),
                    // six dofs per node: twice a solid node's share
                    2.0 * crate::resources::model_bytes(nodes, (div[0] * div[1]) as u64),
                    crate::resources::available_memory(),
                )
                .map_err(|m| ("fem.mesh".to_string(), m))?;
            }
            MeshSpec::Box {
                size,
                element_size,
                divisions,
                origin,
                ..
            } => {
                if size.iter().any(|&s| !(s.is_finite() && s > 0.0)) {
                    return Err((
                        "fem.mesh.size".into(),
                        format!("all sizes must be > 0 m, got {size:?}"),
                    ));
                }
                if origin.iter().any(|o| !o.is_finite()) {
                    return Err(("fem.mesh.origin".into(), "must be finite".into()));
                }
                match (element_size, divisions) {
                    (Some(_), Some(_)) => {
                        return Err((
                            "fem.mesh.divisions".into(),
                            "give either element_size or divisions, not both".into(),
                        ))
                    }
                    (None, None) => {
                        return Err((
                            "fem.mesh".into(),
                            "a generated box needs element_size (or divisions)".into(),
                        ))
                    }
                    (Some(h), None) => {
                        if !(h.is_finite() && *h > 0.0) {
                            return Err((
                                "fem.mesh.element_size".into(),
                                format!("must be > 0 m, got {h}"),
                            ));
                        }
                    }
                    (None, Some(d)) => {
                        if d.contains(&0) {
                            return Err((
                                "fem.mesh.divisions".into(),
                                "must be ≥ 1 in every direction".into(),
                            ));
                        }
                    }
                }
                box_size_check(&self.mesh)?;
            }
        }
        match &self.analysis {
            Analysis::Static => {}
            Analysis::Dynamic {
                alpha_b,
                rayleigh_a,
                rayleigh_b,
                ..
            } => {
                if !(*alpha_b >= -1.0 / 3.0 && *alpha_b <= 0.0) {
                    return Err((
                        "fem.analysis.alpha_b".into(),
                        format!("must lie in [−1/3, 0] (Bossak α_B ≤ 0), got {alpha_b}"),
                    ));
                }
                check_rayleigh(*rayleigh_a, *rayleigh_b)?;
            }
            Analysis::Explicit {
                safety,
                rayleigh_a,
                rayleigh_b,
            } => {
                if !(*safety > 0.0 && *safety <= 1.0) {
                    return Err((
                        "fem.analysis.safety".into(),
                        format!("must be in (0, 1], got {safety}"),
                    ));
                }
                check_rayleigh(*rayleigh_a, *rayleigh_b)?;
            }
        }
        for (i, s) in self.supports.iter().enumerate() {
            check_selector(&s.on, &format!("fem.supports[{i}].on"))?;
            if s.fix.is_empty() && s.rotations.as_ref().is_none_or(|r| r.is_empty()) {
                return Err((
                    format!("fem.supports[{i}].fix"),
                    "fixes no component (and no shell rotation)".into(),
                ));
            }
            if let Some(d) = s.displacement {
                for (c, name) in ["x", "y", "z"].iter().enumerate() {
                    if !d[c].is_finite() {
                        return Err((
                            format!("fem.supports[{i}].displacement"),
                            "must be finite".into(),
                        ));
                    }
                    if d[c] != 0.0 && !s.fix.iter().any(|a| a.index() == c) {
                        return Err((
                            format!("fem.supports[{i}].displacement"),
                            format!("moves {name} by {}, but {name} is not in fix", d[c]),
                        ));
                    }
                }
            }
            if let Some(d) = &s.drive {
                let field = format!("fem.supports[{i}].drive");
                if s.displacement.is_some() || s.history.is_some() {
                    return Err((
                        field,
                        "a support is either driven or displaced by a history, not both".into(),
                    ));
                }
                if !(d.start.is_finite() && d.start >= 0.0) {
                    return Err((
                        format!("{field}.start"),
                        format!("must be ≥ 0 s, got {}", d.start),
                    ));
                }
                for (c, name) in ["x", "y", "z"].iter().enumerate() {
                    if !d.velocity[c].is_finite() {
                        return Err((format!("{field}.velocity"), "must be finite".into()));
                    }
                    if d.velocity[c] != 0.0 && !s.fix.iter().any(|a| a.index() == c) {
                        return Err((
                            format!("{field}.velocity"),
                            format!("moves {name}, but {name} is not in fix"),
                        ));
                    }
                }
                if self.membrane.is_none() {
                    return Err((
                        field,
                        "driven supports are offered for membranes only".into(),
                    ));
                }
            }
            if let Some(h) = &s.history {
                if s.displacement.is_none() {
                    return Err((
                        format!("fem.supports[{i}].history"),
                        "scales nothing: give a displacement".into(),
                    ));
                }
                self.check_history(&format!("fem.supports[{i}].history"), h)?;
            }
        }
        for (name, h) in &self.histories {
            h.validate(&self.histories, 0)
                .map_err(|(p, m)| (join(&format!("fem.histories.{name}"), &p), m))?;
        }
        for (i, l) in self.loads.iter().enumerate() {
            let base = format!("fem.loads[{i}]");
            let history = match l {
                Load::Pressure { on, value, history } => {
                    check_selector(on, &format!("{base}.on"))?;
                    if !value.is_finite() {
                        return Err((format!("{base}.value"), "must be finite".into()));
                    }
                    history
                }
                Load::Force {
                    on,
                    per_node,
                    total,
                    history,
                } => {
                    check_selector(on, &format!("{base}.on"))?;
                    match (per_node, total) {
                        (Some(_), Some(_)) | (None, None) => {
                            return Err((
                                format!("{base}.per_node"),
                                "give exactly one of per_node or total [N]".into(),
                            ))
                        }
                        (Some(f), None) | (None, Some(f)) => {
                            if f.iter().any(|v| !v.is_finite()) {
                                return Err((format!("{base}.total"), "must be finite".into()));
                            }
                        }
                    }
                    history
                }
                Load::Gravity {
                    acceleration,
                    history,
                } => {
                    if acceleration.iter().any(|v| !v.is_finite()) {
                        return Err((format!("{base}.acceleration"), "must be finite".into()));
                    }
                    history
                }
            };
            if let Some(h) = history {
                self.check_history(&format!("{base}.history"), h)?;
            }
        }
        if let Some(i) = &self.interface {
            check_selector(&i.on, "fem.interface.on")?;
        }
        let mut names = std::collections::BTreeSet::new();
        for (i, p) in self.probes.iter().enumerate() {
            if p.name.is_empty() || !names.insert(p.name.clone()) {
                return Err((
                    format!("fem.probes[{i}].name"),
                    format!("probe name '{}' is empty or repeated", p.name),
                ));
            }
            if p.node.is_some() == p.point.is_some() {
                return Err((
                    format!("fem.probes[{i}]"),
                    "give exactly one of node (file id) or point [m]".into(),
                ));
            }
            if let Some(q) = p.point.filter(|q| q.iter().any(|x| !x.is_finite())) {
                return Err((
                    format!("fem.probes[{i}].point"),
                    format!("must be finite (m), got {q:?}"),
                ));
            }
        }
        let mut names = std::collections::BTreeSet::new();
        for (i, g) in self.strain_gauges.iter().enumerate() {
            if g.name.is_empty() || !names.insert(g.name.clone()) {
                return Err((
                    format!("fem.strain_gauges[{i}].name"),
                    format!("strain gauge name '{}' is empty or repeated", g.name),
                ));
            }
            if let Some(on) = &g.on {
                check_selector(on, &format!("fem.strain_gauges[{i}].on"))?;
            }
        }
        Ok(())
    }
}

impl MeshSpec {
    /// The in-plane divisions of a generated plate (its two nonzero axes in increasing
    /// order): `divisions` on those axes, or `size / element_size` rounded, at least 1.
    pub fn plate_divisions(&self) -> Result<[usize; 2], String> {
        let MeshSpec::Plate {
            size,
            element_size,
            divisions,
            ..
        } = self
        else {
            return Err("not a plate".into());
        };
        let axes: Vec<usize> = (0..3).filter(|&k| size[k] != 0.0).collect();
        let d = match (divisions, element_size) {
            (Some(_), Some(_)) => {
                return Err("give either element_size or divisions, not both".into())
            }
            (None, None) => {
                return Err("a generated plate needs element_size (or divisions)".into())
            }
            (Some(d), None) => axes.iter().map(|&k| d[k] as f64).collect::<Vec<_>>(),
            (None, Some(h)) => {
                if !(h.is_finite() && *h > 0.0) {
                    return Err(format!("element_size: must be > 0 m, got {h}"));
                }
                axes.iter()
                    .map(|&k| (size[k] / h).round().max(1.0))
                    .collect()
            }
        };
        if d.iter().any(|n| !(1.0..=1e6).contains(n)) {
            return Err(format!(
                "divisions: 1 to 10⁶ shells along each in-plane axis, got {d:?}"
            ));
        }
        Ok([d[0] as usize, d[1] as usize])
    }

    /// Divisions of a generated box (`divisions`, or `size / element_size` rounded, at least
    /// 1); `None` for a file or when a division does not fit in 32 bits (see
    /// [`box_size_check`], which refuses such a box).
    pub fn box_divisions(&self) -> Option<[usize; 3]> {
        let MeshSpec::Box {
            size,
            element_size,
            divisions,
            ..
        } = self
        else {
            return None;
        };
        let d = match (divisions, element_size) {
            (Some(d), _) => d.map(|n| n as f64),
            (None, Some(h)) => [0, 1, 2].map(|k| (size[k] / h).round().max(1.0)),
            (None, None) => return None,
        };
        if d.iter().all(|n| n.is_finite() && *n <= u32::MAX as f64) {
            Some(d.map(|n| n as usize))
        } else {
            None
        }
    }
}

/// A generated box's node and element counts with overflow-checked products, and the memory
/// the model needs (≈ [`crate::resources::BYTES_PER_NODE`] per node) against the memory
/// available, before anything is allocated. Node indices are 32-bit: the box's grid (which
/// for hex20 / tet10 includes the mid-edge points) must fit.
fn box_size_check(mesh: &MeshSpec) -> Result<(), (String, String)> {
    use crate::resources::{check_memory, format_number, model_bytes};
    let MeshSpec::Box {
        element_size,
        element,
        ..
    } = mesh
    else {
        return Ok(());
    };
    let field = if element_size.is_some() {
        "fem.mesh.element_size"
    } else {
        "fem.mesh.divisions"
    };
    let too_many = |what: String| (field.to_string(), what);
    let div = mesh.box_divisions().ok_or_else(|| {
        too_many(format!(
            "more than {} elements along an edge",
            format_number(u32::MAX as f64)
        ))
    })?;
    let quadratic = matches!(element, ElementKind::Hex20 | ElementKind::Tet10);
    let r: u64 = if quadratic { 2 } else { 1 };
    let per_cell: u64 = match element {
        ElementKind::Tet4 | ElementKind::Tet10 => 6,
        _ => 1,
    };
    let product = |v: [u64; 3]| v[0].checked_mul(v[1])?.checked_mul(v[2]);
    let d = div.map(|n| n as u64);
    let grid = product(d.map(|n| r * n + 1));
    let cells = product(d);
    let elements = cells.and_then(|c| c.checked_mul(per_cell));
    let (Some(grid), Some(elements)) = (grid, elements) else {
        return Err(too_many(format!(
            "divisions {div:?} give more than {} elements (the count overflows)",
            format_number(u64::MAX as f64)
        )));
    };
    // hex20 leaves face and body centres out; every other point of the grid is a node
    let nodes = if *element == ElementKind::Hex20 {
        product(d.map(|n| n + 1)).unwrap_or(grid)
            + d[0] * (d[1] + 1) * (d[2] + 1)
            + (d[0] + 1) * d[1] * (d[2] + 1)
            + (d[0] + 1) * (d[1] + 1) * d[2]
    } else {
        grid
    };
    if grid >= u32::MAX as u64 {
        return Err(too_many(format!(
            "divisions {div:?} give {} grid points, more than the {} a mesh can index",
            format_number(grid as f64),
            format_number(u32::MAX as f64)
        )));
    }
    check_memory(
        &format!(
            "the generated box (divisions {div:?}: {} {} elements, {} nodes)",
            format_number(elements as f64),
            element.name(),
            format_number(nodes as f64)
        ),
        model_bytes(nodes, elements),
        crate::resources::available_memory(),
    )
    .map_err(too_many)
}

fn join(a: &str, b: &str) -> String {
    let b = b.trim_end_matches('.');
    if b.is_empty() {
        a.to_string()
    } else {
        format!("{a}.{b}")
    }
}

fn check_rayleigh(a: f64, b: f64) -> Result<(), (String, String)> {
    if !(a.is_finite() && a >= 0.0) {
        return Err((
            "fem.analysis.rayleigh_a".into(),
            format!("must be ≥ 0 1/s, got {a}"),
        ));
    }
    if !(b.is_finite() && b >= 0.0) {
        return Err((
            "fem.analysis.rayleigh_b".into(),
            format!("must be ≥ 0 s, got {b}"),
        ));
    }
    Ok(())
}

fn check_selector(s: &Selector, path: &str) -> Result<(), (String, String)> {
    let n = s.set.is_some() as u8 + s.bbox.is_some() as u8 + s.plane.is_some() as u8;
    if n != 1 {
        return Err((
            path.to_string(),
            "give exactly one of set, box, plane".into(),
        ));
    }
    if let Some(b) = &s.bbox {
        if (0..3).any(|k| !(b.min[k] <= b.max[k])) {
            return Err((
                format!("{path}.box"),
                "min must be ≤ max in every direction".into(),
            ));
        }
    }
    if let Some(p) = &s.plane {
        if !p.value.is_finite() {
            return Err((
                format!("{path}.plane.value"),
                format!("must be finite (m), got {}", p.value),
            ));
        }
        if let Some(t) = p.tol {
            if !(t >= 0.0 && t.is_finite()) {
                return Err((
                    format!("{path}.plane.tol"),
                    format!("must be finite and ≥ 0 (m), got {t}"),
                ));
            }
        }
    }
    Ok(())
}
