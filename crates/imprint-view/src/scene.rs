//! What the viewer draws: the objects of the pipeline's Render node (so the view is the
//! offline frame), then every other mesh, height field and field the pipeline makes, hidden
//! at first; and the scene for the renderer from the executor's current values.

use glam::Vec3;
use imprint_core::{Aabb, HeightField, Mesh};
use imprint_graph::Executor;
use imprint_graph::Plan;
use imprint_graph::nodes::render::{CameraSpec, RenderNode, RenderObject};
use imprint_graph::schema::{NodeSpec, PortType};
use imprint_graph::value::Value;
use imprint_render::colormap::Colormap;
use imprint_render::frame::{GroundGrid, Object, Scene, srgb_to_linear};
use imprint_render::slice::{Axis, SliceIndex};
use std::sync::Arc;

/// Colour bands of a height field coloured by height.
pub const BANDS: usize = 12;

#[derive(Clone, Debug, PartialEq)]
pub enum Look {
    Mesh {
        color: [f32; 3],
        wireframe: bool,
    },
    /// A field's grid plane along `axis`.
    Slice {
        axis: Axis,
        index: SliceIndex,
    },
    /// Lit in one colour, or coloured by height in [`BANDS`] bands with a legend.
    Heights {
        color: [f32; 3],
        wireframe: bool,
        by_height: bool,
    },
}

/// One thing the viewer can draw.
#[derive(Clone, Debug, PartialEq)]
pub struct ViewObject {
    /// The node whose value it shows.
    pub node: String,
    pub look: Look,
    pub visible: bool,
}

/// The heights shown, for the legend: bands from `min` to `max`.
#[derive(Clone, Debug, PartialEq)]
pub struct Legend {
    pub node: String,
    pub min: f32,
    pub max: f32,
    /// sRGB colour of each band, lowest first.
    pub colors: Vec<[u8; 3]>,
}

/// The first enabled Render node of the plan, if any.
pub fn render_node(plan: &Plan) -> Option<&RenderNode> {
    plan.file.nodes.values().find_map(|n| match n {
        NodeSpec::Render(r) if r.enabled => Some(r),
        _ => None,
    })
}

/// The camera the file sets, if it has a Render node.
pub fn file_camera(plan: &Plan) -> Option<&CameraSpec> {
    render_node(plan).map(|r| &r.camera)
}

/// The Render node's objects, shown, then the running producers it does not draw, hidden.
/// Visibility and slice positions the user chose in `previous` are kept.
pub fn objects(plan: &Plan, previous: &[ViewObject]) -> Vec<ViewObject> {
    let mut list: Vec<ViewObject> = render_node(plan)
        .map(|r| r.objects.iter().map(from_render).collect())
        .unwrap_or_default();
    let no_render = list.is_empty();
    for name in &plan.producers {
        let spec = &plan.file.nodes[name];
        let look = match spec.output() {
            Some(PortType::Mesh) => Look::Mesh {
                color: [0.7, 0.7, 0.72],
                wireframe: false,
            },
            Some(PortType::HeightField) => Look::Heights {
                color: [0.55, 0.6, 0.5],
                wireframe: false,
                by_height: true,
            },
            Some(PortType::DistanceField) => Look::Slice {
                axis: Axis::Z,
                index: SliceIndex::Middle,
            },
            Some(PortType::Boundary) | None => continue,
        };
        if !list.iter().any(|o| &o.node == name) {
            let visible = no_render && !matches!(look, Look::Slice { .. });
            list.push(ViewObject {
                node: name.clone(),
                look,
                visible,
            });
        }
    }
    for o in &mut list {
        if let Some(p) = previous
            .iter()
            .find(|p| p.node == o.node && same_kind(p, o))
        {
            o.visible = p.visible;
            keep_user_choices(&mut o.look, &p.look);
        }
    }
    list
}

fn same_kind(a: &ViewObject, b: &ViewObject) -> bool {
    std::mem::discriminant(&a.look) == std::mem::discriminant(&b.look)
}

/// What the panel sets and the file does not: the slice position, colouring by height.
fn keep_user_choices(look: &mut Look, before: &Look) {
    match (look, before) {
        (Look::Slice { axis, index }, Look::Slice { axis: a, index: i }) => {
            (*axis, *index) = (*a, *i);
        }
        (Look::Heights { by_height, .. }, Look::Heights { by_height: b, .. }) => *by_height = *b,
        _ => {}
    }
}

fn from_render(o: &RenderObject) -> ViewObject {
    let rgb = |c: (f32, f32, f32)| [c.0, c.1, c.2];
    let (node, look) = match o {
        RenderObject::Mesh {
            mesh,
            color,
            wireframe,
        } => (
            mesh,
            Look::Mesh {
                color: rgb(*color),
                wireframe: *wireframe,
            },
        ),
        RenderObject::FieldSlice { field, axis, index } => (
            field,
            Look::Slice {
                axis: *axis,
                index: *index,
            },
        ),
        RenderObject::HeightField {
            heights,
            color,
            wireframe,
        } => (
            heights,
            Look::Heights {
                color: rgb(*color),
                wireframe: *wireframe,
                by_height: false,
            },
        ),
    };
    ViewObject {
        node: node.clone(),
        look,
        visible: true,
    }
}

