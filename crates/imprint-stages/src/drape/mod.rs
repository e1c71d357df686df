//! Drape: pushing a garment out of a body with depth maps (T §(2)④, docs/methods.md §4).
//!
//! **Inputs.** A body (any triangle mesh, possibly deforming: each call renders it afresh,
//! unless [`drape_cached`]'s cache holds that body, positions and triangles bit for bit) and a
//! garment: any set of points (a mesh's positions, a cloth's particles), moved in place.
//! One call is a one-shot fit ([`drape_cpu`]); the same maps, dilated by the cloth's ε and
//! read every substep, are a collider for the cloth ([`collider`]).
//!
//! **T's method.** For each view direction d (T: top, front, back; orthographic) render the
//! body's depth seen along d (its front surface) and seen along −d (its back surface). A
//! garment vertex is inside the body along that view when its depth lies behind both; it is
//! pushed out to the nearer of the two surfaces. Cost O(vertices) after the renders. T reports
//! that the chest still penetrated: the maps hold the first surface from each side only, so
//! where the body has several layers along a view (an arm in front of the chest) the nearer
//! "surface" can be the far side of another part, and the vertex jumps through it.
//!
//! **Where T is thin, our choices.**
//! - *The maps.* Per view line (opposite directions give the same pair of maps, so T's
//!   three views render four), two square `resolution`² maps from
//!   [`crate::snow::arrival::snow_camera`] (the body's box with a texel to spare), rendered by
//!   `imprint_core::raster` with both faces drawn (no culling), so the first surface from each
//!   side whatever the winding.
//! - *Seen inside along a view.* The texel the vertex projects into (nearest) is covered in
//!   both maps and the vertex lies strictly behind both surfaces. The push goes to the nearer
//!   surface, plus `offset`, along ∓d. The surface depth used is the smallest covered depth of
//!   the 2×2 texels around the projection: near silhouettes the surface's depth changes by
//!   several texels across one texel, and the smallest lands the vertex outside where the
//!   nearest texel's depth can leave it just inside (a push up to a texel × slope too long).
//! - *Among views*, the vertex takes the shortest push (as T), even when it is a bad one.
//! - *Inside* (the truth). An exact test: the parity of a ray's surface crossings, by majority
//!   of the three axis rays ([`inside::InsideTest`]; a point exactly on the surface is
//!   outside). Only vertices inside by this test move: a vertex outside the body moves by
//!   exactly 0, even where T's test would call it inside (in a gap between two layers). The test assumes a closed body; for an open one "inside"
//!   means little and neither do the counts. (The distance field cannot say it: it is
//!   unsigned.) The drape builds the test without its far-cell grid
//!   ([`InsideTest::rays_only`]): the garment lies near the surface, where the grid seldom
//!   answers.
//! - *Resolved.* An inside vertex is resolved by the views when its shortest view push
//!   leaves the body cleanly: the straight path to half a texel past the pushed point crosses
//!   the surface once and ends outside (by the inside test). For a push along an axis (the
//!   default views') the crossings are exact: those of the inside test's ray along that axis,
//!   where crossings closer than 10⁻³ texel (or 8 f32 ulps of the coordinates) are one place
//!   and cancel in pairs (a face two touching pieces share is crossed twice: no change). Where
//!   that ray disagrees with the test's vote at the vertex, and for other directions, the path
//!   is sampled every half texel instead: never inside again once outside, the last sample
//!   outside (gaps thinner than half a texel are not seen). So a push that jumps through a gap
//!   and another part of the body (T's chest) is not a resolution, nor one that stays inside.
//! - *Unresolved.* An inside vertex no view resolves: no view sees it inside (its texel
//!   uncovered at a silhouette, or the vertex less than about a texel deep, in front of the
//!   surface its texel centre sees), or the shortest push stays inside or tunnels. Unresolved
//!   vertices are left where they are and counted ([`DrapeReport::unresolved_by_views`]).
//! - *Fallback (beyond T).* With [`Fallback::DistanceField`], the body's distance field (the
//!   voxel and sdf stages) is built and each unresolved vertex is pushed to the surface plus
//!   `offset`, along the first of two candidates that leaves cleanly (the same check, every
//!   half cell or texel, whichever is smaller): toward the closest point of the triangles the
//!   8 cells around it own (the `Closest` boundary keeps each cell's triangle; evaluated at
//!   the vertex itself it is exact where one of them is the vertex's nearest triangle), then
//!   along the field's blended closest-point vector. The blended vector alone fails near
//!   edges: a turned box's vertex 0.001 inside, next to an edge, got a vector twice that long
//!   pointing inward. Only a vertex that leaves cleanly is moved. Vertices deeper than the
//!   band, or with no clean candidate, stay unresolved ([`DrapeReport::unresolved`]).
//!
//! **Accuracy.** A pushed vertex ends within about a texel of the surface along its push
//! (the maps' depth is sampled at texel centres; the 2×2 minimum errs outward). The push is
//! along a view axis, not along the normal, so near a silhouette of the chosen view a
//! vertex lands well away from where a radial (closest-point) projection would put it.
//!
//! **Cost.** Per body: 2 renders per distinct view line, with the inside test's three axis
//! bins (O(triangles)) built alongside; [`drape_cached`] keeps them for the next call on the
//! same body (a static body draped every frame; each Drape node holds its own [`BodyCache`]),
//! [`drape_cpu`] and [`drape_with`] do not. Per garment vertex an
//! inside test (three short triangle lists, whose crossings are kept); per inside vertex one
//! lookup per view and the clean-exit check: for an axis push the crossings along it are
//! those kept, plus at most two lists at the end and two at the pushed point (the self-check),
//! else O(push length / texel) inside tests. The field is built only when the fallback is on
//! and some vertex needs it.
//!
//! **Determinism.** Every vertex is decided on its own from the maps and the mesh; counts and
//! the maximum are gathered in vertex order: the result is the same on any thread count.

pub mod body;
pub mod collider;
pub mod cpu;
pub mod inside;
pub mod params;

pub use body::{DepthBody, DepthBodyState};
pub use collider::{DepthCamera, DepthCollider, DepthColliderParams, DepthPose};
pub use cpu::{
    BodyCache, DrapeReport, Push, Rasterize, body_field, drape_cached, drape_cpu, drape_with,
};
pub use inside::InsideTest;
pub use params::{DrapeParams, Fallback};
