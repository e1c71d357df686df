//! The Ground node's parameters as a pipeline file states them, their defaults and their
//! validation (every error names the field to change).
//!
//! ```ron
//! (size: (2.56, 2.56), resolution: (256, 256), initial: Flat(0.1), material: Preset(Sand))
//! ```

use glam::Vec2;
use imprint_core::{Error, Result};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Everything the ground stage needs besides the objects of the frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct GroundParams {
    /// Extent of the field along x and z, m. Cells are square, so
    /// `size[0] / resolution[0]` must equal `size[1] / resolution[1]`.
    pub size: [f32; 2],
    /// Cells along x and z (O uses 256 × 256). One cell is one pixel of the contact view.
    pub resolution: [u32; 2],
    /// World (x, z) of the centre of cell (0, 0), as in `imprint_core::HeightField`;
    /// omitted: the field is centred on the world origin.
    #[serde(
        default,
        with = "crate::bare_option",
        skip_serializing_if = "Option::is_none"
    )]
    #[schemars(with = "[f32; 2]")]
    pub origin: Option<Vec2>,
    /// The ground before the first frame.
    #[serde(default)]
    pub initial: Initial,
    /// How the ground gives way: a preset of O §3 or custom values.
    #[serde(default)]
    pub material: Material,
    /// How the ground slumps after the press: [`Relaxation::Settle`] (the default: to rest
    /// wherever the ground changed), [`Relaxation::Labelled`] (O's En passes over this
    /// frame's labelled cells) or [`Relaxation::Full`] (the whole field, by sweeps).
    #[serde(default)]
    pub relaxation: Relaxation,
    /// Rings of cells around the contact that the outer contour map labels (O §2.4), the rim
    /// included: the slump of [`Relaxation::Labelled`] moves material no farther out than
    /// this. O gives no number; 16 holds the rim of a sand print several cells high. The
    /// other relaxations are not bounded by it.
    #[serde(default = "default_slump_band")]
    pub slump_band: u32,
    /// The fixed-point unit of heights, m: heights are whole multiples of it (`i32`), so
    /// material is moved in whole units and mass (the sum of the heights) is conserved
    /// exactly. 1e-5 m (10 µm) holds heights up to about 21 km.
    #[serde(default = "default_height_unit")]
    pub height_unit: f64,
    /// The bound on one frame's relaxation, past which it stops with an error (the ground
    /// left as it was at the frame's start): [`Relaxation::Full`], sweeps of its region;
    /// [`Relaxation::Settle`], work-list visits per cell of the field.
    #[serde(default = "default_max_relax_iterations")]
    pub max_relax_iterations: u32,
}

/// The ground before the first frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub enum Initial {
    /// Every cell at this height above the base plane, m (≥ 0).
    Flat(f32),
    /// A grayscale PNG (8- or 16-bit) with one pixel per cell: pixel (i, j) is cell (i, k = j),
    /// so the image is the field seen from above with +x to the right and +z down. Height =
    /// `base + scale * value / max_value`, m.
    Image {
        /// Relative to the pipeline file's folder.
        path: String,
        /// Height of a white pixel above `base`, m.
        scale: f32,
        /// Height of a black pixel, m (≥ 0).
        #[serde(default)]
        base: f32,
    },
}

impl Default for Initial {
    fn default() -> Self {
        Initial::Flat(0.1)
    }
}

/// How the ground gives way (O §2.3, §2.5).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(rename = "GroundMaterial")]
#[serde(deny_unknown_fields)]
pub enum Material {
    /// O §3's parameter sets.
    Preset(Preset),
    Custom {
        /// θ: the steepest slope the slump leaves between neighbouring cells, degrees in
        /// (0, 90]; 90 = no slump (walls stand).
        repose_degrees: f32,
        /// En: slump passes per frame of [`Relaxation::Labelled`] (the other relaxations run
        /// to rest and do not read it).
        slump_iterations: u32,
        /// α in [0, 1]: the fraction of the pressed-out ground pushed to the rim; the rest is
        /// compressed away. 1 conserves mass exactly.
        displace_ratio: f32,
    },
}

