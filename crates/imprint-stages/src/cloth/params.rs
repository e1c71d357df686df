//! The Cloth node's parameters as a pipeline file states them, their defaults and their
//! validation (every error names the field to change).
//!
//! Optional fields are written bare (`wind: (velocity: (1, 0, 0))`), not `Some(...)`, so that
//! plain `ron::from_str` reads what users write; omit a field for `None`.

use glam::Vec3;
use imprint_core::{Error, Result};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Everything the cloth stage needs besides its colliders (the distance fields of the frame).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ClothParams {
    /// The rest shape: a procedural grid or a garment mesh.
    pub shape: Shape,
    /// The spring laws and their constants.
    pub material: Material,
    /// How spring constants are stated; see [`StiffnessMode`].
    #[serde(default)]
    pub stiffness_mode: StiffnessMode,
    /// Mass of one particle, kg.
    #[serde(default = "default_mass")]
    pub mass: f32,
    /// Verlet damping factor d of H eq. 10: x' = x + d (x - x_prev) + a dt². 1 = undamped.
    /// Applied per substep, so the same d damps more with more substeps.
    #[serde(default = "default_damping")]
    pub damping: f32,
    /// Acceleration of gravity, m/s².
    #[serde(default = "default_gravity")]
    #[schemars(with = "[f32; 3]")]
    pub gravity: Vec3,
    /// Air drag against the cloth's faces; none when omitted.
    #[serde(
        default,
        with = "crate::bare_option",
        skip_serializing_if = "Option::is_none"
    )]
    #[schemars(with = "Wind")]
    pub wind: Option<Wind>,
    /// Particles held in place (exactly, bit for bit) or led by [`super::ClothSim::set_pin_targets`].
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub pins: Vec<Pin>,
    /// Contact with the distance fields (and an optional ground plane).
    #[serde(default)]
    pub collision: Collision,
    /// Cloth substeps per body frame (H §5.2): the stability lever of the explicit integrator.
    #[serde(default = "default_substeps")]
    pub substeps: u32,
    /// H §5.3: substep j of n sees the fields blended (1 - j/n, j/n) between the frame's start
    /// and end. Off: every substep sees the end-of-frame field, and contact jerks at frame
    /// boundaries (kept to show that).
    #[serde(default = "default_true")]
    pub blend_fields: bool,
    /// Where a run is declared blown up instead of returning garbage.
    #[serde(default)]
    pub limits: Limits,
}

/// The rest shape.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub enum Shape {
    /// A flat rectangle of `resolution[0] x resolution[1]` particles, `size[0]` wide along its
    /// u axis and `size[1]` along v, centred on `center`, facing `normal`.
    ///
    /// Axes: v is world +y projected onto the plane (so a curtain's "up" is up), or -z when
    /// `normal` is (anti)parallel to y; u = v x normal. UVs run 0..1 along u (warp) and v (weft).
    Grid {
        /// Width along u and height along v, metres.
        size: [f32; 2],
        /// Particles along u and along v (at least 2 each).
        resolution: [u32; 2],
        /// The rectangle's centre, metres (default the origin).
        #[serde(default)]
        #[schemars(with = "[f32; 3]")]
        center: Vec3,
        /// The direction the rectangle faces (default +y: lying flat).
        #[serde(default = "default_normal")]
        #[schemars(with = "[f32; 3]")]
        normal: Vec3,
    },
    /// A garment mesh file (relative to the pipeline file's folder; OBJ, PLY, STL or glTF, as
    /// `imprint_core::load_mesh` reads). Vertices at identical positions are welded into one
    /// particle (OBJ splits them at UV seams); every unique edge becomes a structural spring
    /// and each pair of triangles sharing an edge a shear spring between their opposite
    /// vertices. UVs are kept for the anisotropy lookup and the output.
    Mesh {
        /// The garment file, relative to the pipeline file's folder.
        path: String,
    },
}

