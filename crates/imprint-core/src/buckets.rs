//! Items grouped by a small integer key, each group in the order the items came (a counting
//! sort): the voxeliser's and the error metric's triangles by slab, a mesh's edges by vertex,
//! the ground's cells by contour level.
//! Linear in the items, where a comparison sort is n log n, and stable, so a group of
//! increasing indices stays increasing.

use rayon::prelude::*;

/// Groups `0..len()` of `u32` items; group `b` is [`Buckets::of`]`(b)`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Buckets {
    /// Group b is `items[start[b]..start[b + 1]]`.
    start: Vec<usize>,
    items: Vec<u32>,
}

impl Buckets {
    /// The `(group, item)` pairs that `pairs()` yields, grouped into `groups` groups (every
    /// group below `groups`). `pairs` is called twice, to count and then to place, and must
    /// yield the same pairs both times.
    pub fn build<I>(groups: usize, pairs: impl Fn() -> I) -> Self
    where
        I: Iterator<Item = (usize, u32)>,
    {
        let mut start = vec![0usize; groups + 1];
        for (g, _) in pairs() {
            start[g + 1] += 1;
        }
        for g in 0..groups {
            start[g + 1] += start[g];
        }
        let mut fill = start.clone();
        let mut items = vec![0u32; start[groups]];
        for (g, item) in pairs() {
            items[fill[g]] = item;
            fill[g] += 1;
        }
        Buckets { start, items }
    }

    /// Group `g` of every part joined in the parts' order, the groups copied side by side
    /// (every part has `groups` groups; no parts: `groups` empty groups).
    pub fn join(groups: usize, parts: &[Buckets]) -> Self {
        assert!(
            parts.iter().all(|p| p.groups() == groups),
            "parts differ in groups"
        );
        let mut start = vec![0usize; groups + 1];
        for g in 0..groups {
            start[g + 1] = start[g] + parts.iter().map(|p| p.of(g).len()).sum::<usize>();
        }
        let mut items = vec![0u32; start[groups]];
        let mut rest = &mut items[..];
        let mut outs = Vec::with_capacity(groups);
        for g in 0..groups {
            let (out, after) = rest.split_at_mut(start[g + 1] - start[g]);
            outs.push(out);
            rest = after;
        }
        outs.into_par_iter().enumerate().for_each(|(g, out)| {
            let mut at = 0;
            for part in parts.iter().map(|p| p.of(g)) {
                out[at..at + part.len()].copy_from_slice(part);
                at += part.len();
            }
        });
        Buckets { start, items }
    }

    /// How many groups.
    pub fn groups(&self) -> usize {
        self.start.len().saturating_sub(1)
    }

    /// Group `g`'s items, in the order they came.
    #[inline]
    pub fn of(&self, g: usize) -> &[u32] {
        &self.items[self.start[g]..self.start[g + 1]]
    }

    /// Group `g`'s items, to reorder in place.
    #[inline]
    pub fn of_mut(&mut self, g: usize) -> &mut [u32] {
        &mut self.items[self.start[g]..self.start[g + 1]]
    }
}

#[cfg(test)]
mod tests {
    use super::Buckets;

    /// Against a plain filter: each group holds exactly its items, in the order they came,
    /// built whole or in parts joined (empty groups and parts included).
    #[test]
    fn groups_hold_their_items_in_order_whole_or_joined() {
        let mut seed = 99u32;
        let pairs: Vec<(usize, u32)> = (0..5000)
            .map(|i| {
                seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                (((seed >> 8) % 13) as usize, i)
            })
            .collect();
        let groups = 17; // the last four empty
        let whole = Buckets::build(groups, || pairs.iter().copied());
        let parts: Vec<Buckets> = [0..0, 0..1200, 1200..1201, 1201..5000]
            .into_iter()
            .map(|r| Buckets::build(groups, || pairs[r.clone()].iter().copied()))
            .collect();
        let joined = Buckets::join(groups, &parts);
        assert_eq!(Buckets::join(groups, &[]).groups(), groups);
        assert_eq!(whole, joined);
        assert_eq!(whole.groups(), groups);
        for g in 0..groups {
            let want: Vec<u32> = pairs.iter().filter(|p| p.0 == g).map(|p| p.1).collect();
            assert_eq!(whole.of(g), want.as_slice(), "group {g}");
        }
    }
}
