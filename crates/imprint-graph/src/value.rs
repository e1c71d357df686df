//! The values that flow along edges, kept by producer name and by type: a node reads its
//! inputs through typed handles made when its stage was built (after the plan checked every
//! edge's type), so a read never re-checks a type.
//!
//! A value stays where its producer made it: a GPU field is read back to the CPU only when a
//! CPU consumer asks for it, once per published value.

use imprint_core::{Boundary, DistanceField, Error, HeightField, Mesh, Result};
use imprint_gpu::GpuContext;
use imprint_stages::sdf::gpu::GpuField;
use imprint_stages::voxel::gpu::GpuBoundary;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::sync::{Arc, OnceLock};

/// A value a node publishes.
#[derive(Clone)]
pub enum Value {
    Mesh(Arc<Mesh>),
    Boundary(BoundaryValue),
    Field(Arc<FieldValue>),
    Heights(Arc<HeightField>),
}

impl Value {
    /// Where the value is not finite, if anywhere (a value on the GPU is not looked at).
    pub fn first_non_finite(&self) -> Option<String> {
        self.first_non_finite_since(None)
    }

    /// [`Value::first_non_finite`], looking only at the fields `before` (the node's last
    /// value, already checked) did not hold: an interpolated field publishes the blend of the
    /// same two builds frame after frame, and scanning both (4 M distances for 128³) each
    /// frame cost more than the frame's blend weight changes.
    pub fn first_non_finite_since(&self, before: Option<&Value>) -> Option<String> {
        let checked = |f: &Arc<DistanceField>| match before {
            Some(Value::Field(v)) => match &v.data {
                FieldData::Cpu(g) => Arc::ptr_eq(f, g),
                FieldData::Blend { a, b, .. } => Arc::ptr_eq(f, a) || Arc::ptr_eq(f, b),
                FieldData::Gpu(_) => false,
            },
            _ => false,
        };
        match self {
            Value::Mesh(m) => {
                let i = m.positions.iter().position(|p| !p.is_finite())?;
                Some(format!("vertex {i} is at {}", m.positions[i]))
            }
            Value::Heights(h) => {
                let i = first_non_finite(&h.heights)?;
                let (x, z) = (i as u32 % h.dims.x, i as u32 / h.dims.x);
                Some(format!("the height of cell ({x}, {z}) is {}", h.heights[i]))
            }
            Value::Field(f) => match &f.data {
                FieldData::Cpu(f) if checked(f) => None,
                FieldData::Cpu(f) => {
                    let i = first_non_finite(&f.dist)?;
                    Some(format!("the distance in cell {i} is {}", f.dist[i]))
                }
                FieldData::Blend { a, b, .. } => {
                    let (f, i) = [a, b]
                        .into_iter()
                        .filter(|f| !checked(f))
                        .find_map(|f| Some((f, first_non_finite(&f.dist)?)))?;
                    Some(format!("the distance in cell {i} is {}", f.dist[i]))
                }
                FieldData::Gpu(_) => None,
            },
            Value::Boundary(BoundaryValue::Cpu(b)) => {
                let i = b.points.iter().position(|p| !p.is_finite())?;
                Some(format!("boundary point {i} is at {}", b.points[i]))
            }
            Value::Boundary(BoundaryValue::Gpu(_)) => None,
        }
    }
}

/// The first element of `v` that is not finite. A block of 64 at a time is tested with no
/// early exit, which vectorises: the executor checks every value it publishes (a 128³
/// field's 2 M distances each frame), and the element-by-element search took 0.4 ms a field.
fn first_non_finite(v: &[f32]) -> Option<usize> {
    let block = v
        .chunks(64)
        .position(|c| c.iter().fold(false, |bad, x| bad | !x.is_finite()))?;
    let at = block * 64;
    Some(at + v[at..].iter().position(|x| !x.is_finite())?)
}

#[derive(Clone)]
pub enum BoundaryValue {
    Cpu(Arc<Boundary>),
    Gpu(Arc<GpuBoundary>),
}

impl BoundaryValue {
    /// The boundary on the CPU (read back if it is on the GPU).
    pub fn cpu(&self, gpu: Option<&GpuContext>) -> Result<Arc<Boundary>> {
        match self {
            BoundaryValue::Cpu(b) => Ok(b.clone()),
            BoundaryValue::Gpu(g) => Ok(Arc::new(g.to_cpu(need_gpu(gpu)?)?)),
        }
    }
}