/// The spring model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(rename = "ClothMaterial")]
#[serde(deny_unknown_fields)]
pub enum Material {
    /// H eq. 9: linear springs f = k (|x| - l) to the 4 structural and 4 shear neighbours;
    /// `k_bend` adds skip-one springs (grids only; H omits them for speed).
    Harada {
        /// Stiffness of the springs to the 4 grid (or edge) neighbours, N/m (or N per unit
        /// strain with `stiffness_mode: Strain`).
        k_structural: f32,
        /// Stiffness of the diagonal springs, N/m (or per unit strain).
        k_shear: f32,
        /// Stiffness of the skip-one bending springs, N/m (none when left out; grids only).
        #[serde(
            default,
            with = "crate::bare_option",
            skip_serializing_if = "Option::is_none"
        )]
        #[schemars(with = "f32")]
        k_bend: Option<f32>,
    },
    /// T eq. 1, 2, 5: quadratic springs f = a (r - L)² in compression and b (r - L)² in
    /// stretch (structural and shear alike), hinge bending f = c (cos θ - 1) / d across each
    /// pair of triangles, and an optional texture scaling each spring by its direction.
    Tokoi {
        /// a: the quadratic law's constant in compression, N/m² (or per unit strain²).
        a_compress: f32,
        /// b: the quadratic law's constant in stretch, N/m² (or per unit strain²).
        b_stretch: f32,
        /// c: the hinge bending constant across each pair of triangles, N·m (default 0: none).
        #[serde(default)]
        bend_c: f32,
        /// A texture scaling each spring by its direction (none when left out).
        #[serde(
            default,
            with = "crate::bare_option",
            skip_serializing_if = "Option::is_none"
        )]
        #[schemars(with = "Anisotropy")]
        anisotropy: Option<Anisotropy>,
    },
}

/// How the spring constants in [`Material`] are stated.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
pub enum StiffnessMode {
    /// Per spring, whatever its length: f = k (r - l) (H eq. 9), f = b (r - L)² (T eq. 1).
    #[default]
    Force,
    /// Per unit strain, so that refining the mesh keeps the material: f = Y (r/l - 1), i.e.
    /// k = Y / l for each spring (and b / L² for Tokoi's quadratic law).
    Strain,
}

/// T eq. 5: an RGBA texture whose channels scale the springs by direction, read at the
/// spring's midpoint UV: R = Ka (warp, u), G = Kb (weft, v), B = Kc (diagonal +u+v),
/// A = Kd (diagonal +u-v). A spring's multiplier is `scale * channel / 255`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Anisotropy {
    /// PNG file, relative to the pipeline file's folder.
    pub texture: String,
    /// Multiplier of every channel (a channel of 255 scales its springs by `scale`).
    #[serde(default = "default_one")]
    pub scale: f32,
}

/// Drag of the air on the faces: each particle gets `drag * (n̂ · (velocity - v)) * N`, with
/// N its share of the adjacent faces' area vectors (a third of each), n̂ = N / |N| and v its
/// own velocity. Linear in the relative speed (a light, slow cloth), so no square to blow up.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Wind {
    /// Air velocity, m/s.
    #[schemars(with = "[f32; 3]")]
    pub velocity: Vec3,
    /// Force per unit area per unit of normal relative speed, N·s/m³ (= kg/(m²·s)).
    #[serde(default = "default_drag")]
    pub drag: f32,
}

/// Particles that do not integrate: they stay exactly where they are, or follow targets.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
pub enum Pin {
    /// Particle indices (grids: `i + nx * j`, i along u; meshes: welded-particle order).
    Indices(Vec<u32>),
    /// Every particle whose rest position lies in the box.
    Region {
        /// The box's lowest corner, metres.
        #[schemars(with = "[f32; 3]")]
        min: Vec3,
        /// The box's highest corner, metres.
        #[schemars(with = "[f32; 3]")]
        max: Vec3,
    },
    /// Grids: the row at the +v edge (the top of a curtain). Meshes: the particles at the
    /// highest y, within 1e-4 of the mesh's extent.
    TopEdge,
}

/// H §5.1: contact with the distance fields.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Collision {
    /// A particle closer than ε to a body is moved back to distance ε along the field's
    /// vector (eq. 11). Must be smaller than every collider field's band.
    #[serde(default = "default_epsilon")]
    pub epsilon: f32,
    /// Kinetic friction b (eq. 12): the fraction of the tangential displacement cancelled on
    /// contact, in [0, 1].
    #[serde(default = "default_friction")]
    pub friction: f32,
    /// A ground plane y = h, kept at distance ε like the bodies; none when omitted.
    #[serde(
        default,
        with = "crate::bare_option",
        skip_serializing_if = "Option::is_none"
    )]
    #[schemars(with = "f32")]
    pub ground: Option<f32>,
}

