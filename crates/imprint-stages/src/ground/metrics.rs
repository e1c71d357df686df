//! What a ground frame reports. Volumes come twice: exact, in height units summed over cells
//! (one unit over one cell; what the conservation tests compare), and in m³.

use serde::Serialize;

/// One frame of the ground stage.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct GroundFrameMetrics {
    pub frame: u32,
    /// Cells where an object's bottom was below the ground.
    pub contact_cells: u32,
    /// Deepest inner contour value: how many rings deep the contact is.
    pub max_contour: u32,
    /// Ground pressed out of the contact cells: the objects' penetrating volume
    /// (Σ ground − bottom over the contact cells).
    pub removed_units: i64,
    pub removed_volume: f64,
    /// Of that, what was pushed to the rim (α of it, less anything with no cell outside the
    /// contact to go to); the rest was compressed away.
    pub displaced_units: i64,
    pub displaced_volume: f64,
    /// Σ heights after the frame: constant while α = 1.
    pub mass_units: i64,
    pub mass_volume: f64,
    /// Cells the outer contour map labelled (the slump's domain in `Labelled` mode).
    pub labelled_cells: u32,
    /// Cell visits of the slump, summed over its passes (`Settle`: cells taken off the work
    /// list; `Labelled`: the cells of each ring per pass; `Full`: the cells of the region
    /// swept per iteration).
    pub slump_visits: u64,
    /// Slump passes run: 1 for `Settle` (one work list), at most En in `Labelled` (fewer
    /// when one moves nothing), the iterations to rest in `Full`.
    pub slump_iterations: u32,
    /// Material the slump moved, units.
    pub slumped_units: i64,
    /// Steepest rise over run between 4-neighbours after the frame, over the edges the slump
    /// is responsible for: between labelled cells (`Labelled`), between any two cells not
    /// held under an object (`Full`), or between a cell the settle's work list took this
    /// frame and a neighbour not held (`Settle`; none at θ = 90°). 0 when there are none.
    pub max_slope: f32,
}
