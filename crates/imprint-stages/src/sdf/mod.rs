//! DistanceField (H §2, §6.2): a narrow band of half-width `a` cells around a discrete
//! boundary; per cell the distance to the nearest boundary point and which point it is.
//!
//! Semantics shared by both paths (the GPU path is tested against the CPU path):
//! a cell x is in the band when some boundary point p has |x - p| <= a (grid units); it keeps
//! the nearest such p, ties going to the smaller point index (= smaller surface-cell index).

pub mod cpu;
pub mod gpu;

pub use cpu::{FieldBuilder, build_field_cpu};