/// When a run is stopped with `Error::Numerical` rather than continued.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Limits {
    /// A spring longer than this many times its rest length means the integration exploded.
    #[serde(default = "default_max_stretch")]
    pub max_stretch: f32,
    /// Kinetic energy above this many times max(kinetic energy at the frame's start, the
    /// energy scale M·(|g|·L + |wind|² + (L/dt_frame)²)) means it exploded.
    #[serde(default = "default_energy_growth")]
    pub energy_growth: f32,
}

impl Default for Collision {
    fn default() -> Self {
        Collision {
            epsilon: default_epsilon(),
            friction: default_friction(),
            ground: None,
        }
    }
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_stretch: default_max_stretch(),
            energy_growth: default_energy_growth(),
        }
    }
}

fn default_mass() -> f32 {
    1e-3
}
fn default_damping() -> f32 {
    0.995
}
fn default_gravity() -> Vec3 {
    Vec3::new(0.0, -9.81, 0.0)
}
fn default_normal() -> Vec3 {
    Vec3::Y
}
fn default_substeps() -> u32 {
    16
}
fn default_true() -> bool {
    true
}
fn default_one() -> f32 {
    1.0
}
fn default_drag() -> f32 {
    0.6
}
fn default_epsilon() -> f32 {
    0.01
}
fn default_friction() -> f32 {
    0.3
}
fn default_max_stretch() -> f32 {
    10.0
}
fn default_energy_growth() -> f32 {
    100.0
}

/// More substeps than this is a typo, not an intent (and a frame would take minutes).
pub const MAX_SUBSTEPS: u32 = 100_000;
/// More particles than this would be minutes per frame on the CPU path.
pub const MAX_PARTICLES: u64 = 1 << 22;

impl ClothParams {
    /// Checks one frame's inputs, for both simulator paths: a positive frame duration, and
    /// start fields matching the end fields when they are blended. Returns whether they are.
    pub fn frame_blend(&self, dt_frame: f32, n_start: usize, n_end: usize) -> Result<bool> {
        if !(dt_frame.is_finite() && dt_frame > 0.0) {
            return Err(Error::Invalid(format!(
                "cloth: frame duration {dt_frame} must be a positive finite number"
            )));
        }
        let blend = self.blend_fields && n_start > 0;
        if blend && n_start != n_end {
            return Err(Error::Invalid(format!(
                "cloth: {n_start} start fields for {n_end} end fields; pass one per collider, or none"
            )));
        }
        Ok(blend)
    }

    /// A collider field (its far value in world units, its band in cells) must reach
    /// beyond ε, or contact would never be seen.
    pub fn check_band(&self, far_value: f32, band: f32) -> Result<()> {
        let eps = self.collision.epsilon;
        if eps >= far_value {
            return Err(Error::Invalid(format!(
                "cloth: collision.epsilon {eps} is not inside the collider field's band \
                 ({far_value} = {band} cells); widen the field's band or lower epsilon"
            )));
        }
        Ok(())
    }

    /// A params value with defaults for everything but the shape and the material.
    pub fn new(shape: Shape, material: Material) -> Self {
        ClothParams {
            shape,
            material,
            stiffness_mode: StiffnessMode::default(),
            mass: default_mass(),
            damping: default_damping(),
            gravity: default_gravity(),
            wind: None,
            pins: Vec::new(),
            collision: Collision::default(),
            substeps: default_substeps(),
            blend_fields: true,
            limits: Limits::default(),
        }
    }

