//! Automatic skinning weights (filled in by the rig work).