impl Default for Material {
    fn default() -> Self {
        Material::Preset(Preset::Sand)
    }
}

/// O §3's two grounds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
pub enum Preset {
    /// θ = 90°, En = 0, α = 0: clean-walled prints, no rim.
    Snow,
    /// θ = 30°, En = 5, α = 1: rims that slump.
    Sand,
}

/// A material's numbers, whether from a preset or custom.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct MaterialValues {
    pub repose_degrees: f32,
    pub slump_iterations: u32,
    pub displace_ratio: f32,
}

impl Material {
    pub fn values(&self) -> MaterialValues {
        match *self {
            Material::Preset(Preset::Snow) => MaterialValues {
                repose_degrees: 90.0,
                slump_iterations: 0,
                displace_ratio: 0.0,
            },
            Material::Preset(Preset::Sand) => MaterialValues {
                repose_degrees: 30.0,
                slump_iterations: 5,
                displace_ratio: 1.0,
            },
            Material::Custom {
                repose_degrees,
                slump_iterations,
                displace_ratio,
            } => MaterialValues {
                repose_degrees,
                slump_iterations,
                displace_ratio,
            },
        }
    }
}

/// How and where the ground slumps after the press. One field chooses it; the material's θ
/// sets the slope for all three, and En (`slump_iterations`) counts only for `Labelled`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
pub enum Relaxation {
    /// The default: after every frame, no two 4-neighbouring cells that no object holds
    /// (neither in contact this frame) differ by more than tan θ · cell plus one height unit,
    /// wherever the ground changed (this frame's window around the contact, the cells the
    /// last frame's contact released, what `add_heights` changed), not only this frame's
    /// labelled cells. A FIFO work list from those cells slides whole units from a cell down
    /// a path of lower neighbours, levelled to a ramp of slope θ in one move, until nothing
    /// is too steep (`ground::settle`); its cost grows with the cells that move, and
    /// `max_relax_iterations` bounds it. Material pushed against a body higher than the
    /// body's top spills over it to the far side, so no cell rises above the highest start
    /// height plus the body's height while the body presses. Ground that never changed (e.g.
    /// a steep initial heightmap) is not touched.
    #[default]
    Settle,
    /// O §2.5 as published: `slump_iterations` (En) passes over the labelled cells around
    /// this frame's contact only, ring by ring from the rim outward. Its limitation: En
    /// passes cannot carry away what a dragged body pushes ahead of it, and an old rim that
    /// leaves the labelled region is never slumped again, so a dragged body can leave single
    /// cells metres tall (`tests/tests/ground_settle.rs` measures it).
    Labelled,
    /// The same slope rule over the whole field, in every direction, iterated until nothing
    /// moves (at most `max_relax_iterations`): the converged answer O's shortcut approximates.
    Full,
}

/// More cells per side than the contact view can rasterise.
pub const MAX_RESOLUTION: u32 = imprint_core::raster::MAX_SIZE;
/// More slump passes per frame than this is a typo, not an intent.
pub const MAX_SLUMP_ITERATIONS: u32 = 10_000;
/// Headroom kept above the highest initial height, in units: rims grow above it.
const HEADROOM_UNITS: i64 = 1 << 30;

fn default_slump_band() -> u32 {
    16
}
fn default_height_unit() -> f64 {
    1e-5
}
fn default_max_relax_iterations() -> u32 {
    100_000
}

impl GroundParams {
    /// A field of `resolution` cells centred on the origin, with defaults for the rest.
    pub fn new(size: [f32; 2], resolution: [u32; 2], material: Material) -> Self {
        GroundParams {
            size,
            resolution,
            origin: None,
            initial: Initial::default(),
            material,
            relaxation: Relaxation::default(),
            slump_band: default_slump_band(),
            height_unit: default_height_unit(),
            max_relax_iterations: default_max_relax_iterations(),
        }
    }

    /// Edge length of a cell, m.
    pub fn cell(&self) -> f32 {
        self.size[0] / self.resolution[0] as f32
    }