/// A distance field as its producer made it.
pub enum FieldData {
    Cpu(Arc<DistanceField>),
    Gpu(Arc<GpuField>),
    /// The blend of the builds at keyframes `a_key` and `a_key + every`, with `weight` on the
    /// second (an interpolated field node, H eq. 13-14).
    Blend {
        a: Arc<DistanceField>,
        b: Arc<DistanceField>,
        a_key: i64,
        every: u32,
        weight: f32,
    },
}

/// A distance field and, once a CPU consumer asked, its CPU copy (a read-back or a blend).
pub struct FieldValue {
    pub data: FieldData,
    cpu: OnceLock<Arc<DistanceField>>,
}

impl FieldValue {
    pub fn new(data: FieldData) -> Arc<Self> {
        Arc::new(FieldValue {
            data,
            cpu: OnceLock::new(),
        })
    }

    /// The CPU field itself when nobody else holds this value or its field (its buffers can
    /// then be reused), else the value back.
    pub fn try_take(this: Arc<Self>) -> std::result::Result<DistanceField, Arc<Self>> {
        let unshared = Arc::strong_count(&this) == 1
            && matches!(&this.data, FieldData::Cpu(f) if Arc::strong_count(f) == 1);
        if !unshared {
            return Err(this);
        }
        match Arc::try_unwrap(this) {
            Ok(FieldValue {
                data: FieldData::Cpu(f),
                ..
            }) => Arc::try_unwrap(f).map_err(|f| FieldValue::new(FieldData::Cpu(f))),
            Ok(v) => Err(Arc::new(v)),
            Err(v) => Err(v),
        }
    }

    /// The field on the CPU: computed once per value (a GPU read-back or a blend).
    pub fn cpu(&self, gpu: Option<&GpuContext>) -> Result<Arc<DistanceField>> {
        if let Some(f) = self.cpu.get() {
            return Ok(f.clone());
        }
        let f = match &self.data {
            // Not cached: the producer reuses an unshared field's buffers.
            FieldData::Cpu(f) => return Ok(f.clone()),
            FieldData::Gpu(g) => Arc::new(g.to_cpu(need_gpu(gpu)?)?),
            FieldData::Blend { a, b, weight, .. } => Arc::new(DistanceField::blend(a, b, *weight)?),
        };
        Ok(self.cpu.get_or_init(|| f).clone())
    }
}

fn need_gpu(gpu: Option<&GpuContext>) -> Result<&GpuContext> {
    gpu.ok_or_else(|| Error::Run("a GPU value without a GPU context".into()))
}