    /// Checks every number before anything is allocated; errors name the field.
    pub fn validate(&self) -> Result<()> {
        match &self.shape {
            Shape::Grid {
                size,
                resolution,
                center,
                normal,
            } => {
                positive("shape.size[0]", size[0])?;
                positive("shape.size[1]", size[1])?;
                for (k, &r) in resolution.iter().enumerate() {
                    if r < 2 {
                        return Err(invalid(format!(
                            "shape.resolution[{k}] = {r}: a grid needs at least 2 particles per side"
                        )));
                    }
                }
                let n = resolution[0] as u64 * resolution[1] as u64;
                if n > MAX_PARTICLES {
                    return Err(invalid(format!(
                        "shape.resolution {resolution:?} gives {n} particles, more than the \
                         limit of {MAX_PARTICLES}; lower it"
                    )));
                }
                finite_vec("shape.center", *center)?;
                finite_vec("shape.normal", *normal)?;
                if normal.length_squared() < 1e-12 {
                    return Err(invalid("shape.normal must not be zero".into()));
                }
            }
            Shape::Mesh { path } => {
                if path.trim().is_empty() {
                    return Err(invalid("shape.path must not be empty".into()));
                }
            }
        }
        match &self.material {
            Material::Harada {
                k_structural,
                k_shear,
                k_bend,
            } => {
                non_negative("material.k_structural", *k_structural)?;
                non_negative("material.k_shear", *k_shear)?;
                if let Some(k) = k_bend {
                    non_negative("material.k_bend", *k)?;
                    if matches!(self.shape, Shape::Mesh { .. }) {
                        return Err(invalid(
                            "material.k_bend (skip-one springs) needs a Grid shape; a mesh's \
                             cross-edge shear springs already resist bending, or use Tokoi's \
                             bend_c"
                                .into(),
                        ));
                    }
                }
            }
            Material::Tokoi {
                a_compress,
                b_stretch,
                bend_c,
                anisotropy,
            } => {
                non_negative("material.a_compress", *a_compress)?;
                non_negative("material.b_stretch", *b_stretch)?;
                non_negative("material.bend_c", *bend_c)?;
                if let Some(a) = anisotropy {
                    if a.texture.trim().is_empty() {
                        return Err(invalid(
                            "material.anisotropy.texture must not be empty".into(),
                        ));
                    }
                    non_negative("material.anisotropy.scale", a.scale)?;
                }
            }
        }
        positive("mass", self.mass)?;
        if !(self.damping.is_finite() && self.damping > 0.0 && self.damping <= 1.0) {
            return Err(invalid(format!(
                "damping = {}: must be in (0, 1] (1 = undamped, 0.99 = light damping)",
                self.damping
            )));
        }
        finite_vec("gravity", self.gravity)?;
        if let Some(w) = &self.wind {
            finite_vec("wind.velocity", w.velocity)?;
            non_negative("wind.drag", w.drag)?;
        }
        for (k, pin) in self.pins.iter().enumerate() {
            if let Pin::Region { min, max } = pin {
                finite_vec(&format!("pins[{k}].min"), *min)?;
                finite_vec(&format!("pins[{k}].max"), *max)?;
                if min.cmpgt(*max).any() {
                    return Err(invalid(format!(
                        "pins[{k}]: region min {min} exceeds max {max} on some axis"
                    )));
                }
            }
        }
        positive("collision.epsilon", self.collision.epsilon)?;
        let b = self.collision.friction;
        if !(b.is_finite() && (0.0..=1.0).contains(&b)) {
            return Err(invalid(format!(
                "collision.friction = {b}: must be in [0, 1] (the fraction of the tangential \
                 displacement cancelled on contact)"
            )));
        }
        if let Some(h) = self.collision.ground
            && !h.is_finite()
        {
            return Err(invalid(format!("collision.ground = {h} is not finite")));
        }
        if self.substeps == 0 || self.substeps > MAX_SUBSTEPS {
            return Err(invalid(format!(
                "substeps = {}: must be between 1 and {MAX_SUBSTEPS}",
                self.substeps
            )));
        }
        if !(self.limits.max_stretch.is_finite() && self.limits.max_stretch > 1.0) {
            return Err(invalid(format!(
                "limits.max_stretch = {}: must be a finite number > 1",
                self.limits.max_stretch
            )));
        }
        if !(self.limits.energy_growth.is_finite() && self.limits.energy_growth > 1.0) {
            return Err(invalid(format!(
                "limits.energy_growth = {}: must be a finite number > 1",
                self.limits.energy_growth
            )));
        }
        Ok(())
    }

    /// The same material with every stiffness (springs and bending) multiplied by `s`.
    pub fn scale_stiffness(&mut self, s: f32) {
        match &mut self.material {
            Material::Harada {
                k_structural,
                k_shear,
                k_bend,
            } => {
                *k_structural *= s;
                *k_shear *= s;
                if let Some(k) = k_bend {
                    *k *= s;
                }
            }
            Material::Tokoi {
                a_compress,
                b_stretch,
                bend_c,
                ..
            } => {
                *a_compress *= s;
                *b_stretch *= s;
                *bend_c *= s;
            }
        }
    }
}