    /// World (x, z) of the centre of cell (0, 0).
    pub fn origin(&self) -> Vec2 {
        self.origin.unwrap_or_else(|| {
            let c = self.cell();
            -0.5 * Vec2::new(
                (self.resolution[0] - 1) as f32 * c,
                (self.resolution[1] - 1) as f32 * c,
            )
        })
    }

    /// Checks every number before anything is allocated; errors name the field.
    pub fn validate(&self) -> Result<()> {
        for k in 0..2 {
            let (size, r) = (self.size[k], self.resolution[k]);
            require(
                size.is_finite() && size > 0.0,
                &format!("size[{k}]"),
                size,
                POSITIVE,
            )?;
            let rule = format!("in 1..={MAX_RESOLUTION}");
            require(
                (1..=MAX_RESOLUTION).contains(&r),
                &format!("resolution[{k}]"),
                r,
                &rule,
            )?;
        }
        let (cx, cz) = (
            self.size[0] as f64 / self.resolution[0] as f64,
            self.size[1] as f64 / self.resolution[1] as f64,
        );
        if (cx - cz).abs() > 1e-5 * cx {
            return Err(invalid(format!(
                "size {:?} over resolution {:?} gives cells {cx} m along x but {cz} m along z; \
                 cells must be square (make size[1] = {})",
                self.size,
                self.resolution,
                cx * self.resolution[1] as f64
            )));
        }
        if let Some(o) = self.origin {
            require(o.is_finite(), "origin", o, "finite")?;
        }
        let height = |field: &str, h: f32| {
            require(
                h.is_finite() && h >= 0.0,
                field,
                h,
                "finite and >= 0 (above the base plane)",
            )
        };
        match &self.initial {
            Initial::Flat(h) => height("initial (Flat)", *h)?,
            Initial::Image { path, scale, base } => {
                require(!path.trim().is_empty(), "initial.path", path, "not empty")?;
                require(
                    scale.is_finite() && *scale > 0.0,
                    "initial.scale",
                    scale,
                    POSITIVE,
                )?;
                height("initial.base", *base)?;
            }
        }
        let m = self.material.values();
        let (t, a) = (m.repose_degrees, m.displace_ratio);
        let steep = t.is_finite() && t > 0.0 && t <= 90.0;
        require(
            steep,
            "material.repose_degrees",
            t,
            "in (0, 90] (90: walls stand)",
        )?;
        let rule = format!("at most {MAX_SLUMP_ITERATIONS}");
        let passes = m.slump_iterations;
        require(
            passes <= MAX_SLUMP_ITERATIONS,
            "material.slump_iterations",
            passes,
            &rule,
        )?;
        let ratio = a.is_finite() && (0.0..=1.0).contains(&a);
        let rule = "in [0, 1] (the fraction of the pressed-out ground pushed to the rim)";
        require(ratio, "material.displace_ratio", a, rule)?;
        let band = self.slump_band;
        let rule = format!("in 1..={MAX_RESOLUTION} rings");
        require(
            (1..=MAX_RESOLUTION).contains(&band),
            "slump_band",
            band,
            &rule,
        )?;
        let (u, cell) = (self.height_unit, self.cell() as f64);
        let rule = format!("in [1e-9, cell size {cell}] m");
        require(
            u.is_finite() && u >= 1e-9 && u <= cell,
            "height_unit",
            u,
            &rule,
        )?;
        let cap = self.max_relax_iterations;
        require(cap > 0, "max_relax_iterations", cap, "at least 1")
    }

    /// Checks that `max_height` (m) leaves room in the fixed-point heights for rims above it.
    pub fn check_height_range(&self, max_height: f64) -> Result<()> {
        let units = max_height / self.height_unit;
        if units > (i32::MAX as i64 - HEADROOM_UNITS) as f64 {
            return Err(invalid(format!(
                "height_unit = {}: the highest initial height {max_height} m is {units:.3e} \
                 units, more than the {} the fixed-point heights hold with headroom; raise \
                 height_unit",
                self.height_unit,
                i32::MAX as i64 - HEADROOM_UNITS
            )));
        }
        Ok(())
    }
}

pub(super) fn invalid(message: String) -> Error {
    Error::Invalid(format!("ground: {message}"))
}

