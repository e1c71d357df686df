//! Checkpoints of stage state. Every stateful stage (`ClothSim`, `GroundSim`, `SnowSim`,
//! `ParticleSkin`, a `FieldBuild` under way) derives serde's traits over all its fields, so
//! serialising it (the executor uses `postcard`), loading it and stepping on gives the same
//! bytes as never having stopped. Floats travel as their bits in binary formats.
//!
//! Pipeline parameters are written for people: optional fields are bare and left out when
//! `None` (`crate::bare_option`), which only self-describing formats read back. A sim that
//! holds such parameters stores them through [`ron_text`].

/// Serde `with` module for a value whose serde form needs a self-describing format (the
/// stage parameters, see the module doc): in a human-readable format (RON, JSON) it is
/// written as itself; in a binary one (postcard) as its RON text, which reads back exactly
/// (RON writes each float's shortest round-trip form).
pub mod ron_text {
    use serde::de::{DeserializeOwned, Error as _};
    use serde::ser::Error as _;
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    pub fn serialize<S: Serializer, T: Serialize>(v: &T, s: S) -> Result<S::Ok, S::Error> {
        if s.is_human_readable() {
            v.serialize(s)
        } else {
            let text = ron::to_string(v).map_err(S::Error::custom)?;
            s.serialize_str(&text)
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>, T: DeserializeOwned>(
        d: D,
    ) -> Result<T, D::Error> {
        if d.is_human_readable() {
            T::deserialize(d)
        } else {
            let text = String::deserialize(d)?;
            ron::from_str(&text).map_err(D::Error::custom)
        }
    }
}

#[cfg(test)]
mod tests;
