//! When each node computes: the per-node `every`, `offset`, `split` and `interpolate` of the
//! pipeline file, as arithmetic on frame numbers (the executor asks; `imprint check` prints).
//!
//! - **Keyframes** are the frames where (frame − offset) mod every = 0. A compute node
//!   computes on a keyframe when one of its inputs changed since it last computed (and always
//!   on the run's first frame, so that its consumers have something); in between, consumers
//!   reuse its last result, at most `every − 1` frames old.
//! - **Split** spreads a build over `split` frames: keyframe K's parts run on frames
//!   K … K + split − 1, all from the inputs as they were at K, and the result appears on the
//!   last of them (`split − 1` frames after K).
//! - **Interpolate** (fields): consumers of frame f see the linear blend of the builds at the
//!   two keyframes around it, so the builds must exist before they are needed: keyframe K is
//!   first needed on frame K − every + 1 (when the cloth starts stepping from K − every toward
//!   K), and its parts run on the `split` frames ending there, from the mesh at K's own time.
//!   The blend adds no lag; it costs a third field in memory while the next build is under way.

/// A node's schedule. Frames are signed: an interpolated node's first segment may start at
/// a keyframe before frame 0 (its mesh is a function of time, so that is fine).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Schedule {
    pub every: u32,
    pub offset: u32,
    pub split: u32,
    pub interpolate: bool,
}

impl Default for Schedule {
    fn default() -> Self {
        Schedule {
            every: 1,
            offset: 0,
            split: 1,
            interpolate: false,
        }
    }
}

impl Schedule {
    /// Keyframes every `every` frames from `offset`, whole builds, no interpolation.
    pub fn every(every: u32, offset: u32) -> Self {
        Schedule {
            every,
            offset,
            ..Schedule::default()
        }
    }

    fn k(&self) -> i64 {
        self.every.max(1) as i64
    }

    /// Whether (frame − offset) mod every = 0.
    pub fn is_key(&self, frame: i64) -> bool {
        (frame - self.offset as i64).rem_euclid(self.k()) == 0
    }

    /// The latest keyframe at or before `frame`.
    pub fn key_at_or_before(&self, frame: i64) -> i64 {
        frame - (frame - self.offset as i64).rem_euclid(self.k())
    }

    /// Without interpolation: the keyframe whose build has a part on `frame`, and which part
    /// (0-based); parts of keyframe K run on K … K + split − 1.
    pub fn part_at(&self, frame: i64) -> Option<(i64, u32)> {
        let key = self.key_at_or_before(frame);
        let part = frame - key;
        (part < self.split as i64).then_some((key, part as u32))
    }

    /// With interpolation: the segment [a, a + every] whose blend the consumers of `frame`
    /// see, and the weight of its end. The segment holds the whole step from frame − 1 to
    /// frame (what the cloth integrates over); on the run's `first` frame, frame itself.
    pub fn segment(&self, frame: i64, first: i64) -> (i64, f32) {
        let t = if frame == first { frame } else { frame - 1 };
        let a = self.key_at_or_before(t);
        (a, (frame - a) as f32 / self.k() as f32)
    }

    /// With interpolation: the keyframe whose build has a part on `frame`, and which part:
    /// keyframe K is first needed on frame K − every + 1, and its parts run on the `split`
    /// frames ending there.
    pub fn ahead_part_at(&self, frame: i64) -> Option<(i64, u32)> {
        let (k, s) = (self.k(), self.split as i64);
        (0..s)
            .map(|p| (frame + k + s - 2 - p, p as u32))
            .find(|&(key, _)| self.is_key(key))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(every: u32, offset: u32, split: u32, interpolate: bool) -> Schedule {
        Schedule {
            every,
            offset,
            split,
            interpolate,
        }
    }

    #[test]
    fn keyframes_follow_every_and_offset() {
        let sc = s(4, 1, 1, false);
        let keys: Vec<i64> = (0..12).filter(|&f| sc.is_key(f)).collect();
        assert_eq!(keys, [1, 5, 9]);
        assert_eq!(sc.key_at_or_before(0), -3);
        assert_eq!(sc.key_at_or_before(8), 5);
    }

    #[test]
    fn split_parts_run_on_the_frames_after_each_keyframe() {
        let sc = s(4, 0, 3, false);
        let parts: Vec<Option<(i64, u32)>> = (0..9).map(|f| sc.part_at(f)).collect();
        assert_eq!(
            parts,
            [
                Some((0, 0)),
                Some((0, 1)),
                Some((0, 2)),
                None,
                Some((4, 0)),
                Some((4, 1)),
                Some((4, 2)),
                None,
                Some((8, 0))
            ]
        );
    }

    #[test]
    fn interpolated_builds_finish_the_frame_they_are_first_needed() {
        let sc = s(4, 0, 2, true);
        // Frames 1..=4 step from 0 to 4: segment [0, 4]; frame 5 steps from 4: [4, 8].
        assert_eq!(sc.segment(0, 0), (0, 0.0));
        assert_eq!(sc.segment(1, 0), (0, 0.25));
        assert_eq!(sc.segment(4, 0), (0, 1.0));
        assert_eq!(sc.segment(5, 0), (4, 0.25));
        // Keyframe 8 is first needed on frame 5: its two parts run on frames 4 and 5.
        assert_eq!(sc.ahead_part_at(4), Some((8, 0)));
        assert_eq!(sc.ahead_part_at(5), Some((8, 1)));
        assert_eq!(sc.ahead_part_at(6), None);
        assert_eq!(sc.ahead_part_at(7), None);
        assert_eq!(sc.ahead_part_at(8), Some((12, 0)));
        // Unsplit: the build runs on the frame it is first needed.
        let one = s(4, 0, 1, true);
        assert_eq!(one.ahead_part_at(5), Some((8, 0)));
        assert_eq!(one.ahead_part_at(4), None);
    }
}