const POSITIVE: &str = "a positive finite number";

/// `Ok` when `ok`; otherwise an error naming the field, its value and the rule it breaks.
fn require(ok: bool, field: &str, value: impl std::fmt::Debug, rule: &str) -> Result<()> {
    ok.then_some(())
        .ok_or_else(|| invalid(format!("{field} = {value:?}: must be {rule}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_a_pipeline_style_node_with_defaults() {
        let p: GroundParams = ron::from_str(
            r#"(size: (2.56, 1.28), resolution: (256, 128), material: Preset(Snow),
                initial: Image(path: "dunes.png", scale: 0.2), origin: (0, 0))"#,
        )
        .unwrap();
        p.validate().unwrap();
        assert_eq!(p.material.values().repose_degrees, 90.0);
        assert_eq!(p.relaxation, Relaxation::Settle);
        assert_eq!(p.height_unit, 1e-5);
        assert_eq!(p.origin(), Vec2::ZERO);
        assert!((p.cell() - 0.01).abs() < 1e-7);
        let back: GroundParams = ron::from_str(&ron::to_string(&p).unwrap()).unwrap();
        assert_eq!(back, p);

        let c: GroundParams = ron::from_str(
            r#"(size: (1, 1), resolution: (4, 4), relaxation: Full,
                material: Custom(repose_degrees: 45, slump_iterations: 3, displace_ratio: 0.5))"#,
        )
        .unwrap();
        c.validate().unwrap();
        assert_eq!(c.initial, Initial::Flat(0.1));
        assert_eq!(c.origin(), Vec2::splat(-0.375));
        assert_eq!(c.material.values().slump_iterations, 3);
    }

    #[test]
    fn unknown_fields_are_refused() {
        let e = ron::from_str::<GroundParams>(r#"(size: (1, 1), resolution: (4, 4), band: 3)"#)
            .unwrap_err();
        assert!(e.to_string().contains("band"), "{e}");
    }

    #[test]
    fn errors_name_the_field() {
        let base = GroundParams::new([1.0, 1.0], [8, 8], Material::Preset(Preset::Sand));
        base.validate().unwrap();
        let custom = |t: f32, n: u32, a: f32| Material::Custom {
            repose_degrees: t,
            slump_iterations: n,
            displace_ratio: a,
        };
        let with = |edit: &dyn Fn(&mut GroundParams)| {
            let mut p = base.clone();
            edit(&mut p);
            p
        };
        let image = Initial::Image {
            path: "a.png".into(),
            scale: 0.0,
            base: 0.0,
        };
        let cases = [
            ("size[1]", with(&|p| p.size[1] = 0.0)),
            ("resolution[0]", with(&|p| p.resolution[0] = 0)),
            ("square", with(&|p| p.size = [1.0, 2.0])),
            (
                "origin",
                with(&|p| p.origin = Some(Vec2::new(f32::NAN, 0.0))),
            ),
            ("initial", with(&|p| p.initial = Initial::Flat(-1.0))),
            ("initial.scale", with(&|p| p.initial = image.clone())),
            (
                "material.repose_degrees",
                with(&|p| p.material = custom(0.0, 1, 1.0)),
            ),
            (
                "material.repose_degrees",
                with(&|p| p.material = custom(95.0, 1, 1.0)),
            ),
            (
                "material.displace_ratio",
                with(&|p| p.material = custom(30.0, 1, 1.5)),
            ),
            (
                "material.slump_iterations",
                with(&|p| p.material = custom(30.0, u32::MAX, 1.0)),
            ),
            ("slump_band", with(&|p| p.slump_band = 0)),
            ("height_unit", with(&|p| p.height_unit = 0.0)),
            (
                "max_relax_iterations",
                with(&|p| p.max_relax_iterations = 0),
            ),
        ];
        for (field, p) in cases {
            let e = p.validate().unwrap_err().to_string();
            assert!(e.contains(field), "{field}: {e}");
        }
        let e = base.check_height_range(1e6).unwrap_err().to_string();
        assert!(e.contains("height_unit"), "{e}");
        base.check_height_range(10.0).unwrap();
    }
}
