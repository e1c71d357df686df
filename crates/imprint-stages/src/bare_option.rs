//! `Option<T>` written as a bare `T` in pipeline files (and left out when `None`), so files
//! need no `Some(..)` whether or not the reader enables RON's `implicit_some`. Used by every
//! stage's params as `#[serde(default, with = "crate::bare_option")]`.

use serde::{Deserialize, Deserializer, Serialize, Serializer};

pub fn serialize<S: Serializer, T: Serialize>(v: &Option<T>, s: S) -> Result<S::Ok, S::Error> {
    match v {
        Some(v) => v.serialize(s),
        None => s.serialize_none(),
    }
}

pub fn deserialize<'de, D: Deserializer<'de>, T: Deserialize<'de>>(
    d: D,
) -> Result<Option<T>, D::Error> {
    T::deserialize(d).map(Some)
}
