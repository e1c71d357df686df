//! Skinning weights for the blends: up to [`MAX_INFLUENCES`] (bone, weight) pairs per vertex,
//! summing to 1, most-weighted first (DQS takes its hemisphere from the first).
//!
//! **Automatic weights** ([`automatic`], [`WeightMethod::Distance`]): inverse-distance
//! weights to the bones' segments, w_b ∝ 1/d_b^power with d_b the distance from the vertex to
//! segment b, the 4 largest kept and renormalised. A vertex on a segment (d = 0) goes to that
//! bone alone. Higher powers give sharper joints; the default, 4, gives a vertex in the middle
//! of a limb's bone more than 0.95 for its own bone when the limb is slender (the radius
//! under about a third of the bone's half-length), and 0.5/0.5 on the joint plane
//! of a straight two-bone limb. Why not heat diffusion (Baran and Popović): it needs a
//! surface Laplacian and a visibility test per bone; distance weights are what the LBS/DQS
//! comparison needs (smooth, symmetric at a straight joint) and are exact to reason about.
//! Deterministic: per vertex, in f64, ties broken by bone index.

use glam::{DVec3, Vec3};
use imprint_core::{Error, Result};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// The most bones a vertex follows.
pub const MAX_INFLUENCES: usize = 4;

/// Per-vertex (bone index, weight) lists: at most 4, weights > 0 summing to 1, sorted by
/// weight (largest first), then bone index.
#[derive(Clone, Debug, PartialEq)]
pub struct Weights {
    start: Vec<u32>,
    entries: Vec<(u32, f32)>,
}

impl Weights {
    /// Vertex `v`'s influences, most-weighted first.
    pub fn of(&self, v: usize) -> &[(u32, f32)] {
        &self.entries[self.start[v] as usize..self.start[v + 1] as usize]
    }

    /// The number of vertices.
    pub fn len(&self) -> usize {
        self.start.len() - 1
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The bone vertex `v` follows most.
    pub fn main_bone(&self, v: usize) -> u32 {
        self.of(v)[0].0
    }

    /// Builds from per-vertex lists that are already valid (normalises, sorts, keeps 4).
    fn from_raw(lists: impl Iterator<Item = Vec<(u32, f64)>>) -> Weights {
        let mut start = vec![0u32];
        let mut entries = Vec::new();
        for mut list in lists {
            list.retain(|&(_, w)| w > 0.0);
            list.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
            list.truncate(MAX_INFLUENCES);
            let sum: f64 = list.iter().map(|e| e.1).sum();
            entries.extend(list.iter().map(|&(b, w)| (b, (w / sum) as f32)));
            start.push(entries.len() as u32);
        }
        Weights { start, entries }
    }
}

/// How [`automatic`] weighs bones.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub enum WeightMethod {
    /// w ∝ 1 / distance-to-segment^power.
    Distance {
        /// Exponent of the inverse distance (> 0); higher gives sharper joints.
        #[serde(default = "four")]
        power: f32,
    },
}

fn four() -> f32 {
    4.0
}

impl Default for WeightMethod {
    fn default() -> Self {
        WeightMethod::Distance { power: 4.0 }
    }
}

impl WeightMethod {
    pub fn validate(&self) -> Result<()> {
        match *self {
            WeightMethod::Distance { power } => {
                if !(power.is_finite() && power > 0.0) {
                    return Err(Error::Invalid(format!(
                        "weights Distance.power must be a finite number > 0, got {power} \
                         (4 is a good start; higher gives sharper joints)"
                    )));
                }
            }
        }
        Ok(())
    }
}

/// Automatic weights of `positions` to bones given as (head, tail) segments (at rest).
pub fn automatic(positions: &[Vec3], segments: &[(Vec3, Vec3)], method: &WeightMethod) -> Weights {
    assert!(
        !segments.is_empty(),
        "automatic weights need at least one bone"
    );
    let WeightMethod::Distance { power } = *method;
    let power = power as f64;
    let segs: Vec<(DVec3, DVec3)> = segments
        .iter()
        .map(|(a, b)| (a.as_dvec3(), b.as_dvec3()))
        .collect();
    Weights::from_raw(positions.iter().map(|p| {
        let p = p.as_dvec3();
        let d: Vec<f64> = segs
            .iter()
            .map(|&(a, b)| segment_distance(p, a, b))
            .collect();
        let scale = d.iter().fold(0.0f64, |m, &x| m.max(x)).max(1e-300);
        if let Some(on) = d.iter().position(|&x| x <= 1e-12 * scale) {
            return vec![(on as u32, 1.0)];
        }
        // Relative to the nearest distance, so no overflow for high powers.
        let near = d.iter().fold(f64::INFINITY, |m, &x| m.min(x));
        d.iter()
            .enumerate()
            .map(|(b, &x)| (b as u32, (near / x).powf(power)))
            .collect()
    }))
}