macro_rules! handle {
    ($(#[$doc:meta])* $name:ident) => {
        $(#[$doc])*
        #[derive(Clone, Debug)]
        pub struct $name(String);
        impl $name {
            pub fn new(node: &str) -> Self {
                $name(node.to_string())
            }
            pub fn node(&self) -> &str {
                &self.0
            }
        }
    };
}

handle!(
    /// A Mesh input.
    MeshIn
);
handle!(
    /// A Boundary input.
    BoundaryIn
);
handle!(
    /// A DistanceField input.
    FieldIn
);
handle!(
    /// A HeightField input.
    HeightsIn
);

/// Every node's current value, by type and name.
#[derive(Clone, Default)]
pub struct Values {
    meshes: BTreeMap<String, Arc<Mesh>>,
    boundaries: BTreeMap<String, BoundaryValue>,
    fields: BTreeMap<String, Arc<FieldValue>>,
    heights: BTreeMap<String, Arc<HeightField>>,
}

/// A producer read before it produced: the executor's order is wrong (a bug, not bad input).
fn missing(node: &str) -> Error {
    Error::Run(format!(
        "internal: node '{node}' was read before it produced a value"
    ))
}

impl Values {
    pub fn mesh(&self, h: &MeshIn) -> Result<&Arc<Mesh>> {
        self.meshes.get(h.node()).ok_or_else(|| missing(h.node()))
    }
    pub fn meshes(&self, hs: &[MeshIn]) -> Result<Vec<Arc<Mesh>>> {
        hs.iter().map(|h| self.mesh(h).cloned()).collect()
    }
    pub fn boundary(&self, h: &BoundaryIn) -> Result<&BoundaryValue> {
        self.boundaries
            .get(h.node())
            .ok_or_else(|| missing(h.node()))
    }
    pub fn field(&self, h: &FieldIn) -> Result<&Arc<FieldValue>> {
        self.fields.get(h.node()).ok_or_else(|| missing(h.node()))
    }
    pub fn heights(&self, h: &HeightsIn) -> Result<&Arc<HeightField>> {
        self.heights.get(h.node()).ok_or_else(|| missing(h.node()))
    }

    /// Whether `node` has published a value.
    pub fn has(&self, node: &str) -> bool {
        self.get(node).is_some()
    }

    /// `node`'s value, whatever its type.
    pub fn get(&self, node: &str) -> Option<Value> {
        if let Some(m) = self.meshes.get(node) {
            return Some(Value::Mesh(m.clone()));
        }
        if let Some(b) = self.boundaries.get(node) {
            return Some(Value::Boundary(b.clone()));
        }
        if let Some(f) = self.fields.get(node) {
            return Some(Value::Field(f.clone()));
        }
        self.heights.get(node).map(|h| Value::Heights(h.clone()))
    }

    pub fn set(&mut self, node: &str, value: Value) {
        let n = node.to_string();
        match value {
            Value::Mesh(m) => self.meshes.insert(n, m).map(drop),
            Value::Boundary(b) => self.boundaries.insert(n, b).map(drop),
            Value::Field(f) => self.fields.insert(n, f).map(drop),
            Value::Heights(h) => self.heights.insert(n, h).map(drop),
        };
    }

    /// Takes `node`'s value out (to lend it to the node for a frame).
    pub fn take(&mut self, node: &str) -> Option<Value> {
        if let Some(m) = self.meshes.remove(node) {
            return Some(Value::Mesh(m));
        }
        if let Some(b) = self.boundaries.remove(node) {
            return Some(Value::Boundary(b));
        }
        if let Some(f) = self.fields.remove(node) {
            return Some(Value::Field(f));
        }
        self.heights.remove(node).map(Value::Heights)
    }

    /// Forgets `node`'s value (it is rebuilt).
    pub fn remove(&mut self, node: &str) {
        self.meshes.remove(node);
        self.boundaries.remove(node);
        self.fields.remove(node);
        self.heights.remove(node);
    }

    /// Every value on the CPU, for a checkpoint.
    pub fn snapshot(&self, gpu: Option<&GpuContext>) -> Result<ValuesSnapshot> {
        let mut fields = BTreeMap::new();
        for (n, f) in &self.fields {
            let snap = match &f.data {
                FieldData::Blend {
                    a,
                    b,
                    a_key,
                    every,
                    weight,
                } => FieldSnapshot::Blend {
                    a: Box::new((**a).clone()),
                    b: Box::new((**b).clone()),
                    a_key: *a_key,
                    every: *every,
                    weight: *weight,
                },
                _ => FieldSnapshot::One(Box::new((*f.cpu(gpu)?).clone())),
            };
            fields.insert(n.clone(), snap);
        }
        let mut boundaries = BTreeMap::new();
        for (n, b) in &self.boundaries {
            boundaries.insert(n.clone(), (*b.cpu(gpu)?).clone());
        }
        Ok(ValuesSnapshot {
            meshes: self
                .meshes
                .iter()
                .map(|(n, m)| (n.clone(), (**m).clone()))
                .collect(),
            boundaries,
            fields,
            heights: self
                .heights
                .iter()
                .map(|(n, h)| (n.clone(), (**h).clone()))
                .collect(),
        })
    }

    /// The values a snapshot holds (all on the CPU; GPU consumers upload them).
    pub fn from_snapshot(s: ValuesSnapshot) -> Self {
        Values {
            meshes: s
                .meshes
                .into_iter()
                .map(|(n, m)| (n, Arc::new(m)))
                .collect(),
            boundaries: s
                .boundaries
                .into_iter()
                .map(|(n, b)| (n, BoundaryValue::Cpu(Arc::new(b))))
                .collect(),
            fields: s
                .fields
                .into_iter()
                .map(|(n, f)| (n, FieldValue::new(f.into_data())))
                .collect(),
            heights: s
                .heights
                .into_iter()
                .map(|(n, h)| (n, Arc::new(h)))
                .collect(),
        }
    }
}

/// [`Values`] as a checkpoint stores them.
#[derive(Clone, Serialize, Deserialize)]
pub struct ValuesSnapshot {
    meshes: BTreeMap<String, Mesh>,
    boundaries: BTreeMap<String, Boundary>,
    fields: BTreeMap<String, FieldSnapshot>,
    heights: BTreeMap<String, HeightField>,
}

#[derive(Clone, Serialize, Deserialize)]
enum FieldSnapshot {
    /// Boxed, as the two below (serde writes a box as what it holds).
    One(Box<DistanceField>),
    /// Boxed: two fields beside one.
    Blend {
        a: Box<DistanceField>,
        b: Box<DistanceField>,
        a_key: i64,
        every: u32,
        weight: f32,
    },
}

impl FieldSnapshot {
    fn into_data(self) -> FieldData {
        match self {
            FieldSnapshot::One(f) => FieldData::Cpu(Arc::new(*f)),
            FieldSnapshot::Blend {
                a,
                b,
                a_key,
                every,
                weight,
            } => FieldData::Blend {
                a: Arc::new(*a),
                b: Arc::new(*b),
                a_key,
                every,
                weight,
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{UVec2, Vec2, Vec3};

    /// The block search finds the first non-finite element wherever it is: in the first or
    /// a later block of 64, at a block's edge, in a short last block, with later ones too.
    #[test]
    fn the_first_non_finite_element_is_found_in_any_block() {
        for len in [0, 1, 63, 64, 65, 200] {
            let clean = vec![1.5f32; len];
            assert_eq!(first_non_finite(&clean), None);
            for at in [0, 1, 62, 63, 64, 127, 128, 199]
                .into_iter()
                .filter(|&a| a < len)
            {
                for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
                    let mut v = clean.clone();
                    v[at] = bad;
                    v[len - 1] = f32::NAN;
                    assert_eq!(first_non_finite(&v), Some(at), "len {len}, at {at}");
                }
            }
        }
    }

    #[test]
    fn non_finite_values_are_found_and_named() {
        let mut mesh = Mesh {
            positions: vec![Vec3::ZERO, Vec3::new(1.0, f32::NAN, 0.0)],
            ..Default::default()
        };
        let v = Value::Mesh(Arc::new(mesh.clone()));
        assert!(v.first_non_finite().unwrap().starts_with("vertex 1 is at"));
        mesh.positions[1].y = 2.0;
        assert_eq!(Value::Mesh(Arc::new(mesh)).first_non_finite(), None);
        let h = HeightField::new(Vec2::ZERO, 0.1, UVec2::new(2, 2), vec![0.0; 4]).unwrap();
        let mut bad = h.clone();
        bad.heights[3] = f32::INFINITY;
        assert_eq!(Value::Heights(Arc::new(h)).first_non_finite(), None);
        let said = Value::Heights(Arc::new(bad)).first_non_finite().unwrap();
        assert_eq!(said, "the height of cell (1, 1) is inf");
    }

    /// A blend's builds are looked at unless the node's last value held them: a new build
    /// with a bad cell is found whichever end it is, beside a build already checked.
    #[test]
    fn a_blend_is_checked_where_its_builds_are_new() {
        let spec = imprint_core::GridSpec::new(Vec3::ZERO, 0.1, glam::UVec3::splat(4)).unwrap();
        let field = |bad: bool| {
            let mut f = DistanceField::from_closest_points(spec, 2.0, |p| p.with_x(0.0));
            if bad {
                f.dist[37] = f32::NAN;
            }
            Arc::new(f)
        };
        let blend = |a: &Arc<DistanceField>, b: &Arc<DistanceField>| {
            Value::Field(FieldValue::new(FieldData::Blend {
                a: a.clone(),
                b: b.clone(),
                a_key: 0,
                every: 4,
                weight: 0.5,
            }))
        };
        let (good, bad, next) = (field(false), field(true), field(false));
        let said = "the distance in cell 37 is NaN";
        // Nothing before: both ends are scanned.
        for v in [blend(&good, &bad), blend(&bad, &good)] {
            assert_eq!(v.first_non_finite_since(None).as_deref(), Some(said));
        }
        // The segment moved on: `next` is new and clean, `good` was checked.
        let last = blend(&good, &good);
        assert_eq!(
            blend(&good, &next).first_non_finite_since(Some(&last)),
            None
        );
        // A new bad build beside a checked one is found, at either end.
        assert_eq!(
            blend(&good, &bad)
                .first_non_finite_since(Some(&last))
                .as_deref(),
            Some(said)
        );
        assert_eq!(
            blend(&bad, &good)
                .first_non_finite_since(Some(&last))
                .as_deref(),
            Some(said)
        );
        // A build the last value held is not scanned again (here a bad one, to show it).
        let held = blend(&bad, &good);
        assert_eq!(blend(&bad, &next).first_non_finite_since(Some(&held)), None);
        let one = Value::Field(FieldValue::new(FieldData::Cpu(bad.clone())));
        assert_eq!(one.first_non_finite_since(Some(&held)), None);
        assert_eq!(
            one.first_non_finite_since(Some(&last)).as_deref(),
            Some(said)
        );
    }
}