fn invalid(message: String) -> Error {
    Error::Invalid(format!("cloth: {message}"))
}

fn positive(field: &str, v: f32) -> Result<()> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(invalid(format!(
            "{field} = {v}: must be a positive finite number"
        )))
    }
}

fn non_negative(field: &str, v: f32) -> Result<()> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(invalid(format!(
            "{field} = {v}: must be a finite number >= 0"
        )))
    }
}

fn finite_vec(field: &str, v: Vec3) -> Result<()> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(invalid(format!("{field} = {v} is not finite")))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_a_pipeline_style_node_with_defaults() {
        let p: ClothParams = ron::from_str(
            r#"(shape: Grid(size: (1.2, 1.0), resolution: (70, 60), center: (0, 0.8, 0)),
                material: Harada(k_structural: 40, k_shear: 10),
                pins: [TopEdge, Indices([0, 5])],
                collision: (epsilon: 0.01, friction: 0.3, ground: 0.0),
                wind: (velocity: (1, 0, 0)))"#,
        )
        .unwrap();
        p.validate().unwrap();
        assert_eq!(p.substeps, 16);
        assert!(p.blend_fields);
        assert_eq!(p.collision.ground, Some(0.0));
        assert_eq!(p.wind.unwrap().drag, default_drag());
        let back: ClothParams = ron::from_str(&ron::to_string(&p).unwrap()).unwrap();
        assert_eq!(back, p);
    }

    #[test]
    fn parses_tokoi_with_a_texture() {
        let p: ClothParams = ron::from_str(
            r#"(shape: Mesh(path: "shirt.obj"),
                material: Tokoi(a_compress: 1, b_stretch: 400, bend_c: 1e-4,
                                anisotropy: (texture: "assets/textures/anisotropy_example.png")),
                stiffness_mode: Strain)"#,
        )
        .unwrap();
        p.validate().unwrap();
        assert_eq!(p.stiffness_mode, StiffnessMode::Strain);
    }

    #[test]
    fn unknown_fields_are_refused() {
        let e = ron::from_str::<ClothParams>(
            r#"(shape: Grid(size: (1, 1), resolution: (4, 4)),
                material: Harada(k_structural: 1, k_shear: 1), substep: 4)"#,
        )
        .unwrap_err();
        assert!(e.to_string().contains("substep"), "{e}");
    }

    #[test]
    fn errors_name_the_field() {
        let base = ClothParams::new(
            Shape::Grid {
                size: [1.0, 1.0],
                resolution: [4, 4],
                center: Vec3::ZERO,
                normal: Vec3::Y,
            },
            Material::Harada {
                k_structural: 1.0,
                k_shear: 1.0,
                k_bend: None,
            },
        );
        type Edit = Box<dyn Fn(&mut ClothParams)>;
        let cases: Vec<(Edit, &str)> = vec![
            (Box::new(|p| p.mass = 0.0), "mass"),
            (Box::new(|p| p.damping = 1.5), "damping"),
            (Box::new(|p| p.substeps = 0), "substeps"),
            (
                Box::new(|p| p.collision.friction = 2.0),
                "collision.friction",
            ),
            (
                Box::new(|p| p.collision.epsilon = -1.0),
                "collision.epsilon",
            ),
            (
                Box::new(|p| {
                    p.material = Material::Harada {
                        k_structural: f32::NAN,
                        k_shear: 1.0,
                        k_bend: None,
                    }
                }),
                "material.k_structural",
            ),
            (
                Box::new(|p| {
                    if let Shape::Grid { resolution, .. } = &mut p.shape {
                        *resolution = [1, 4];
                    }
                }),
                "shape.resolution[0]",
            ),
            (
                Box::new(|p| {
                    p.pins = vec![Pin::Region {
                        min: Vec3::ONE,
                        max: Vec3::ZERO,
                    }]
                }),
                "pins[0]",
            ),
        ];
        for (edit, field) in cases {
            let mut p = base.clone();
            edit(&mut p);
            let e = p.validate().unwrap_err().to_string();
            assert!(e.contains(field), "{field}: {e}");
        }
    }
}
