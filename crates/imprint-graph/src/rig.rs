//! Rig files: parsing and validating a rig (RON) with positions in errors (filled in by the rig work).
