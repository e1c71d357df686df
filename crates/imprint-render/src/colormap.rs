//! Colour maps for scalar fields.
//!
//! - [`Colormap::Viridis`]: matplotlib's viridis (van der Walt & Smith), perceptually uniform
//!   and readable in grey and by most colour-blind readers; the default for distances, which
//!   run one way from 0.
//! - [`Colormap::Diverging`]: ColorBrewer RdBu (blue, white, red), for signed values around a
//!   centre (errors, differences): t = 0.5 is white.
//!
//! Both are tables of sRGB bytes, sampled with linear interpolation between entries; `t` is
//! clamped to [0, 1] (NaN reads as 0), so a caller never indexes out of the table.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Which colour map a picture uses (serde: `Viridis`, `Diverging`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
pub enum Colormap {
    #[default]
    Viridis,
    Diverging,
}

impl Colormap {
    /// The colour at `t` in [0, 1] (clamped).
    pub fn sample(self, t: f32) -> [u8; 3] {
        match self {
            Colormap::Viridis => sample_table(&VIRIDIS, t),
            Colormap::Diverging => sample_table(&RDBU, t),
        }
    }

    /// The table the map interpolates, first entry at t = 0, last at t = 1.
    pub fn table(self) -> &'static [[u8; 3]] {
        match self {
            Colormap::Viridis => &VIRIDIS,
            Colormap::Diverging => &RDBU,
        }
    }
}

/// Viridis at `t` in [0, 1] (clamped).
pub fn viridis(t: f32) -> [u8; 3] {
    Colormap::Viridis.sample(t)
}

/// Blue (0) - white (0.5) - red (1) at `t` (clamped).
pub fn diverging(t: f32) -> [u8; 3] {
    Colormap::Diverging.sample(t)
}

/// Linear interpolation between the two table entries around `t`, rounded to bytes.
fn sample_table(table: &[[u8; 3]], t: f32) -> [u8; 3] {
    let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
    let x = t * (table.len() - 1) as f32;
    let i = (x.floor() as usize).min(table.len() - 2);
    let f = x - i as f32;
    let (a, b) = (table[i], table[i + 1]);
    std::array::from_fn(|c| (a[c] as f32 + f * (b[c] as f32 - a[c] as f32)).round() as u8)
}

/// matplotlib's 256-entry viridis, as `rrggbb` hex (the same bytes d3 and matplotlib ship).
const VIRIDIS_HEX: &str = concat!(
    "44015444025645045745055946075a46085c460a5d460b5e470d60470e61471063471164471365481467481668481769",
    "48186a481a6c481b6d481c6e481d6f481f70482071482173482374482475482576482677482878482979472a7a472c7a",
    "472d7b472e7c472f7d46307e46327e46337f463480453581453781453882443983443a83443b84433d84433e85423f85",
    "4240864241864142874144874045884046883f47883f48893e49893e4a893e4c8a3d4d8a3d4e8a3c4f8a3c508b3b518b",
    "3b528b3a538b3a548c39558c39568c38588c38598c375a8c375b8d365c8d365d8d355e8d355f8d34608d34618d33628d",
    "33638d32648e32658e31668e31678e31688e30698e306a8e2f6b8e2f6c8e2e6d8e2e6e8e2e6f8e2d708e2d718e2c718e",
    "2c728e2c738e2b748e2b758e2a768e2a778e2a788e29798e297a8e297b8e287c8e287d8e277e8e277f8e27808e26818e",
    "26828e26828e25838e25848e25858e24868e24878e23888e23898e238a8d228b8d228c8d228d8d218e8d218f8d21908d",
    "21918c20928c20928c20938c1f948c1f958b1f968b1f978b1f988b1f998a1f9a8a1e9b8a1e9c891e9d891f9e891f9f88",
    "1fa0881fa1881fa1871fa28720a38620a48621a58521a68522a78522a88423a98324aa8325ab8225ac8226ad8127ad81",
    "28ae8029af7f2ab07f2cb17e2db27d2eb37c2fb47c31b57b32b67a34b67935b77937b87838b9773aba763bbb753dbc74",
    "3fbc7340bd7242be7144bf7046c06f48c16e4ac16d4cc26c4ec36b50c46a52c56954c56856c66758c7655ac8645cc863",
    "5ec96260ca6063cb5f65cb5e67cc5c69cd5b6ccd5a6ece5870cf5773d05675d05477d1537ad1517cd2507fd34e81d34d",
    "84d44b86d54989d5488bd6468ed64590d74393d74195d84098d83e9bd93c9dd93ba0da39a2da37a5db36a8db34aadc32",
    "addc30b0dd2fb2dd2db5de2bb8de29bade28bddf26c0df25c2df23c5e021c8e020cae11fcde11dd0e11cd2e21bd5e21a",
    "d8e219dae319dde318dfe318e2e418e5e419e7e419eae51aece51befe51cf1e51df4e61ef6e620f8e621fbe723fde725",
);