/// The scene of the visible objects from the executor's current values (objects without a
/// value yet are skipped), with the legend of the first height field coloured by height.
pub fn scene(
    ex: &Executor,
    objects: &[ViewObject],
    grid: bool,
) -> imprint_core::Result<(Scene, Option<Legend>)> {
    let mut scene = Scene {
        ground_grid: grid.then(GroundGrid::default),
        ..Default::default()
    };
    let mut legend = None;
    for o in objects.iter().filter(|o| o.visible) {
        let Some(value) = ex.value(&o.node) else {
            continue;
        };
        match (&o.look, value) {
            (Look::Mesh { color, wireframe }, Value::Mesh(m)) => {
                scene.objects.push(Object::Mesh {
                    mesh: m,
                    color: *color,
                    wireframe: *wireframe,
                });
            }
            (Look::Slice { axis, index }, Value::Field(f)) => {
                scene.objects.push(Object::FieldSlice {
                    field: f.cpu(ex.gpu())?,
                    axis: *axis,
                    index: *index,
                    colormap: Colormap::Viridis,
                });
            }
            (look @ Look::Heights { .. }, Value::Heights(h)) => {
                let made = height_objects(&o.node, look, &h);
                scene.objects.extend(made.0);
                legend = legend.or(made.1);
            }
            _ => {}
        }
    }
    Ok((scene, legend))
}

/// A height field as one lit mesh, or as [`BANDS`] meshes, one per height band.
fn height_objects(node: &str, look: &Look, h: &HeightField) -> (Vec<Object>, Option<Legend>) {
    let Look::Heights {
        color,
        wireframe,
        by_height,
    } = *look
    else {
        return (Vec::new(), None);
    };
    let mesh = h.to_mesh();
    if !by_height {
        let o = Object::Mesh {
            mesh: Arc::new(mesh),
            color,
            wireframe,
        };
        return (vec![o], None);
    }
    let (min, max) = mesh
        .positions
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), p| {
            (a.min(p.y), b.max(p.y))
        });
    let span = (max - min).max(1e-9);
    let mut bands: Vec<Vec<[u32; 3]>> = vec![Vec::new(); BANDS];
    for t in &mesh.triangles {
        let y = t.iter().map(|&i| mesh.positions[i as usize].y).sum::<f32>() / 3.0;
        let b = (((y - min) / span) * BANDS as f32) as usize;
        bands[b.min(BANDS - 1)].push(*t);
    }
    let colors: Vec<[u8; 3]> = (0..BANDS)
        .map(|b| Colormap::Viridis.sample((b as f32 + 0.5) / BANDS as f32))
        .collect();
    let objects = bands
        .into_iter()
        .zip(&colors)
        .filter(|(tris, _)| !tris.is_empty())
        .map(|(triangles, c)| Object::Mesh {
            mesh: Arc::new(Mesh {
                positions: mesh.positions.clone(),
                triangles,
                ..Mesh::default()
            }),
            color: c.map(srgb_to_linear),
            wireframe,
        })
        .collect();
    let legend = Legend {
        node: node.to_string(),
        min,
        max,
        colors,
    };
    (objects, Some(legend))
}

/// The box around every mesh and height field value (to frame a pipeline with no camera).
pub fn bounds(ex: &Executor, objects: &[ViewObject]) -> Option<Aabb> {
    let mut b: Option<Aabb> = None;
    let mut add = |p: Vec3| {
        let a = b.get_or_insert(Aabb { min: p, max: p });
        a.min = a.min.min(p);
        a.max = a.max.max(p);
    };
    for o in objects {
        match ex.value(&o.node) {
            Some(Value::Mesh(m)) => m.positions.iter().for_each(|p| add(*p)),
            Some(Value::Heights(h)) => h.to_mesh().positions.iter().for_each(|p| add(*p)),
            _ => {}
        }
    }
    b
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{UVec2, Vec2};

    #[test]
    fn heights_coloured_by_height_split_into_bands_that_keep_every_triangle() {
        // A ramp from 0 to 1.1 along x: every band gets triangles, lowest band lowest.
        let dims = UVec2::new(24, 4);
        let heights = (0..dims.y)
            .flat_map(|_| (0..dims.x).map(|x| x as f32 * 1.1 / 23.0))
            .collect();
        let h = HeightField::new(Vec2::ZERO, 0.1, dims, heights).unwrap();
        let look = Look::Heights {
            color: [1.0; 3],
            wireframe: false,
            by_height: true,
        };
        let (objects, legend) = height_objects("ground", &look, &h);
        let legend = legend.unwrap();
        assert_eq!((legend.min, legend.max), (0.0, 1.1));
        assert_eq!(legend.colors.len(), BANDS);
        assert_eq!(objects.len(), BANDS);
        let triangles: Vec<&Mesh> = objects
            .iter()
            .map(|o| match o {
                Object::Mesh { mesh, .. } => mesh.as_ref(),
                _ => panic!("bands are meshes"),
            })
            .collect();
        let total: usize = triangles.iter().map(|m| m.triangles.len()).sum();
        assert_eq!(total, h.to_mesh().triangles.len());
        let mean_y = |m: &Mesh| {
            let ys = m
                .triangles
                .iter()
                .flatten()
                .map(|&i| m.positions[i as usize].y);
            ys.sum::<f32>() / (3 * m.triangles.len()) as f32
        };
        assert!(mean_y(triangles[0]) < mean_y(triangles[BANDS - 1]));
        // One colour when not coloured by height, and no legend.
        let plain = Look::Heights {
            color: [1.0; 3],
            wireframe: false,
            by_height: false,
        };
        let (objects, legend) = height_objects("ground", &plain, &h);
        assert_eq!((objects.len(), legend), (1, None));
    }
}