/// A file's weights (a glTF skin's, up to 8 per vertex): a bone listed twice counts once
/// with the sum of its weights, the [`MAX_INFLUENCES`] largest are kept and renormalised (a
/// vertex's lesser influences are dropped, as real-time engines do). Errors as
/// [`from_lists`]: bones out of range, weights not finite and ≥ 0, no positive weight.
pub fn from_influences(lists: &[Vec<(u32, f32)>], bones: usize) -> Result<Weights> {
    let merged: Vec<Vec<(u32, f32)>> = lists
        .iter()
        .map(|list| {
            let mut m: Vec<(u32, f32)> = Vec::with_capacity(list.len());
            for &(b, w) in list {
                match m.iter_mut().find(|e| e.0 == b) {
                    Some(e) => e.1 += w,
                    None => m.push((b, w)),
                }
            }
            m.retain(|e| e.1 != 0.0);
            m.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
            m.truncate(MAX_INFLUENCES);
            m
        })
        .collect();
    from_lists(&merged, bones)
}

/// Explicit weights: one list of (bone, weight) per vertex, at most 4 entries, weights finite
/// and ≥ 0 with a positive sum (normalised here), bones below `bones`.
pub fn from_lists(lists: &[Vec<(u32, f32)>], bones: usize) -> Result<Weights> {
    for (v, list) in lists.iter().enumerate() {
        let bad = |what: String| Err(Error::Invalid(format!("weights of vertex {v}: {what}")));
        if list.len() > MAX_INFLUENCES {
            return bad(format!(
                "{} bones, at most {MAX_INFLUENCES} allowed",
                list.len()
            ));
        }
        if let Some(&(b, _)) = list.iter().find(|e| e.0 as usize >= bones) {
            return bad(format!("bone index {b}, the rig has {bones} bones"));
        }
        if let Some(&(b, w)) = list.iter().find(|e| !(e.1.is_finite() && e.1 >= 0.0)) {
            return bad(format!("weight {w} for bone {b} must be finite and ≥ 0"));
        }
        for (i, e) in list.iter().enumerate() {
            if list[..i].iter().any(|o| o.0 == e.0) {
                return bad(format!("bone {} listed twice", e.0));
            }
        }
        if list.iter().map(|e| e.1 as f64).sum::<f64>() <= 0.0 {
            return bad("no positive weight; every vertex must follow some bone".into());
        }
    }
    Ok(Weights::from_raw(
        lists
            .iter()
            .map(|l| l.iter().map(|&(b, w)| (b, w as f64)).collect()),
    ))
}

/// Distance from p to the segment a–b.
fn segment_distance(p: DVec3, a: DVec3, b: DVec3) -> f64 {
    let ab = b - a;
    let len2 = ab.length_squared();
    let s = if len2 > 0.0 {
        ((p - a).dot(ab) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p - (a + s * ab)).length()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn explicit_weights_normalise_and_sort() {
        let w = from_lists(&[vec![(0, 1.0), (1, 3.0)], vec![(1, 2.0)]], 2).unwrap();
        assert_eq!(w.of(0), &[(1, 0.75), (0, 0.25)]);
        assert_eq!(w.of(1), &[(1, 1.0)]);
        assert_eq!(w.len(), 2);
        assert!(from_lists(&[vec![(2, 1.0)]], 2).is_err());
        assert!(from_lists(&[vec![(0, 0.0)]], 2).is_err());
        assert!(from_lists(&[vec![(0, 1.0); 5]], 8).is_err());
    }

    /// A file's lists: a bone listed twice counts once with the sum, the 4 largest of 6 are
    /// kept and renormalised, zero weights go; out-of-range bones are still refused.
    #[test]
    fn file_influences_merge_keep_four_and_renormalise() {
        let w = from_influences(
            &[
                vec![(3, 0.25), (1, 0.25), (3, 0.25), (0, 0.25)],
                vec![(0, 0.3), (1, 0.2), (2, 0.2), (3, 0.1), (4, 0.1), (5, 0.1)],
                vec![(0, 0.0), (2, 2.0)],
            ],
            6,
        )
        .unwrap();
        assert_eq!(w.of(0), &[(3, 0.5), (0, 0.25), (1, 0.25)]);
        let kept: Vec<u32> = w.of(1).iter().map(|e| e.0).collect();
        assert_eq!(kept, [0, 1, 2, 3]);
        let sum: f32 = w.of(1).iter().map(|e| e.1).sum();
        assert!((sum - 1.0).abs() < 1e-6 && (w.of(1)[0].1 - 0.375).abs() < 1e-6);
        assert_eq!(w.of(2), &[(2, 1.0)]);
        assert!(from_influences(&[vec![(6, 1.0)]], 6).is_err());
    }

    #[test]
    fn on_a_segment_follows_it_alone_and_the_joint_plane_splits_evenly() {
        let segs = [(Vec3::ZERO, Vec3::X), (Vec3::X, Vec3::new(2.0, 0.0, 0.0))];
        let w = automatic(
            &[Vec3::new(0.5, 0.0, 0.0), Vec3::new(1.0, 0.3, 0.0)],
            &segs,
            &WeightMethod::default(),
        );
        assert_eq!(w.of(0), &[(0, 1.0)]);
        assert_eq!(w.of(1), &[(0, 0.5), (1, 0.5)]);
    }
}