/// ColorBrewer RdBu, 11 classes, reversed so that t = 0 is blue (low) and t = 1 red (high).
const RDBU_HEX: &str = "0530612166ac4393c392c5ded1e5f0f7f7f7fddbc7f4a582d6604db2182b67001f";

/// The tables, decoded from hex at compile time.
pub const VIRIDIS: [[u8; 3]; 256] = decode_hex(VIRIDIS_HEX);
pub const RDBU: [[u8; 3]; 11] = decode_hex(RDBU_HEX);

const fn decode_hex<const N: usize>(hex: &str) -> [[u8; 3]; N] {
    const fn nibble(c: u8) -> u8 {
        match c {
            b'0'..=b'9' => c - b'0',
            b'a'..=b'f' => c - b'a' + 10,
            _ => panic!("colour table: not a lowercase hex digit"),
        }
    }
    let b = hex.as_bytes();
    assert!(b.len() == N * 6, "colour table: wrong length");
    let mut out = [[0u8; 3]; N];
    let mut i = 0;
    while i < N {
        let mut c = 0;
        while c < 3 {
            let at = 6 * i + 2 * c;
            out[i][c] = nibble(b[at]) * 16 + nibble(b[at + 1]);
            c += 1;
        }
        i += 1;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn endpoints_equal_the_table_and_clamp() {
        // Published viridis endpoints: #440154 and #fde725.
        assert_eq!(viridis(0.0), [0x44, 0x01, 0x54]);
        assert_eq!(viridis(1.0), [0xfd, 0xe7, 0x25]);
        assert_eq!(viridis(-3.0), VIRIDIS[0]);
        assert_eq!(viridis(7.0), VIRIDIS[255]);
        assert_eq!(viridis(f32::NAN), VIRIDIS[0]);
        assert_eq!(diverging(0.0), RDBU[0]);
        assert_eq!(diverging(1.0), RDBU[10]);
        assert_eq!(diverging(0.5), [0xf7, 0xf7, 0xf7], "the centre is white");
    }

    #[test]
    fn samples_hit_table_entries_and_interpolate_between() {
        // t = i / 255 lands exactly on entry i.
        for i in [1usize, 64, 128, 200, 254] {
            assert_eq!(viridis(i as f32 / 255.0), VIRIDIS[i], "entry {i}");
        }
        // Half-way between two entries is their mean.
        let mid = viridis(100.5 / 255.0);
        for c in 0..3 {
            let m = (VIRIDIS[100][c] as f32 + VIRIDIS[101][c] as f32) / 2.0;
            assert!((mid[c] as f32 - m).abs() <= 0.5 + 1e-3);
        }
    }

    #[test]
    fn viridis_gets_lighter_monotonically() {
        // Perceptual uniformity's visible half: luma never decreases along the map.
        let luma = |c: [u8; 3]| 0.2126 * c[0] as f32 + 0.7152 * c[1] as f32 + 0.0722 * c[2] as f32;
        for w in VIRIDIS.windows(2) {
            assert!(luma(w[1]) >= luma(w[0]) - 0.5, "{:?} -> {:?}", w[0], w[1]);
        }
    }
}
