//! The adaptive close-packed particle fill (T §(3)①) (filled in by the particle work).
