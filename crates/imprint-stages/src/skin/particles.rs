//! Particle-based skinning: forces, leap-frog, vertices following particles (filled in by the particle work).
