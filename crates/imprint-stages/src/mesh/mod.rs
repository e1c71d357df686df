//! Mesh source: written next.
